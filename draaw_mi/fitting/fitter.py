"""Inverse fitting: recover material parameters (roughness, metallic, colour, ...) from images.

``fit(scene, references, params=["mat.roughness", "mat.metallic"])`` renders the scene with a
differentiable (path-replay) integrator, compares it with one reference image per view, and
runs Adam on the named parameters (texture maps: :mod:`~draaw_mi.fitting.maps`). It runs in
four phases around a :class:`~draaw_mi.fitting.settings.FitSettings`:
:func:`~draaw_mi.fitting.settings.validate` (every argument, before anything renders),
:func:`_set_up` (references, views or captures, integrator, parameters: a
:class:`~draaw_mi.fitting.problem.FitProblem`), :func:`_iterate` (the Adam loop, each
iteration one render and gradient pass per view through the scene's render session) and
:func:`~draaw_mi.fitting.report.report` (the averaged values, written back into the caller's
scene, each capture's misfit, and the :class:`~draaw_mi.fitting.result.FitResult`).

How it stays robust and unbiased (see design.md §8, the guide §1b, §9, and
benchmarks/fit_accuracy.md, benchmarks/fit_cases.md for the measurements):

* **Valid ranges by projection.** After every Adam step each parameter is clipped to its
  range (roughness, metallic, specular, reflection, direct_to_scatter in [0, 1]; colours >= 0,
  or [0, 1] for ``base_color``). Projection rather than a sigmoid reparameterisation keeps the
  exact bounds reachable (metallic exactly 0 or 1) with no vanishing gradients near them.
* **Roughness in log space.** Adam moves ``log(roughness)``: a step is a relative change, so
  0.05 vs 0.03 resolves as finely as 0.5 vs 0.3. In linear space Adam overshoots small targets
  into the region below the alpha clamp (alpha = sqrt(r^4 + alpha_min^2)), where the gradient
  vanishes like r^3, and stays at 0. The log-space floor is ``0.6 * sqrt(alpha_min)`` (0.019
  by default): every roughness below it renders within 6 % of alpha_min, i.e. the same.
* **Adam with beta_2 = 0.9** (not 0.999). The gradient shrinks by orders of magnitude on the
  way to the optimum; with a long second-moment memory the early, large gradients keep the
  step tiny and the fit stalls wherever it is after a few dozen iterations (measured: 0.062
  instead of 0.05 after 150 iterations, with a gradient pointing down at SNR 2.7 per step).
* **Decorrelated, sanitised gradients.** Each iteration renders with a new seed and the
  adjoint pass with another (Mitsuba's ``seed_grad``), so ``2 (I - ref) dI`` is unbiased for
  the gradient of the expected loss. NaN/Inf gradient entries are zeroed before each step,
  so one bad sample cannot poison Adam's moments for the rest of the run.
* **One kernel per run.** Resolution, spp and the integrator stay fixed; only the seed (not
  baked into the kernel) and the parameter values (arrays) change, so the render kernels are
  compiled in a view's first two passes (the second records the replay) and then reused
  (``result.kernel_compiles`` counts those compiled later).
* **Replayed, not traced.** Each capture's render, loss and backward pass is one
  :meth:`~draaw_mi.rendering.session.Session.gradient_pass`, which replays a ``dr.freeze``
  recording after the capture's first passes where the scene can be recorded (not with a post
  chain, SDF objects or media): the SVBRDF benchmark's iterations take 0.51-0.73x the time
  they took when every pass was traced (``benchmarks/results/fit_iteration_cost.md``).
* **Noise-robust estimate.** The reported values are the average of the iterates over the last
  ``average_last`` fraction of the run (Polyak averaging), which removes most of the Monte Carlo
  jitter of the final iterate; the learning rate decays along a cosine to ``lr_final * lr``.
* **Non-linear losses see an averaged render** (``smooth``, on with a post chain or the l1
  loss). A non-linear map of a noisy render is biased: E[f(I)] != f(E[I]) (a clamped bloom
  moves metallic 0.6 -> 0.78). With ``smooth`` the chain receives a running mean of the recent
  renders (weight = current learning-rate fraction) that carries the current render's
  derivative: ``mean + (I - detach(I))``.
* **Exposure.** ``exposure="fit"`` compares ``s * image`` with the reference, where
  ``s = <ref, ref> / <image, ref>`` (detached) is recomputed every iteration: the fit becomes
  insensitive to a global exposure difference (the scale is reported in stops, averaged like
  the parameters). This estimate is unbiased under Monte Carlo noise; the least-squares
  ``<image, ref> / <image, image>`` is not (its denominator adds the pixel variance).
* **Seeds.** The same ``seed`` gives the same run, noise included: repeated runs with one seed
  agree with each other whatever the error is, and ``prb`` and ``v4`` share most random
  numbers. Judge accuracy over seeds.

Example::

    >>> import draaw_mi
    >>> scene = draaw_mi.load_scene("scenes/fit_sphere.toml", resolution=(32, 32))
    >>> ref = draaw_mi.render(scene, version="path", spp=64)
    >>> res = draaw_mi.fit(scene, ref, params=["target.roughness", "target.metallic"],
    ...                    iterations=3, spp=4, progress=False)             # doctest: +SKIP
    >>> sorted(res.values)                                                  # doctest: +SKIP
    ['target.metallic', 'target.roughness']
"""
from __future__ import annotations

import time
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import post as post_mod
from ..errors import ParameterError
from ..guard import in_foreground
from ..integrators import is_draaw, resolve_version
from ..progress import check_mode, progress_bar
from ..rendering.frozen import owned_tensor
from ..rendering.session import holding, session_of
from ..scene import DraawScene, load_scene
from .captures import CaptureOverrides, capture_references, light_names, parse_captures
from .maps import MapOptions, MapSet
from .polish import POLISH_LR, joined, polish_maps, polish_samples
from .reference import check_reference_size, display_encoded_post, is_display_reference, load_reference, unclipped_mask
from .problem import FitProblem, PassLoss
from .history import history_entry, progress_values
from .report import leave_in_callers_scene, report
from .result import FitResult
from .settings import FitSettings, validate
from .start import fit_parameters
from .views import sampler_spp, view_sensors

#: iterations after which a parameter that never got a gradient is reported (_warn_unmoved)
ZERO_GRADIENT_ITERATIONS = 5


@in_foreground
def fit(scene, references, params, version: str | None = None, spp: int = 16, iterations: int = 100,
        lr: float = 0.05, loss: str = "l2", views=None, post=None, progress: bool | str = True,
        seed: int = 0, exposure: str = "fixed", init: dict | None = None, max_depth: int | None = None,
        average_last: float = 0.25, tol: float = 5e-3, resolution=None, lr_final: float = 0.1,
        spp_grad: int | None = None, beta_2: float = 0.9, smooth: bool | None = None,
        integrator_options: dict | None = None, captures: list | None = None, maps=None,
        batch: int | None = None, polish: int = 0, polish_spp: int | None = None) -> FitResult:
    """Fit ``params`` of ``scene`` so that its renders match ``references``.

    Args:
        scene: a DraawScene, scene file or description dict. On return the scene holds the
            fitted values.
        references: one reference per view (or capture): an EXR/PNG path, an (H, W, 3) float array or tensor
            (linear; see :func:`load_reference`). Of the scene's size, or of another size with
            its aspect ratio: the fit then renders at the references' size.
            A PNG/JPEG is a display image, clipped to [0, 1] when written: the loss leaves its
            saturated pixels out (:func:`unclipped_mask`; fit_sphere at 64x64 with 6 % of its
            pixels above 1 fits roughness 0.37 / metallic 0.54, against the EXR's 0.25 / 0.81,
            when they count).
        params: names as ``material.parameter`` (``"gold.roughness"``) or full ``mi.traverse`` keys.
        version: integrator (``v1``..``v4``, ``prb``); must be differentiable. Default the
            scene's ``render.version`` where it is one, else ``v4`` (same expectation as ``path``).
        spp, iterations, lr: samples per pixel per iteration (a power of two avoids recompiles),
            Adam iterations and learning rate (in the parameter's space: a roughness step of
            ``lr`` is a relative change, see :class:`~draaw_mi.fitting.params.FitParam`).
        spp_grad: samples per pixel of the gradient (adjoint) pass; default ``spp``.
        loss: ``"l2"``, ``"l1"`` or ``"relative_l2"``.
        views: None (the scene's camera) or a list of camera tables / mi.Sensor, one per reference
            (a table without ``fov`` has the scene camera's field of view).
        post: a post-processing chain (list of dicts) applied to each render inside the loss;
            default the scene's ``post``, as :func:`draaw_mi.render` applies it (``[]``: none).
            The scene's ``hide_emitters`` holds too: a reference rendered from the scene file
            is then one the fit can render.
        exposure: ``"fixed"`` or ``"fit"`` (see the module docstring).
        init: starting values by parameter name (e.g. ``{"gold.roughness": 0.5}``): a number
            for a single value, one number (a grey) or three for a colour, three for a point, and
            for a texture one number, one per channel or an array of its shape; default the
            scene's current values.
        seed: seed of the run; iteration ``i`` renders with an independent seed derived from it,
            and the gradient pass with another one (Mitsuba decorrelates primal and adjoint).
        lr_final: the learning rate decays along a cosine from ``lr`` to ``lr * lr_final``.
        average_last: the reported values are the mean of the iterates over this last fraction.
        beta_2: Adam's second-moment decay (0.9: the step size follows the shrinking gradient).
        smooth: feed the loss a running mean of recent renders carrying the current render's
            derivative; default on with ``post`` or ``loss="l1"`` (non-linear in the image).
        tol: plateau tolerance of ``converged`` (see :func:`~draaw_mi.fitting.result.settled`).
        progress: a tqdm bar (``"bar"``), a line every 10 s (``"lines"``, for logs), either as
            the stream suits (``True``: the bar on a terminal or in a notebook) or none.
        integrator_options: further integrator properties, as :func:`draaw_mi.render` takes
            them (e.g. ``{"sdf_silhouettes": False}``).
        captures: instead of ``views``, one dict per reference with its ``camera`` and the
            ``lights`` it was taken under (factors by light name: 0 switches a light off), other
            scene ``params``, and its ``reference`` when ``references`` is None (see
            :mod:`~draaw_mi.fitting.captures`). The result's ``captures`` says how well each
            was explained.
        maps: how texture parameters (maps of base colour, roughness, ...) are fitted: a dict
            of :class:`~draaw_mi.fitting.maps.MapOptions` (``parametrisation`` "pyramid" or
            "texels", ``tv``, ``lr``, ``lr_scale``, ``fill``); default a multi-scale pyramid in range,
            its metallic maps at 5x ``lr``, its roughness maps under a smoothness prior.
        batch: views (captures) rendered per iteration, drawn at random without repetition
            (default all): a fit of many captures then takes more, cheaper iterations.
        polish: iterations of a second fit from the first's values at ``polish_spp`` (default
            8x ``spp``; ``spp_grad``, where given, 8x too), at 0.4x ``lr`` (and the maps' ``lr``)
            held constant, every capture in each iteration (:mod:`~draaw_mi.fitting.polish`):
            where a 16-spp gradient is too noisy to settle the last hundredths (a near-mirror
            under an environment map stops at roughness 0.064-0.070 for a truth of 0.05;
            polished, 0.055-0.059). The result's ``stages`` give both runs' iterations, spp and
            seconds; its ``image``, ``captures``, ``observed`` and ``exposure_stops`` are the
            polish's, ``converged`` is judged on the joined history.

    Maps, for example (one photo per capture; lights by their names in the scene)::

        res = draaw_mi.fit(scene, None, ["obj.base_color", "obj.roughness", "obj.metallic"],
                           captures=[{"reference": "photo0.png", "camera": {...},
                                      "lights": {"sun": 1, "lamp": 0}}, ...], batch=2)
        res.save_maps("maps/")                # EXR and PNG, one per map
    """
    check_mode(progress, "fit")
    t0 = time.perf_counter()
    settings = validate(FitSettings(
        version=version, spp=spp, iterations=iterations, lr=lr, loss=loss, post=post, progress=progress, seed=seed,
        exposure=exposure, init=init, max_depth=max_depth, average_last=average_last, tol=tol, resolution=resolution,
        lr_final=lr_final, spp_grad=spp_grad, beta_2=beta_2, smooth=smooth,
        integrator_options=integrator_options, maps=MapOptions.parse(maps), batch=batch, polish=polish,
        polish_spp=polish_spp))
    references_given, views_given, captures_given = references, views, captures   # (for the polish)
    if captures is not None:
        if views is not None:
            raise ParameterError("fit: give views or captures, not both (a capture has its camera)")
        captures = parse_captures(captures, references)
        if references is None:
            references = capture_references(captures)
        views = [c["camera"] for c in captures]
    elif references is None:
        raise ParameterError("fit: references is None; give one reference per view, or captures with theirs")
    problem = _set_up(scene, references, params, views, settings, captures)
    opt = _optimiser(problem, settings)
    history, compiles = _iterate(problem, settings, opt)
    result = report(problem, settings, opt, history, compiles, t0)
    if not polish:
        return result
    spp_polish = polish_samples(problem.spp, polish_spp)
    grad_polish = None if problem.spp_grad is None else polish_samples(problem.spp_grad, None)
    # (maps: their own rate scaled too; every capture in each iteration, so that the polish sees
    # every texel the fit saw and its fill of unseen texels undoes none of the fit's)
    again = fit(problem.callers_scene, references_given, params, version=result.version, spp=spp_polish, iterations=polish,
                lr=POLISH_LR * lr, loss=loss, views=views_given, post=post, progress=progress,
                seed=(seed + 1) & 0xFFFFFFFF, exposure=exposure, max_depth=max_depth, average_last=average_last,
                tol=tol, resolution=resolution, lr_final=1.0, beta_2=beta_2, smooth=smooth,
                spp_grad=grad_polish, integrator_options=integrator_options, captures=captures_given,
                maps=polish_maps(maps, settings.maps), batch=None if result.observed else batch)
    return joined(result, again, (problem.spp, problem.spp_grad), (spp_polish, grad_polish), t0, tol)


def _set_up(scene, references, params, views, s: FitSettings, captures) -> FitProblem:
    """The scene at the references' size, its views, the integrator and the parameters."""
    if isinstance(params, str):
        params = [params]
    if not isinstance(params, (list, tuple)) or not all(isinstance(k, str) for k in params):
        hint = " (start values go in init=)" if isinstance(params, dict) else ""
        raise ParameterError(f"fit: params={params!r}; expected a name or a list of names{hint}")
    if not params:
        raise ParameterError("fit: params is empty; name at least one parameter, e.g. 'mat.roughness'")
    if not isinstance(scene, DraawScene):
        scene = load_scene(scene)
    version = s.version
    if version is None:                 # the scene's where it can be differentiated, else v4
        own = scene.settings.get("version") or "v4"
        version = own if is_draaw(own) or resolve_version(own) in ("prb", "prbvolpath") else "v4"
    post = list(scene.settings.get("post", [])) if s.post is None else s.post   # as render() does
    chain = None
    if post:
        chain = post_mod.load_chain(post) if not callable(post) else post
    encoded = chain is not None and display_encoded_post(post)
    given = references if isinstance(references, (list, tuple)) else [references]
    if not given:
        raise ParameterError("fit: references is empty; give one reference image per view")
    refs = [load_reference(r, encoded, who=f"fit: references[{i}]" if len(given) > 1 else "fit")
            for i, r in enumerate(given)]
    # (owned: the gradient passes' recordings take them as inputs; see owned_tensor)
    masks = [owned_tensor(unclipped_mask(r)) if is_display_reference(g) else None
             for g, r in zip(given, refs)]
    h, w = refs[0].shape[:2]
    if any(r.shape != refs[0].shape for r in refs):
        raise ParameterError(f"fit: references differ in shape: {[r.shape for r in refs]}")
    callers_scene = scene
    if s.resolution is not None or scene.resolution != (w, h):
        if s.resolution is not None and tuple(s.resolution) != (w, h):
            raise ParameterError(f"fit: resolution {tuple(s.resolution)} differs from the references' {w}x{h}")
        check_reference_size(scene, w, h, given[0])
        scene = scene.with_resolution(w, h)
    sensors = view_sensors(scene, views, cameras_of_captures=captures is not None)
    spp = sampler_spp(scene, s.spp, "spp")
    spp_grad = None if s.spp_grad is None else sampler_spp(scene, s.spp_grad, "spp_grad")
    if len(sensors) != len(refs):
        raise ParameterError(f"fit: {len(refs)} reference(s) for {len(sensors)} view(s); give one per view")
    session = session_of(scene)
    session.check_version_sees(version)      # prb would fit a smoke scene as if it had no smoke
    integrator = session.integrator(version, scene.settings["max_depth"] if s.max_depth is None else s.max_depth,
                                    scene.settings.get("hide_emitters", False), **(s.integrator_options or {}))
    if not isinstance(integrator, mi.ad.integrators.common.ADIntegrator):
        raise ParameterError(f"fit: version {version!r} is not differentiable; use v1..v4 or 'prb'")
    keys, names, prm, start, initial = fit_parameters(scene, params, s.init)
    smooth = (chain is not None or s.loss == "l1") if s.smooth is None else bool(s.smooth)
    overrides = CaptureOverrides.build(scene.params, captures or [{"lights": {}, "params": {}}] * len(sensors),
                                       keys, light_names(scene.params))
    maps = MapSet({k: (np.array(initial[k], dtype=np.float64).reshape(prm[k].shape), prm[k].lo, prm[k].hi)
                   for k in keys if prm[k].shape is not None and prm[k].lo is not None
                   and s.maps.parametrisation == "pyramid"}, s.maps)
    return FitProblem(scene, callers_scene, session, integrator, sensors, [owned_tensor(r) for r in refs], masks,
                      chain, keys, names, prm, start, initial, version, spp, spp_grad, smooth, overrides, maps)


def _optimiser(problem: FitProblem, s: FitSettings):
    """Adam over each parameter's latent (its optimiser coordinate), from its start."""
    opt = mi.ad.Adam(lr=s.lr, beta_2=s.beta_2)
    for k in problem.keys:
        if k not in problem.maps.latents:
            opt[k] = problem.prm[k].to_latent(problem.initial[k])
    return opt


def _push(problem: FitProblem, opt, view: int) -> None:
    """Scene values for ``view``: its capture's lights and parameters, the fitted values from
    the optimiser's latents and the maps (AD-attached); then update the scene."""
    p = problem.scene.all_params
    problem.overrides.apply(p, view)
    for k in problem.keys:
        if k not in problem.maps.latents:
            p[k] = problem.prm[k].from_latent(opt[k])
    problem.maps.attach(p)
    p.update()
    problem.session.scene_changed()            # e.g. V4's light powers, if lights are fitted


def _iterate(problem: FitProblem, s: FitSettings, opt):
    """Run the Adam iterations; returns ``(history, kernels compiled once every view rendered
    had had two passes)``.
    Interrupted, the scene keeps the last iterate (detached)."""
    keys, names, prm, sensors, maps = problem.keys, problem.names, problem.prm, problem.sensors, problem.maps
    p = problem.scene.all_params
    means: list = [None] * len(sensors)
    bar = progress_bar(s.iterations, "fit", "it", s.progress, where="fit")
    history: list = []
    problem.texture_sums.clear()             # (the averaged iterates of this run's textures)
    sdf_groups = _sdf_groups(problem)        # SDF objects with two or more fitted values
    textures = {names[k] for k in keys if prm[k].shape is not None}
    moved: set = set()                       # parameters that got a non-zero gradient
    scale = mi.Float(1.0)
    compiles = 0
    # a view's gradient pass is recorded at its first pass and once more at its second (its
    # inputs then hold what the first iteration's step made: dr.freeze records anew); its
    # later passes replay, and an iteration of only such passes should compile nothing
    view_passes = [0] * len(sensors)
    order = np.random.default_rng(s.seed)    # which captures an iteration renders (batch)
    batch = len(sensors) if s.batch is None else min(s.batch, len(sensors))
    pass_loss = PassLoss(s.loss, s.exposure, 1.0 / batch, problem.chain, problem.smooth)
    history_was_on = dr.flag(dr.JitFlag.KernelHistory)     # a caller's own measurement
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    try:
        for it in range(s.iterations):
            frac = it / max(s.iterations - 1, 1)
            decay = s.lr_final + (1.0 - s.lr_final) * 0.5 * (1.0 + np.cos(np.pi * frac))
            opt.set_learning_rate(s.lr * decay)
            views = range(len(sensors)) if batch == len(sensors) else sorted(int(v) for v in order.choice(len(sensors), batch, replace=False))
            view_losses = {}
            settled = all(view_passes[v] >= 2 for v in views)
            for v in views:
                view_passes[v] += 1
            with holding(problem.scene):      # one render at a time (draaw_mi.guard)
                total = mi.Float(0.0)
                for v in views:
                    _push(problem, opt, v)    # fresh AD edges latent -> scene value for this view
                    problem.overrides.select_lights(problem.integrator, problem.scene.mi_scene, v)
                    first = problem.smooth and means[v] is None
                    if first:                 # (opaque: as later means, one kernel)
                        means[v] = dr.zeros(mi.TensorXf, problem.refs[v].shape)
                        dr.make_opaque(means[v])
                    # render, loss and backward (one view at a time: the gradients accumulate
                    # in the latents), replayed from a recording where the scene can be recorded
                    lv, (sv, mean) = problem.session.gradient_pass(
                        problem.integrator, problem.spp, (s.seed * 7919 + it * len(sensors) + v) & 0xFFFFFFFF,
                        pass_loss, params=p, sensor=sensors[v], spp_grad=problem.spp_grad,
                        inputs=(problem.refs[v], problem.masks[v], means[v],
                                _mean_weight(opt, s.lr, first) if problem.smooth else None),
                        freeze=problem.chain is None)
                    problem.overrides.remember_lights(problem.integrator, problem.scene.mi_scene, v)
                    if problem.smooth:
                        means[v] = mean
                    if v == 0:
                        scale = sv
                    maps.collect()
                    total += lv
                    view_losses[v] = lv
                for k in keys:
                    if k in maps.latents:
                        g_any = bool(np.any(maps.grads[k] != 0))
                    else:
                        g = dr.grad(opt[k])
                        g = dr.select(dr.isfinite(g), g, 0.0)
                        dr.set_grad(opt[k], g)
                        # (a host read per parameter, in the first iterations only)
                        g_any = it < ZERO_GRADIENT_ITERATIONS and k not in moved and dr.any(g != 0, axis=None)
                    if it < ZERO_GRADIENT_ITERATIONS and g_any:
                        moved.add(k)
                if it == min(s.iterations, ZERO_GRADIENT_ITERATIONS) - 1:
                    _warn_unmoved([names[k] for k in keys if k not in moved], it + 1)
                opt.step()
                maps.step((s.maps.lr or s.lr) * decay)
                for k in keys:
                    if k not in maps.latents:
                        opt[k] = prm[k].clip(opt[k])
                _project_sdf_nodes(problem, opt, sdf_groups)
            entry, new = history_entry(problem, s, opt, it, float(total[0]), scale)
            entry["views"] = {v: float(lv[0]) * len(views) for v, lv in view_losses.items()}
            history.append(entry)
            if settled:
                compiles += new
            if bar is not None:
                shown_values = progress_values(entry["values"], textures)
                if s.loss == "l2" and entry["loss"] > 0:      # the image's PSNR (peak 1)
                    shown_values = {"psnr": f"{-10 * np.log10(entry['loss']):.1f}", **shown_values}
                bar.set_postfix(loss=f"{entry['loss']:.3g}", **shown_values)
                bar.update(1)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, history_was_on)
        if bar is not None:
            bar.close()
        if len(history) < s.iterations:      # interrupted: leave the last iterate, detached
            values = maps.values()
            for k in keys:
                p[k] = owned_tensor(values[k]) if k in values else prm[k].from_latent(dr.detach(opt[k]))
            problem.overrides.restore(p)
            with holding(problem.scene):
                p.update()
            leave_in_callers_scene(problem, keys)
    return history, compiles


def _sdf_groups(problem: FitProblem) -> dict:
    """``{SDF object's name: {parameter: fitted key}}`` for the objects with two or more fitted
    values (those :func:`_project_sdf_nodes` moves together)."""
    by_node: dict = {}
    for k in problem.keys:
        node_param = problem.scene.sdf_param(k)
        if node_param is not None:
            node, _, param = node_param.partition(".")
            by_node.setdefault(node, {})[param] = k
    return {node: keys for node, keys in by_node.items() if len(keys) >= 2}


def _project_sdf_nodes(problem: FitProblem, opt, groups: dict) -> None:
    """Move the fitted parameters of each SDF object of ``groups`` (:func:`_sdf_groups`) into
    their joint range (:meth:`SDFNode.project <draaw_mi.sdf.node.SDFNode.project>`: a round
    box's radius at most half its new size): each was clipped to a range that held the others
    at their start."""
    prm = problem.prm
    for node, keys in groups.items():
        values = {param: np.array(dr.detach(prm[k].from_latent(opt[k])), dtype=np.float64).ravel()
                  for param, k in keys.items()}
        projected = problem.scene.sdf.nodes[node].project(values)
        for param, k in keys.items():
            new = np.asarray(projected[param], dtype=np.float64).ravel()
            if not np.array_equal(new, values[param]):
                opt[k] = prm[k].to_latent(prm[k].type(*[float(x) for x in new]) if new.size > 1
                                          else prm[k].type(float(new[0])))


def _mean_weight(opt, lr: float, first: bool):
    """The weight of the current render in the running mean that the loss sees with
    ``smooth`` (:class:`~draaw_mi.fitting.problem.PassLoss`): the current learning-rate fraction
    (1 -> lr_final), so the mean spans more iterations as the parameters slow down; 1 for a
    capture's ``first`` render, whose mean starts as that render (with batches a capture is
    first drawn in a later iteration, when the fraction is below 1)."""
    return dr.opaque(mi.Float, 1.0 if first or not isinstance(opt.lr, float) else opt.lr / lr)


def _warn_unmoved(names: list, iterations: int) -> None:
    """Warn about parameters whose gradient was zero in every iteration so far: the renders
    do not depend on them through anything the version differentiates (an environment map's
    texels in Mitsuba 3.9, a light its plugin samples without gradients), so they keep their
    starting values."""
    if names:
        warnings.warn(f"fit: {', '.join(names)} got a zero gradient in all of the first {iterations} "
                      "iterations: the renders do not depend on it through anything this version "
                      "differentiates (is it visible? differentiable? at a start where its gradient is 0, "
                      "which a warning before the fit names?); it keeps its value",
                      RuntimeWarning, stacklevel=4)
