"""One wavefront in which every pixel gets its own number of samples (a per-pixel spp map).

* :func:`render_spp_map` (public): the per-pixel mean and, optionally, sample variance of
  ``integrator.sample`` with ``spp_map[y, x]`` samples at pixel ``(x, y)``, as NumPy arrays.
* :func:`pass_sums`: the same wavefront kept in Dr.Jit as per-pixel sums, one kernel for the
  paths and every sum; what the pilot and main passes of
  :func:`~draaw_mi.integrators.adaptive_sampling.render_adaptive` render (``render_adaptive``
  below).
* :func:`pixel_of_samples`: the pixel of each sample index, found inside the kernel, so that
  memory does not grow with spp.

With a box filter each sample belongs to its pixel; under another filter the samples are
splatted with the weight ``1 / count`` of their pixel, which keeps the filtered image's
expectation (:mod:`~draaw_mi.integrators.film_splat`).

>>> pixel, _ = pixel_of_samples(dr.arange(mi.UInt32, 5), np.array([1, 3, 1], np.uint32))
>>> pixel
[0, 1, 1, 1, 2]
"""
from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi
import numpy as np

from .emission_split import PrimaryRays, film_mapping
from .film_splat import FilmSplat
from .guiding import recording
from .strata_sampler import strata_sampler


def render_spp_map(integrator, scene: mi.Scene, sensor: mi.Sensor, spp_map: np.ndarray,
                   seed: int, moments: bool = False, alpha: bool = False):
    """Mean (H, W, 3) and, with ``moments``, per-pixel sample variance (H, W, 3), alpha
    (H, W) and mean path length in segments (H, W; 1 where the integrator does not report
    ``last_depth``) of ``integrator.sample`` with ``spp_map[y, x]`` samples at pixel (x, y).
    ``alpha`` (without ``moments``): the mean is (H, W, 4), the fraction of samples that hit
    something (or saw an environment) in its fourth channel.

    ``spp_map``: (H, W) integers >= 1 (the film's crop window). Primal only (no gradients).
    NumPy float64 results, for inspection; ``render_adaptive`` keeps its passes in
    Dr.Jit (a 1024x1024 pilot's fourteen per-pixel sums would take 112 MB per float64 copy).
    """
    film = sensor.film()
    w, h = (int(v) for v in film.crop_size())
    counts = check_map(spp_map, h, w)
    sums, filtered = pass_sums(integrator, scene, sensor, counts, seed, moments, alpha)
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


def check_map(spp_map, h: int, w: int) -> np.ndarray:
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


def pass_sums(integrator, scene: mi.Scene, sensor: mi.Sensor, counts, seed: int,
               moments: bool, alpha: bool, pilot: bool = False, gather_first: bool = False,
               into=None, record=None, stratified: tuple | None = None):
    """``(per-pixel sums, filtered image | None)`` of one wavefront, both in Dr.Jit and
    evaluated by one kernel. ``counts``: flat uint32 counts per pixel, or an int (the same
    count everywhere: no per-pixel table). The sums' channels: R, G, B; with ``moments`` or
    ``alpha`` the hit count; with ``moments`` the summed path lengths and R^2, G^2, B^2.
    ``pilot`` (uniform ``counts``): what ``render_adaptive`` reads in as few channels as
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
    not independent ones (a pilot whose variance maps go unused: ``render_adaptive``
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
            pixel, starts = pixel_of_samples(idx, counts)
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


def pixel_of_samples(idx: mi.UInt32, counts: np.ndarray):
    """``(pixel, starts)``: the pixel of every sample index ``idx``, found inside the kernel
    (no per-sample array: memory does not grow with spp), and the pixels' first sample
    indices (``counts[p]`` contiguous samples from ``starts[p]``; ``counts`` >= 1).

    A table of the pixel that holds every ``block``-th sample, ``block`` three times the
    smallest count, leaves each sample at most three pixels past its block's: two bisection
    steps. A binary search over all pixels (16 dependent gathers at 256^2, 10 % of the
    monkey's main pass at 128^2) remains where that table would hold more entries than
    there are pixels (a smallest count under a third of the mean).

    >>> pixel, _ = pixel_of_samples(dr.arange(mi.UInt32, 12), np.array([2, 5, 1, 4], np.uint32))
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
