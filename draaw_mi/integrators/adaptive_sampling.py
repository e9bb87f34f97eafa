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
  passes would not be: the counts would depend on the pilot's values). Under a filter other
  than box both passes splat into one image block, each sample weighted by its pass's share
  (``a / spp``, ``1 - a / spp``) over its pixel's count: the block's sums estimate the same
  filtered integrals, and the film develops the image once. Where the pilot's
  even and odd samples disagree on where the noise is (:func:`pilot_agreement`: rare bright
  paths, as light that arrives through a doorway or off a glossy panel), the main pass is
  uniform.

Same seed, same image (up to the order of atomic additions into the per-pixel sums): the
pilot and main passes use seeds derived from ``seed``, and the rounding generator is seeded
from it too. Memory does not grow with spp: each sample finds its pixel inside the kernel
(:func:`_pixel_of_samples`: a table of every few samples' pixels and two bisection steps
over the per-pixel start indices) and is summed into per-pixel totals.

>>> import numpy as np
>>> m = allocate(np.array([0.0, 1.0, 4.0, 0.0]).reshape(1, 4), budget=16, m_min=1, seed=0,
...              smooth=False)
>>> int(m.min()) >= 1, abs(int(m.sum()) - 16) <= 2
(True, True)
"""
from __future__ import annotations

import contextlib
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .emission_split import PrimaryRays, film_mapping
from .features import sampler_plugin
from .film_splat import FilmSplat, release_cache
from .guiding import recording, share_after
from .strata_sampler import strata_sampler

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


# Below this rank correlation the pilot's two halves disagree on where the noise is: its map
# would be noise. Measured (Spearman of the 3x3-smoothed per-pixel deviations of even and odd
# pilot samples, 4 samples per pixel, 128^2 and 256^2): 0.58-0.95 on the speed suite's scenes
# where adaptive sampling pays, 0.15 in the room lit through a doorway and 0.09-0.11 on the
# floor lit by a glossy panel, where it cost 1.8x the error of a uniform render.
AGREEMENT_MIN = 0.35
# Computed on 2^12 pixels at most (every s-th row and column): on the speed suite at 128^2
# and 256^2 the statistic moves by 0.04 at most from its value on 2^16 pixels (0.65-0.95 and
# 0.09-0.16, against the 0.35 between), and the ranking takes 2 ms instead of 27 ms at 256^2
# (3 % of a fast scene's render).
AGREEMENT_PIXELS = 1 << 12


def _ranks(a: np.ndarray) -> np.ndarray:
    """Ranks of ``a`` (0-based), tied values sharing their mean rank: a mostly black image's
    many zero variances must not be ranked by pixel index (the same order in both halves,
    which would read as agreement)."""
    order = np.argsort(a, kind="stable")
    sa = a[order]
    new = np.empty(a.size, bool)
    new[:1] = True
    np.not_equal(sa[1:], sa[:-1], out=new[1:])
    starts = np.flatnonzero(new)
    sizes = np.diff(np.append(starts, a.size))
    r = np.empty(a.size, np.float64)
    r[order] = np.repeat(starts + (sizes - 1) / 2.0, sizes)
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
    >>> dark = np.zeros((16, 16, 2)); dark[3, 4, 0] = dark[12, 9, 1] = 1.0   # one speck each
    >>> pilot_agreement(dark) < 0.35
    True
    """
    a, b = (np.sqrt(_box3(np.asarray(halves[..., i], np.float32))) for i in range(2))
    s = math.ceil(math.sqrt(a.size / AGREEMENT_PIXELS))    # every s-th row and column
    a, b = a[::s, ::s].ravel(), b[::s, ::s].ravel()
    n = a.size
    if n < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return 1.0
    ra, rb = _ranks(a), _ranks(b)
    ra -= (n - 1) / 2.0                # (the mean rank, ties or not)
    rb -= (n - 1) / 2.0
    den = np.sqrt((ra * ra).sum() * (rb * rb).sum())
    return float((ra * rb).sum() / den) if den > 0 else 1.0   # (no BLAS: see allocate)


def render_spp_map(integrator, scene: mi.Scene, sensor: mi.Sensor, spp_map: np.ndarray,
                   seed: int, moments: bool = False, alpha: bool = False):
    """Mean (H, W, 3) and, with ``moments``, per-pixel sample variance (H, W, 3), alpha
    (H, W) and mean path length in segments (H, W; 1 where the integrator does not report
    ``last_depth``) of ``integrator.sample`` with ``spp_map[y, x]`` samples at pixel (x, y).
    ``alpha`` (without ``moments``): the mean is (H, W, 4), the fraction of samples that hit
    something (or saw an environment) in its fourth channel.

    ``spp_map``: (H, W) integers >= 1 (the film's crop window). Primal only (no gradients).
    NumPy float64 results, for inspection; :func:`render_adaptive` keeps its passes in
    Dr.Jit (a 1024x1024 pilot's fourteen per-pixel sums would take 112 MB per float64 copy).
    """
    film = sensor.film()
    w, h = (int(v) for v in film.crop_size())
    counts = _check_map(spp_map, h, w)
    sums, filtered = _pass_sums(integrator, scene, sensor, counts, seed, moments, alpha)
    if filtered is not None and not moments:
        return np.array(filtered, dtype=np.float64).reshape(h, w, -1)[..., :4 if alpha else 3]
    arr = np.stack([np.array(v, dtype=np.float64) for v in sums], -1) / counts[:, None]
    if not moments:
        return arr.reshape(h, w, 4 if alpha else 3)
    n = counts[:, None].astype(np.float64)
    var = np.maximum(arr[:, 5:8] - arr[:, :3] ** 2, 0.0) * n / np.maximum(n - 1, 1)
    mean = arr[:, :3].reshape(h, w, 3) if filtered is None else \
        np.array(filtered, dtype=np.float64).reshape(h, w, -1)[..., :3]
    return mean, var.reshape(h, w, 3), arr[:, 3].reshape(h, w), arr[:, 4].reshape(h, w)


def _check_map(spp_map, h: int, w: int) -> np.ndarray:
    """``spp_map`` as flat uint32 counts, or ValueError naming what is wrong with it."""
    m = np.asarray(spp_map)
    # (refused: a transposed (W, H) or flat map would be read in the wrong pixel order, 2.9 samples as 2)
    if m.shape != (h, w) or not np.issubdtype(m.dtype, np.number) or not np.isfinite(m).all()\
            or (m != np.round(m)).any() or m.min() < 1:
        what = (f"shape {m.shape}" if m.shape != (h, w) else f"dtype {m.dtype}"
                if not np.issubdtype(m.dtype, np.number) else f"values from {m.min()} to {m.max()}")
        raise ValueError(f"render_spp_map: spp_map has {what}; expected ({h}, {w}) whole counts >= 1")
    if int(m.sum(dtype=np.int64)) >= 2 ** 32:
        raise ValueError(f"render_spp_map: {int(m.sum(dtype=np.int64))} samples exceed 2^32; render in passes")
    return m.astype(np.uint32).reshape(-1)


def _pass_sums(integrator, scene: mi.Scene, sensor: mi.Sensor, counts, seed: int,
               moments: bool, alpha: bool, pilot: bool = False, gather_first: bool = False,
               into=None, record=None, stratified: tuple | None = None):
    """``(per-pixel sums, filtered image | None)`` of one wavefront, both in Dr.Jit and
    evaluated by one kernel. ``counts``: flat uint32 counts per pixel, or an int (the same
    count everywhere: no per-pixel table). The sums' channels: R, G, B; with ``moments`` or
    ``alpha`` the hit count; with ``moments`` the summed path lengths and R^2, G^2, B^2.
    ``pilot`` (uniform ``counts``): what :func:`render_adaptive` reads in as few channels as
    it can: R, G, B, [hits if ``alpha`` and the filter is box: otherwise the block holds the
    alpha], path lengths, the sum of R^2 + G^2 + B^2, and of the
    channel sum ``s = R + G + B``: ``s`` and ``s^2`` over the odd samples, ``s^2`` over the
    even ones; with ``gather_first`` (a ``draaw_v4`` pilot) last, the light gathered at the
    paths' first vertices, R + G + B (all of it where the integrator does not report it:
    V4's media paths). Under a filter other than box the image is the splatted one
    (``film_splat``); with ``into``, a ``(FilmSplat, share)`` that several passes fill, this
    pass's samples go there with their weights ``1 / count`` times ``share`` and the filtered
    image is left to the caller (None). ``record``: :class:`~draaw_mi.integrators.guiding.Records`
    the paths fill for a guide's training (``draaw_v4``), evaluated by the same kernel.
    ``stratified`` (uniform ``counts``), a ``(pattern, offset)``: V4's stratified samples, these
    samples of each pixel's pattern (:func:`~draaw_mi.integrators.strata_sampler.strata_sampler`),
    not independent ones (a pilot whose variance maps go unused: :func:`render_adaptive`
    with ``rest_render``)."""
    film = sensor.film()
    w, h = (int(v) for v in film.crop_size())
    ox, oy = (int(v) for v in film.crop_offset())
    uniform = isinstance(counts, int)
    total = counts * w * h if uniform else int(counts.sum(dtype=np.int64))
    with dr.suspend_grad():
        if stratified is not None and uniform:
            sampler = strata_sampler(counts, seed, total, stratified)
        else:
            sampler = mi.load_dict({"type": "independent"})
            sampler.seed(seed, total)
        idx = dr.arange(mi.UInt32, total)
        if uniform:        # (opaque: one kernel for every pilot size)
            pixel = idx // dr.opaque(mi.UInt32, counts)
            first = lambda: pixel * dr.opaque(mi.UInt32, counts)             # noqa: E731
            count_of = lambda: dr.opaque(mi.Float, counts)                   # noqa: E731
        else:
            pixel, starts = _pixel_of_samples(idx, counts)
            first = lambda: dr.gather(mi.UInt32, starts, pixel)              # noqa: E731
            count_of = lambda: dr.gather(mi.Float, mi.Float(counts.astype(np.float32)), pixel)  # noqa: E731
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
        splat = share = None
        if into is not None:
            splat, share = into[0], dr.rcp(count_of()) * into[1]
        elif not film.rfilter().is_box_filter():   # weighted by 1 / the sample's pixel's count
            film.prepare([])
            splat = FilmSplat(film)
            share = dr.rcp(count_of())
        reports_depth = (moments or pilot) and hasattr(integrator, "want_depth")     # draaw_v4
        reports_first = pilot and gather_first and hasattr(integrator, "want_first")  # draaw_v4
        set_primary = getattr(integrator, "set_primary_rays", None)      # draaw_v4
        try:
            if reports_depth:
                integrator.want_depth = True
            if reports_first:
                integrator.want_first = True
            if set_primary is not None:       # each ray's pixel, for its emission splitting
                set_primary(PrimaryRays(ray, sensor, corner, scale, offset, weight,
                                        splat=None if splat is None else (splat, share, pos)))
            with contextlib.nullcontext() if record is None else recording(integrator, record):
                L, valid, _, _ = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler,
                                                   ray=ray, depth=mi.UInt32(0), δL=None, δaovs=None,
                                                   state_in=None, active=mi.Bool(True))
            if record is not None:
                record.finish(L)
            depth = integrator.last_depth if reports_depth else None   # segments per path
            light_first = integrator.last_first if reports_first else None
        finally:
            if reports_depth:
                integrator.want_depth, integrator.last_depth = False, None
            if reports_first:
                integrator.want_first, integrator.last_first = False, None
            if set_primary is not None:
                set_primary(None)
        value = L * weight
        filtered = None
        if splat is not None:
            splat.put(pos, value, dr.select(valid, 1.0, 0.0), share)
            if into is None:
                filtered = splat.develop()
        chans = [value.x, value.y, value.z]
        hits = dr.select(valid, 1.0, 0.0) + 0.0 * value.x if moments or alpha or pilot else None
        # (1 per path where the integrator reports no lengths: V4's media paths)
        lengths = (mi.Float(depth) if depth is not None else 1.0) + 0.0 * value.x if moments or pilot else None
        if pilot:
            odd = ((idx - first()) & 1) == 1
            v = value.x + value.y + value.z
            chans += [hits] if alpha and splat is None else []    # (filtered: alpha is the block's)
            chans += [lengths, dr.squared_norm(value), dr.select(odd, v, 0.0),
                      dr.select(odd, v * v, 0.0), dr.select(odd, 0.0, v * v)]
            if gather_first:
                chans += [v if light_first is None else light_first * ((weight.x + weight.y + weight.z) / 3.0)]
        elif moments or alpha:
            chans += [hits]
            if moments:
                chans += [lengths, dr.square(value.x), dr.square(value.y), dr.square(value.z)]
        if splat is not None and not (moments or pilot):
            chans = []                # the splatted image is the result
        # Samples of a pixel are contiguous: a local (in-packet) reduction before the atomics.
        sums = [dr.zeros(mi.Float, w * h) for _ in chans]
        for acc, v in zip(sums, chans):
            dr.scatter_reduce(dr.ReduceOp.Add, acc, v, pixel, mode=dr.ReduceMode.Local)
        dr.eval(sums, filtered, splat.tensors() if into is not None else None,   # one kernel traces the paths
                None if record is None else record.arrays())
    return sums, filtered


def _pixel_of_samples(idx: mi.UInt32, counts: np.ndarray):
    """``(pixel, starts)``: the pixel of every sample index ``idx``, found inside the kernel
    (no per-sample array: memory does not grow with spp), and the pixels' first sample
    indices (``counts[p]`` contiguous samples from ``starts[p]``; ``counts`` >= 1).

    A table of the pixel that holds every ``block``-th sample, ``block`` three times the
    smallest count, leaves each sample at most three pixels past its block's: two bisection
    steps. A binary search over all pixels (16 dependent gathers at 256^2, 10 % of the
    monkey's main pass at 128^2) remains where that table would hold more entries than
    there are pixels (a smallest count under a third of the mean).

    >>> pixel, _ = _pixel_of_samples(dr.arange(mi.UInt32, 12), np.array([2, 5, 1, 4], np.uint32))
    >>> pixel
    [0, 0, 1, 1, 1, 1, 1, 2, 3, 3, 3, 3]
    """
    n = len(counts)
    first = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
    starts = mi.UInt32(first.astype(np.uint32))
    block = min(3 * int(counts.min()), int(first[-1])) if n else 0
    if block == 0 or -(-int(first[-1]) // block) > n:
        return dr.binary_search(0, n, lambda i: dr.gather(mi.UInt32, starts, i) <= idx) - 1, starts
    table = np.searchsorted(first, np.arange(0, first[-1], block), side="right") - 1
    pixel = dr.gather(mi.UInt32, mi.UInt32(table.astype(np.uint32)), idx // dr.opaque(mi.UInt32, block))
    for step in (2, 1):           # the last pixel whose first sample is at or before idx
        # (starts[n] = the total > idx: a candidate past the last pixel is never taken)
        later = dr.gather(mi.UInt32, starts, dr.minimum(pixel + step, n)) <= idx
        pixel = dr.select(later, pixel + step, pixel)
    return pixel, starts


def _box3(a: np.ndarray) -> np.ndarray:
    p = np.pad(a, 1, mode="edge")
    out = p[:a.shape[0], :a.shape[1]].copy()
    for i in range(3):
        for j in range(3):
            if i or j:
                out += p[i:i + a.shape[0], j:j + a.shape[1]]
    out /= 9.0
    return out


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
    v = _box3(np.asarray(variance, np.float32)) if smooth else np.array(variance, np.float32)
    score = np.sqrt(np.maximum(v, 0.0, out=v), out=v)            # the deviation, in place
    c = np.ones_like(score) if cost is None else np.maximum(np.asarray(cost, np.float32), 1e-6)
    extra = max(budget - m_min * float(c.sum(dtype=np.float64)), 0.0)
    score /= np.sqrt(c)
    if score_cap is not None and score.size:
        # A pilot of a few samples sees a rare bright path (a glint, a caustic) in some pixels
        # and misses it in their twins: uncapped, the few pixels that saw one take most of the
        # budget and the rest fall to the minimum. The cap bounds a pixel's share.
        mean = float((score * c).sum(dtype=np.float64) / c.sum(dtype=np.float64))
        if mean > 0:
            np.minimum(score, score_cap * mean, out=score)
    # (no np.dot: OpenBLAS's threads spin on after a call and slowed the main pass's kernel,
    # launched right after, by a third on two cores)
    total = float((score * c).sum(dtype=np.float64))
    # no variance seen anywhere (a black or noise-free image): the same count everywhere
    if total > 0:
        want = score
        want *= np.float32(extra / total)
    else:
        want = np.full_like(score, extra / float(c.sum(dtype=np.float64)))
    want += m_min
    rng = np.random.default_rng(seed)
    base = np.floor(want)
    want -= base                      # the fraction, rounded up with that probability
    return (base + (rng.random(want.shape, dtype=np.float32) < want)).astype(np.uint32)


def render_adaptive(integrator, scene: mi.Scene, sensor: mi.Sensor, seed: int, spp: int,
                    alpha: bool, decide=None, rest_render=None):
    """Two-pass adaptive render (see the module docstring); returns an (H, W, 3|4) tensor.

    ``decide`` (``draaw_v4``, guiding's first decision on a scene,
    :class:`~draaw_mi.integrators.guide_cache.PilotDecision`): the pilot's paths fill its
    ``records(lanes)`` (where it has them), and it is called with the pilot's indirect share
    (:func:`pilot_indirect_share`); where it returns true (the main pass is now guided), the
    main pass samples every pixel alike. ``rest_render(count, seed)`` (``draaw_v4`` where it would
    otherwise render stratified: the pilot only decides, and its samples are the first ``a``
    of each pixel's stratified pattern of ``spp``, its variance maps unused): where ``decide``
    returns false, the main pass is that uniform render of the rest of the pattern (with the
    pilot's seed), and the image is ``(a / spp) * pilot + (1 - a / spp) * rest_render(spp - a,
    seed)``: with a box filter, one stratified render's.

    Memory: both passes' per-pixel sums stay in Dr.Jit (float32); what the allocation needs
    (four (H, W) float32 maps) is read back, and the image is formed in Dr.Jit. Under a filter
    other than box the passes share one :class:`~draaw_mi.integrators.film_splat.FilmSplat`
    (no pilot image is developed and kept through the main pass) and the film holds the
    image, as after Mitsuba's own render."""
    film = sensor.film()
    w, h = (int(v) for v in film.crop_size())
    seed = int(seed)
    a = max(2, spp // PILOT_FRACTION)
    rest = spp - a
    wp = a / spp
    splat = None
    if not film.rfilter().is_box_filter():   # both passes splat into one block (film_splat)
        film.prepare([])
        splat = FilmSplat(film)
    records = None if decide is None else decide.records(a * w * h)
    sums, _ = _pass_sums(integrator, scene, sensor, a, seed, False, alpha, pilot=True,
                         gather_first=decide is not None, into=None if splat is None else (splat, wp),
                         record=records, stratified=None if rest_render is None else (spp, 0))
    del records                       # (decide holds them until it has learned)
    guided = decide is not None and decide(pilot_indirect_share(sums[:3], sums.pop()))
    s2 = (seed * 0x9E3779B1 + 0x7F4A7C15) & 0xFFFFFFFF
    if rest_render is not None and not guided:
        # the pilot's image and the rest's, weighted a / spp and 1 - a / spp: constants, so
        # each part keeps its expectation (under other filters the ratio estimate, as path's)
        pilot = _pilot_image(sums, splat, a, 4 if alpha else 3, h, w)
        dr.eval(pilot)
        del sums, splat
        release_cache()
        img = pilot * wp + rest_render(spp - a, seed) * (1.0 - wp)
        dr.eval(img)
        return img
    hits = alpha and splat is None
    var, segments, halves = _pilot_maps(sums, a, hits, h, w)     # (keeps only the image's sums)
    if splat is not None:
        del sums                      # (the image is in the block)
        release_cache()
    channels = 4 if alpha else 3      # (alpha: whether the film has an alpha channel)
    if guided or pilot_agreement(halves) < AGREEMENT_MIN:
        # guided: measured better uniform; or the pilot cannot tell where the noise is
        counts = np.full(h * w, rest, np.uint32)
    else:
        # Cost of a sample ~ rays traced: the camera ray, then a shadow ray and a continuation
        # ray per segment (smoothed like the variance: both are estimated from few samples).
        cost = _box3(COST_FIXED + 2.0 * segments)
        # Variance of the sum of the channels (one number per pixel); same total cost as uniform.
        counts = allocate(var, rest * float(cost.sum(dtype=np.float64)),
                          max(1, int(rest // MIN_FRACTION)), s2, cost=cost,
                          score_cap=SCORE_CAP).reshape(-1)
    del var, segments, halves
    if splat is not None:
        # Each pass's samples weigh 1 / count times the pass's share of the image (wp, 1 - wp):
        # both blocks' sums estimate the filtered integrals (film_splat), as one pass would.
        _pass_sums(integrator, scene, sensor, counts, s2 ^ 0x5BD1E995, False, alpha, False,
                   into=(splat, 1.0 - wp))
        del counts
        release_cache()               # (the passes' per-pixel tables, before the image's blocks)
        img = splat.develop()
        dr.eval(img)
        return img                    # (H, W, 3|4): the film's own channels
    pilot = [v * (wp / a) for v in sums[:channels]]
    del sums
    main, _ = _pass_sums(integrator, scene, sensor, counts, s2 ^ 0x5BD1E995, False, alpha, False)
    per = (1.0 - wp) * dr.rcp(mi.Float(counts.astype(np.float32)))
    del counts
    img = _image([dr.fma(main[c], per, pilot[c]) for c in range(channels)], h, w)
    dr.eval(img)
    return img


def _image(chans: list, h: int, w: int) -> mi.TensorXf:
    """An (h, w, len(chans)) tensor of per-pixel channel arrays."""
    out = dr.zeros(mi.Float, h * w * len(chans))
    at = dr.arange(mi.UInt32, h * w) * len(chans)
    for c, v in enumerate(chans):
        dr.scatter(out, v, at + c)
    return mi.TensorXf(out, (h, w, len(chans)))


def _pilot_image(sums: list, splat, a: int, channels: int, h: int, w: int) -> mi.TensorXf:
    """The developed image of a pilot of ``a`` samples per pixel: its per-pixel ``sums`` over
    ``a`` (box filter), or the block ``splat`` that holds its samples alone, developed."""
    if splat is not None:
        return splat.develop()
    return _image([sums[c] * (1.0 / a) for c in range(channels)], h, w)


def pilot_indirect_share(rgb: list, first) -> float:
    """Share of a pilot's light that arrives after the paths' first vertex, from its per-pixel
    sums of R, G, B and of the light gathered at the first vertex (R + G + B), as
    :func:`~draaw_mi.integrators.guiding.indirect_share` measures it from paths of its own.
    Under a filter other than box the light seen directly is splatted apart (``film_splat``)
    and in neither sum, so the share reads a little higher there.

    >>> round(pilot_indirect_share([mi.Float(1.0, 2.0)] * 3, mi.Float(1.5, 3.0)), 2)
    0.5
    """
    total, at_first = dr.sum(rgb[0] + rgb[1] + rgb[2]), dr.sum(first)
    dr.eval(total, at_first)          # (one kernel for both sums)
    return share_after(float(total[0]), float(total[0]) - float(at_first[0]))


def _pilot_maps(sums: list, n: int, hits: bool, h: int, w: int):
    """From a uniform pilot's sums (:func:`_pass_sums` with ``pilot``, ``n`` samples per
    pixel; ``hits``: whether they hold the hit count after R, G, B): the summed per-channel
    sample variance, the mean path length and the two halves' variances of the channel sum,
    as (H, W) float32 maps (computed in Dr.Jit). Removes the moments from ``sums`` (the
    image's channels stay) and frees their memory."""
    k = 4 if hits else 3
    lengths, squares, odd_s, odd_s2, even_s2 = sums[k:k + 5]
    inv = 1.0 / n
    var = squares * inv
    for c in range(3):
        var -= dr.square(sums[c] * inv)
    var = dr.maximum(var, 0.0) * (n / max(n - 1, 1))
    halves = []
    even_s = sums[0] + sums[1] + sums[2] - odd_s
    for m, s, s2 in ((n - n // 2, even_s, even_s2), (n // 2, odd_s, odd_s2)):
        mean = s * (1.0 / m)
        halves.append(dr.maximum(s2 * (1.0 / m) - mean * mean, 0.0) * (m / max(m - 1, 1)))
    seg = lengths * inv
    dr.eval(var, seg, halves)
    del sums[k:], lengths, squares, odd_s, odd_s2, even_s2, even_s     # the image's sums stay
    release_cache()                   # the moments' memory, before the NumPy copies
    as_map = lambda v: np.array(v, dtype=np.float32).reshape(h, w)   # noqa: E731
    return as_map(var), as_map(seg), np.stack([as_map(v) for v in halves], -1)
