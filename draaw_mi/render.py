"""``draaw_mi.render``: render a scene with a chosen version, in passes, with progress and budget.

Large sample counts are split into passes of at most ``pass_spp`` samples with independent
seeds; the image is the spp-weighted mean of the passes (GO-Draaw's "frame averaging", done as
a true mean rather than its exponential moving average). Same arguments and seed, same image.

>>> import draaw_mi
>>> scene = draaw_mi.load_scene({"render": {"resolution": [16, 16]},
...     "shapes": [{"type": "sphere"}], "lights": [{"type": "constant"}],
...     "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
>>> img = draaw_mi.render(scene, version="path", spp=4, seed=1)
>>> img.shape
(16, 16, 3)
"""
from __future__ import annotations

import numbers
import re
import threading
import time
import warnings

import drjit as dr
import mitsuba as mi

from .errors import RenderError, suggest
from .progress import check_mode, progress_bar
from .integrators import VERSION_GRADES, is_draaw, resolve_version
from .frozen import (freeze_render, freeze_supported, other_live_bsdfs,  # noqa: F401 (re-exported)
                     scene_scalars, scene_state)
from .guard import RENDER_GUARD
from .film_colour import check_film_colour as _check_film_colour, film_colour_names, scene_colour_names  # noqa: F401
from .passes import pass_seed, pass_seeds, sample_passes  # noqa: F401 (re-exported)

_INTEGRATOR_CACHE: dict = {}      # plugin properties -> integrator
_INTEGRATOR_KEYS: dict = {}       # make_integrator's arguments as given -> plugin properties
MAX_PASS_SPP = 256


def make_integrator(version: str, max_depth: int, hide_emitters: bool = False, aovs=(), **options):
    """Instantiate (and cache) the integrator plugin for ``version`` with these options.

    One instance serves every thread: integrators keep state between and during traces (V4's
    light pilot, its selection table), and :data:`draaw_mi.guard.RENDER_GUARD` lets one
    thread trace at a time (two previews' workers tracing one V4 instance at once failed:
    "loop state variable ... changed")."""
    try:                                 # the arguments as given (a render's first step)
        fast = (version, max_depth, bool(hide_emitters), tuple(aovs), tuple(sorted(options.items())))
        integrator = _INTEGRATOR_CACHE.get(_INTEGRATOR_KEYS.get(fast))
    except TypeError:                    # an unhashable option value
        fast = integrator = None
    if integrator is not None:
        return integrator
    plugin = resolve_version(version)
    props = {"type": plugin, "max_depth": int(max_depth)}
    if hide_emitters:
        props["hide_emitters"] = True
    if aovs:
        props["aovs"] = ",".join(aovs)
    props.update(options)
    key = tuple(sorted((k, str(v)) for k, v in props.items()))
    if key not in _INTEGRATOR_CACHE:
        try:
            _INTEGRATOR_CACHE[key] = mi.load_dict(props)
        except Exception as e:  # noqa: BLE001
            raise _integrator_error(plugin, props, e) from None
    if fast is not None:
        _INTEGRATOR_KEYS[fast] = key
    return _INTEGRATOR_CACHE[key]


def _integrator_error(plugin: str, props: dict, e: Exception) -> RenderError:
    """A clear message for an integrator Mitsuba would not create from ``props``."""
    from .scene.mitsuba_load import mitsuba_error_message
    text = str(e)
    if props.get("aovs") and not plugin.startswith("draaw"):
        return RenderError(f"render: AOVs ({props['aovs']}) come from the draaw versions v1..v4; "
                           f"{plugin!r} renders colour only: drop aovs or pick v1..v4")
    names = re.findall(r'^\s*- \w+ "([^"]+)"', text, flags=re.M)
    if "unreferenced propert" in text and names:
        known = _plugin_parameters(plugin)
        hint = suggest(names[0], known) if known else ""
        return RenderError(f"render: the integrator {plugin!r} has no option "
                           f"{', '.join(repr(n) for n in names)}{hint}")
    return RenderError(f"render: cannot create integrator {plugin!r}: {mitsuba_error_message(e)}")


def _plugin_parameters(plugin: str) -> list[str]:
    """The parameters of a draaw integrator: its docstring table's (``* - name`` rows), the
    SDF tracer's and, for V1 / V2, the medium march's."""
    if not plugin.startswith("draaw"):
        return []
    try:
        doc = type(mi.load_dict({"type": plugin})).__doc__ or ""
    except Exception:  # noqa: BLE001 - only a hint
        return []
    names = re.findall(r"^\s*\* - (\w+)\s*$", doc, flags=re.M)
    names += ["sdf_epsilon", "sdf_max_steps", "sdf_relaxation"]
    if plugin in ("draaw_v1", "draaw_v2"):
        names.append("medium_steps")
    return sorted(set(names))


def scene_holds(scene) -> dict:
    """``{"sdf": bool, "media": bool}``: whether the :class:`DraawScene` has ``[[sdf]]``
    objects or participating media (found once per scene)."""
    memo = scene_state(scene).memo
    key = ("draaw_mi.render.holds",)
    holds = memo.get(key)
    if holds is None:                  # (the integrators' own feature detection, once per scene)
        from .integrators.features import detect_features
        feats = detect_features(scene.mi_scene)
        holds = memo[key] = {"sdf": bool(feats["sdf"]), "media": bool(feats["media"])}
    return holds


# What Mitsuba's own integrators cannot show: draaw-mi traces SDF objects inside v1..v4 only,
# and path / prb pass through media as if they were empty
_BLIND = {"path": ("sdf", "media"), "prb": ("sdf", "media"), "volpath": ("sdf",), "prbvolpath": ("sdf",)}


def check_version_sees(scene, version: str) -> None:
    """Raise :class:`RenderError` when ``version`` cannot show what ``scene`` (a
    :class:`DraawScene`) holds: ``[[sdf]]`` objects for any of Mitsuba's integrators, media
    for ``path`` / ``prb``. The render would otherwise drop them without a word."""
    plugin = resolve_version(version)
    blind = _BLIND.get(plugin)
    if not blind:
        return
    holds = scene_holds(scene)
    if "sdf" in blind and holds["sdf"]:
        raise RenderError(f"render: {scene.source} has [[sdf]] objects, which Mitsuba's {plugin!r} "
                          "cannot see (draaw-mi traces them in v1..v4); pick v1..v4")
    if "media" in blind and holds["media"]:
        raise RenderError(f"render: {scene.source} has participating media, which Mitsuba's "
                          f"{plugin!r} passes through as empty; pick v1..v4 or volpath")


def scene_changed(mi_scene) -> None:
    """Tell the cached integrators that ``mi_scene``'s parameters changed: V4 recomputes its
    power-based light-selection table at the next render instead of keeping the old one (a
    table its light pilot learned stays: see :mod:`draaw_mi.integrators.light_pilot`). The
    preview, the batch executor and the fitter call this after ``params.update()``; call it
    too after changing light intensities yourself (renders stay unbiased without it, but a
    stale table can sample a dimmed light as often as before)."""
    for integrator in list(_INTEGRATOR_CACHE.values()):
        forget = getattr(integrator, "forget_scene", None)
        if forget is not None:
            forget(mi_scene)


def _scene_lock(scene) -> threading.Lock:
    return scene_state(scene).lock


def _scene_passes(scene, spp: int, pass_spp: int) -> list[int]:
    """:func:`sample_passes` for a :class:`DraawScene`, remembered per scene where its sampler
    is one of Mitsuba's (about 0.05 ms a render otherwise, with the caches cold after the
    last render's kernels)."""
    state = scene_state(scene)
    counts = state.passes.get((spp, pass_spp))
    if counts is None:
        counts = sample_passes(scene.mi_scene, spp, pass_spp)
        if type(scene.mi_scene.sensors()[0].sampler()) is mi.Sampler:
            if len(state.passes) >= 64:
                state.passes.clear()
            state.passes[(spp, pass_spp)] = counts
    return list(counts)


def _warn_grade_left_out(version: str, chain) -> None:
    """Warn when a GO-Draaw graded version name (``V4-Log``) comes without its grade's post
    filter: the name renders linear light, as ``V4`` does (it said nothing)."""
    grade = VERSION_GRADES.get(str(version).strip().lower())
    if grade is None or (chain is not None and any(e.get("type") == grade for e in chain.to_list())):
        return
    warnings.warn(f"render: version {version!r} renders linear light, as {resolve_version(version)!r} "
                  f"does; its {grade.capitalize()} colour grade is the post filter {grade!r} (add "
                  f"{{'type': '{grade}'}} to the post chain)", RuntimeWarning, stacklevel=3)


def render(scene, version: str | None = None, spp: int | None = None, seed: int | None = None,
           max_depth: int | None = None, resolution=None, *, params=None, progress: bool | str = False,
           time_budget: float | None = None, pass_spp: int | None = None, post=None,
           hide_emitters: bool | None = None, aovs=None, return_info: bool = False,
           integrator_options: dict | None = None, adaptive: int | None = None, denoise: bool = False):
    """Render ``scene`` and return an (H, W, C) ``mi.TensorXf`` (C = the film's colour channels,
    R, G, B, or an XML film's R, G, B, A / X, Y, Z[, A] / Y[, A], + AOV channels).

    Parameters
    ----------
    scene: a :class:`DraawScene`, file name, description dict or ``mi.Scene`` (load a file
        once and pass the scene: small renders replay a recording kept with it).
    version: ``"v1"`` .. ``"v4"`` (GO-Draaw names accepted), ``"path"`` or ``"prb"``, and
        ``"volpath"`` / ``"prbvolpath"`` for media; default the scene's ``render.version``.
        Mitsuba's integrators cannot see ``[[sdf]]`` objects, ``path`` / ``prb`` not media:
        such a request raises :class:`RenderError`.
    spp, seed, max_depth, resolution ((W, H)): override the scene's render settings.
    params: ``mi.traverse`` parameters, for differentiable renders (``dr.backward`` works).
    progress: ``True``/``"bar"`` a tqdm bar over passes, ``"lines"`` a line now and then
        (for logs, :mod:`draaw_mi.progress`).
    time_budget: seconds; stop after the pass that reaches it (at least one pass runs); the
        image is the mean of the passes done (``return_info`` tells how many samples).
    pass_spp: samples per pass (default: all at once up to 256, 16 with a time budget). The
        bar advances per pass: give e.g. 16 for a finer one (another layout of passes draws
        other samples: another image of the same expectation).
    post: a post-processing chain (list of dicts) to apply; default the scene's ``post``;
        ``[]`` disables it.
    hide_emitters: hide directly seen lights (default: the scene's ``render.hide_emitters``).
    aovs: extra outputs after the colour, any of ``"depth"``, ``"depth_log"``, ``"normal"``,
        ``"albedo"`` (or ``"all"``): channels ``depth.Z``, ``N.X/Y/Z``, ``albedo.R/G/B``
        (draaw versions only; default the scene's ``render.aovs``).
    integrator_options: further properties of the integrator plugin, e.g. ``{"rr_depth": 8}``
        or V4's ``{"light_selection": "power"}`` (see each integrator's docstring).
    return_info: also return a dict with ``spp``, ``passes``, ``seconds``, ``channels`` (names),
        ``post`` (the chain applied) and ``non_finite`` (NaN/inf values of the render before
        denoising and the chain, which read them as 0).
    adaptive: block size (a power of two, e.g. 8) for adaptive subsampling with bilinear
        interpolation (see :mod:`draaw_mi.adaptive`; biased, not differentiable, no AOVs).
    denoise: denoise the colour with Intel OIDN (:func:`draaw_mi.denoise`, needs ``pyoidn``),
        guided by albedo and normal AOVs rendered for it (returned only if asked for in
        ``aovs``); applied before the post chain. Biased, not differentiable.

    Example::

        >>> import draaw_mi
        >>> img, info = draaw_mi.render("scenes/cornell.toml", spp=4, resolution=(32, 24),
        ...                             aovs=["depth"], return_info=True)
        >>> img.shape, info["channels"]
        ((24, 32, 4), ['R', 'G', 'B', 'depth.Z'])
    """
    check_mode(progress, "render")
    if adaptive is not None and (time_budget is not None or pass_spp is not None):
        given = "time_budget" if time_budget is not None else "pass_spp"
        raise RenderError(f"render: adaptive= renders every sample in one launch, without passes; "
                          f"drop {given}= or adaptive=")
    from .scene import DraawScene, load_scene

    if not isinstance(scene, DraawScene):
        scene = load_scene(scene)
    s = scene.settings
    if resolution is not None:
        from .scene.schema import Where, resolution as parse_res
        size = tuple(parse_res(resolution, Where("render") / "resolution"))
        if params is not None and size != scene.resolution:
            # (the reloaded copy has its own parameters: gradients would not reach `params`)
            raise RenderError(f"render: resolution={resolution!r} with params= renders a reloaded "
                              "copy of the scene that `params` do not belong to; render "
                              "`scene.with_resolution(w, h)` and traverse that instead")
        scene = scene.with_resolution(*size)
    version = s["version"] if version is None else version
    spp = s["spp"] if spp is None else spp
    seed = s["seed"] if seed is None else seed
    max_depth = s["max_depth"] if max_depth is None else max_depth
    spp = _check_int("spp", spp, 1)
    seed = _check_int("seed", seed, 0, 2 ** 32 - 1)          # (a UInt32: 2**40 was a raw Dr.Jit error)
    max_depth = _check_int("max_depth", max_depth, -1)
    if time_budget is not None and (isinstance(time_budget, bool) or not (
            isinstance(time_budget, numbers.Real) and 0 < time_budget < float("inf"))):
        raise RenderError(f"render: time_budget={time_budget!r}; expected a positive number of seconds")
    if pass_spp is None:
        # Not after the progress mode: the passes' seeds make the samples (a bar gave another
        # image than none), and V4 samples adaptively only in passes of 64 spp or more.
        pass_spp = min(spp, 16 if time_budget else MAX_PASS_SPP)
    pass_spp = _check_int("pass_spp", pass_spp, 1)
    hide = s.get("hide_emitters", False) if hide_emitters is None else hide_emitters
    import numpy as np
    if not isinstance(hide, (bool, np.bool_)):
        # (any truthy value hid the lights: the string "false" too)
        raise RenderError(f"render: hide_emitters={hide!r}; expected True or False")
    hide = bool(hide)
    if integrator_options is not None and not isinstance(integrator_options, dict):
        raise RenderError(f"render: integrator_options={integrator_options!r}; expected a dict of "
                          "integrator plugin properties, e.g. {'rr_depth': 8}")
    if aovs is None:
        aovs = s.get("aovs", [])
        if aovs and not is_draaw(version):
            warnings.warn(f"render: {version!r} renders colour only; the scene's AOVs "
                          f"({', '.join(aovs)}) come from v1..v4", RuntimeWarning, stacklevel=2)
            aovs = []
    elif isinstance(aovs, str):
        aovs = [aovs]                    # "depth" or "all", not its characters
    check_version_sees(scene, version)
    from .post.chain import Chain
    if callable(post) and not isinstance(post, Chain):     # (it failed after the whole render)
        raise RenderError(f"render: post={post!r}; expected a chain (a list of filter tables, a Chain "
                          "or a JSON file): apply a function of your own to the returned image")
    chain = s.get("post", []) if post is None else post
    # read and checked once, now, not after the render (an unknown filter); ``chain`` stays as
    # given: the info (and a batch frame's header) records it as the user wrote it
    from . import post as post_mod
    loaded = post_mod.load_chain(chain) if chain else None
    _warn_grade_left_out(version, loaded)
    if (chain or denoise) and adaptive is None:
        _check_film_colour(scene, "a post chain" if chain else "denoising")
    if denoise:     # ---- denoising: check early, render the guide AOVs with the image
        aovs, extra_aovs = _denoise_aovs(params, adaptive, aovs, version)
    if adaptive is not None:
        with RENDER_GUARD:
            integrator = make_integrator(version, max_depth, hide, (), **(integrator_options or {}))
        return _render_adaptive(scene, adaptive, integrator, version, spp, seed, params, aovs, chain,
                                loaded, return_info, progress)
    with RENDER_GUARD:    # (both may make plugins: the integrator, a sampler probed for its counts)
        integrator = make_integrator(version, max_depth, hide, aovs, **(integrator_options or {}))
        counts = _scene_passes(scene, spp, pass_spp)
    n_passes = len(counts)
    seeds = pass_seeds(int(seed), n_passes)
    # (the samples taken: a sampler rounds spp up to its pattern, 5 -> 8 of ldsampler, and
    # the bar read 8/5 spp)
    bar = progress_bar(sum(counts), f"render {version}", "spp", progress, leave=False, where="render")
    acc, done, passes, t0 = None, 0, 0, time.perf_counter()
    with _scene_lock(scene):
        for count, pseed in zip(counts, seeds):
            # every evaluation of the pass, its sync too, under the guard (draaw_mi.guard)
            with RENDER_GUARD:        # (per pass: a preview's frame can render between passes)
                img = None
                if params is None and freeze_eligible(scene.mi_scene, count, scene):
                    img = frozen_render(integrator, count, scene)(scene.mi_scene, dr.opaque(mi.UInt32, pseed), scene)
                if img is None:
                    img = mi.render(scene.mi_scene, params, integrator=integrator, seed=pseed, spp=count)
                if n_passes == 1:
                    acc = img            # one pass: no extra scaling kernels (small renders)
                else:
                    acc = img * count if acc is None else acc + img * count
                dr.eval(acc)
                dr.sync_thread()
            done += count
            passes += 1
            if bar is not None:
                bar.set_postfix(seconds=f"{time.perf_counter() - t0:.1f}")
                bar.update(count)
            if time_budget is not None and time.perf_counter() - t0 >= time_budget:
                break
    if bar is not None:
        bar.close()
    # the film's colour channels as its pixel_format stores them (R, G, B[, A], X, Y, Z[, A],
    # Y[, A]: an rgba or luminance XML film was named R, G, B and refused by write_exr; an xyz
    # film's X, Y, Z were written as R, G, B), then the AOVs'
    from .io import channel_names
    aov_names = integrator.aov_names()
    colour = scene_colour_names(scene)
    names = (colour + aov_names if len(colour) + len(aov_names) == acc.shape[2]
             else channel_names(acc.shape[2], aov_names))
    image = acc
    if n_passes > 1:
        with RENDER_GUARD:
            image = acc / done
            dr.eval(image)
            dr.sync_thread()
    # (counted before denoising and the post chain, which read NaN/inf as 0 and would hide
    # them from the caller's NaN guard: a batch frame or the CLI's warning)
    bad = non_finite_count(image) if return_info else 0
    if denoise or chain:
        with RENDER_GUARD:            # denoising, post: their kernels and reads back
            if denoise:
                image, names = _denoised(image, names, extra_aovs)
            if chain:
                image = _apply_post(image, loaded)
    if return_info:
        return image, {"spp": done, "passes": passes, "seconds": time.perf_counter() - t0,
                       "channels": names, "version": version, "integrator": resolve_version(version),
                       "denoised": bool(denoise), "non_finite": bad, "post": chain}
    return image


def non_finite_count(image) -> int:
    """How many values of ``image`` (a tensor) are NaN or ±inf."""
    with RENDER_GUARD:
        n = int(dr.count(~dr.isfinite(image.array))[0])
    return n


# ------------------------------------------------------------------ frozen small renders
# Small renders (the Jupyter preview, the fit loop) would otherwise spend much of their time
# re-tracing the Python integrator: ``dr.freeze`` records the kernels of the first call and
# replays them; the seed is an opaque ``mi.UInt32`` so that a new seed is new data, not a new
# kernel (benchmarks/render_overhead.py measures it).
FREEZE_MAX_PIXELS = 128 * 128
FREEZE_MAX_SPP = 16
FREEZE = True                      # set False to trace every render (debugging)
_FROZEN: dict = {}


def freeze_eligible(mi_scene, spp: int, scene=None) -> bool:
    """Whether a primal render of ``spp`` samples of ``mi_scene`` goes through
    :func:`frozen_render`. With ``scene``, the :class:`DraawScene` of ``mi_scene``,
    :func:`freeze_supported` (a walk over the shapes, which cannot gain media or SDF objects
    after loading) is asked once per scene; the film size is read every time (params can
    change it)."""
    if not FREEZE or spp > FREEZE_MAX_SPP:
        return False
    if scene is None:
        ok = freeze_supported(mi_scene)
        film = mi_scene.sensors()[0].film()
    else:
        state = scene_state(scene)
        if state.freezable is None:
            state.freezable = freeze_supported(mi_scene)
            state.film = mi_scene.sensors()[0].film()        # a sensor's film stays its own
        ok, film = state.freezable, state.film
    w, h = film.size()
    return ok and int(w) * int(h) <= FREEZE_MAX_PIXELS


def frozen_render(integrator, spp: int, scene=None):
    """``f(mi_scene, seed: mi.UInt32, scene) -> image``: ``mi.render`` recorded with
    ``dr.freeze``, one recording per integrator and spp, and per :class:`DraawScene` ``scene``
    (kept with it). Dr.Jit re-records when the inputs' layout changes, but not when a scene of
    the same layout replaces a freed one: the replay then called the freed scene's Python
    BSDFs, and a scene loaded again rendered black every other time."""
    key = (id(integrator), int(spp))
    cache = _FROZEN if scene is None else scene_state(scene).frozen
    fn = cache.get(key)
    if fn is None:
        def render_once(mi_scene, seed):
            return mi.render(mi_scene, integrator=integrator, seed=seed, spp=spp)
        fn = cache[key] = freeze_render(integrator, render_once)
    return fn


def _render_adaptive(scene, block, integrator, version, spp, seed, params, aovs, chain, loaded, return_info,
                     progress):
    from .adaptive import render_adaptive
    if params is not None:
        raise RenderError("render: adaptive subsampling is not differentiable; drop params= or adaptive=")
    if aovs:
        raise RenderError("render: adaptive subsampling renders colour only; drop aovs or adaptive=")
    holds = scene_holds(scene)
    if holds["sdf"] or holds["media"]:
        # its corner signatures (camera, shadow and mirror rays) see meshes only: SDF objects
        # and smoke came out as interpolated smears (RMSE 0.097 on sdf_csg, against 0.055 on
        # the Cornell box)
        what = "[[sdf]] objects" if holds["sdf"] else "participating media"
        raise RenderError(f"render: adaptive subsampling cannot see {what} ({scene.source}); drop adaptive=")
    t0 = time.perf_counter()
    bar = progress_bar(spp, f"render {version} adaptive", "spp", progress, leave=False, where="render")
    with _scene_lock(scene), RENDER_GUARD:
        image, stats = render_adaptive(scene, block=block, spp=spp, seed=seed, integrator=integrator)
    if bar is not None:                  # (one launch: the bar fills at once)
        bar.update(spp)
        bar.close()
    bad = non_finite_count(image) if return_info else 0      # (before the chain: see render)
    if chain:
        image = _apply_post(image, loaded)
    if return_info:
        return image, {"non_finite": bad, "spp": spp, "passes": 1, "seconds": time.perf_counter() - t0,
                       "channels": ["R", "G", "B"], "version": version,
                       "integrator": resolve_version(version), "adaptive": stats, "post": chain}
    return image


def _denoise_aovs(params, adaptive, aovs, version):
    """(AOVs to render, the ones added only to guide the denoiser) for ``denoise=True``.
    Mitsuba's own integrators (``path``, ``prb``) have no AOV outputs: colour-only denoising."""
    from .denoise import AUX_AOVS, _pyoidn
    if params is not None:
        raise RenderError("render: denoise=True is not differentiable; drop params= or denoise=")
    if adaptive is not None:
        raise RenderError("render: denoise=True cannot be combined with adaptive= (no AOVs there)")
    _pyoidn()                            # the one-line install hint before any rendering
    aovs = [aovs] if isinstance(aovs, str) else list(aovs)
    if not is_draaw(version):
        return aovs, []
    asked = {a.strip() for item in aovs for a in str(item).split(",")}
    if "all" in asked:
        return aovs, []
    extra = [a for a in AUX_AOVS if a not in asked]
    return aovs + extra, extra


def _denoised(image, names, extra_aovs):
    from .denoise import denoise_aovs
    from .integrators.common import AOV_CHANNELS
    out = denoise_aovs(image, names)
    drop = {c for a in extra_aovs for c in AOV_CHANNELS[a]}
    keep = [i for i, n in enumerate(names) if n not in drop]
    if len(keep) < len(names):
        import numpy as np
        out = mi.TensorXf(np.ascontiguousarray(np.asarray(out)[..., keep]))
        names = [names[i] for i in keep]
    return out, names


def _check_int(name, value, lo, hi=None) -> int:
    """``value`` as a Python int, numpy integers too (``2 ** np.arange(k)`` in a notebook)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo \
            or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise RenderError(f"render: {name}={value!r}; expected an integer {rng}")
    return int(value)


def _apply_post(image, chain):
    from . import post
    c = image.shape[2]
    if c <= 4:
        return post.apply(image, chain)
    color = post.apply(image[:, :, :3], chain)
    return dr.concat([color, image[:, :, 3:]], axis=2)
