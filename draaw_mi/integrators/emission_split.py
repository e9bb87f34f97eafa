"""Emitters seen directly: their emission estimated from several stratified camera rays.

Why: in a scene that shows its lights, most of a low-spp image's squared error sits in the
pixels that straddle the edge of a visible emitter: a sample either hits the light (radiance
~10-20) or the dark surround. On the Cornell box at 128x128 and 2 spp, 109 pixels on the
light (0.7 % of the image) carry 87 % of the per-pixel variance of ``path`` and V4 alike.
The emission seen at the first hit, ``Le(x0)``, is a 2D integral over the pixel of a
piecewise-constant function, and cheap to evaluate: one intersection and one emitter lookup,
no shading. So V4 drops the camera path's own ``Le(x0)`` and estimates that term from ``k``
extra camera rays, one in each cell of a ``sqrt(k) x sqrt(k)`` grid over the pixel, jittered
in its cell (stratified sampling: the error of an edge falls faster than ``1/k``). The rest
of the path (everything after the first hit) is estimated from the camera sample as before.

Unbiased with a box pixel filter: with the film's box filter a sample counts only for its
own pixel, and the pixel value is the mean over the pixel of ``W(x) L(x)`` (``W`` the
sensor's importance weight); each stratified ray is uniform over its cell, so the ``k`` rays'
mean ``W Le`` has the same expectation as the camera sample's. With other filters a sample is
splatted with a weight that depends on its position, which the extra rays do not share: no
splitting there.

Only where the scene calls for it (:func:`applies`): a light the camera can hit (area
emitters, an environment), emitters shown (not ``hide_emitters``), a box filter, a sensor
without aperture or shutter samples, no SDF objects (sphere-traced surfaces would occlude
the light for the camera path but not for the extra rays) and no media (V4 hands those to
:mod:`~draaw_mi.integrators.volume`). The extra rays need the camera sample's pixel, which
Mitsuba's ``sample()`` interface does not carry: the ray generator records it in a
:class:`PrimaryRays` beside the rays (:meth:`DraawV4Integrator.sample_rays
<draaw_mi.integrators.v4.DraawV4Integrator.sample_rays>`,
:func:`draaw_mi.adaptive_sampling.render_spp_map`) and ``sample()`` uses it only for
those same ray objects.

Measured (``benchmarks/results/speed_suite.md``): see the V4 docstring.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError

DEFAULT_RAYS = 16       # 4 x 4 cells per camera sample in edge pixels (see the V4 docstring)
EDGE_CONTRAST = 0.1     # a pixel is an edge pixel where its corners' emission differs by more


@dataclass
class PrimaryRays:
    """What a ray generator knows about its camera rays and ``sample()`` does not.

    ``pixel``: integer corner of each ray's pixel in film coordinates; ``origin`` / ``size``:
    the first pixel and the size of the pixel grid rendered (the film's crop window);
    ``scale`` / ``offset``: film position -> the sensor's ``[0, 1]^2`` sample;
    ``weight``: the camera rays' importance weights (the renderer multiplies ``L`` by them).
    """
    ray: object
    sensor: mi.Sensor
    pixel: mi.Vector2f
    origin: tuple
    size: tuple
    scale: mi.ScalarVector2f
    offset: mi.ScalarVector2f
    weight: mi.Spectrum


def check_rays(k: int) -> int:
    """``k`` if it is a usable number of rays per sample (1 or a square: 1, 4, 9, 16, ...).

    >>> check_rays(16)
    16
    >>> check_rays(3)
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: draaw_v4: emission_split=3; expected 1 (off) or a square number of rays per sample (4, 9, 16, ...)
    """
    g = math.isqrt(max(int(k), 0))
    if k < 1 or g * g != k:
        raise ParameterError(f"draaw_v4: emission_split={k}; expected 1 (off) or a square number "
                             "of rays per sample (4, 9, 16, ...)")
    return int(k)


def applies(k: int, hide_emitters: bool, sensor: mi.Sensor, feats: dict[str, bool]) -> bool:
    """Whether splitting is on for this scene and sensor (Python-level: no kernel code else)."""
    if k <= 1 or hide_emitters or not feats["area_lights"] or feats["sdf"] or feats["media"]:
        return False
    return (sensor.film().rfilter().is_box_filter() and not sensor.needs_aperture_sample()
            and sensor.shutter_open_time() == 0)


def emitter_rect(scene: mi.Scene, sensor: mi.Sensor) -> tuple[int, int, int, int] | None:
    """``(x0, y0, x1, y1)``: the film pixels (half-open, film coordinates, inside the crop
    window) where the scene's emitting surfaces can be seen, from their bounding boxes'
    corners projected by ``sensor``; ``None`` when none is in view.

    Conservative where it matters: a box with some corners out of view gives the whole
    window. A light whose box corners are all out of view while it crosses the view (a
    panel larger than the view) is taken as unseen: its pixels are not split (no gain
    there, no bias). Reads the projections back: call it outside recordings and cache it
    (:meth:`DraawV4Integrator.split_rect <draaw_mi.integrators.v4.DraawV4Integrator.split_rect>`).
    """
    film = sensor.film()
    ox, oy = (int(v) for v in film.crop_offset())
    cw, ch = (int(v) for v in film.crop_size())
    boxes = [em.get_shape().bbox() for em in scene.emitters() if em.get_shape() is not None]
    if not boxes:
        return None
    pts = np.array([[list(b.corner(i)) for i in range(8)] for b in boxes], dtype=np.float64).reshape(-1, 3)
    with dr.suspend_grad():
        it = dr.zeros(mi.Interaction3f, len(pts))
        it.p = mi.Point3f(pts[:, 0], pts[:, 1], pts[:, 2])
        ds, _ = sensor.sample_direction(it, mi.Point2f(0.5), True)
        uv = np.array(ds.uv, dtype=np.float64).T.reshape(len(boxes), 8, 2)
        seen = (np.array(ds.pdf) > 0).reshape(len(boxes), 8)
    x0 = y0 = math.inf
    x1 = y1 = -math.inf
    for box_uv, box_seen in zip(uv, seen):
        if not box_seen.any():
            continue
        if not box_seen.all():
            return ox, oy, ox + cw, oy + ch
        x0, y0 = min(x0, box_uv[:, 0].min()), min(y0, box_uv[:, 1].min())
        x1, y1 = max(x1, box_uv[:, 0].max()), max(y1, box_uv[:, 1].max())
    if x0 == math.inf:
        return None
    # one pixel of margin for rounding; the projection of a box lies in its corners' hull
    rect = (max(ox, math.floor(x0) - 1), max(oy, math.floor(y0) - 1),
            min(ox + cw, math.ceil(x1) + 1), min(oy + ch, math.ceil(y1) + 1))
    return rect if rect[0] < rect[2] and rect[1] < rect[3] else None


def _emission_seen(scene: mi.Scene, ray: mi.Ray3f, flags: mi.RayFlags, active: mi.Bool,
                   surfaces_only: bool = False):
    """``(si, mask)``: the first hit of ``ray`` where its emission is needed (emitting
    surfaces, and misses unless ``surfaces_only``). The full interaction is computed only
    there: the rays' kernel time on the Cornell box fell from +34 % to +22 %."""
    pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
    hit_emitter = pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711
    seen = active & (hit_emitter if surfaces_only else (hit_emitter | ~pi.is_valid()))
    return pi.compute_surface_interaction(ray, flags, seen), seen


def _film_ray(primary: PrimaryRays, pos: mi.Vector2f, active) -> tuple:
    sensor = primary.sensor
    return sensor.sample_ray(sensor.shutter_open(), 0.0, dr.fma(pos, primary.scale, primary.offset),
                             mi.Point2f(0.5), active)


def edge_pixels(scene: mi.Scene, primary: PrimaryRays, rect, flags: mi.RayFlags,
                active: mi.Bool) -> mi.Bool:
    """Samples whose pixel straddles an edge of a visible emitting surface: the emission seen
    through the pixel's four corners differs by more than ``EDGE_CONTRAST`` of the largest.

    ``rect``: four opaque ``mi.UInt32`` (x0, y0, x1, y1) from :func:`emitter_rect`; only
    pixels inside it are probed, one ray per pixel corner, in a kernel of their own
    (deterministic: the same pixels in the primal and adjoint passes; opaque bounds: a moved
    camera compiles nothing new). Only edge pixels' samples trace the extra rays; a SIMD
    packet without one skips them, so the cost follows the number of edge pixels. A light
    smaller than a pixel can fall between the corners: its pixels are not split.
    """
    x0, y0, x1, y1 = rect
    cw, ch = primary.size
    idx = dr.arange(mi.UInt32, (cw + 1) * (ch + 1))
    cy = idx // (cw + 1)
    cx = idx - cy * (cw + 1)
    fx, fy = cx + primary.origin[0], cy + primary.origin[1]        # film coordinates
    probe = (fx >= x0) & (fx <= x1) & (fy >= y0) & (fy <= y1)
    ray, _ = _film_ray(primary, mi.Vector2f(mi.Float(fx), mi.Float(fy)), probe)
    si, seen = _emission_seen(scene, ray, flags, probe, surfaces_only=True)
    lum = mi.luminance(si.emitter(scene).eval(si, seen))
    lum = dr.select(seen & dr.isfinite(lum), lum, 0.0)
    dr.eval(lum)
    px, py = mi.UInt32(primary.pixel.x), mi.UInt32(primary.pixel.y)
    inside = active & (px >= x0) & (px < x1) & (py >= y0) & (py < y1)
    c = (py - primary.origin[1]) * (cw + 1) + (px - primary.origin[0])
    e = [dr.gather(mi.Float, lum, c + d, inside) for d in (0, 1, cw + 1, cw + 2)]
    hi = dr.maximum(dr.maximum(e[0], e[1]), dr.maximum(e[2], e[3]))
    lo = dr.minimum(dr.minimum(e[0], e[1]), dr.minimum(e[2], e[3]))
    return inside & (hi - lo > EDGE_CONTRAST * hi)


@dr.syntax
def visible_emission(mode: dr.ADMode, scene: mi.Scene, primary: PrimaryRays, sampler: mi.Sampler,
                     k: int, flags: mi.RayFlags, active: mi.Bool, δL) -> tuple:
    """``(value, tangent)``: the emission seen at the first hit, in the camera path's units
    (divided by its weight), estimated from ``k`` stratified rays through each active
    sample's pixel (zero for the other samples).

    ``value`` is detached. In the backward pass of path replay the derivative with respect to
    emitter parameters is propagated here (``δL``: each sample's adjoint radiance); in the
    forward pass ``tangent`` is the value's derivative (zero otherwise).
    """
    primal = mode == dr.ADMode.Primal
    g = math.isqrt(k)
    inv_w = dr.select(primary.weight != 0.0, dr.rcp(primary.weight), 0.0) / k
    total = mi.Spectrum(0.0)
    tangent = mi.Spectrum(0.0)
    j = mi.UInt32(0)
    while active & (j < k):
        cell = mi.Vector2f(mi.Float(j % g), mi.Float(j // g))
        ray, w = _film_ray(primary, primary.pixel + (cell + sampler.next_2d(active)) / g, active)
        si, seen = _emission_seen(scene, dr.detach(ray), flags, active)
        with dr.resume_grad(when=not primal):
            Le = dr.detach(w) * inv_w * si.emitter(scene).eval(si, seen)
            if dr.hint(not primal, mode="scalar"):
                if dr.hint(dr.grad_enabled(Le), mode="scalar"):
                    if dr.hint(mode == dr.ADMode.Backward, mode="scalar"):
                        dr.backward_from(δL * Le)
                    else:
                        tangent += dr.forward_to(Le)
        total += dr.detach(Le)
        j += 1
    return total, tangent
