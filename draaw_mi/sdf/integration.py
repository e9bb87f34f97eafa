"""The draaw integrators' SDF hooks (feature ``sdf``; absent SDFs compile none of this).

An integrator asks :func:`hook` once per traced render; with SDF objects in the scene it gets
an :class:`SDFHook` and calls

* :meth:`SDFHook.intersect` after each ``scene.ray_intersect`` (camera, bounce and gather
  rays): the SDF is sphere-traced up to the mesh hit (the depth test) and, where it is
  closer, the mesh interaction is replaced by a synthesised ``SurfaceInteraction3f`` on the
  material slot's hidden proxy shape, so ``si.bsdf()``, ``si.to_local``, ``si.spawn_ray`` and
  emitter sampling work unchanged. Where a smooth operator blends two materials, the slot is
  picked at random with the blend weights (a stochastic mixture: its expectation is the
  weight-blended BSDF; :meth:`SDFHook.pick_weight` differentiates the pick); AOVs take the blend of the materials' values
  (:meth:`SDFHook.blended`).
* :meth:`SDFHook.occluded` for shadow rays (through ``common.sample_emitter``): SDFs cast
  shadows on meshes and on themselves.
* :meth:`SDFHook.reattach` in the differential phases: the hit point, normal, frame and
  ``wi`` of SDF hits are recomputed so that they carry derivatives with respect to the SDF
  parameters (implicit re-attachment of ``t``, see :func:`draaw_mi.sdf.tracer.reattach_t`),
  and :meth:`SDFHook.emitter_geometry` re-attaches the emitter sample's direction and its
  ``cos / dist^2`` factor to the moving point; :meth:`SDFHook.reattach_sampled` re-evaluates
  a BSDF-sampled direction (V3, V4) held fixed in world space at the re-attached point.

In scenes with participating media (feature ``media``) the volumetric paths
(:mod:`draaw_mi.integrators.volume` for V3/V4, :mod:`draaw_mi.integrators.volume_march` for
V1/V2) use :meth:`SDFHook.intersect` (free flights and march segments end at the nearer hit)
and :meth:`SDFHook.occluded` (before ratio tracking / marching the shadow ray), but not
:meth:`SDFHook.reattach`: SDF shape parameters get no gradient in media scenes.

**Differentiated:** material and emitter parameters (path replay, as for meshes); SDF shape
parameters (radius, centre, size, translation, scale, smooth ``k``) through the position,
normal, direct lighting and (V3, V4) BSDF-sampled light of SDF points seen by the camera or
by a path vertex (the interior terms), and, in the gradient passes, through outlines seen by
the camera (:mod:`draaw_mi.integrators.silhouettes`) and shadow edges on light samples
(:meth:`SDFHook.shadow_boundary`): the boundary terms of :mod:`draaw_mi.sdf.silhouette`.
**Not differentiated:** outlines met by bounce rays (also light reached by BSDF sampling past
an SDF edge), the curve where an SDF meets a mesh, a mesh's shadow edge on a moving SDF point,
and in V1/V2 the light scattered or gathered from an SDF point (its direction is kept in the
local frame). The weights of blended materials are differentiated through the random pick
(:meth:`SDFHook.pick_weight`).

**Not differentiated either: how a moving SDF point moves the next bounce.** Each vertex is
re-attached along its own ray, whose origin is detached, and the next ray leaves from the
detached point, so light that reaches the camera through two or more bounces changes only
through each vertex's own re-attachment, not through the segment between a moving SDF vertex
and the next one. Direct light, and every path of ``max_depth = 2``, are exact; indirect light
off SDF surfaces (``max_depth >= 3``) is missed, most in closed rooms. Measured (whole-image
mean, central finite differences with step 0.02): an SDF plane's offset, a mesh ceiling out of
view and a point light between: depth 2, V4 0.4879 against 0.4880; depth 3, V1 0.4825, V3
0.4879, V4 0.4879 against 0.5525, 0.5631, 0.5637. Camera and point light inside an SDF sphere
of radius 2, its radius: depth 2, V4 -0.0861 against -0.0861; depth 3, -0.140 against
-0.191; depth 6, about -0.04 against -0.405. Including it needs the area-measure form (each
vertex moving with its surface, the geometric term between consecutive attached vertices
evaluated anew, and the change of the area element).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..errors import RenderError
from .scene import find
from .silhouette import attached_minimum, closest_approach, kernel
from .tracer import TracerOptions, march, near_crease, normal, reattach_t


def hook(integrator, scene: mi.Scene, feats: dict) -> "SDFHook | None":
    """The SDF hook for ``scene`` or ``None`` (no SDF objects: no SDF code in the kernel)."""
    if not feats.get("sdf"):
        return None
    sdf = find(scene)
    if sdf is None:
        return None
    opts = getattr(integrator, "sdf_tracer", None) or TracerOptions()
    return SDFHook(sdf, scene, opts, getattr(integrator, "sdf_band", None),
                   getattr(integrator, "sdf_creases", False))


class SDFHook:
    """``band``: a :class:`~draaw_mi.sdf.silhouette.Band` while a gradient pass wants boundary
    terms (:mod:`draaw_mi.integrators.silhouettes` sets it), else ``None``. ``creases``: keep
    the normal's derivative at creases (:meth:`reattach`)."""
    def __init__(self, sdf, scene: mi.Scene, opts: TracerOptions, band=None, creases: bool = False):
        self.sdf = sdf
        self.opts = opts
        self.band = band
        self.creases = creases
        by_id = {sh.id(): sh for sh in scene.shapes()}
        missing = [pid for pid in sdf.proxy_ids if pid not in by_id]
        if missing:     # (merged into another mesh: load with optimize=False, scene.mitsuba_load.load_mitsuba_dict)
            raise RenderError(f"SDF tracer: the scene lacks the proxy shapes {missing} of its SDF "
                              "objects (merged by Mitsuba's scene optimisation?)")
        self.proxies = [by_id[pid] for pid in sdf.proxy_ids]
        self.proxy_ptrs = mi.ShapePtr(self.proxies)

    # ------------------------------------------------------------------ primal
    def intersect(self, ray: mi.Ray3f, si: mi.SurfaceInteraction3f, sampler, active):
        """``si`` (mesh hit of ``ray``) with closer SDF hits substituted (detached)."""
        with dr.suspend_grad():
            d = dr.detach(ray.d)
            # no further than the mesh hit, or than the ray's maxt (a camera's far clip)
            tmax = dr.select(si.is_valid(), si.t, ray.maxt)
            t, hit, _ = march(self.sdf, ray.o, d, tmax, mi.Bool(active), self.opts)
            p = dr.fma(d, t, ray.o)
            n = normal(self.sdf, mi.Point3f(p), -d)
            shape = mi.ShapePtr(self.proxies[0]) if len(self.proxies) == 1 else None
            if shape is None and sampler is None:     # no random numbers (AOVs): largest weight
                _, w = self.sdf.eval(mi.Point3f(p))
                idx, best = mi.UInt32(0), w[0]
                for i, wi in enumerate(w[1:]):
                    idx = dr.select(wi > best, mi.UInt32(i + 1), idx)
                    best = dr.maximum(best, wi)
                shape = dr.gather(mi.ShapePtr, self.proxy_ptrs, idx, hit)
            elif shape is None:
                _, w = self.sdf.eval(mi.Point3f(p))
                u = sampler.next_1d(hit)
                idx = mi.UInt32(0)
                acc = mi.Float(0.0)
                total = mi.Float(0.0)
                for wi in w:
                    total += dr.maximum(wi, 0.0)
                for i, wi in enumerate(w[:-1]):
                    acc += dr.maximum(wi, 0.0)
                    idx = dr.select(u * total >= acc, mi.UInt32(i + 1), idx)
                shape = dr.gather(mi.ShapePtr, self.proxy_ptrs, idx, hit)
            s = self._interaction(ray, t, p, n, shape)
            return dr.select(hit, s, si)

    def blended(self, si: mi.SurfaceInteraction3f, bsdf: mi.BSDFPtr, value, active):
        """``value(bsdf, mask)`` (an AOV of a BSDF at ``si``) as the expectation of
        :meth:`intersect`'s pick at SDF points: each material slot's value weighted by its
        blend weight at ``si.p`` (a smooth blend's AOV, the same in every version, whether
        ``si`` got a material at random for the path or the largest weight's); ``bsdf``'s
        own value elsewhere (meshes) and where every weight is zero."""
        own = value(bsdf, active)
        if len(self.proxies) == 1:
            return own
        on_sdf = mi.Bool(False)
        for proxy in self.proxies:
            on_sdf |= si.shape == mi.ShapePtr(proxy)
        m = active & on_sdf
        _, w = self.sdf.eval(mi.Point3f(si.p))
        total, acc = mi.Float(0.0), dr.zeros(type(own))
        for proxy, wi in zip(self.proxies, w):
            wi = dr.maximum(wi, 0.0)
            total += wi
            acc += wi * value(mi.BSDFPtr(proxy.bsdf()), m)
        return dr.select(m & (total > 0.0), acc / dr.maximum(total, 1e-30), own)

    def pick_weight(self, si: mi.SurfaceInteraction3f, active):
        """``1`` carrying the derivative of :meth:`intersect`'s material pick at ``si`` (call
        under ``dr.resume_grad()`` with a re-attached ``si``): ``p_I / detach(p_I)``, ``p_I`` the
        picked slot's blend weight over their sum. Multiplying the radiance an SDF point
        reflects by it makes the mixture's weights differentiable (the score of the pick: its
        expectation is the weights' own derivative times each material's radiance). ``1.0``
        with a single material slot (no code)."""
        if len(self.proxies) == 1:
            return 1.0
        _, w = self.sdf.eval(mi.Point3f(si.p))
        total, mine = mi.Float(0.0), mi.Float(0.0)
        for proxy, wi in zip(self.proxies, w):
            wi = dr.maximum(wi, 0.0)
            total += wi
            mine = dr.select(si.shape == mi.ShapePtr(proxy), wi, mine)
        ok = self.is_sdf(si, active) & (mine > 0) & (total > 0)
        prob = mine / dr.select(ok, total, 1.0)
        ratio = prob / dr.select(ok, dr.detach(prob), 1.0)
        return dr.select(ok, dr.replace_grad(mi.Float(1.0), ratio), 1.0)

    @staticmethod
    def _interaction(ray, t, p, n, shape):
        s = dr.zeros(mi.SurfaceInteraction3f)
        s.t = mi.Float(t)
        s.time = ray.time
        s.wavelengths = ray.wavelengths
        s.p = mi.Point3f(p)
        s.n = mi.Normal3f(n)
        s.sh_frame = mi.Frame3f(mi.Vector3f(n))
        s.dp_du = s.sh_frame.s
        s.dp_dv = s.sh_frame.t
        s.wi = s.sh_frame.to_local(-ray.d)
        s.shape = shape
        return s

    def occluded(self, si: mi.SurfaceInteraction3f, ds: mi.DirectionSample3f, active) -> mi.Bool:
        """Whether an SDF blocks the shadow ray from ``si`` to the emitter sample ``ds``."""
        with dr.suspend_grad():
            ray = si.spawn_ray(dr.detach(ds.d))
            # an environment or a sun is at infinity, not at the finite ds.dist Mitsuba gives
            # it (twice the radius of the mesh scene's bounds, which leave out the SDF objects:
            # a closed SDF sphere of radius 100 would let the sky in)
            far = ~dr.isfinite(ds.dist) | mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite)
            tmax = dr.select(far, dr.inf, ds.dist * (1.0 - 1e-4))
            _, hit, _ = march(self.sdf, ray.o, ray.d, tmax, mi.Bool(active), self.opts)
        return hit

    def shadow_boundary(self, si: mi.SurfaceInteraction3f, ds: mi.DirectionSample3f, em_weight,
                        active):
        """``em_weight`` plus the shadow-edge term of a visible light sample (value 0; only in
        the differential phases, with a :attr:`band`): where the shadow ray passes an SDF
        within the band, ``em_weight * k(m) * dm/dpi`` (:mod:`draaw_mi.sdf.silhouette`: a
        growing object shadows the samples it approaches). ``ds.d`` and ``si.p`` attached (the
        closest point moves with a re-attached SDF point); call after
        :meth:`emitter_geometry`."""
        if self.band is None:
            return em_weight
        with dr.suspend_grad():
            ray = si.spawn_ray(dr.detach(ds.d))
            far = ~dr.isfinite(ds.dist) | mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite)
            tmax = dr.select(far, dr.inf, ds.dist * (1.0 - 1e-4))
            hit, t, m, found = closest_approach(self.sdf, ray.o, ray.d, tmax, mi.Bool(active),
                                                self.opts, self.band.pad(self.sdf))
            p = dr.fma(ray.d, t, ray.o)
            eps = self.band.epsilon(p)
            k = kernel(m, eps)
            on = active & found & ~hit & (k != 0)
            along = dr.dot(p - dr.detach(si.p), ray.d)
        with dr.resume_grad():
            m_att = attached_minimum(self.sdf, si.p, ds.d, along, m, 0.5 * m + 1e-4 * eps, on)
            term = dr.select(on, k * (m_att - dr.detach(m_att)), 0.0)
            return em_weight + dr.detach(em_weight) * term

    def is_sdf(self, si: mi.SurfaceInteraction3f, active) -> mi.Bool:
        m = mi.Bool(False)
        for sh in self.proxies:
            m |= si.shape == mi.ShapePtr(sh)
        return active & si.is_valid() & m

    # ------------------------------------------------------------------ differential
    def reattach(self, ray: mi.Ray3f, si: mi.SurfaceInteraction3f, active):
        """``si`` whose SDF hits carry derivatives w.r.t. the SDF parameters (call under
        ``dr.resume_grad()``; mesh hits are returned unchanged)."""
        on = self.is_sdf(si, active)
        o, d = dr.detach(ray.o), dr.detach(ray.d)
        t = reattach_t(self.sdf, o, d, dr.detach(si.t), on)
        p = mi.Point3f(dr.fma(d, t, o))
        n = normal(self.sdf, p, -d)
        # at a crease the stencil straddles two faces: the normal's derivative is a spike of
        # height ~1/h that averages to the shading jump's moving-edge term. Kept with
        # ``creases`` (unbiased, and noise for every sample that does not land in it: a box's
        # size gradient under a sky had a standard error of its own size at 32 spp, and a box
        # size fit did not converge); left out by default
        if not self.creases:
            n = dr.select(near_crease(self.sdf, p, n), dr.detach(n), n)
        s = self._interaction(ray, t, p, n, si.shape)
        s.t = dr.detach(si.t)
        return dr.select(on, s, si)

    def reattach_sampled(self, ray: mi.Ray3f, si: mi.SurfaceInteraction3f, wo: mi.Vector3f, active):
        """``(si_d, wo_d)`` for re-evaluating a BSDF sample ``wo`` (local to ``si``) with SDF
        shape derivatives: ``si`` re-attached (:meth:`reattach`) and the sampled direction
        held fixed in *world* space, so that a turning normal changes the BSDF value. Held in
        the local frame it would turn with the surface: V4 under an environment it reaches by
        BSDF sampling alone would get a zero radius gradient (finite differences: 0.039)."""
        si_d = self.reattach(ray, si, active)
        return si_d, si_d.to_local(dr.detach(si.to_world(wo)))

    @staticmethod
    def emitter_geometry(si: mi.SurfaceInteraction3f, ds: mi.DirectionSample3f, em_weight, active):
        """Re-attach ``ds.d`` and the ``1 / dist^2`` (and, for area lights, the emitter-side
        cosine) factor of ``em_weight`` to the (attached) point ``si.p``; values unchanged.
        Directional and environment samples depend on the direction only: they are told by
        their emitter's ``Infinite`` flag, as a directional light's samples carry a finite
        ``dist`` (twice the scene's radius; by that alone a sun would be a point light, with a
        gradient 2.2x too large). ``common.sample_emitter`` evaluates the emitter at the
        detached point in SDF scenes, so that a point light's own ``1 / dist^2`` is not
        counted twice."""
        infinite = mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite)
        finite = active & ~infinite & dr.isfinite(ds.dist) & (ds.dist > 0)
        v = mi.Vector3f(dr.detach(ds.p)) - si.p
        dist2 = dr.squared_norm(v)
        ok = finite & (dist2 > 0)
        inv = dr.rsqrt(dr.select(ok, dist2, 1.0))
        d_att = dr.select(ok, v * inv, dr.detach(ds.d))
        geo = dr.select(ok, 1.0 / dr.select(ok, dist2, 1.0), 1.0)
        area = ok & ~ds.delta
        cos_l = dr.abs(dr.dot(dr.detach(ds.n), d_att))
        geo = dr.select(area, geo * cos_l, geo)
        geo_d = dr.detach(geo)
        rel = dr.select(geo_d > 0, geo / dr.select(geo_d > 0, geo_d, 1.0), 1.0)
        ds.d = dr.replace_grad(dr.detach(ds.d), d_att)
        return ds, em_weight * dr.replace_grad(mi.Float(1.0), rel)


__all__ = ["hook", "SDFHook", "TracerOptions"]
