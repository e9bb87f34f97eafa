"""V4's stratified samples: Mitsuba's ``multijitter`` pattern where the scene's sampler is
``independent`` (Mitsuba's default).

The independent sampler draws each dimension of each sample at random. A stratified pattern
spreads a pixel's samples evenly over the pixel and over each pair of dimensions its paths
use (lens, each bounce's BSDF and light samples), which removes much of the variance of the
smooth parts of the integrand. Each sample stays uniformly distributed (``multijitter``
jitters within its strata and permutes them per pixel and per dimension), so every pixel's
expectation is the independent sampler's, and ``path``'s.

Measured at 64 spp, 128x128, against a 2048-spp reference (MSE relative to ``path`` with the
independent sampler; ``benchmarks/results/speed_suite.md``): V4 stratified 0.13 / 0.48 / 0.31
/ 0.60 on the Cornell box, the material spheres, the environment map and the room lit
through a doorway, where V4 with adaptive sampling (independent samples) reached 0.16 / 0.66
/ 0.62 / 1.01. Adaptive sampling on top of stratification loses (1.23-1.44x the variance x
time of uniform V4 with the same sampler: its pilot's sample variance no longer measures a
stratified mean's error), so V4 renders stratified scenes uniformly.

Kept independent, both measured worse stratified (``benchmarks/results/speed_suite.md``,
2026-12-05): delta lights' glints on near-mirror surfaces
(:func:`~draaw_mi.integrators.adaptive_sampling.pilot_can_miss`; the thesis glass scene at
64 spp: V4 1.14 / 0.84x ``path``'s MSE stratified against 0.38 / 0.63x at 128x128 / 256x256,
and ``path`` with ``multijitter`` 2.15x its own independent MSE; why is not understood), and
guided renders (the floor lit through a glossy panel: 1.31 / 1.22x ``path``'s time per
render against 1.12 / 1.09x, the pattern's hashing on guiding's extra dimensions, for
0.93 / 0.94x its MSE).

Counts: ``multijitter`` takes ``n`` as it is when ``n = a * ceil(n / a)`` with
``a = floor(sqrt(n))`` (1, 2, 4, 8, 16, 24, 48, 64, 100, 256, 1024, ...) and rounds others up
(32 -> 35, 128 -> 132). A primal render of such a count renders in equal passes of a count it
takes (128 = 2 x 64), all accumulated in the film (its weights sum over the passes, as one
render's would); a gradient pass, which Mitsuba runs as one, keeps the independent sampler at
such counts.

>>> taken(64), taken(32), passes(128), passes(32), passes(17)
(True, False, [64, 64], [16, 16], None)
"""
from __future__ import annotations

import functools

import drjit as dr
import mitsuba as mi

from .features import sampler_plugin

PATTERN = "multijitter"
MAX_PASSES = 4                 # a count is split into at most this many passes


@functools.lru_cache(maxsize=256)
def taken(n: int) -> bool:
    """Whether :data:`PATTERN` renders ``n`` samples per pixel when asked for ``n``."""
    sampler = mi.load_dict({"type": PATTERN})
    logger = mi.logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)       # (the "rounded up" warnings of the probe)
    try:
        sampler.set_sample_count(int(n))
    finally:
        logger.set_log_level(level)
    return int(sampler.sample_count()) == int(n)


def passes(n: int) -> list[int] | None:
    """``n`` samples per pixel as equal passes of a count :data:`PATTERN` takes (at most
    :data:`MAX_PASSES`), or ``None`` where there are none."""
    for k in range(1, MAX_PASSES + 1):
        if n % k == 0 and taken(n // k):
            return [n // k] * k
    return None


def applies(sensor: mi.Sensor, n: int) -> bool:
    """Whether a render of ``n`` spp through ``sensor`` renders stratified: its sampler is
    ``independent`` and ``n`` splits into passes :data:`PATTERN` takes."""
    return n > 0 and sampler_plugin(sensor.sampler()) == "independent" and passes(n) is not None


def prepare(sensor: mi.Sensor, seed, spp: int, aovs, clear_film: bool = True):
    """:meth:`mitsuba.ad.integrators.common.ADIntegrator.prepare` with a :data:`PATTERN`
    sampler of ``spp`` (a count it takes) in place of the sensor's: ``(sampler, spp)``, the
    sampler seeded for the wavefront, the film prepared (cleared unless ``clear_film`` is
    false: a later pass of one render adds to it)."""
    film = sensor.film()
    sampler = mi.load_dict({"type": PATTERN, "sample_count": int(spp)})
    sampler.set_samples_per_wavefront(int(spp))
    size = film.crop_size()
    if film.sample_border():
        size += 2 * film.rfilter().border_size()
    wavefront = int(dr.prod(size)) * int(spp)
    if wavefront > 2 ** 32:
        raise RuntimeError(f"draaw_v4: {wavefront} samples in one pass exceed 2^32; render in passes")
    sampler.seed(seed, wavefront)
    if clear_film:
        film.prepare(aovs)
    return sampler, int(spp)


def describe(sensor: mi.Sensor, n: int) -> str:
    """How ``draaw_v4`` (``stratify`` on) samples a render of ``n`` spp through ``sensor``, in
    a few words (``draaw-mi info``)."""
    kind = sampler_plugin(sensor.sampler())
    if kind != "independent":
        return f"the scene's {kind} sampler, every pixel alike"
    counts = passes(n)
    if counts is None:
        return (f"independent (the {PATTERN} pattern takes {n} spp in no {MAX_PASSES} equal passes); "
                "adaptive from 64 spp")
    split = f"{len(counts)} passes of {counts[0]}" if len(counts) > 1 else "one pass"
    return f"the {PATTERN} pattern in place of the independent sampler, {split} (stratify=false: independent)"


def render_passes(integrator, counts: list, seed, evaluate: bool, render_pass):
    """A primal render in passes of ``counts`` spp: ``render_pass(seed, count, evaluate)``
    renders one (its image is the film's so far); the later ones keep the film
    (``integrator._keep_film``, read by ``draaw_v4``'s ``prepare``), which sums them, so the
    last pass's image is the render's."""
    try:
        for k, count in enumerate(counts):
            integrator._keep_film = k > 0
            img = render_pass(pass_seed(seed, k), count, evaluate or k + 1 < len(counts))
    finally:
        integrator._keep_film = False
    return img


def pass_seed(seed, k: int):
    """The seed of pass ``k`` of a render seeded ``seed`` (pass 0: ``seed`` itself)."""
    return seed if k == 0 else (seed + k * 0x9E3779B9) & 0xFFFFFFFF if isinstance(seed, int) \
        else seed + mi.UInt32(k * 0x9E3779B9 & 0xFFFFFFFF)
