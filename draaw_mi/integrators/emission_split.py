"""Emitters seen directly: their emission estimated in edge pixels from stratified extra rays.

Why: in a scene that shows its lights, most of a low-spp image's squared error sits in the
pixels that straddle the edge of a visible emitter: a sample either hits the light (radiance
~10-20) or the dark surround. On the Cornell box at 128x128 and 4 spp, the 109 pixels with a
light in them (0.7 % of the image) carry 87 % of the per-pixel variance of ``path`` and V4
alike. The emission seen at the first hit, ``Le(x0)``, is a 2D integral over the pixel of a
piecewise-constant function, and cheap to evaluate: one intersection and one emitter lookup,
no shading. So in those pixels V4 drops the camera path's own ``Le(x0)`` and estimates that
term from ``k`` extra camera rays (16 by default), one in each cell of a ``sqrt(k) x sqrt(k)``
grid over the pixel, jittered in its cell (stratified sampling: the error of an edge falls
faster than ``1/k``). The rest of the path is estimated from the camera sample as without splitting.

Unbiased with a box pixel filter: with the film's box filter a sample counts only for its
own pixel, and the pixel value is the mean over the pixel of ``W(x) L(x)`` (``W`` the
sensor's importance weight); each stratified ray is uniform over its cell, so the ``k`` rays'
mean ``W Le`` has the same expectation as the camera sample's. Which pixels split does not
depend on the samples (an edge map fixed before the render), so any choice keeps the
expectation. With other filters a sample is splatted with a weight that depends on its
position: there the emission seen at the first hit goes to an image block of its own,
developed with its own weights, each extra ray at its own position and every other camera
sample at its own (:mod:`~draaw_mi.integrators.film_splat`; primal renders only: the
adjoint passes of a filtered film do not split).

Which pixels (:func:`edge_map`): the emitting surfaces' bounding boxes, projected by the
sensor, bound where a light can be seen (:func:`emitter_rect`); inside that rectangle probe
rays on a half-pixel lattice (pixel corners, edge midpoints, centres) read the emission seen
there, and a pixel whose nine probes differ by more than ``EDGE_CONTRAST`` of the largest is
an edge pixel. The map depends on the
scene and the camera, not on the seed: V4 computes it once per camera and reuses it (a
repeated render launches no probe kernel). A SIMD packet of samples without an edge pixel
skips the extra rays, so their cost follows the number of edge pixels. A light thinner
than half a pixel can fall between the probes: its pixels are not split, which loses the
gain there, not the expectation.

Only where the scene calls for it (:func:`applies`): an area emitter, emitters shown (not
``hide_emitters``), a sensor without aperture or shutter samples, no SDF
objects (sphere-traced surfaces would occlude the light for the camera path but not for the
extra rays), no media (V4 hands those to :mod:`~draaw_mi.integrators.volume`), and an
emitting surface in view with at least one edge pixel (lights seen only from behind have
none); otherwise the kernels are exactly those without splitting.
The extra rays need the camera sample's pixel, which Mitsuba's ``sample()`` interface does
not carry: the ray generator records it in a :class:`PrimaryRays` beside the rays
(:meth:`DraawV4Integrator.sample_rays <draaw_mi.integrators.v4.DraawV4Integrator.sample_rays>`,
:func:`draaw_mi.integrators.spp_map.render_spp_map`) and ``sample()`` uses it only for those
same ray objects.

Measured: see the V4 docstring and ``benchmarks/results/speed_suite.md``.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from .common import DraawIntegrator, parse_int
from .scene_view import SceneView, scene_view

DEFAULT_RAYS = 16       # 4 x 4 cells per camera sample in edge pixels (see the V4 docstring)
EDGE_CONTRAST = 0.1     # an edge pixel: its probes' emission differs by more than this share


class PrimaryRays:
    """What a ray generator knows about its camera rays and ``sample()`` does not.

    ``pixel``: integer corner of each ray's pixel in film coordinates (crop offset included);
    ``scale`` / ``offset``: film position -> the sensor's ``[0, 1]^2`` sample;
    ``weight``: the camera rays' importance weights (the renderer multiplies ``L`` by them);
    ``splat``: ``None`` (the extra rays' emission is added to ``L``: box filters) or
    ``(FilmSplat, per-sample weight, film position)``: the emission seen at the first hit is
    splatted into the emission's own block, by each extra ray at its own position in edge
    pixels, by the camera sample at its position elsewhere
    (:mod:`~draaw_mi.integrators.film_splat`).

    A plain class, not a dataclass or tuple: ``dr.syntax`` loops in ``sample()`` read the
    integrator, and Dr.Jit takes the arrays of every dataclass / tuple attribute it reaches
    as loop state (an edge map held in a tuple breaks V4's loop with a size mismatch).
    """
    __slots__ = ("ray", "sensor", "pixel", "scale", "offset", "weight", "splat")

    def __init__(self, ray, sensor, pixel, scale, offset, weight, splat=None):
        self.ray, self.sensor, self.pixel = ray, sensor, pixel
        self.scale, self.offset, self.weight = scale, offset, weight
        self.splat = splat


class Held:
    """A value kept on the integrator out of ``dr.syntax`` loops' reach (see :class:`PrimaryRays`)."""
    __slots__ = ("value",)

    def __init__(self, value):
        self.value = value


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


def sensor_allows(k: int, hide_emitters: bool, sensor: mi.Sensor,
                  no_aperture: bool | None = None) -> bool:
    """The integrator's and the sensor's side of :func:`applies` (cheap: no scene walk).
    ``no_aperture``: whether the sensor samples no aperture, if known
    (:class:`~.scene_view.SceneView`); the shutter is read each time."""
    if k <= 1 or hide_emitters or mi.is_spectral:
        return False             # (spectral: the extra rays would need the path's wavelengths)
    if no_aperture is None:
        no_aperture = not sensor.needs_aperture_sample()
    return no_aperture and sensor.shutter_open_time() == 0


def applies(k: int, hide_emitters: bool, sensor: mi.Sensor, feats: dict[str, bool]) -> bool:
    """Whether splitting is on for this scene and sensor (Python-level: no kernel code else)."""
    if not feats["area_lights"] or feats["sdf"] or feats["media"]:
        return False
    return sensor_allows(k, hide_emitters, sensor)


def emitter_rect(scene: mi.Scene, sensor: mi.Sensor) -> tuple[int, int, int, int] | None:
    """``(x0, y0, x1, y1)``: the film pixels (half-open, film coordinates, inside the crop
    window) where the scene's emitting surfaces can be seen, from their bounding boxes'
    corners projected by ``sensor``; ``None`` when none is in view.

    Conservative where it matters: a box with some corners out of view gives the whole
    window. A light whose box corners are all out of view while it crosses the view (a
    panel larger than the view) is taken as unseen: its pixels are not split (no gain
    there, no bias). Reads the projections back: call it outside recordings and cache it
    (:meth:`DraawV4Integrator.edge_map <draaw_mi.integrators.v4.DraawV4Integrator.edge_map>`).
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
        try:
            ds, _ = sensor.sample_direction(it, mi.Point2f(0.5), True)
        except RuntimeError:     # a sensor that cannot project points: no splitting
            return None
        # (the sensor projects into the crop window: film coordinates add its offset)
        uv = (np.array(ds.uv, dtype=np.float64).T + [ox, oy]).reshape(len(boxes), 8, 2)
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
                   surfaces_only: bool = False, pi: mi.PreliminaryIntersection3f | None = None):
    """``(si, mask)``: the first hit of ``ray`` where its emission is needed (emitting
    surfaces, and misses unless ``surfaces_only``). The full interaction is computed only
    there: the rays' kernel time on the Cornell box is +22 %, against +34 % with it everywhere.
    ``pi``: the rays' preliminary intersection, if already traced."""
    if pi is None:
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
    hit_emitter = pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711
    seen = active & (hit_emitter if surfaces_only else (hit_emitter | ~pi.is_valid()))
    return pi.compute_surface_interaction(ray, flags, seen), seen


def _film_ray(sensor: mi.Sensor, pos: mi.Vector2f, scale, offset, active) -> tuple:
    return sensor.sample_ray(sensor.shutter_open(), 0.0, dr.fma(pos, scale, offset),
                             mi.Point2f(0.5), active)


def film_mapping(film: mi.Film) -> tuple:
    """Film position -> the sensor's ``[0, 1]^2`` sample, as Mitsuba's ``sample_rays``."""
    scale = dr.rcp(mi.ScalarVector2f(film.crop_size()))
    return scale, -mi.ScalarVector2f(film.crop_offset()) * scale


def edge_map(scene: mi.Scene, sensor: mi.Sensor, rect: tuple[int, int, int, int],
             flags: mi.RayFlags) -> mi.Bool:
    """Edge pixels of the emitting surfaces seen by ``sensor``: one flag per pixel of its
    crop window (row-major), evaluated. Probes on a half-pixel lattice (the pixel corners,
    edge midpoints and centres: nine per pixel, shared with the neighbours), only inside
    ``rect`` (:func:`emitter_rect`); the rest of the map is false. A pixel is an edge pixel
    where its nine probes' emission differs by more than ``EDGE_CONTRAST`` of the largest."""
    film = sensor.film()
    ox, oy = (int(v) for v in film.crop_offset())
    cw, ch = (int(v) for v in film.crop_size())
    rx0, ry0, rx1, ry1 = rect
    lw, lh = 2 * (rx1 - rx0) + 1, 2 * (ry1 - ry0) + 1                # lattice over the rectangle
    with dr.suspend_grad():
        # opaque sizes and bounds: a moved camera (a preview's orbit, a batch's frames) moves
        # the rectangle, and literals would compile a new probe kernel for every camera; the
        # lattice spans the rectangle only (the whole film's took 16 MB at 1024x1024)
        w_l = dr.opaque(mi.UInt32, lw)
        idx = dr.arange(mi.UInt32, lw * lh)
        ly = idx // w_l
        lx = idx - ly * w_l
        fx = 0.5 * mi.Float(lx) + dr.opaque(mi.Float, rx0)               # film coordinates
        fy = 0.5 * mi.Float(ly) + dr.opaque(mi.Float, ry0)
        ray, _ = _film_ray(sensor, mi.Vector2f(fx, fy), *film_mapping(film), True)
        si, seen = _emission_seen(scene, ray, flags, mi.Bool(True), surfaces_only=True)
        lum = mi.luminance(si.emitter(scene).eval(si, seen))
        lum = dr.select(seen & dr.isfinite(lum), lum, 0.0)
        dr.eval(lum)
        p = dr.arange(mi.UInt32, cw * ch)
        py = mi.Int32(p // cw)
        qx = mi.Int32(p) - py * cw + (ox - dr.opaque(mi.Int32, rx0))    # pixel in the rectangle
        qy = py + (oy - dr.opaque(mi.Int32, ry0))
        inside = (qx >= 0) & (qx < dr.opaque(mi.Int32, rx1 - rx0)) & (qy >= 0) & (qy < dr.opaque(mi.Int32, ry1 - ry0))
        c = mi.UInt32(2 * qy * mi.Int32(w_l) + 2 * qx)                  # the pixel's top-left corner
        hi, lo = mi.Float(0.0), mi.Float(dr.inf)
        for dy in range(3):
            for dx in range(3):
                v = dr.gather(mi.Float, lum, c + dy * w_l + dx, inside)
                hi, lo = dr.maximum(hi, v), dr.minimum(lo, v)
        edges = inside & (hi - lo > EDGE_CONTRAST * hi)
        dr.eval(edges)
    return edges


def edges_of(primary: PrimaryRays, edges: mi.Bool, active: mi.Bool) -> mi.Bool:
    """Per sample: whether its pixel is an edge pixel in ``edges`` (:func:`edge_map`)."""
    film = primary.sensor.film()
    ox, oy = (int(v) for v in film.crop_offset())
    cw, ch = (int(v) for v in film.crop_size())
    x = mi.Int32(primary.pixel.x) - ox
    y = mi.Int32(primary.pixel.y) - oy
    inside = active & (x >= 0) & (x < cw) & (y >= 0) & (y < ch)
    return inside & dr.gather(mi.Bool, edges, mi.UInt32(y * cw + x), inside)


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
    splat = primary.splat if primal else None
    inv_w = dr.select(primary.weight != 0.0, dr.rcp(primary.weight), 0.0) / k
    if dr.hint(splat is not None, mode="scalar"):
        block, share = splat[0], splat[1] / k        # film units: the camera weight stays on
        inv_w = share
    total = mi.Spectrum(0.0)
    tangent = mi.Spectrum(0.0)
    j = mi.UInt32(0)
    while active & (j < k):
        cell = mi.Vector2f(mi.Float(j % g), mi.Float(j // g))
        pos = primary.pixel + (cell + sampler.next_2d(active)) / g
        ray, w = _film_ray(primary.sensor, pos, primary.scale, primary.offset, active)
        si, seen = _emission_seen(scene, dr.detach(ray), flags, active)
        with dr.resume_grad(when=not primal):
            Le = dr.detach(w) * inv_w * si.emitter(scene).eval(si, seen)
            if dr.hint(not primal, mode="scalar"):
                if dr.hint(dr.grad_enabled(Le), mode="scalar"):
                    if dr.hint(mode == dr.ADMode.Backward, mode="scalar"):
                        dr.backward_from(δL * Le)
                    else:
                        tangent += dr.forward_to(Le)
        if dr.hint(splat is not None, mode="scalar"):
            block.put_emission(pos, Le, share, active)   # at its own position, with its own weight
            Le = mi.Spectrum(0.0)
        total += dr.detach(Le)
        j += 1
    return total, tangent


def splat_own_emission(scene: mi.Scene, primary: PrimaryRays, ray: mi.Ray3f,
                       pi: mi.PreliminaryIntersection3f, flags: mi.RayFlags, active: mi.Bool) -> None:
    """Under a filter other than box (``primary.splat``): the emission that the camera rays
    ``ray`` see at their first hit ``pi``, splatted into the emission's block at the samples'
    positions with their weights (``active``: the samples outside edge pixels, whose emission
    the camera path then leaves out). The surface interaction is computed only where an
    emitting surface or nothing was hit (:func:`_emission_seen`)."""
    block, share, pos = primary.splat
    si, seen = _emission_seen(scene, ray, flags, active, pi=pi)
    Le = dr.detach(primary.weight) * share * si.emitter(scene).eval(si, seen)
    block.put_emission(pos, Le, share, active)


class EmissionSplitting(DraawIntegrator):
    """Base of ``draaw_v4`` for emission splitting (one base class: nanobind types take no
    mixins): keeps the camera rays' pixels (:meth:`sample_rays`) and one edge map per scene and camera
    (:meth:`edge_map`); ``sample()`` asks :meth:`split_inputs` what to split."""

    def init_emission_split(self, props: mi.Properties) -> None:
        # (a fraction or a bool is refused, not rounded)
        self.emission_split = check_rays(parse_int(props, "draaw_v4", "emission_split", DEFAULT_RAYS, 1))
        self._primary = None           # PrimaryRays of the rays being rendered
        self._edge_maps = {}           # (scene, camera) key -> Held((emitter array, edge map | None))
        self._frozen_edges = None      # Held(edge map | None) while a recording runs

    def split_inputs(self, scene: mi.Scene, ray, feats: dict[str, bool]) -> tuple:
        """``(primary, edge map)`` for ``sample()``'s ``ray``, or ``(None, None)``: not these
        rays' generator, splitting off for the scene or sensor, or no emitting surface in view."""
        primary = self._primary if self._primary is not None and self._primary.ray is ray else None
        if primary is None or not applies(self.emission_split, self.hide_emitters, primary.sensor, feats):
            return None, None
        edges = self.edge_map(scene, primary.sensor)
        return (None, None) if edges is None else (primary, edges)

    def frozen_edge_map(self, scene: mi.Scene, view: SceneView | None = None, sensor: mi.Sensor | None = None):
        """The edge map a recording of a render of ``scene`` from ``sensor`` (default its
        first) takes as input, or ``None`` where the integrator or sensor rules splitting out
        (then nothing is built). ``view``: the scene's :class:`~.scene_view.SceneView`, if the
        caller keeps one (fewer calls into Mitsuba on this per-render path). The scene's side
        (no area light, SDF objects, media) is not walked here (a feature walk costs ~80 us):
        there ``sample()`` ignores the map, which costs one probe pass per camera, or none
        without an area light."""
        view = scene_view(scene) if view is None else view
        if sensor is None or sensor is view.sensor:
            sensor, no_aperture = view.sensor, view.no_aperture
        else:
            no_aperture = None                    # (sensor_allows asks the sensor)
        if sensor is None or not sensor_allows(self.emission_split, self.hide_emitters, sensor, no_aperture):
            return None
        return self.edge_map(scene, sensor, view)

    def edge_map(self, scene: mi.Scene, sensor: mi.Sensor, view: SceneView | None = None):
        """Edge pixels of the emitting surfaces that ``sensor`` sees (:func:`edge_map`), or
        ``None`` when none is in view. Cached per scene, camera (the JIT variables of its
        transform, the film's size and crop window) and emitter bounds, so a repeated render
        launches no probe kernel and reads nothing back; within a recording, the map that the
        integrator's ``freeze_state`` passed. (A stale map, say after an occluder moved, costs
        gain, not the expectation: which pixels split does not depend on the samples.)"""
        if self._frozen_edges is not None:
            return self._frozen_edges.value
        if dr.flag(dr.JitFlag.FreezingScope):
            return None                # a recording made without freeze_state: no splitting
        view = scene_view(scene) if view is None else view
        film = view.film if sensor is view.sensor else sensor.film()
        key = (view.key, id(sensor), tuple(dr.detail.collect_indices(sensor.world_transform().matrix)),
               tuple(film.size()), tuple(film.crop_offset()), tuple(film.crop_size()),
               view.emitter_bounds())
        entry = self._edge_maps.get(key)
        if entry is None:
            if len(self._edge_maps) >= 8:
                self._edge_maps.pop(next(iter(self._edge_maps)))
            rect = emitter_rect(scene, sensor)
            edges = None if rect is None else edge_map(scene, sensor, rect,
                                                       self.ray_flags(self.features(scene)))
            if edges is not None and not dr.any(edges):
                edges = None             # lights in view but no edge (seen from behind): no code
            # the entry holds the scene's emitter array: while it does, the array's JIT index
            # (in the key) cannot go to another scene's, so a dead scene's map is never found;
            # Held: a bare tuple here would become V4's loop state (see PrimaryRays)
            entry = self._edge_maps[key] = Held((view.emitter_array, edges))
        return entry.value[1]

    def sample_rays(self, scene, sensor, sampler, *args, **kwargs):
        """Mitsuba's camera rays, with their pixels kept for the split."""
        ray, weight, pos = super().sample_rays(scene, sensor, sampler, *args, **kwargs)
        film = sensor.film()
        self._primary = None
        # (other filters: film_splat.render_uniform makes its own, with a splat)
        if self.emission_split > 1 and film.rfilter().is_box_filter():
            # with a box filter ``pos`` is the pixel's integer corner
            scale, offset = film_mapping(film)
            self._primary = PrimaryRays(ray, sensor, mi.Vector2f(pos), scale, offset, weight)
        return ray, weight, pos

    def set_primary_rays(self, primary) -> None:
        """For ray generators other than :meth:`sample_rays` (adaptive sampling's)."""
        self._primary = primary

    def render_forward(self, *args, **kwargs):
        try:
            return super().render_forward(*args, **kwargs)
        finally:
            self._primary = None       # the rays die with the render

    def render_backward(self, *args, **kwargs):
        try:
            return super().render_backward(*args, **kwargs)
        finally:
            self._primary = None
