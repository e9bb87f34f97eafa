"""V4's speed-ups under any pixel filter: samples splatted with per-sample weights.

Mitsuba's film splats each sample into every pixel whose filter covers it and divides by the
summed filter weights: pixel ``p = sum_s f(x_s - p) L_s / sum_s f(x_s - p)``. With samples
spread uniformly over the film this converges to ``int f(x - p) L(x) dx / int f(x - p) dx``,
the filtered image: what ``path`` renders with that filter. Two of V4's speed-ups change the
samples:

* **adaptive sampling** gives pixel ``q`` its own count ``d_q``, so samples are denser where
  noise is. Each sample's filter weight and value are scaled by ``1 / d_q`` (its pixel's
  count), which makes both sums estimate the same integrals as with uniform samples
  (``E[sum_s f(x_s - p) g(x_s) / d(x_s)] = int f(x - p) g(x) dx``): same limit as ``path``.
* **emission splitting**'s extra rays (:mod:`~draaw_mi.integrators.emission_split`) estimate
  the emission seen at the first hit from stratified positions over the sample's pixel. With
  a box filter every position of a pixel has the same weight, so their mean replaces the
  camera ray's own. With another filter each extra ray is splatted at *its own* position
  with its own filter weight and ``1 / k`` of the sample's share, into the value channels
  only (weight channel 0): the numerator's emission term keeps its expectation
  (``E[f(y - p) Le(y)]`` with ``y`` uniform over the pixel, as for the camera ray), the
  denominator is the camera samples'.

So both are as unbiased as ``path``'s own ratio (consistent; its ``O(1/n)`` bias is that of
the film's division), for box, tent, gaussian, Lanczos, Mitchell and Catmull-Rom filters
alike (negative lobes are weights like any other). With a box filter the renderers keep
their per-pixel sums (a box splat is the same thing, and those kernels are unchanged).

:class:`FilmSplat` is the accumulation (the film's own :class:`mitsuba.ImageBlock` and its
:meth:`develop`), :func:`render_uniform` V4's primal render at one count per pixel when a
light's edges are in view under such a filter (otherwise Mitsuba's ``render`` is used as is).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .emission_split import PrimaryRays, film_mapping


class FilmSplat:
    """Samples of one render splatted through ``film``'s pixel filter, each with a weight.

    ``put`` adds a camera sample: ``value`` (film units: radiance times the camera weight),
    ``alpha`` and ``weight`` (the sample's ``1 / d``) into the value, alpha and weight channels;
    ``put_emission`` adds an emission-only sample (value channels only). ``develop`` divides by
    the summed weights (the film's own development: 0 where no weight arrived).

    >>> import draaw_mi, mitsuba as mi
    >>> scene = mi.load_dict(mi.cornell_box())
    >>> film = scene.sensors()[0].film()
    >>> _ = film.prepare([])
    >>> s = FilmSplat(film)
    >>> s.put(mi.Point2f(10.5, 20.5), mi.Color3f(2.0), mi.Float(1.0), mi.Float(0.5))
    >>> img = s.develop()
    >>> [round(float(v), 3) for v in img.array[(20 * 256 + 10) * 3:(20 * 256 + 10) * 3 + 3]]
    [2.0, 2.0, 2.0]
    """
    __slots__ = ("film", "block", "alpha", "extra")

    def __init__(self, film: mi.Film, aov_count: int = 0):
        """``film``: prepared (``film.prepare(aov_names)``) for ``aov_count`` AOV channels."""
        self.film = film
        self.block = film.create_block()
        self.alpha = mi.has_flag(film.flags(), mi.FilmFlags.Alpha)
        self.extra = aov_count

    def put(self, pos: mi.Point2f, value: mi.Color3f, alpha: mi.Float, weight: mi.Float,
            aovs=(), active: mi.Bool = True) -> None:
        chans = [value.x * weight, value.y * weight, value.z * weight]
        if self.alpha:
            chans.append(alpha * weight)
        chans.append(weight + 0.0 * value.x)
        chans += [a * weight for a in aovs]
        self.block.put(pos, chans, active)

    def put_emission(self, pos: mi.Point2f, value: mi.Color3f, active: mi.Bool) -> None:
        zero = mi.Float(0.0)
        chans = [value.x, value.y, value.z] + [zero] * (int(self.alpha) + 1 + self.extra)
        self.block.put(pos, chans, active)

    def develop(self) -> mi.TensorXf:
        self.film.put_block(self.block)
        return self.film.develop()


def render_uniform(integrator, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int,
                   develop: bool, evaluate: bool):
    """Mitsuba's path-replay primal render (``ADIntegrator.render``) with emission splitting's
    extra rays splatted through the film's filter (see the module docstring)."""
    if not develop:
        raise ValueError("render_uniform: develop=False; AD integrators render with develop=True")
    film = sensor.film()
    with dr.suspend_grad():
        sampler, spp = integrator.prepare(sensor=sensor, seed=seed, spp=spp, aovs=integrator.aov_names())
        ray, weight, pos = integrator.sample_rays(scene, sensor, sampler)
        splat = FilmSplat(film, len(integrator.aov_names()))
        one = mi.Float(1.0)
        scale, offset = film_mapping(film)
        integrator.set_primary_rays(PrimaryRays(ray, sensor, dr.floor(pos), scale, offset, weight,
                                                splat=(splat, one)))
        try:
            L, valid, aovs, _ = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler,
                                                  ray=ray, depth=mi.UInt32(0), δL=None, δaovs=None,
                                                  state_in=None, active=mi.Bool(True))
        finally:
            integrator.set_primary_rays(None)
        splat.put(pos, L * weight, dr.select(valid, 1.0, 0.0), one, aovs)
        del sampler, ray, weight, L, valid, aovs
        img = splat.develop()
        if evaluate:
            dr.eval(img)
        return img
