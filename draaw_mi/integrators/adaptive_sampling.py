"""Unbiased adaptive sampling: a per-pixel sample-count map, and a two-pass render that sets it.

* :func:`render_spp_map` renders one wavefront in which pixel ``i`` gets ``spp_map[i]``
  samples (any counts >= 1; the wavefront is ``sum(spp_map)`` samples long, each sample
  finds its pixel) and returns the per-pixel mean and, optionally, the per-pixel sample
  variance. With a box filter each sample belongs to its pixel; with another filter the
  samples are splatted with the weight ``1 / spp_map`` of their pixel, which keeps the
  filtered image's expectation (:mod:`~draaw_mi.integrators.film_splat`); the variance is
  always that of the pixel's own samples (what the allocation needs).
* :func:`allocate` turns a per-pixel variance estimate into a map: ``m_i = m_min + extra_i``
  with ``extra_i`` proportional to the (3x3-smoothed) standard deviation, which minimises
  ``sum_i sigma_i^2 / m_i`` for a fixed total (as Cycles' adaptive sampling aims for); counts
  are rounded stochastically with a seeded generator, so the total is the budget on average.
* :func:`render_adaptive` (``draaw_v4``'s primal render for ``spp >= min_spp``): a *pilot*
  pass of ``a = spp / 16`` samples per pixel estimates the variance, a *main* pass spends the
  rest of the budget with the map, and the image is ``(a / spp) * pilot + (1 - a / spp) *
  main``. The weights are constants and the main pass's counts depend only on the pilot, so
  ``E[main | pilot] = E[pixel]`` and the image is unbiased (a count-weighted mean of both
  passes would not be: the counts would depend on the pilot's values). Where the pilot's
  even and odd samples disagree on where the noise is (:func:`pilot_agreement`: rare bright
  paths, as light that arrives through a doorway or off a glossy panel), the main pass is
  uniform.

Same seed, same image (up to the order of atomic additions into the per-pixel sums): the
pilot and main passes use seeds derived from ``seed``, and the rounding generator is seeded
from it too. Memory does not grow with spp: each sample finds its pixel by a binary search
over the per-pixel start indices inside the kernel and is summed into per-pixel totals.

>>> import numpy as np
>>> m = allocate(np.array([0.0, 1.0, 4.0, 0.0]).reshape(1, 4), budget=16, m_min=1, seed=0,
...              smooth=False)
>>> int(m.min()) >= 1, abs(int(m.sum()) - 16) <= 2
(True, True)
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .emission_split import PrimaryRays, film_mapping
from .features import sampler_plugin, scene_shapes
from .film_splat import FilmSplat

PILOT_FRACTION = 16         # pilot = spp / 16 samples per pixel (at least 2)
MIN_FRACTION = 2            # every pixel keeps at least (spp - pilot) / 2 main samples
# Floor and cap bound what a wrong pilot costs. A 4-sample pilot misses rare bright paths (the
# point light's glints on the thesis scene's near-mirror floor, 95 % of its variance in ten
# pixels): with a floor of 1/4 and no cap V4 measures 3.0x path's variance x time there at
# 256x256, with 1/2 and a cap of 4x the mean score 1.3x; the Cornell box's gain shrinks from
# 0.26x to 0.43x, the spheres' from 0.61x to 0.70x (benchmarks/results/speed_suite.md).
SCORE_CAP = 4.0             # cap of a pixel's allocation score, in multiples of the mean
COST_FIXED = 1.0            # cost of a sample beyond its rays, in rays (camera ray, set-up, film)


def supported(sensor: mi.Sensor) -> bool:
    """Whether adaptive sampling can render for this sensor and pays: an ``hdrfilm``-like film
    (not spectral-special) that does not sample its border, and the independent sampler. Any
    pixel filter (:mod:`~draaw_mi.integrators.film_splat`), any crop window.

    Not with a stratifying sampler (``multijitter``, ``ldsampler``, ...): stratification
    already removes most of the variance that adaptive sampling would move (multijitter has
    a tenth of the independent sampler's variance at 64 spp on the Cornell box), a pilot's
    sample variance no longer measures a stratified mean's error, and per-pixel counts break
    the strata. Measured with stratified rounds (each pixel's count split into uniform
    rounds the sampler can stratify): 1.23-1.44x the variance x time of uniform V4 with the
    same sampler on the Cornell box, the spheres and the envmap scene at 128x128, 64 spp
    (``benchmarks/results/speed_suite.md``)."""
    if sampler_plugin(sensor.sampler()) != "independent":
        return False
    film = sensor.film()
    if mi.has_flag(film.flags(), mi.FilmFlags.Special):
        return False
    return not film.sample_border()


GLINT_ROUGHNESS = 0.1       # below this roughness a delta light's highlight is a rare event
# Below this rank correlation the pilot's two halves disagree on where the noise is: its map
# would be noise. Measured (Spearman of the 3x3-smoothed per-pixel deviations of even and odd
# pilot samples, 4 samples per pixel, 128^2 and 256^2): 0.58-0.95 on the speed suite's scenes
# where adaptive sampling pays, 0.15 in the room lit through a doorway and 0.09-0.11 on the
# floor lit by a glossy panel, where it cost 1.8x the error of a uniform render.
AGREEMENT_MIN = 0.35


def _ranks(a: np.ndarray) -> np.ndarray:
    r = np.empty(a.size)
    r[np.argsort(a, kind="stable")] = np.arange(a.size)
    return r


def pilot_agreement(halves: np.ndarray) -> float:
    """Rank correlation, over pixels, of the noise that two independent halves of a pilot see
    (``halves``: (H, W, 2) per-pixel sample variances, :func:`render_spp_map`'s fifth result),
    after the 3x3 smoothing the allocation uses: near 1 where the pilot finds the noisy pixels
    reliably, near 0 where rare paths make its variance map noise (1.0 for an image without
    noise: nothing to disagree about).

    >>> rng = np.random.default_rng(0)
    >>> noise = rng.random((16, 16)) ** 4
    >>> same = np.stack([noise, noise * 1.1], -1)
    >>> apart = np.stack([noise, rng.random((16, 16)) ** 4], -1)
    >>> round(pilot_agreement(same), 2), pilot_agreement(apart) < 0.35
    (1.0, True)
    """
    a, b = (np.sqrt(_box3(halves[..., i])).ravel() for i in range(2))
    if a.size < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return 1.0
    return float(np.corrcoef(_ranks(a), _ranks(b))[0, 1])


def _min_roughness(bsdf: mi.BSDF) -> float:
    """Smallest roughness (draaw) or alpha (Mitsuba's rough BSDFs) of ``bsdf``; 1 when it has
    none (delta or diffuse lobes cannot make a delta light's glint)."""
    p = mi.traverse(bsdf)
    vals = []
    for key in p.keys():
        leaf = key.split(".")[-2] if key.endswith((".value", ".data")) else key.split(".")[-1]
        if leaf in ("roughness", "alpha", "alpha_u", "alpha_v"):
            v = np.array(p[key], dtype=np.float64).ravel()
            if v.size:
                vals.append(float(v.min()))
    return min(vals) if vals else 1.0


def pilot_can_miss(scene: mi.Scene) -> bool:
    """Whether the scene's error may sit in events too rare for a pilot of a few samples:
    the highlights of delta lights (point, spot, sun) on near-mirror surfaces. There the
    pilot misses most of the pixels that carry the variance, and every pixel it judged quiet
    loses samples: measured on the thesis scene (a point light over a floor of roughness
    0.05), adaptive sampling costs 2.0x ``path``'s variance x time at 256x256 (24 renders)
    where V4 without it costs 1.15x. Such scenes render with uniform sampling."""
    delta = any(mi.has_flag(e.flags(), mi.EmitterFlags.Delta) for e in scene.emitters())
    if not delta:
        return False
    seen = set()
    for shape in scene_shapes(scene):
        b = shape.bsdf()
        if b is None or id(b) in seen:
            continue
        seen.add(id(b))
        if _min_roughness(b) < GLINT_ROUGHNESS:
            return True
    return False


def render_spp_map(integrator, scene: mi.Scene, sensor: mi.Sensor, spp_map: np.ndarray,
                   seed: int, moments: bool = False, alpha: bool = False, halves: bool = False):
    """Mean (H, W, 3) and, with ``moments``, per-pixel sample variance (H, W, 3), alpha
    (H, W) and mean path length in segments (H, W; 1 where the integrator does not report
    ``last_depth``) of ``integrator.sample`` with ``spp_map[y, x]`` samples at pixel (x, y).
    ``alpha`` (without ``moments``): the mean is (H, W, 4), the fraction of samples that hit
    something (or saw an environment) in its fourth channel. ``halves`` (with ``moments``):
    a fifth result, (H, W, 2), the sample variance of the channel sum over each pixel's even
    and odd samples apart (two independent estimates, for :func:`pilot_agreement`).

    ``spp_map``: (H, W) integers >= 1 (the film's crop window). Primal only (no gradients).
    """
    film = sensor.film()
    w, h = (int(v) for v in film.crop_size())
    ox, oy = (int(v) for v in film.crop_offset())
    box = film.rfilter().is_box_filter()
    m = np.asarray(spp_map)
    # (refused: a transposed (W, H) or flat map would be read in the wrong pixel order, 2.9 samples as 2)
    if m.shape != (h, w) or not np.issubdtype(m.dtype, np.number) or not np.isfinite(m).all()\
            or (m != np.round(m)).any() or m.min() < 1:
        what = (f"shape {m.shape}" if m.shape != (h, w) else f"dtype {m.dtype}"
                if not np.issubdtype(m.dtype, np.number) else f"values from {m.min()} to {m.max()}")
        raise ValueError(f"render_spp_map: spp_map has {what}; expected ({h}, {w}) whole counts >= 1")
    counts = m.astype(np.int64).reshape(-1)
    total = int(counts.sum())
    if total >= 2 ** 32:
        raise ValueError(f"render_spp_map: {total} samples exceed 2^32; render in passes")
    with dr.suspend_grad():
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed, total)
        # pixel of every sample, inside the kernel (no per-sample array: memory does not grow
        # with spp): the last pixel whose first sample index is <= the sample index
        starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.uint32)   # P + 1 entries
        first = mi.UInt32(starts)
        idx = dr.arange(mi.UInt32, total)
        pixel = dr.binary_search(0, w * h, lambda i: dr.gather(mi.UInt32, first, i) <= idx) - 1
        y = pixel // w
        x = pixel - y * w
        corner = mi.Vector2f(mi.Float(x + ox), mi.Float(y + oy))     # film coordinates
        pos = corner + sampler.next_2d()
        aperture = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Vector2f(0.0)
        time = sensor.shutter_open()
        if sensor.shutter_open_time() > 0:
            time += sampler.next_1d() * sensor.shutter_open_time()
        scale, offset = film_mapping(film)
        sample2 = pos * scale if (ox, oy) == (0, 0) else dr.fma(pos, scale, offset)
        ray, weight = sensor.sample_ray_differential(time=time, sample1=0.0, sample2=sample2,
                                                     sample3=aperture)
        splat = None
        if not box:      # the filtered image, from samples weighted by 1 / their pixel's count
            film.prepare([])
            splat = FilmSplat(film)
            share = dr.rcp(dr.gather(mi.Float, mi.Float(counts.astype(np.float32)), pixel))
        reports_depth = moments and hasattr(integrator, "want_depth")     # draaw_v4
        if reports_depth:
            integrator.want_depth = True
        set_primary = getattr(integrator, "set_primary_rays", None)      # draaw_v4
        if set_primary is not None:       # each ray's pixel, for its emission splitting
            set_primary(PrimaryRays(ray, sensor, corner, scale, offset, weight,
                                    splat=None if splat is None else (splat, share)))
        try:
            L, valid, _, _ = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler,
                                               ray=ray, depth=mi.UInt32(0), δL=None, δaovs=None,
                                               state_in=None, active=mi.Bool(True))
            depth = integrator.last_depth if reports_depth else None   # segments per path
        finally:
            if reports_depth:
                integrator.want_depth, integrator.last_depth = False, None
            if set_primary is not None:
                set_primary(None)
        value = L * weight
        if splat is not None:
            splat.put(pos, value, dr.select(valid, 1.0, 0.0), share)
            filtered = splat.develop()
            if not moments:
                dr.eval(filtered)
                return np.array(filtered, dtype=np.float64).reshape(h, w, 4 if alpha else 3)
        chans = [value.x, value.y, value.z]
        if moments or alpha:
            chans += [dr.select(valid, 1.0, 0.0) + 0.0 * value.x]
        if moments:
            chans += [(mi.Float(depth) if depth is not None else 1.0) + 0.0 * value.x,
                      dr.square(value.x), dr.square(value.y), dr.square(value.z)]
        if moments and halves:       # the channel sum's moments over odd and even samples apart
            odd = ((idx - dr.gather(mi.UInt32, first, pixel)) & 1) == 1
            v = value.x + value.y + value.z
            for part in (~odd, odd):
                chans += [dr.select(part, v, 0.0), dr.select(part, dr.square(v), 0.0),
                          dr.select(part, 1.0, 0.0) + 0.0 * v]
        # Samples of a pixel are contiguous: a local (in-packet) reduction before the atomics.
        sums = [dr.zeros(mi.Float, w * h) for _ in chans]
        for acc, v in zip(sums, chans):
            dr.scatter_reduce(dr.ReduceOp.Add, acc, v, pixel, mode=dr.ReduceMode.Local)
        dr.eval(sums if splat is None else (sums, filtered))     # one kernel traces the paths
    arr = np.stack([np.array(v, dtype=np.float64) for v in sums], -1) / counts[:, None]
    if not moments:
        return arr.reshape(h, w, 4 if alpha else 3)
    n = counts[:, None].astype(np.float64)
    var = np.maximum(arr[:, 5:8] - arr[:, :3] ** 2, 0.0) * n / np.maximum(n - 1, 1)
    mean = arr[:, :3].reshape(h, w, 3) if splat is None else \
        np.array(filtered, dtype=np.float64).reshape(h, w, -1)[..., :3]
    out = (mean, var.reshape(h, w, 3), arr[:, 3].reshape(h, w), arr[:, 4].reshape(h, w))
    if not halves:
        return out
    parts = []
    for j in (8, 11):                  # (sum, sum of squares, count) of even, then odd samples
        k = np.maximum(arr[:, j + 2] * counts, 1.0)
        m1, m2 = arr[:, j] * counts / k, arr[:, j + 1] * counts / k
        parts.append(np.maximum(m2 - m1 * m1, 0.0) * k / np.maximum(k - 1, 1))
    return out + (np.stack(parts, -1).reshape(h, w, 2),)


def _box3(a: np.ndarray) -> np.ndarray:
    p = np.pad(a, 1, mode="edge")
    return sum(p[i:i + a.shape[0], j:j + a.shape[1]] for i in range(3) for j in range(3)) / 9.0


def allocate(variance: np.ndarray, budget: float, m_min: int, seed: int,
             smooth: bool = True, cost: np.ndarray | None = None,
             score_cap: float | None = None) -> np.ndarray:
    """Per-pixel counts (H, W) >= ``m_min``.

    Without ``cost``: about ``budget`` samples in all, the part above the minimum proportional
    to the standard deviation (``variance``: (H, W), per pixel). With ``cost`` (relative cost
    of one sample per pixel, (H, W) > 0): ``budget`` is a total *cost*, and the part above the
    minimum is proportional to ``sd / sqrt(cost)`` -- the allocation that minimises
    ``sum_i variance_i / m_i`` for that total cost.
    """
    v = _box3(variance) if smooth else variance
    sd = np.sqrt(np.maximum(v, 0.0))
    c = np.ones_like(sd) if cost is None else np.maximum(cost, 1e-6)
    extra = max(budget - m_min * c.sum(), 0.0)
    score = sd / np.sqrt(c)
    if score_cap is not None and score.size:
        # A pilot of a few samples sees a rare bright path (a glint, a caustic) in some pixels
        # and misses it in their twins: uncapped, the few pixels that saw one take most of the
        # budget and the rest fall to the minimum. The cap bounds a pixel's share.
        mean = float((score * c).sum() / c.sum())
        if mean > 0:
            score = np.minimum(score, score_cap * mean)
    total = float((score * c).sum())
    # no variance seen anywhere (a black or noise-free image): the same count everywhere
    want = m_min + (extra * score / total if total > 0 else np.full_like(sd, extra / c.sum()))
    rng = np.random.default_rng(seed)
    base = np.floor(want)
    return (base + (rng.random(want.shape) < want - base)).astype(np.int64)


def render_adaptive(integrator, scene: mi.Scene, sensor: mi.Sensor, seed: int, spp: int,
                    alpha: bool):
    """Two-pass adaptive render (see the module docstring); returns an (H, W, 3|4) tensor."""
    film = sensor.film()
    w, h = (int(v) for v in film.crop_size())
    seed = int(seed)
    a = max(2, spp // PILOT_FRACTION)
    rest = spp - a
    pilot, var, valid, segments, halves = render_spp_map(
        integrator, scene, sensor, np.full((h, w), a), seed, moments=True, halves=True)
    s2 = (seed * 0x9E3779B1 + 0x7F4A7C15) & 0xFFFFFFFF
    if pilot_agreement(halves) < AGREEMENT_MIN:
        counts = np.full((h, w), rest)          # the pilot cannot tell where the noise is
    else:
        # Cost of a sample ~ rays traced: the camera ray, then a shadow ray and a continuation
        # ray per segment (smoothed like the variance: both are estimated from few samples).
        cost = _box3(COST_FIXED + 2.0 * segments)
        # Variance of the sum of the channels (one number per pixel); same total cost as uniform.
        counts = allocate(var.sum(-1), rest * cost.sum(), max(1, int(rest // MIN_FRACTION)), s2,
                          cost=cost, score_cap=SCORE_CAP)
    main = render_spp_map(integrator, scene, sensor, counts, s2 ^ 0x5BD1E995, alpha=alpha)
    if alpha:       # (from the pilot alone, an edge pixel's alpha would have the pilot's 4-spp noise)
        pilot = np.concatenate([pilot, valid[..., None]], -1)
    wp = a / spp
    img = wp * pilot + (1.0 - wp) * main
    return mi.TensorXf(img.astype(np.float32))
