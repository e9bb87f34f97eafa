"""When V4 stratifies: its own sampler (:mod:`~draaw_mi.integrators.strata_sampler`) in
place of the scene's ``independent`` sampler (Mitsuba's default), in renders and gradient
passes.

The independent sampler draws each dimension of each sample at random. A stratified pattern
spreads a pixel's samples evenly over the pixel and over each dimension its paths use (lens,
each bounce's BSDF and light samples), which removes much of the variance of the smooth parts
of the integrand, at every sample count and in one pass. Each sample stays jointly uniform
over the dimensions it uses, so every pixel's expectation is the independent sampler's, and
``path``'s. Mitsuba's own stratifying samplers do not serve: ``multijitter``, ``stratified``
and ``ldsampler`` correlate dimensions below 256 spp (a biased estimate), ``orthogonal``
takes only squares of primes and costs 1.5x ``path``'s time per sample
(``benchmarks/results/speed_suite.md``, 2026-12-05).

Where V4 keeps the scene's sampler: a sampler other than ``independent`` (the user chose
it); one sample per pixel; the gradient passes of scenes whose SDF shapes get boundary terms
(the whole pass: ``silhouettes.py`` reseeds its sampler for the rays of a band); guided renders and delta lights' glints
on near-mirror surfaces (both measured worse stratified; see ``draaw_v4``'s
:meth:`~draaw_mi.integrators.v4.DraawV4Integrator.stratified`); participating media. Adaptive
sampling on top of a stratified pattern measured 1.23-1.44x the variance x time of uniform V4
with the same sampler (its pilot's sample variance no longer measures a stratified mean's
error), so V4 renders stratified scenes uniformly. (A scene's first render from 2^20 samples
runs the adaptive pilot, the first 1/16 of each pixel's stratified pattern, to decide on
guiding; left unguided, the rest of the pattern renders uniformly:
``adaptive_sampling.render_adaptive``'s ``rest_render``.)
"""
from __future__ import annotations

import mitsuba as mi

from .features import sampler_plugin


def applies(sensor: mi.Sensor, n: int) -> bool:
    """Whether a render of ``n`` spp through ``sensor`` may render stratified: its sampler is
    ``independent`` and ``n`` is at least 2 (one sample per pixel has nothing to stratify:
    such a render keeps Mitsuba's samples, the ones its ``aov`` integrator draws)."""
    return n > 1 and sampler_plugin(sensor.sampler()) == "independent"


def describe(integrator, scene: mi.Scene, sensor: mi.Sensor, n: int) -> str:
    """How ``integrator`` (a ``draaw_v4``) samples a render of ``scene`` of ``n`` spp through
    ``sensor``, in a few words (``draaw-mi info``).

    >>> scene = mi.load_dict(mi.cornell_box())
    >>> v4 = mi.load_dict({"type": "draaw_v4"})
    >>> describe(v4, scene, scene.sensors()[0], 64)
    'stratified (its own correlated multi-jittered samples in place of the independent sampler, unless a guide is learned; stratify=false: independent)'
    """
    kind = sampler_plugin(sensor.sampler())
    if kind != "independent":
        return f"the scene's {kind} sampler, every pixel alike"
    why = integrator.independent_because(scene, sensor, n)
    if why is not None:
        return f"independent ({why})"
    return ("stratified (its own correlated multi-jittered samples in place of the independent "
            "sampler, unless a guide is learned; stratify=false: independent)")
