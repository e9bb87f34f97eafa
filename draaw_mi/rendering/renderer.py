"""``draaw_mi.render``: render a scene with a chosen version, in passes, with progress and budget.

Large sample counts are split into passes of at most ``pass_spp`` samples with independent
seeds; the image is the spp-weighted mean of the passes (GO-Draaw's "frame averaging", done as
a true mean rather than its exponential moving average). Same arguments and seed, same image.
Each pass is rendered by the scene's :class:`~draaw_mi.rendering.session.Session`; a render
runs in three phases: :func:`_settings` (check and resolve every argument, before anything
renders), the passes, and :func:`_finish` (the mean, channel names, denoising, the post chain).

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
import time
import warnings
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import post as post_mod
from ..errors import DraawError, NonFiniteWarning, RenderError
from ..guard import RENDER_GUARD, in_foreground
from ..integrators import SCENE_VERSION, VERSION_GRADES, is_draaw, resolve_version, version_key
from ..integrators.common import AOV_CHANNELS, parse_aovs
from ..io import channel_names
from ..progress import check_mode, closed_after, progress_bar
from ..scene import DraawScene, load_scene
from ..scene.schema import Where
from ..scene.schema import resolution as parse_res
from ..sdf.params import SDFParameters
from .denoiser import AUX_AOVS, denoise_aovs, load_pyoidn
from .film_colour import check_film_colour, scene_colour_names, sensor_index, sensor_spp
from .passes import pass_seed
from .session import apply_post, non_finite_count, session_of
from .subsample import render_adaptive

#: the most samples of one pass (memory: each sample's path state lives at once)
MAX_PASS_SPP = 256


@dataclass
class RenderSettings:
    """What :func:`render` renders, every argument checked and resolved against the scene."""
    scene: DraawScene
    version: str
    spp: int
    seed: int
    max_depth: int
    pass_spp: int
    hide_emitters: bool
    aovs: list
    options: dict
    chain: list | None                 # the post chain as given (recorded as the user wrote it)
    loaded: object = None              # ... and loaded (a draaw_mi.post.Chain), or None
    denoise: bool = False
    guide_aovs: list = field(default_factory=list)   # AOVs rendered only for the denoiser
    sensor: int = 0                    # the index of the sensor that renders


@in_foreground
def render(scene, version: str | None = None, spp: int | None = None, seed: int | None = None,
           max_depth: int | None = None, resolution=None, *, params=None, progress: bool | str = False,
           time_budget: float | None = None, pass_spp: int | None = None, post=None,
           hide_emitters: bool | None = None, aovs=None, return_info: bool = False,
           integrator_options: dict | None = None, adaptive: int | None = None, denoise: bool = False,
           sensor: int | str = 0):
    """Render ``scene`` and return an (H, W, C) ``mi.TensorXf`` (C = the film's colour channels,
    R, G, B, or an XML film's R, G, B, A / X, Y, Z[, A] / Y[, A], + AOV channels).

    Args:
        scene: a :class:`DraawScene`, file name, description dict or ``mi.Scene`` (load a file
            once and pass the scene: small renders replay a recording kept with it).
        version: ``"v1"`` .. ``"v4"`` (GO-Draaw names accepted), ``"path"`` or ``"prb"``, and
            ``"volpath"`` / ``"prbvolpath"`` for media; default the scene's ``render.version``.
            Mitsuba's integrators cannot see ``[[sdf]]`` objects, ``path`` / ``prb`` not media:
            such a request raises :class:`RenderError`.
        spp, seed, max_depth, resolution: override the scene's render settings (``resolution``
            as ``(W, H)``).
        params: ``mi.traverse`` parameters, for differentiable renders (``dr.backward`` works).
        progress: ``"bar"`` a tqdm bar over passes, ``"lines"`` a line now and then (for logs),
            ``True`` the bar on a terminal or in a notebook and the lines elsewhere
            (:mod:`draaw_mi.progress`).
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
            interpolation (see :mod:`draaw_mi.rendering.subsample`; biased, not differentiable, no AOVs).
        denoise: denoise the colour with Intel OIDN (:func:`draaw_mi.denoise`, needs ``pyoidn``),
            guided by albedo and normal AOVs rendered for it (returned only if asked for in
            ``aovs``); applied before the post chain. Biased, not differentiable. With a draaw
            version and emitters shown, the emitters seen directly are rendered apart and
            added undenoised (OIDN smears a bright emitter's edge); ``return_info`` holds
            the undenoised colour as ``info["raw"]`` (with any version).
        sensor: which of the scene's sensors renders: its index, or its id in the scene file
            (an XML scene's ``<sensor id="top">``); default the first.

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
    if not isinstance(return_info, (bool, np.bool_)):
        raise RenderError(f"render: return_info={return_info!r}; expected True or False")
    rs = _settings(scene, version, spp, seed, max_depth, resolution, params, time_budget, pass_spp, post,
                   hide_emitters, aovs, integrator_options, adaptive, denoise, sensor)
    session = session_of(rs.scene)
    if adaptive is not None:
        return _render_adaptive(rs, session, adaptive, params, return_info, progress)
    if _emission_apart(rs, session):
        return _render_denoised_apart(rs, progress, return_info, time_budget)
    integrator = session.integrator(rs.version, rs.max_depth, rs.hide_emitters, rs.aovs, **rs.options)
    if time_budget is None:
        counts = session.sample_passes(rs.spp, rs.pass_spp, rs.sensor)
        n_passes = len(counts)
        # (the samples taken: a sampler rounds spp up to its pattern, 5 -> 8 of ldsampler)
        total = sum(counts)
    else:                # (as many as the budget allows of up to 2^32 - 1: not listed up front)
        counts, n_passes, total = _budget_passes(session, rs.spp, rs.pass_spp, rs.sensor), None, rs.spp
    with closed_after(progress_bar(total, f"render {rs.version}", "spp", progress, leave=False,
                                   where="render")) as bar:
        acc, done, passes, t0 = None, 0, 0, time.perf_counter()
        with session.lock:                         # the passes of one render see one scene
            for i, count in enumerate(counts):
                img = session.render_pass(integrator, count, pass_seed(rs.seed, i), params=params,
                                          sensor=rs.sensor or None)
                if n_passes == 1:
                    acc = img                      # one pass: no extra scaling kernels (small renders)
                else:
                    with RENDER_GUARD:
                        acc = img * count if acc is None else acc + img * count
                        dr.eval(acc)
                        dr.sync_thread()
                done += count
                passes += 1
                if bar is not None:
                    bar.update(count)              # (the bar shows the time itself)
                if time_budget is not None and time.perf_counter() - t0 >= time_budget:
                    break
    image, names, bad, raw = _finish(rs, integrator, acc, done, summed=n_passes != 1)
    _warn_non_finite(bad, rs)
    if return_info:
        info = {"spp": done, "passes": passes, "seconds": time.perf_counter() - t0,
                "channels": names, "version": rs.version, "integrator": session_of(rs.scene).plugin_name(rs.version),
                "denoised": rs.denoise, "non_finite": bad, "post": rs.chain, "sensor": rs.sensor}
        if raw is not None:
            info["raw"] = raw
        return image, info
    return image


#: the most samples per pixel a render takes (Mitsuba's samplers count them in 32 bits)
MAX_SPP = 2 ** 32 - 1


def _budget_passes(session, spp: int, pass_spp: int, sensor: int = 0):
    """The pass counts of ``spp`` samples, as :meth:`Session.sample_passes` gives them, made
    4096 passes at a time: a time budget ends a render early, and 4e9 spp asked for in
    passes of 16 listed up front took 1.4 GB and the budget before a pass rendered."""
    left = spp
    while left > 0:
        part = session.sample_passes(min(left, pass_spp * 4096), pass_spp, sensor)
        yield from part
        left -= sum(part)


def _settings(scene, version, spp, seed, max_depth, resolution, params, time_budget, pass_spp, post,
              hide_emitters, aovs, integrator_options, adaptive, denoise, sensor=0) -> RenderSettings:
    """:func:`render`'s arguments checked and resolved against the scene's settings (nothing
    renders before every argument is known to be good)."""
    if not isinstance(scene, DraawScene):
        scene = load_scene(scene)
    s = scene.settings
    if params is not None and not isinstance(params, mi.SceneParameters):
        raise RenderError(f"render: params of type {type(params).__name__}; expected the scene's "
                          "parameters (scene.params, or mi.traverse(scene.mi_scene)) with gradients "
                          "enabled on some")
    if params is not None and not _parameters_of(scene, params):
        raise RenderError(f"render: params belong to another scene than {scene.source} (a scene loaded "
                          "again, say): gradients would not reach them; pass this scene's scene.params")
    given, sensor = sensor, sensor_index(scene, sensor)
    if resolution is not None and sensor:
        raise RenderError(f"render: resolution={resolution!r} sizes the scene's first film; sensor={given!r} "
                          "renders another at its own size: drop resolution=")
    if resolution is not None:
        size = tuple(parse_res(resolution, Where("render") / "resolution"))
        if params is not None and size != scene.resolution:
            # the reloaded copy has its own parameters: gradients would not reach `params`
            raise RenderError(f"render: resolution={resolution!r} with params= renders a reloaded "
                              "copy of the scene that `params` do not belong to; render "
                              "`scene.with_resolution(w, h)` and traverse that instead")
        scene = scene.with_resolution(*size)
    version = s["version"] if version is None else version
    if sensor and adaptive is not None:
        raise RenderError(f"render: adaptive subsampling renders the first sensor; sensor={sensor} with "
                          "adaptive=: drop one")
    if spp is None:
        spp = sensor_spp(scene, sensor)
    if resolve_version(version) == SCENE_VERSION:
        ignored = [f"{n}={v!r}" for n, v in (("max_depth", max_depth), ("hide_emitters", hide_emitters))
                   if v is not None]
        if ignored:
            warnings.warn(f"render: version 'scene' renders with the integrator the scene declares, "
                          f"with its own settings: {', '.join(ignored)} not applied (give a version "
                          "such as 'v4' or 'path' to set them)", RuntimeWarning, stacklevel=3)
    spp = _check_int("spp", spp, 1, MAX_SPP)
    seed = _check_int("seed", s["seed"] if seed is None else seed, 0, 2 ** 32 - 1)     # a UInt32
    max_depth = _check_int("max_depth", s["max_depth"] if max_depth is None else max_depth, -1)
    if time_budget is not None and (isinstance(time_budget, bool) or not (
            isinstance(time_budget, numbers.Real) and 0 < time_budget < float("inf"))):
        raise RenderError(f"render: time_budget={time_budget!r}; expected a positive number of seconds")
    if pass_spp is None:
        # not from the progress mode: the passes' seeds make the samples, and V4 samples
        # adaptively only in passes of 64 spp or more
        pass_spp = min(spp, 16 if time_budget else MAX_PASS_SPP)
    pass_spp = _check_int("pass_spp", pass_spp, 1)
    hide = s.get("hide_emitters", False) if hide_emitters is None else hide_emitters
    for name, flag in (("hide_emitters", hide), ("denoise", denoise)):
        if not isinstance(flag, (bool, np.bool_)):         # a truthy string is not True
            raise RenderError(f"render: {name}={flag!r}; expected True or False")
    if integrator_options is not None and not isinstance(integrator_options, dict):
        raise RenderError(f"render: integrator_options={integrator_options!r}; expected a dict of "
                          "integrator plugin properties, e.g. {'rr_depth': 8}")
    if aovs is None:
        aovs = s.get("aovs", [])
        if aovs and not is_draaw(version):
            warnings.warn(f"render: {version!r} renders colour only; the scene's AOVs "
                          f"({', '.join(aovs)}) come from v1..v4", RuntimeWarning, stacklevel=3)
            aovs = []
    elif isinstance(aovs, str):
        aovs = [aovs]                          # "depth" or "all", not its characters
    elif isinstance(aovs, np.ndarray):         # (numpy strings are strings)
        aovs = [str(a) if isinstance(a, np.str_) else a for a in aovs.tolist()]
    if not isinstance(aovs, (list, tuple)) or not all(isinstance(a, str) for a in aovs):
        raise RenderError(f"render: aovs={aovs!r}; expected a list of AOV names "
                          f"({', '.join(AOV_CHANNELS)}) or 'all'")
    try:                                       # (names: the integrator's own check, in render's words)
        parse_aovs("render", ",".join(aovs))
    except DraawError as e:
        raise RenderError(str(e)) from None
    if params is not None and aovs:
        # (Mitsuba's adjoint pass splats AOVs with a Python float among them: a TypeError
        # from ImageBlock.put inside dr.backward)
        raise RenderError(f"render: AOVs ({', '.join(aovs)}) are not differentiable; drop params= or "
                          "pass aovs=[] (render the AOVs apart, without params=)")
    session_of(scene).check_version_sees(version)
    if callable(post) and not isinstance(post, post_mod.Chain):
        raise RenderError(f"render: post={post!r}; expected a chain (a list of filter tables, a Chain "
                          "or a JSON file): apply a function of your own to the returned image")
    chain = s.get("post", []) if post is None else post
    # loaded and checked now, before the render; ``chain`` stays as given: the info (and a
    # batch frame's header) records it as the user wrote it
    loaded = post_mod.load_chain(chain) if chain else None
    _warn_grade_left_out(version, loaded)
    if (chain or denoise) and adaptive is None:
        check_film_colour(scene, "a post chain" if chain else "denoising", sensor)
    guides: list = []
    if denoise:                                # check early, render the guide AOVs with the image
        aovs, guides = _denoise_aovs(params, adaptive, aovs, version)
    return RenderSettings(scene, version, spp, seed, max_depth, pass_spp, bool(hide), list(aovs),
                          dict(integrator_options or {}), chain, loaded, bool(denoise), guides, sensor)


def _parameters_of(scene: DraawScene, params) -> bool:
    """Whether ``params`` (``mi.SceneParameters``) are ``scene``'s: its own, or a traversal of
    its objects (``mi.traverse(scene.mi_scene)``: the same plugin objects behind the keys)."""
    if params is scene.params or params is scene.all_params:
        return True
    props = (params.base if isinstance(params, SDFParameters) else params).properties
    own = scene.params.properties
    for key, entry in props.items():
        if key in own and entry[2] is not None:
            return own[key][2] is entry[2]
    return not props                           # (nothing to tell by)


def _warn_non_finite(bad: int, rs: RenderSettings) -> None:
    """Say that an image holds NaN / inf values (``info["non_finite"]`` counts them too): a
    value set through ``scene.params`` that a scene file would refuse (a NaN colour, a negative
    roughness) renders them, and a post chain or denoiser reads them as 0 and hides them. Say
    it of such a value set since the last render even when the image is finite: a NaN texel of
    a roughness map, a Henyey-Greenstein g past +-0.999 render finite pixels that are wrong."""
    why = rs.scene.out_of_range(1) if bad else rs.scene.out_of_range(1, changed_only=True)
    if bad:
        warnings.warn(f"render: {bad} value(s) of the {rs.version} render of {rs.scene.source} are NaN "
                      "or inf" + (f"; {why[0].removeprefix('out_of_range: ')} (set through scene.params: "
                                  "scene.out_of_range() lists what a scene file would refuse)" if why else ""),
                      NonFiniteWarning, stacklevel=3)
    elif why:
        warnings.warn(f"render: the {rs.version} render of {rs.scene.source} used "
                      f"{why[0].removeprefix('out_of_range: ')}; its pixels are not to be trusted (set "
                      "through scene.params: scene.out_of_range() lists what a scene file would refuse)",
                      RuntimeWarning, stacklevel=3)


def _finish(rs: RenderSettings, integrator, acc, done: int, summed: bool):
    """``(image, channel names, non-finite values, the undenoised colour or None)``: the mean
    of the passes, named by the film's colour channels as its pixel_format stores them (R, G,
    B[, A], X, Y, Z[, A] or Y[, A]) and the AOVs', denoised and post-processed as asked. The
    non-finite values are counted before denoising and the chain, which read NaN/inf as 0 and
    would hide them; the undenoised colour (H, W, 3) is kept where denoising was asked for (any
    version: ``info["raw"]``, the CLI's ``raw.R/G/B``)."""
    aov_names = integrator.aov_names()
    colour = scene_colour_names(rs.scene, rs.sensor)
    names = (colour + aov_names if len(colour) + len(aov_names) == acc.shape[2]
             else channel_names(acc.shape[2], aov_names))
    image = acc
    if summed:                                 # (passes weighted by their counts: / the total)
        with RENDER_GUARD:
            image = acc / done
            dr.eval(image)
            dr.sync_thread()
    bad = non_finite_count(image)              # (one small kernel: said, and in the info)
    raw = None
    if rs.denoise or rs.chain:
        with RENDER_GUARD:                     # denoising, post: their kernels and reads back
            if rs.denoise:
                raw = np.array(image)[..., :3].copy()
                image, names = _denoised(image, names, rs.guide_aovs)
            if rs.chain:
                image = apply_post(image, rs.loaded, names)
    return image, names, bad, raw


def _emission_apart(rs: RenderSettings, session) -> bool:
    """Whether ``denoise=True`` keeps the emitters seen directly out of the denoiser: draaw
    versions (the guides), emitters shown, an RGB film, no media."""
    return (rs.denoise and is_draaw(rs.version) and not rs.hide_emitters
            and scene_colour_names(rs.scene, rs.sensor) == ["R", "G", "B"] and not session.holds()["media"])


def _render_denoised_apart(rs: RenderSettings, progress, return_info, time_budget=None):
    """``denoise=True`` with the emitters seen directly left out of the denoiser: OIDN smears
    the edge of a bright emitter (the Cornell box's ceiling light at 18 next to a ceiling at
    0.2 came out 3.5 lower along its edge, an RMSE of 0.042 at 256x256 where the raw 64-spp
    render has 0.020). The full render is the undenoised image, ``info["raw"]`` (H, W, 3);
    the emitters seen by the camera (``max_depth=1``, the same seed: the same camera rays where
    the sampling is not adaptive) are rendered apart, the rest (full minus seen, at least 0) is
    denoised, and the seen emitters are added back undenoised. (Rendering the rest with the
    emitters hidden instead would shade what lies behind an area light where the camera sees
    it: a light seen from its back would vanish.) With a time budget the emitters take the
    passes the full render did (the same seeds and counts: the first passes of the spp
    asked); AOVs asked for come with the full render."""
    common = dict(version=rs.version, seed=rs.seed, pass_spp=rs.pass_spp, post=[],
                  integrator_options=rs.options or None, sensor=rs.sensor)
    t0 = time.perf_counter()
    full, info = render(rs.scene, max_depth=rs.max_depth, hide_emitters=False, aovs=rs.aovs, spp=rs.spp,
                        time_budget=time_budget, progress=progress, return_info=True, **common)
    seen = render(rs.scene, max_depth=1, hide_emitters=False, aovs=[], spp=info["spp"], **common)
    with RENDER_GUARD:
        arr = np.array(full)
        emission = np.nan_to_num(np.array(seen)[..., :3])
        raw = arr[..., :3].copy()
        arr[..., :3] = np.maximum(np.nan_to_num(arr[..., :3]) - emission, 0.0)
        out, names = _denoised(mi.TensorXf(arr), info["channels"], rs.guide_aovs)
        out = np.array(out)
        out[..., :3] += emission
        image = mi.TensorXf(np.ascontiguousarray(out))
        if rs.chain:
            image = apply_post(image, rs.loaded, names)
    if return_info:
        info.update({"channels": names, "denoised": True, "post": rs.chain, "raw": raw,
                     "seconds": time.perf_counter() - t0,
                     "emitters_denoised": False})
        return image, info
    return image


def _warn_grade_left_out(version: str, chain) -> None:
    """Warn when a GO-Draaw graded version name (``V4-Log``) comes without its grade's post
    filter: the name renders linear light, as ``V4`` does."""
    grade = VERSION_GRADES.get(version_key(version))         # (V4_Log as V4-Log)
    if grade is None or (chain is not None and any(e.get("type") == grade for e in chain.to_list())):
        return
    warnings.warn(f"render: version {version!r} renders linear light, as {resolve_version(version)!r} "
                  f"does; its {grade.capitalize()} colour grade is the post filter {grade!r} (add "
                  f"{{'type': '{grade}'}} to the post chain)", RuntimeWarning, stacklevel=4)


def _render_adaptive(rs: RenderSettings, session, block, params, return_info, progress):
    """:func:`render` with adaptive subsampling (:mod:`draaw_mi.rendering.subsample`)."""
    if params is not None:
        raise RenderError("render: adaptive subsampling is not differentiable; drop params= or adaptive=")
    if rs.aovs:
        raise RenderError("render: adaptive subsampling renders colour only; drop aovs or adaptive=")
    holds = session.holds()
    if holds["sdf"] or holds["media"]:
        # its corner signatures (camera, shadow and mirror rays) see meshes only: SDF objects
        # and smoke would come out as interpolated smears
        what = "[[sdf]] objects" if holds["sdf"] else "participating media"
        raise RenderError(f"render: adaptive subsampling cannot see {what} ({rs.scene.source}); drop adaptive=")
    integrator = session.integrator(rs.version, rs.max_depth, rs.hide_emitters, (), **rs.options)
    t0 = time.perf_counter()
    with closed_after(progress_bar(rs.spp, f"render {rs.version} adaptive", "spp", progress, leave=False,
                                   where="render")) as bar:
        image, stats = render_adaptive(rs.scene, block=block, spp=rs.spp, seed=rs.seed, integrator=integrator)
        if bar is not None:                    # one launch: the bar fills at once
            bar.update(rs.spp)
    bad = non_finite_count(image)                            # before the chain: see _finish
    _warn_non_finite(bad, rs)
    if rs.chain:                               # (colour only: no AOVs in an adaptive render)
        image = apply_post(image, rs.loaded, scene_colour_names(rs.scene))
    if return_info:
        return image, {"non_finite": bad, "spp": rs.spp, "passes": 1, "seconds": time.perf_counter() - t0,
                       "channels": ["R", "G", "B"], "version": rs.version,
                       "integrator": session_of(rs.scene).plugin_name(rs.version), "adaptive": stats, "post": rs.chain}
    return image


def _denoise_aovs(params, adaptive, aovs, version):
    """(AOVs to render, the ones added only to guide the denoiser) for ``denoise=True``.
    Mitsuba's own integrators (``path``, ``prb``) have no AOV outputs: colour-only denoising."""
    if params is not None:
        raise RenderError("render: denoise=True is not differentiable; drop params= or denoise=")
    if adaptive is not None:
        raise RenderError("render: denoise=True cannot be combined with adaptive= (no AOVs there)")
    load_pyoidn()                             # the one-line install hint before any rendering
    aovs = [aovs] if isinstance(aovs, str) else list(aovs)
    if not is_draaw(version):
        return aovs, []
    asked = {a.strip() for item in aovs for a in str(item).split(",")}
    if "all" in asked:
        return aovs, []
    extra = [a for a in AUX_AOVS if a not in asked]
    return aovs + extra, extra


def _denoised(image, names, extra_aovs):
    out = denoise_aovs(image, names)
    drop = {c for a in extra_aovs for c in AOV_CHANNELS[a]}
    keep = [i for i, n in enumerate(names) if n not in drop]
    if len(keep) < len(names):
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
