"""``draaw_v1`` / ``draaw_v2`` in scenes with media: GO-Draaw's single-scattering ray march,
fixed (``go-draaw-spec.md`` §4.3).

GO-Draaw marches 12 equal steps with one *global* density, uses a transmittance that starts
at a user "transmittance" value (a brightness gain), estimates the light's transmittance from
the whole box chord regardless of where the light is, and ignores surfaces. Here:

* the camera ray is marched through every medium segment it crosses (``null`` boundaries
  switch media) in ``medium_steps`` equal steps per segment with a random offset (stochastic
  midpoint rule), reading the medium's own ``sigma_t`` / ``sigma_s`` at each sample (per-cell
  density and albedo), with transmittance ``T = exp(-sum sigma_t dt)`` starting at 1;
* single scattering: at each sample, one emitter sample, HG phase, and the light's *real*
  transmittance, marched the same way along the shadow ray up to the light (opaque surfaces
  block);
* the first opaque surface adds its emission and direct light (the BSDF's ``eval``, one
  emitter sample, marched transmittance), attenuated by ``T``. No multiple scattering and no
  indirect light: biased by design (the cheap rung), ``medium_steps`` is the knob.
* Rays cross up to ``MAX_SEGMENTS`` (1024) null surfaces: a shadow ray still crossing at
  that cap counts as blocked, a camera ray ends there (what lies behind is not seen).
* SDF objects (feature ``sdf``): the march of a segment stops at the nearer of the mesh and
  SDF hits, SDF surfaces are lit like opaque surfaces, and SDFs block the shadow rays.
* An unbounded medium (a ``homogeneous`` one as the camera's medium) is marched up to a
  sphere around the scene (twice its bounding radius, larger for a camera outside that);
  past that it lets nothing through unless its ``sigma_t`` is 0,
  so a camera ray does not see the environment through it (as in ``volpath`` and V3/V4, where
  such a ray always scatters). Light samples of the sun or an environment are attenuated over
  the distance Mitsuba gives them (twice the scene's radius), as in ``volpath`` and V3/V4.

Primal only: in media scenes V1/V2 are not differentiable (use ``draaw_v3`` / ``draaw_v4``).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..errors import RenderError
from . import pass_sensor
from .volume_tracking import coefficients, medium_interaction, partly_null
from .volume_tracking import scatters as vt_scatters

# null-surface crossings per ray (index-matched boundaries, masks). A shadow ray still live at
# the cap counts as blocked (T = 0: no light leaks through a blocker behind many null
# surfaces); a camera ray ends there, its pixel keeping what it gathered before (what lies
# behind more null surfaces than this is not seen; documented in docs/guides/voxels.md)
MAX_SEGMENTS = 1024


def _segment_end(scene, ray, t0, t1, active):
    """``(t1', unbounded)``: the end of the marched stretch ``[t0, t1]``. An unbounded medium
    (Mitsuba's ``homogeneous`` as the camera's medium: its box is all space) along a ray that
    leaves the scene has ``t1 = inf``, and equal steps over it give NaN pixels. Its stretch
    ends where the ray leaves a sphere of twice the scene's bounding radius: the light
    scattered in beyond it is not gathered (bias, as the march's), and the transmittance
    past it is :func:`_tail`'s."""
    unbounded = active & ~dr.isfinite(t1)
    box = scene.bbox()
    bs = box.bounding_sphere() if box.valid() else None          # (no shapes: no box)
    ok = bs is not None and all(math.isfinite(float(x)) for x in (*bs.center, bs.radius))
    centre, r0 = (mi.Point3f(bs.center), max(float(bs.radius), 1.0)) if ok else (mi.Point3f(0.0), 1.0)
    oc = ray.o - centre
    # a sphere around the origin too (a camera far outside the scene): the larger root
    radius = dr.maximum(2.0 * r0, dr.norm(oc) + r0)
    b = dr.dot(oc, ray.d)
    far = -b + dr.safe_sqrt(b * b - (dr.squared_norm(oc) - radius * radius))
    return dr.select(unbounded, dr.maximum(far, t0), t1), unbounded


def _tail(medium, ray, t, unbounded, active):
    """Transmittance from ``t`` to infinity through a homogeneous unbounded medium: 0 where it
    attenuates at all, else 1 (``exp(-sigma_t * inf)`` without the NaN of ``0 * inf``)."""
    _, _, s_t = _coeffs(medium, ray, t, active & unbounded)
    return dr.select(active & unbounded & (s_t > 0), 0.0, 1.0)


def _coeffs(medium, ray, t, active):
    """(interaction, sigma_s, grey sigma_t) at ``ray(t)`` (as the tracking code computes them)."""
    mei = medium_interaction(ray, t, medium)
    sigma_s, sigma_t = coefficients(medium, mei, active)
    return mei, sigma_s, sigma_t


@dr.syntax
def marched_transmittance(scene, ray: mi.Ray3f, dist, medium, steps: int, u: mi.Float, active,
                          partial: bool = False):
    """``exp(-integral sigma_t)`` along ``ray`` up to ``dist`` by ``steps`` samples per medium
    segment (offset ``u``), through null surfaces; 0 if an opaque surface blocks, or if the ray
    would cross more than ``MAX_SEGMENTS`` null surfaces."""
    T = mi.Float(1.0)
    r = mi.Ray3f(ray)
    rem = mi.Float(dist)
    med = dr.select(active, medium, dr.zeros(mi.MediumPtr))
    live = mi.Bool(active)
    n = mi.UInt32(0)
    flags = mi.RayFlags.All if partial else mi.RayFlags.Minimal     # partial: partly_null(scene)
    while live:
        r.maxt = rem
        si = scene.ray_intersect(r, flags, False, live)
        seg = dr.minimum(si.t, rem)
        in_med = live & (med != None)  # noqa: E711
        ok, mint, maxt = med.intersect_aabb(r)
        t0 = dr.maximum(mint, 0.0)
        t1, unbounded = _segment_end(scene, r, t0, dr.minimum(maxt, seg), in_med & ok)
        march = in_med & ok & (t1 > t0)
        dt = dr.select(march, (t1 - t0) / steps, 0.0)
        tau = mi.Float(0.0)
        k = mi.UInt32(0)
        while march & (k < steps):
            _, _, s_t = _coeffs(med, r, t0 + (mi.Float(k) + u) * dt, march)
            tau += s_t * dt
            k += 1
        T[march] = T * dr.exp(-tau) * _tail(med, r, t1, unbounded, march)
        hit = live & si.is_valid() & (si.t < rem)
        bsdf = si.bsdf()
        null = hit & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null)
        T[hit & ~null] = 0.0
        if dr.hint(partial, mode="scalar"):      # a mask passes 1 - opacity
            T[null] = T * bsdf.eval_null_transmission(si, null).x
        med[null & si.is_medium_transition()] = si.target_medium(r.d)
        rem[null] = rem - si.t
        r[null] = si.spawn_ray(r.d)
        n += 1
        live &= null & (T > 0)
        T[live & (n >= MAX_SEGMENTS)] = 0.0       # still crossing at the cap: blocked
        live &= n < MAX_SEGMENTS
    return T


def _light(scene, sampler, it, medium, steps, active, sdf=None, partial=False):
    """One emitter sample from ``it``: ``(ds, Le / pdf * T_light)``; ``sdf``: the scene's SDF
    hook (SDF occluders block the sample before its transmittance is marched)."""
    ds, em_w = scene.sample_emitter_direction(it, sampler.next_2d(active), False, active)
    active = active & (ds.pdf != 0)
    if sdf is not None:
        active &= ~sdf.occluded(it, ds, active)
    r = it.spawn_ray(ds.d)
    dist = dr.select(dr.isfinite(ds.dist), ds.dist * (1.0 - mi.math.ShadowEpsilon), dr.inf)
    T = marched_transmittance(scene, r, dist, medium, steps, sampler.next_1d(active), active, partial)
    return ds, dr.select(active, em_w * T, 0.0)


@dr.syntax
def sample(integ, mode, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f, active: mi.Bool):
    """The body of ``draaw_v1`` / ``draaw_v2``'s ``sample()`` for scenes with media."""
    if mode != dr.ADMode.Primal:
        raise RenderError(f"{integ.PLUGIN}: scenes with participating media are rendered primal-only "
                          "by V1/V2 (single-scattering march); differentiate with draaw_v3 / draaw_v4")
    steps = int(getattr(integ, "medium_steps", 12))
    partial = partly_null(scene)
    # SDF objects (feature 'sdf'): the march stops at the nearer of the mesh / SDF hit
    feats = integ.features(scene)
    sdf = integ.sdf_hook(scene, feats)
    ctx = mi.BSDFContext()
    aovs = integ.camera_aovs(scene, ray, active, feats, sdf)
    ray = mi.Ray3f(ray)
    ray.d = dr.normalize(ray.d)
    L = mi.Spectrum(0.0)
    T = mi.Spectrum(1.0)
    medium = dr.zeros(mi.MediumPtr)
    # camera rays start in the rendered sensor's medium (pass_sensor, kept by the render
    # passes; sensor 0 when sample() is called outside them)
    sensor = pass_sensor.sensor_of(integ)
    if sensor is None and len(scene.sensors()) > 0:
        sensor = scene.sensors()[0]
    cam_medium = None if sensor is None else sensor.get_medium()
    if dr.hint(cam_medium is not None, mode="scalar"):
        medium = dr.select(active, mi.MediumPtr(cam_medium), medium)
    live = mi.Bool(active)
    valid = mi.Bool(False)
    n = mi.UInt32(0)
    while live:
        si = scene.ray_intersect(ray, mi.RayFlags.All, False, live)
        if dr.hint(sdf is not None, mode="scalar"):
            si = sdf.intersect(ray, si, sampler, live)
        in_med = live & (medium != None)  # noqa: E711
        ok, mint, maxt = medium.intersect_aabb(ray)
        t0 = dr.maximum(mint, 0.0)
        t1, unbounded = _segment_end(scene, ray, t0, dr.minimum(maxt, si.t), in_med & ok)
        march = in_med & ok & (t1 > t0)
        dt = dr.select(march, (t1 - t0) / steps, 0.0)
        u = sampler.next_1d(march)
        k = mi.UInt32(0)
        while march & (k < steps):
            mei, s_s, s_t = _coeffs(medium, ray, t0 + (mi.Float(k) + u) * dt, march)
            ds, Lw = _light(scene, sampler, mei, medium, steps, march, sdf, partial)
            phase = medium.phase_function()
            ph, _ = phase.eval_pdf(mi.PhaseFunctionContext(sampler), mei, ds.d, march)
            # this step's own attenuation up to the sample, then through it
            T_half = T * dr.exp(-s_t * (u * dt))
            # (an infinite sigma: T_half 0 times sigma_s inf is NaN)
            L[march & (dr.max(T_half) > 0)] = L + T_half * s_s * ph * Lw * dt
            T[march] = T * dr.exp(-s_t * dt)
            k += 1
        T[march] = T * _tail(medium, ray, t1, unbounded, march)
        valid |= live & si.is_valid()
        bsdf = si.bsdf(ray)
        hit = live & si.is_valid()
        null = hit & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null)
        opaque = hit & ~null
        shaded = opaque                  # lit here: opaque surfaces, and masks in part
        if dr.hint(partial, mode="scalar"):
            shaded = hit & (~null | vt_scatters(bsdf.flags()))
        # emission of what the ray finally sees (surface or environment)
        seen = (live & ~si.is_valid()) | opaque
        # (the march never turns: every segment is the camera ray, so what it ends on is seen
        # directly, through any number of smoke boundaries; hiding only segment 0 would show the
        # sky through a smoke box)
        if dr.hint(not integ.hide_emitters, mode="scalar"):
            L[seen] = L + T * si.emitter(scene).eval(si, seen)
        # direct light at the surface
        m2 = dr.select(si.is_medium_transition(), si.target_medium(si.to_world(si.wi)), medium)
        ds, Lw = _light(scene, sampler, si, m2, steps, shaded, sdf, partial)
        f = bsdf.eval(ctx, si, si.to_local(ds.d), shaded)     # (a mask's: opacity times its BSDF's)
        L[shaded] = L + T * f * Lw
        if dr.hint(partial, mode="scalar"):      # then on through it with 1 - opacity
            T[null] = T * bsdf.eval_null_transmission(si, null)
        medium[null & si.is_medium_transition()] = si.target_medium(ray.d)
        ray[null] = si.spawn_ray(ray.d)
        n += 1
        live &= null & (n < MAX_SEGMENTS)
    return L, valid | mi.Bool(scene.environment() is not None), aovs, L
