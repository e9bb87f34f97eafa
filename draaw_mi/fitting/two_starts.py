"""Texture maps fitted from two starts of their metallic maps, merged region by region.

A metallic map is 0 or 1 almost everywhere, and a fit of one stops in local minima that no
smaller step escapes. From metallic 0.5 a dark dielectric turns metal (turning metal is the
fastest way to darken a texel, and the colour then brightens to make up for it); from
metallic 0 (the material's default) part of a real metal patch can stay dielectric. The two
fail in different places. :func:`fit_two_starts`:

1. **fits twice** with :func:`~draaw_mi.fitting.fitter.fit`: from the scene's values, and
   from the same values with every fitted metallic map at 0;
2. **merges**: starting from the fit whose renders match the captures better, each region
   where the two disagree on metal (a connected set of texels where one says metal and the
   other not, widened by one texel) takes the other fit's maps if that lowers the captures'
   error, largest region first (greedy: the merged maps' error is never above either fit's);
3. **refines** the merged maps with a shorter fit (``refine`` times ``iterations``, at a
   smaller learning rate), which settles the seams between regions.

The error estimates the squared difference between each capture's expected render and its
reference, with saturated pixels of display references masked as the fit masks them: the
product of two renders' differences from the reference, with independent seeds (their noise
cancels in its expectation; fixed seeds, so the candidates share their noise), at
:data:`EVAL_SPP`. One render's squared difference adds that render's variance, which is
larger where a region is metal (its highlights are noisier): on the benchmark's sphere at 64
spp it was 72 % noise and took a dielectric hole into a metal patch (3 dB of albedo PSNR
lost). The regions' swaps change the error by 2-5 %, so the renders need spp: on that
sphere's two fits the two-render estimate at 64 spp took 5 of 8 regions (merged albedo PSNR
27.8 dB, metallic MAE 0.035), at 256 spp 6 (33.9 dB, 0.021), deciding as 512-spp renders do
on the two largest regions (``benchmarks/results/svbrdf_fit.md``, 2026-12-05).

Measured on the SVBRDF benchmark (8 captures, 64² maps, 128² images, 600 iterations per
start; ``benchmarks/results/svbrdf_fit.md``), albedo PSNR / roughness MAE / metallic MAE, one
fit against two starts: the sphere 26.5 / 0.033 / 0.043 against 32.7 / 0.026 / 0.018, the
monkey 26.2 / 0.044 / 0.046 against 36.1 / 0.016 / 0.007, the tile (where both starts agree)
32.3 / 0.036 / 0.023 against 32.0 / 0.033 / 0.022 (2026-12-04); with the merge as now, two
starts give 34.5 / 0.023 / 0.015, 37.1 / 0.017 / 0.007 and 33.0 / 0.028 / 0.020 in 320-440 s.
It takes about three fits' time (two fits, the merge's renders and a refine of a third).
"""
from __future__ import annotations

import time

import numpy as np

from ..errors import ParameterError
from ..progress import closed_after, progress_bar
from ..rendering.frozen import owned_tensor
from ..rendering.session import holding, session_of
from ..scene import DraawScene, load_scene
from ..scene.values import value_like
from .captures import capture_references, parse_captures, render_capture
from .fitter import fit
from .maps import material_parameter
from .reference import is_display_reference, load_reference, unclipped_mask
from .result import FitResult
from .settings import check_counts

#: the refining fit's learning rate, as a multiple of the two fits' (it starts near an optimum)
REFINE_LR = 0.4
#: spp of the renders that compare candidate maps
EVAL_SPP = 256
#: seed offset of the second render of each capture in :func:`_captures_error`
SECOND_RENDER = 0x5EC0D


def fit_two_starts(scene, references=None, params=(), *, captures: list, iterations: int = 300,
                   refine: float = 0.33, lr: float = 0.05, seed: int = 0, min_texels: int = 4,
                   eval_spp: int = EVAL_SPP, **fit_kwargs) -> FitResult:
    """Fit texture maps (with at least one metallic map among ``params``) from two starts of
    the metallic maps, merged region by region by the captures' error, then refined (module
    docstring).

    Args:
        scene, references, params, captures, lr, seed, ``fit_kwargs``: as
            :func:`~draaw_mi.fitting.fitter.fit` takes them (``polish`` polishes the refining
            fit only, at 0.4x its rate; the "refined" stage then holds the polish's). The first start is the scene's
            values (``init`` over them; a metallic map that starts at 0 everywhere starts at
            0.5 here, so that the two starts differ), the second the same with the metallic
            maps at 0. Captures are required; no post chain (``post=[]`` turns the scene's
            off) and no ``exposure="fit"``: the merge compares linear renders, at the scene's
            ``max_depth``, with the references.
        iterations: iterations of each of the two fits.
        refine: the refining fit's iterations, as a fraction of ``iterations`` (in (0, 1]).
        min_texels: regions of disagreement smaller than this (before widening) are not tested.
        eval_spp: spp of the renders that compare candidates (two per capture and candidate).

    Returns:
        The refining fit's :class:`~draaw_mi.fitting.result.FitResult` (its ``values``,
        ``image``, ``captures``, ``observed`` and ``converged`` are the refine's: the scene
        holds its values), with ``history`` the three fits' (and a polish's) in order (each entry's
        ``iteration`` counts from 0 within its fit), ``iterations`` and ``seconds`` the
        totals, and ``stages``: per stage its name, captures error and seconds, and for the
        merge how many regions it tested and took. The refined maps are returned even where
        their error is above the merged maps' (``stages`` shows both).

    Example::

        res = fit_two_starts(scene, None, ["obj.base_color", "obj.roughness", "obj.metallic"],
                             captures=captures, iterations=600, batch=2)
        res.stages    # [{"stage": "from the scene's start", "error": ...}, ...]
    """
    t0 = time.perf_counter()
    if not isinstance(scene, DraawScene):
        scene = load_scene(scene)
    names = [params] if isinstance(params, str) else list(params)
    _check_options(scene, fit_kwargs, refine, min_texels, eval_spp)
    p = scene.all_params
    keys = {n: scene.key(n) for n in names}
    metal = [n for n in names if material_parameter(keys[n]) == "metallic"]
    if not metal or any(np.asarray(p[keys[n]]).ndim != 3 for n in metal):
        what = "no metallic parameter" if not metal else "a metallic value, not a map"
        raise ParameterError(f"fit_two_starts: params {names} hold {what}; expected at least one metallic "
                             "texture (or fit() / the CLI without --two-starts)")
    init = dict(fit_kwargs.pop("init", None) or {})
    unknown = sorted(set(init) - set(names) - set(keys.values()))
    if unknown:
        raise ParameterError(f"fit_two_starts: init names {unknown}, which are not in params {names}")
    given = {n: init.get(n, init.get(keys[n])) for n in names}
    original = {n: _value(p[keys[n]], None) for n in names}
    start = {n: _value(p[keys[n]], given[n]) for n in names}
    for n in metal:
        if not np.any(start[n]):               # already 0: the first start at 0.5
            start[n] = np.full_like(start[n], 0.5)
    listed = references if references is None or isinstance(references, (list, tuple)) else [references]
    caps = parse_captures(captures, listed)
    sources = listed if listed is not None else capture_references(caps)
    refs = [load_reference(r, who=f"fit_two_starts: {'references' if listed is not None else 'captures'}[{i}]")
            for i, r in enumerate(sources)]
    masks = [unclipped_mask(r) if is_display_reference(g) else None for g, r in zip(sources, refs)]
    polish = {k: fit_kwargs.pop(k) for k in ("polish", "polish_spp") if k in fit_kwargs}   # (the refine's)
    common = dict(captures=captures, seed=seed, **fit_kwargs)

    def run(values, its, rate, **extra):
        _set_values(scene, values)
        r = fit(scene, listed, names, iterations=its, lr=rate, **common, **extra)
        return r, {n: np.asarray(r.values[n], dtype=np.float32) for n in names}

    h, w = refs[0].shape[:2]
    view = scene if scene.resolution == (w, h) else scene.with_resolution(w, h)   # (built once)

    def error(values):
        return _captures_error(view, values, caps, refs, masks, version, eval_spp, seed)

    try:
        a, va = run(start, iterations, lr)
        version = a.version
        b, vb = run(dict(start, **{n: np.zeros_like(start[n]) for n in metal}), iterations, lr)
        ea, eb = error(va), error(vb)
        stages = [{"stage": "from the scene's start", "error": ea, "seconds": a.seconds},
                  {"stage": "from metallic 0", "error": eb, "seconds": b.seconds}]
        t_merge = time.perf_counter()
        base, err, tested, taken = merge(scene, *((va, vb, ea) if ea <= eb else (vb, va, eb)), metal, error,
                                         min_texels, progress=fit_kwargs.get("progress", True))
        stages.append({"stage": "merged", "error": err, "seconds": time.perf_counter() - t_merge,
                       "regions": tested, "taken": taken})
        r, final = run(base, max(1, int(round(refine * iterations))), REFINE_LR * lr, **polish)
        stages.append({"stage": "refined", "error": error(final), "seconds": r.seconds,
                       **({"polish": r.stages[-1]} if r.stages else {})})
        _set_values(scene, final)
    except BaseException:
        _set_values(scene, original)       # (an interrupted merge leaves no candidate behind)
        raise
    r.history = a.history + b.history + r.history
    r.iterations = a.iterations + b.iterations + r.iterations
    r.seconds = time.perf_counter() - t0
    r.stages = stages
    return r


def _check_options(scene, fit_kwargs: dict, refine, min_texels, eval_spp) -> None:
    """ParameterError for what :func:`fit_two_starts` cannot merge by, before any fit runs."""
    post = scene.settings.get("post") if fit_kwargs.get("post") is None else fit_kwargs["post"]
    if post:
        where = "the scene has" if fit_kwargs.get("post") is None else "post= gives"
        raise ParameterError(f"fit_two_starts: {where} a post chain; expected none (the merge compares linear "
                             "renders with the references; post=[] turns the scene's off)")
    if fit_kwargs.get("exposure", "fixed") == "fit":
        raise ParameterError("fit_two_starts: exposure='fit'; expected the default (the merge compares "
                             "unscaled renders with the references)")
    if isinstance(refine, bool) or not isinstance(refine, (int, float)) or not 0 < refine <= 1:
        raise ParameterError(f"fit_two_starts: refine={refine!r}; expected a fraction of iterations in (0, 1]")
    check_counts("fit_two_starts", ("polish_spp",), min_texels=(min_texels, 1), eval_spp=(eval_spp, 1),
                 polish=(fit_kwargs.get("polish", 0), 0), polish_spp=(fit_kwargs.get("polish_spp"), 1))


def merge(scene, base: dict, other: dict, base_error: float, metal: list, error, min_texels: int = 4,
          progress=False):
    """``(maps, their error, regions tested, regions taken)``: ``base`` (name -> value) with
    each region where ``base`` and ``other`` disagree on metal (:func:`_regions`, per metallic
    map named in ``metal``) taken from ``other`` where that lowers ``error(maps)``, largest
    region first; ``base_error`` is ``error(base)``. ``progress`` as :func:`~draaw_mi.progress.progress_bar`
    takes it: a step per region (each one ``error`` call: 8-10 s at the benchmark's size)."""
    # (a swap changes only its own material's maps, so no map's regions move while another's merge)
    regions = [(n, r) for n in metal for r in _regions(base[n][..., 0] > 0.5, other[n][..., 0] > 0.5, min_texels)]
    with closed_after(progress_bar(len(regions), "two starts: merge", "region", progress,
                                   where="fit_two_starts")) as bar:
        taken = 0
        for n, region in regions:
            cand = _swap(base, other, region, scene.key(n), scene)
            e = error(cand)
            if e < base_error:
                base, base_error, taken = cand, e, taken + 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(taken=taken)
    return base, base_error, len(regions), taken


def _value(current, given):
    """A parameter's start, ``given`` (``init``) where set, else the scene's: a float32 array
    for a texture, else a number or a list (as ``fit(init=...)`` takes them).

    >>> _value(np.full((2, 2, 1), 0.5), None).shape, _value([0.25], None), _value(0.3, [0.1, 0.2, 0.3])
    ((2, 2, 1), 0.25, [0.1, 0.2, 0.3])
    """
    v = np.array(current if given is None else given, dtype=np.float64)
    if v.ndim == 3:
        return v.astype(np.float32)
    v = v.reshape(-1)
    return float(v[0]) if v.size == 1 else [float(x) for x in v]


def _regions(base_metal: np.ndarray, other_metal: np.ndarray, min_texels: int) -> list:
    """Boolean (H, W) masks of the connected regions (four-neighbour) where the two maps
    disagree on metal, those of fewer than ``min_texels`` texels dropped, each widened by one
    texel (its four neighbours), largest first.

    >>> a = np.zeros((6, 6), bool); b = a.copy(); b[1:3, 1:3] = True; b[5, 5] = True
    >>> [int(m.sum()) for m in _regions(a, b, 1)], [int(m.sum()) for m in _regions(a, b, 2)]
    ([12, 3], [12])
    """
    labels = _components(base_metal != other_metal)
    sizes = np.bincount(labels.ravel())
    out = [_widened(labels == i) for i in np.flatnonzero(sizes) if i > 0 and sizes[i] >= min_texels]
    return sorted(out, key=lambda m: -int(m.sum()))


def _components(mask: np.ndarray) -> np.ndarray:
    """Labels (H, W) of ``mask``'s four-neighbour connected components (0 outside the mask):
    each texel takes the smallest label among its neighbours until none changes.

    >>> _components(np.array([[1, 1, 0, 1], [0, 0, 0, 1]], bool)).tolist()
    [[1, 1, 0, 4], [0, 0, 0, 4]]
    """
    big = mask.size + 1
    labels = np.where(mask, np.arange(1, mask.size + 1).reshape(mask.shape), big)
    while True:
        p = np.pad(labels, 1, constant_values=big)
        low = np.minimum.reduce([labels, p[:-2, 1:-1], p[2:, 1:-1], p[1:-1, :-2], p[1:-1, 2:]])
        low = np.where(mask, low, big)
        if np.array_equal(low, labels):
            return np.where(mask, labels, 0)
        labels = low


def _widened(region: np.ndarray) -> np.ndarray:
    """``region`` and its texels' four neighbours."""
    p = np.pad(region, 1)
    return region | p[:-2, 1:-1] | p[2:, 1:-1] | p[1:-1, :-2] | p[1:-1, 2:]


def _swap(base: dict, other: dict, region: np.ndarray, metal_key: str, scene) -> dict:
    """``base`` with ``other``'s texels inside ``region`` for every map of the metallic map's
    material and size."""
    material = _material(metal_key)
    out = dict(base)
    for n, v in base.items():
        if v.ndim == 3 and v.shape[:2] == region.shape and _material(scene.key(n)) == material:
            out[n] = np.where(region[..., None], other[n], v)
    return out


def _material(key: str) -> str:
    """The material id of a parameter key: ``"Material.001.metallic.data"`` -> ``"Material.001"``."""
    return key.removesuffix(".data").removesuffix(".value").rsplit(".", 1)[0]


def _set_values(scene, values: dict) -> None:
    """Write ``values`` (name -> array or number) into ``scene``'s parameters."""
    p = scene.all_params
    with holding(scene):
        for n, v in values.items():
            k = scene.key(n)
            v = np.asarray(v, dtype=np.float32)
            # (textures owned: see owned_tensor; the rest in the parameter's own type)
            p[k] = owned_tensor(v) if v.ndim == 3 else value_like(p[k], v.tolist() if v.ndim else float(v), k)
        p.update()
        session_of(scene).scene_changed()


def _captures_error(view, values: dict, caps: list, refs: list, masks: list, version: str, spp: int,
                    seed: int) -> float:
    """Mean over the captures of an unbiased estimate of the squared difference between the
    expected render of ``view`` (the scene at the references' size) with ``values`` and the
    capture's reference: the product of two renders' differences from it (capture ``i`` with
    seeds ``seed + i`` and ``seed + i +`` :data:`SECOND_RENDER`), whose noise cancels in
    expectation (module docstring). Slightly negative where the maps render the references
    within the noise."""
    _set_values(view, values)
    total = 0.0
    for i, (c, ref, mask) in enumerate(zip(caps, refs, masks)):
        setup = {k: v for k, v in c.items() if k != "reference"}
        target = np.asarray(ref)[..., :3]
        a, b = (render_capture(view, setup, spp=spp, version=version,
                               seed=(seed + i + k) & 0xFFFFFFFF).astype(np.float64) - target
                for k in (0, SECOND_RENDER))
        if mask is not None:
            m = np.asarray(mask)[..., :a.shape[2]]
            a, b = a * m, b * m
        total += float(np.mean(a * b))
    return total / len(caps)
