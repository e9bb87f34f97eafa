"""Unbiased adaptive sampling: a per-pixel sample-count map, and a two-pass render that sets it.

* :func:`~draaw_mi.integrators.spp_map.render_spp_map` (:mod:`~draaw_mi.integrators.spp_map`)
  renders one wavefront in which pixel ``i`` gets ``spp_map[i]`` samples (any counts >= 1;
  the wavefront is ``sum(spp_map)`` samples long, each sample finds its pixel) and returns
  the per-pixel mean and, optionally, the per-pixel sample variance. With a box filter each
  sample belongs to its pixel; with another filter the samples are splatted with the weight
  ``1 / spp_map`` of their pixel, which keeps the filtered image's expectation
  (:mod:`~draaw_mi.integrators.film_splat`); the variance is always that of the pixel's own
  samples (what the allocation needs).
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
(:func:`~draaw_mi.integrators.spp_map.pixel_of_samples`: a table of every few samples' pixels and two bisection steps
over the per-pixel start indices) and is summed into per-pixel totals.

>>> import numpy as np
>>> m = allocate(np.array([0.0, 1.0, 4.0, 0.0]).reshape(1, 4), budget=16, m_min=1, seed=0,
...              smooth=False)
>>> int(m.min()) >= 1, abs(int(m.sum()) - 16) <= 2
(True, True)
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from .features import sampler_plugin
from .film_splat import FilmSplat, release_cache
from .guiding import share_after
from .spp_map import pass_sums, render_spp_map  # noqa: F401  (render_spp_map: public here too)

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
    (``halves``: (H, W, 2) per-pixel sample variances, :func:`_pilot_maps`' third result),
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
    of each pixel's stratified pattern of ``spp``, its variance maps unused): the main pass is
    that uniform render of ``spp - a`` samples: where ``decide`` returns false, of the rest of
    the pattern with the pilot's seed, and the image is ``(a / spp) * pilot + (1 - a / spp) *
    rest_render(spp - a, seed)`` (with a box filter, one stratified render's); where it
    returns true, guided, with a seed of its own, and the image is the rest's alone.

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
    sums, _ = pass_sums(integrator, scene, sensor, a, seed, False, alpha, pilot=True,
                         gather_first=decide is not None, into=None if splat is None else (splat, wp),
                         record=records, stratified=None if rest_render is None else (spp, 0))
    del records                       # (decide holds them until it has learned)
    guided = decide is not None and decide(pilot_indirect_share(sums[:3], sums.pop()))
    s2 = (seed * 0x9E3779B1 + 0x7F4A7C15) & 0xFFFFFFFF
    if rest_render is not None and guided:
        # the rest alone, independent samples of a seed of its own: the pilot's unguided
        # samples (they taught the guide) would add their variance, 16x a guided shared
        # sample's on the glossy panel, at a sixteenth of the weight (0.16x path's MSE with
        # them, 0.09x without, 128^2)
        del sums, splat
        release_cache()
        img = rest_render(spp - a, s2 ^ 0x5BD1E995)
        dr.eval(img)
        return img
    if rest_render is not None:
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
        pass_sums(integrator, scene, sensor, counts, s2 ^ 0x5BD1E995, False, alpha, False,
                   into=(splat, 1.0 - wp))
        del counts
        release_cache()               # (the passes' per-pixel tables, before the image's blocks)
        img = splat.develop()
        dr.eval(img)
        return img                    # (H, W, 3|4): the film's own channels
    pilot = [v * (wp / a) for v in sums[:channels]]
    del sums
    main, _ = pass_sums(integrator, scene, sensor, counts, s2 ^ 0x5BD1E995, False, alpha, False)
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
    """From a uniform pilot's sums (:func:`~draaw_mi.integrators.spp_map.pass_sums` with ``pilot``, ``n`` samples per
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
