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

The error is the mean squared difference between renders of every capture (fixed seeds, so
the candidates share their noise) and its reference, with saturated pixels of display
references masked as the fit masks them. Measured on the SVBRDF benchmark (8 captures, 64²
maps, 128² images, 600 iterations per start; ``benchmarks/results/svbrdf_fit.md``), albedo
PSNR / roughness MAE / metallic MAE, one fit against two starts: the sphere 26.5 / 0.033 /
0.043 against 32.7 / 0.026 / 0.018, the monkey 26.2 / 0.044 / 0.046 against 36.1 / 0.016 /
0.007, the tile (where both starts agree) 32.3 / 0.036 / 0.023 against 32.0 / 0.033 / 0.022.
It takes about three fits' time.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.ndimage

from ..errors import ParameterError
from ..rendering.frozen import owned_tensor
from ..rendering.session import holding, session_of
from ..scene import DraawScene, load_scene
from .captures import capture_references, parse_captures, render_capture
from .fitter import fit
from .maps import material_parameter
from .reference import is_display_reference, load_reference, unclipped_mask
from .result import FitResult

#: the refining fit's learning rate, as a multiple of the two fits' (it starts near an optimum)
REFINE_LR = 0.4
#: spp of the renders that compare candidate maps
EVAL_SPP = 64


def fit_two_starts(scene, references=None, params=(), *, captures: list, iterations: int = 300,
                   refine: float = 0.33, lr: float = 0.05, seed: int = 0, min_texels: int = 4,
                   eval_spp: int = EVAL_SPP, **fit_kwargs) -> FitResult:
    """Fit texture maps (with at least one metallic map among ``params``) from two starts of
    the metallic maps, merged region by region by the captures' error, then refined (module
    docstring).

    Args:
        scene, references, params, captures, lr, seed, ``fit_kwargs``: as
            :func:`~draaw_mi.fitting.fitter.fit` takes them (``init`` sets the first start;
            the second is the same with the metallic maps at 0). Captures are required.
        iterations: iterations of each of the two fits.
        refine: the refining fit's iterations, as a fraction of ``iterations`` (0: none).
        min_texels: regions smaller than this keep the better fit's maps untested.
        eval_spp: spp of the renders that compare candidates.

    Returns:
        The refining fit's :class:`~draaw_mi.fitting.result.FitResult` (the merged maps' when
        ``refine`` is 0), with ``history`` the three fits' in order, ``iterations`` and
        ``seconds`` their totals, and ``stages``: per stage its name, error and seconds, and
        for the merge how many regions it tested and took.

    Example::

        res = fit_two_starts(scene, None, ["obj.base_color", "obj.roughness", "obj.metallic"],
                             captures=captures, iterations=600, batch=2)
        res.stages    # [{"stage": "from the scene's start", "error": ...}, ...]
    """
    t0 = time.perf_counter()
    if not isinstance(scene, DraawScene):
        scene = load_scene(scene)
    names = [params] if isinstance(params, str) else list(params)
    if scene.settings.get("post") or fit_kwargs.get("post"):
        raise ParameterError("fit_two_starts: the scene has a post chain; expected none (the merge compares "
                             "linear renders with the references)")
    if not (isinstance(refine, (int, float)) and 0 <= refine <= 1):
        raise ParameterError(f"fit_two_starts: refine={refine!r}; expected a fraction of iterations in [0, 1]")
    p = scene.all_params
    metal = [n for n in names if material_parameter(scene.key(n)) == "metallic"
             and np.asarray(p[scene.key(n)]).ndim == 3]
    if not metal:
        raise ParameterError(f"fit_two_starts: params {names} hold no metallic map; expected at least one "
                             "(a texture), or use fit()")
    start = {n: _value(p[scene.key(n)], (fit_kwargs.get("init") or {}).get(n)) for n in names}
    caps = parse_captures(captures, references)
    refs = [load_reference(r, who=f"fit_two_starts: captures[{i}]")
            for i, r in enumerate(references if references is not None else capture_references(caps))]
    masks = [unclipped_mask(r) if is_display_reference(g) else None
             for g, r in zip(references if references is not None else capture_references(caps), refs)]
    kwargs = {k: v for k, v in fit_kwargs.items() if k != "init"}
    common = dict(captures=captures, lr=lr, seed=seed, **kwargs)

    def run(init, its, rate):
        r = fit(scene, references, names, iterations=its, init=init, **dict(common, lr=rate))
        return r, {n: np.asarray(r.values[n], dtype=np.float32) for n in names}

    def error(values):
        return _captures_error(scene, values, caps, refs, masks, version, eval_spp, seed)

    zero = dict(start, **{n: np.zeros_like(start[n]) for n in metal})
    a, va = run(start, iterations, lr)
    version = a.version
    b, vb = run(zero, iterations, lr)
    ea, eb = error(va), error(vb)
    stages = [{"stage": "from the scene's start", "error": ea, "seconds": a.seconds},
              {"stage": "from metallic 0", "error": eb, "seconds": b.seconds}]
    t_merge = time.perf_counter()
    base, err, tested, taken = merge(scene, *((va, vb, ea) if ea <= eb else (vb, va, eb)), metal, error,
                                     min_texels)
    stages.append({"stage": "merged", "error": err, "seconds": time.perf_counter() - t_merge,
                   "regions": tested, "taken": taken})
    runs = [a, b]
    if refine > 0:
        r, final = run(base, max(1, int(round(refine * iterations))), REFINE_LR * lr)
        runs.append(r)
        stages.append({"stage": "refined", "error": error(final), "seconds": r.seconds})
    else:
        r = a
        _set_values(scene, base)
        r.values = {n: base[n] for n in names}
    r.history = [h for run_ in runs for h in run_.history]
    r.iterations = sum(run_.iterations for run_ in runs)
    r.seconds = time.perf_counter() - t0
    r.stages = stages
    return r


def merge(scene, base: dict, other: dict, base_error: float, metal: list, error, min_texels: int = 4):
    """``(maps, their error, regions tested, regions taken)``: ``base`` (name -> value) with
    each region where ``base`` and ``other`` disagree on metal (:func:`_regions`, per metallic
    map named in ``metal``) taken from ``other`` where that lowers ``error(maps)``, largest
    region first; ``base_error`` is ``error(base)``."""
    tested = taken = 0
    for n in metal:
        for region in _regions(base[n][..., 0] > 0.5, other[n][..., 0] > 0.5, min_texels):
            cand = _swap(base, other, region, scene.key(n), scene)
            e = error(cand)
            tested += 1
            if e < base_error:
                base, base_error, taken = cand, e, taken + 1
    return base, base_error, tested, taken


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
    """Boolean (H, W) masks of the connected regions where the two maps disagree on metal,
    each widened by one texel (its four neighbours), largest first; those under ``min_texels``
    dropped.

    >>> a = np.zeros((6, 6), bool); b = a.copy(); b[1:3, 1:3] = True; b[5, 5] = True
    >>> [int(m.sum()) for m in _regions(a, b, 3)], [int(m.sum()) for m in _regions(a, b, 4)]
    ([12, 3], [12])
    """
    labels, n = scipy.ndimage.label(base_metal != other_metal)
    out = [scipy.ndimage.binary_dilation(labels == i) for i in range(1, n + 1)]
    return sorted((m for m in out if m.sum() >= min_texels), key=lambda m: -int(m.sum()))


def _swap(base: dict, other: dict, region: np.ndarray, metal_key: str, scene) -> dict:
    """``base`` with ``other``'s texels inside ``region`` for every map of the metallic map's
    material and size."""
    material = metal_key.split(".")[0]
    out = dict(base)
    for n, v in base.items():
        if v.ndim == 3 and v.shape[:2] == region.shape and scene.key(n).split(".")[0] == material:
            out[n] = np.where(region[..., None], other[n], v)
    return out


def _set_values(scene, values: dict) -> None:
    """Write ``values`` (name -> array or number) into ``scene``'s parameters."""
    p = scene.all_params
    with holding(scene):
        for n, v in values.items():
            k = scene.key(n)
            p[k] = owned_tensor(v) if np.ndim(v) == 3 else type(p[k])(v.tolist() if np.ndim(v) else float(v))
        p.update()
        session_of(scene).scene_changed()


def _captures_error(scene, values: dict, caps: list, refs: list, masks: list, version: str, spp: int,
                    seed: int) -> float:
    """Mean over the captures of the mean squared difference between a render of ``scene``
    with ``values`` (capture ``i`` with seed ``seed + i``) and its reference."""
    _set_values(scene, values)
    h, w = refs[0].shape[:2]
    view = scene if scene.resolution == (w, h) else scene.with_resolution(w, h)
    if view is not scene:
        _set_values(view, values)
    total = 0.0
    for i, (c, ref, mask) in enumerate(zip(caps, refs, masks)):
        setup = {k: v for k, v in c.items() if k != "reference"}
        d = render_capture(view, setup, spp=spp, version=version, seed=seed + i).astype(np.float64) - np.asarray(ref)[..., :3]
        if mask is not None:
            d = d * np.asarray(mask)[..., :d.shape[2]]
        total += float(np.mean(d * d))
    return total / len(caps)
