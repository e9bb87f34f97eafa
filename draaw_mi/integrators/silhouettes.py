"""Camera-silhouette gradients of SDF shape parameters: the boundary pass of the gradient
renders (theory in :mod:`draaw_mi.sdf.silhouette`).

:class:`~draaw_mi.integrators.common.DraawIntegrator` runs it after Mitsuba's path-replay
pass (the interior term) in ``render_backward`` and ``render_forward``, when the scene has SDF
objects with a parameter that tracks gradients and the integrator's ``sdf_silhouettes`` is on;
during both passes the integrator's ``sdf_band`` tells the SDF hook to add shadow-edge terms
to its light samples (``SDFHook.shadow_boundary``). Primal renders trace none of it.

The pass traces one camera ray per sample (its own seed), finds the rays that pass an SDF
outline within the band (:func:`~draaw_mi.sdf.silhouette.closest_approach`, up to the first
mesh), and, for those only, estimates the radiance on both sides of the outline with the
integrator's own ``sample()`` (primal): the ray as it is (outside) and turned to graze the
surface just inside (:func:`~draaw_mi.sdf.silhouette.inside_ray`; two depths, extrapolated to
the outline). Each sample's value,
``k(m) (L_in - L_out) (detach(m) - m)``, has the boundary term as its derivative and is
splatted through the film like Mitsuba's samples, so every pixel filter weighs it as it weighs
the image.
"""
from __future__ import annotations

from contextlib import contextmanager

import drjit as dr
import mitsuba as mi

from ..sdf.scene import find
from ..sdf.silhouette import Band, attached_minimum, closest_approach, inside_ray, kernel

ADIntegrator = mi.ad.integrators.common.ADIntegrator
SEED_SALT = 0x2545F491          # the pass's samples are independent of the interior pass's


def wanted(integrator, scene: mi.Scene) -> bool:
    """Whether a gradient render of ``scene`` needs the boundary terms: silhouettes on, SDF
    objects outside media (SDF shapes get no gradient in media), a shape parameter with
    gradients enabled."""
    if not getattr(integrator, "sdf_silhouettes", False):
        return False
    feats = integrator.features(scene)
    if not feats.get("sdf") or feats.get("media"):
        return False
    sdf = find(scene)
    return sdf is not None and any(dr.grad_enabled(v) for v in sdf.params().values())


@contextmanager
def boundary_band(integrator, scene: mi.Scene, sensor: mi.Sensor):
    """Within: ``integrator.sdf_band`` is the sensor's :class:`Band` when :func:`wanted` (the
    SDF hooks of the passes add shadow-edge terms), else ``None``; yields it."""
    band = Band.of_sensor(sensor, integrator.sdf_band_width) if wanted(integrator, scene) else None
    integrator.sdf_band = band
    try:
        yield band
    finally:
        integrator.sdf_band = None


def boundary_samples(integrator, scene: mi.Scene, sensor: mi.Sensor, sampler: mi.Sampler, seed):
    """``(value, weight, pos, ray)``: one camera sample per ray of Mitsuba's grid, whose
    ``value`` (attached; 0 outside the band) has the silhouette term as its derivative. The
    band's rays (a few per cent) are gathered into arrays of their own before their inside
    rays are found and their three radiance estimates traced."""
    ray, weight, pos = integrator.sample_rays(scene, sensor, sampler)
    sdf = find(scene)
    band = integrator.sdf_band
    n_all = dr.width(ray)
    with dr.suspend_grad():
        r = mi.Ray3f(dr.detach(ray))
        mesh = scene.ray_intersect(r, mi.RayFlags.Minimal, True)   # the depth test
        tmax = dr.select(mesh.is_valid(), mesh.t, r.maxt)
        hit, t, m, found = closest_approach(sdf, r.o, r.d, tmax, mi.Bool(True),
                                            integrator.sdf_tracer, band.pad(sdf))
        # one pixel at the closest point, from this ray's own differentials
        pixel = dr.norm(ray.o_x - ray.o) + t * dr.norm(ray.d_x - ray.d)
        eps = band.width * pixel
        k = kernel(m, eps)
        idx = dr.compress(found & (k != 0))
    n = dr.width(idx)
    value = dr.zeros(mi.Spectrum, n_all)
    if n == 0:
        return value, weight, pos, ray
    with dr.suspend_grad():
        r, t, m, eps, k = (dr.gather(type(x), x, idx) for x in (r, t, m, eps, k))
        d_in, ok = inside_ray(sdf, r.o, r.d, t, m, eps, integrator.sdf_tracer)
        d_deep, ok_deep = inside_ray(sdf, r.o, r.d, t, m, eps, integrator.sdf_tracer, deeper=4.0)
        on = ok & ok_deep
        # three radiance estimates of one path kernel: evaluated one by one, they compile it
        # once (fused, one kernel held three copies of the integrator: 9 s to compile)
        dr.eval(r, t, m, eps, k, d_in, d_deep, on)
        band_sampler = sampler.clone()
        band_seed = mi.UInt32(seed) + 1
        dr.make_opaque(band_seed)          # (a literal seed would compile a kernel per step)
        band_sampler.seed(band_seed, n)
        L_out = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=band_sampler,
                                  ray=mi.Ray3f(r), δL=None, state_in=None, active=mi.Bool(on))[0]
        dr.eval(L_out, band_sampler)
        # the inside radiance at the outline: 2 L(s) - L(4 s) (sdf.silhouette), one path's
        # random numbers for both
        twin = band_sampler.clone()
        r_in = mi.Ray3f(r)
        r_in.d = d_in
        L_in = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=band_sampler, ray=r_in,
                                 δL=None, state_in=None, active=mi.Bool(on))[0]
        dr.eval(L_in)
        r_in.d = d_deep
        L_deep = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=twin, ray=r_in,
                                   δL=None, state_in=None, active=mi.Bool(on))[0]
        jump = dr.select(on, (2.0 * L_in - L_deep - L_out) * k, 0.0)
        jump = dr.select(dr.isfinite(jump), jump, 0.0)
        delta = 0.5 * m + 1e-4 * eps
        # each ray's place among the band's rays (gathered back: a scatter into an attached
        # array leaves it dirty inside the AD traversal). The gather's adjoint is a plain
        # atomic scatter-add (ReduceMode.Direct): Auto expands a small target per thread with
        # its size, the band's ray count, a literal: a new kernel for each count
        # (each new SDF parameter value, in a fit)
        slot = dr.full(mi.UInt32, 0xFFFFFFFF, n_all)
        dr.scatter(slot, dr.arange(mi.UInt32, n), idx)
        dr.eval(slot)
        in_band = slot != 0xFFFFFFFF
    with dr.resume_grad():
        m_att = attached_minimum(sdf, r.o, r.d, t, m, delta, on)
        value = dr.gather(mi.Spectrum, jump * (dr.detach(m_att) - m_att), slot, in_band,
                          mode=dr.ReduceMode.Direct)
    return value, weight, pos, ray


def _splat(integrator, film, spp, pos, value, ray):
    block = film.create_block()
    block.set_coalesce(block.coalesce() and spp >= 4)
    zeros = dr.zeros(mi.Float, dr.width(ray))
    ADIntegrator._splat_to_block(block, film, pos, value=value, weight=1.0, alpha=zeros,
                                 aovs=[zeros for _ in integrator.aov_names()],
                                 wavelengths=ray.wavelengths)
    film.put_block(block)
    return film.develop()


def backward(integrator, scene: mi.Scene, grad_in: mi.TensorXf, sensor: mi.Sensor, seed, spp: int):
    """Back-propagate ``grad_in`` through the silhouette term (after the interior pass)."""
    film = sensor.film()
    with dr.suspend_grad():
        sampler, spp = integrator.prepare(sensor, seed ^ SEED_SALT, spp, integrator.aov_names())
        value, weight, pos, ray = boundary_samples(integrator, scene, sensor, sampler, seed ^ SEED_SALT)
        with dr.resume_grad():
            image = _splat(integrator, film, spp, pos, value * weight, ray)
            dr.set_grad(image, grad_in)
            dr.enqueue(dr.ADMode.Backward, image)
            dr.traverse(dr.ADMode.Backward)
        del value, weight, pos, ray, sampler
        dr.eval()


def forward(integrator, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int) -> mi.TensorXf:
    """The silhouette term's share of the gradient image (the parameters' tangents as set)."""
    film = sensor.film()
    with dr.suspend_grad():
        sampler, spp = integrator.prepare(sensor, seed ^ SEED_SALT, spp, integrator.aov_names())
        value, weight, pos, ray = boundary_samples(integrator, scene, sensor, sampler, seed ^ SEED_SALT)
        with dr.resume_grad():
            tangent = dr.forward_to(value)
        return _splat(integrator, film, spp, pos, dr.detach(tangent) * weight, ray)


__all__ = ["wanted", "boundary_band", "boundary_samples", "backward", "forward"]
