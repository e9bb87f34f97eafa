"""``draaw_v1`` -- classic ray tracer: Whitted mirrors + Phong + one-bounce gather (GO-Draaw "V1")."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError
from .common import (
    DraawIntegrator,
    emitter_sample_one,
    flip_z,
    parse_int,
    propagate_adjoint,
    relative,
    sample_emitter,
    side_sign,
    with_shared_parameters,
)
from .phong import say_diffuse_only, mirror_dir, phong_eval, phong_material

# Light from every emitter individually up to this many emitters (else one random emitter).
MAX_UNROLLED_EMITTERS = 8
MAX_SCATTER = 64                 # gather rays per shading point at most (unrolled)


@with_shared_parameters
class DraawV1Integrator(DraawIntegrator):
    r"""
    .. _integrator-draaw_v1:

    draaw V1: classic ray tracer (:monosp:`draaw_v1`)
    ---------------------------------------------------

    .. pluginparameters::

     * - max_depth
       - |int|
       - Longest path depth (-1: unbounded): 1 shows emitters only, 2 adds direct light,
         3 adds the one-bounce gather; each further level allows one more mirror
         reflection (GO-Draaw "depth"). (Default: 6)

     * - scatter
       - |int|
       - Cosine-weighted gather rays per shading point (GO-Draaw "scatter"); each collects
         the direct light reflected by the surface it hits. 0 disables indirect light. At
         most 64: each ray is unrolled into the kernel (64 compile in ~7 s; more spp gather
         more). (Default: 4)

     * - rr_depth
       - |int|
       - Accepted as Mitsuba's integrators take it (a scene's ``rr_depth`` loads), and
         checked (>= 1); this version has no Russian roulette. (Default: 5)

     * - hide_emitters
       - |bool|
       - Do not show directly visible emitters (area emitters are skipped, the environment
         is transparent), as Mitsuba's ``path``. (Default: |false|)

     * - aovs
       - |string|
       - Comma-separated AOVs: ``depth``, ``depth_log``, ``normal``, ``albedo`` or ``all``
         (see ``draaw_mi.integrators.common``). (Default: none)

     * - medium_steps
       - |int|
       - Scenes with media: march steps per medium segment, at a random offset
         (:mod:`~draaw_mi.integrators.volume_march`: single scattering, biased by design;
         more steps, less bias). (Default: 12)

    The cheap rung of the ladder. At every shading point of a Whitted-style mirror chain
    (camera ray, then perfect mirror reflections):

    - emitted radiance of the surface hit;
    - direct light from **every** emitter (one sample and one shadow ray each; above
      8 emitters, one emitter picked at random) through the legacy Lambert + normalised Phong
      model of ``draaw_v2`` (exponent from roughness, see
      :class:`~draaw_mi.integrators.phong.PhongMaterial`);
    - ``scatter`` cosine-weighted gather rays: indirect diffuse light from the direct light
      reflected (Lambert + Phong, one random emitter sample) by the surfaces they hit, times
      the local diffuse albedo and ``direct_to_scatter``;
    - a perfect mirror reflection weighted by ``reflection`` (tinted for metals), followed
      recursively up to ``max_depth``.

    Biased by design: transport is truncated after one diffuse bounce (no light from emitters
    seen by gather rays, no glossy indirect light, no caustics), so V1 is darker than V2-V4.
    Other BSDFs act as Lambertian with their diffuse reflectance clipped to [0, 1] (see
    ``draaw_v2``: glass renders black, ``roughconductor`` white).

    Differentiable by path replay (primal, forward and backward modes) with respect to the
    ``draaw`` knobs, other BSDFs' diffuse reflectance and emitter parameters.

    Deviations from GO-Draaw's V1 (``go-draaw-spec.md`` §3.1): GO-Draaw never lights the
    albedo (direct light is an additive light-coloured highlight ``I^2 max(0, N.L) Lc^2``),
    follows the light's mirror direction for reflections and bounces, gathers neighbour
    *albedo* as if it were radiance and mixes terms with ``directToScatter`` in ways that do
    not conserve energy, and darkens shadows to a constant 0.005. draaw_v1 keeps the
    structure (direct light + gather + mirror recursion) with physically meaningful terms:
    lit Lambert + Phong, view mirror direction, gathered *radiance*, pdf-correct cosine
    sampling.

    .. tabs::

        .. code-tab:: python

            'type': 'draaw_v1',
            'max_depth': 4,
            'scatter': 8
    """
    READS_NORMAL_MAPS = False          # (the Phong model: common.DraawIntegrator.ray_flags)
    DIFFERENTIATES_MEDIA = False       # (volume_march: a primal single-scattering march)
    PLUGIN = "draaw_v1"
    before_pass = staticmethod(say_diffuse_only)

    def __init__(self, props: mi.Properties):
        self.scatter = parse_int(props, self.PLUGIN, "scatter", 4, 0)
        if self.scatter > MAX_SCATTER:   # (each gather ray is unrolled into the kernel)
            raise ParameterError(f"{self.PLUGIN}: scatter={self.scatter}; expected an integer in "
                                 f"[0, {MAX_SCATTER}] (each gather ray enters the kernel: 64 take ~7 s "
                                 "to compile, 256 ~90 s; more samples per pixel gather more)")
        # media scenes: march steps per medium segment (draaw_mi.integrators.volume_march)
        self.medium_steps = parse_int(props, self.PLUGIN, "medium_steps", 12, 1)
        super().__init__(props)

    def _extra_repr(self) -> str:
        return f", scatter={self.scatter}"

    # ------------------------------------------------------------------ direct light
    def _direct(self, scene, sampler, si, mat, wi, sign, active, primal, every_emitter, sdf=None):
        """Reflected direct light at ``si`` (call under resume_grad in the adjoint)."""
        emitters = scene.emitters()
        L = mi.Spectrum(0.0)
        if len(emitters) == 0:
            return L
        if every_emitter and len(emitters) <= MAX_UNROLLED_EMITTERS:
            for em in emitters:
                ds, em_w, act = emitter_sample_one(em, scene, si, sampler.next_2d(), active, primal,
                                                   sdf)
                fd, fg = phong_eval(mat, wi, flip_z(si.to_local(ds.d), sign), act)
                L += (fd + fg) * em_w
        else:
            ds, em_w, act = sample_emitter(scene, si, sampler.next_2d(), active, primal, sdf)
            fd, fg = phong_eval(mat, wi, flip_z(si.to_local(ds.d), sign), act)
            L += (fd + fg) * em_w
        return L

    def _gather(self, scene, sampler, si, mat, sign, active, primal, feats, flags, sdf=None):
        """``scatter`` cosine-weighted rays collecting direct light one bounce away."""
        L = mi.Spectrum(0.0)
        for _ in range(self.scatter):
            wo = flip_z(mi.warp.square_to_cosine_hemisphere(sampler.next_2d()), sign)
            ray_g = si.spawn_ray(si.to_world(wo))
            with dr.suspend_grad():
                si_g = scene.ray_intersect(ray_g, ray_flags=flags, coherent=False, active=active)
                if sdf is not None:
                    si_g = sdf.intersect(ray_g, si_g, sampler, active)
            act_g = active & si_g.is_valid()
            bsdf_g = si_g.bsdf(ray_g)
            sign_g = side_sign(bsdf_g, si_g, act_g)
            mat_g = phong_material(bsdf_g, si_g, act_g, feats)
            L += self._direct(scene, sampler, si_g, mat_g, flip_z(si_g.wi, sign_g), sign_g,
                              act_g, primal, every_emitter=False, sdf=sdf)
        # cosine sampling: f cos / pdf = kd (1 - mirror) per ray
        return L * mat.kd * ((1.0 - mat.mirror) * mat.scatter / self.scatter)

    # ------------------------------------------------------------------ integrator
    @dr.syntax
    def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):
        primal = mode == dr.ADMode.Primal
        if dr.hint(self.max_depth == 0, mode="scalar"):
            return mi.Spectrum(0.0), mi.Bool(False), self.zero_aovs(), mi.Spectrum(0.0)
        feats = self.features(scene)
        # ---- participating media: GO-Draaw's single-scattering march, fixed (volume_march)
        if dr.hint(feats["media"], mode="scalar"):
            from . import volume_march  # (60 ms to import: paid by scenes with media only)
            return volume_march.sample(self, mode, scene, sampler, ray, active)
        # ---- end media
        flags = self.ray_flags(feats)
        hit_em = feats["hittable_lights"]
        gather = self.scatter > 0

        # --------------------- Configure loop state ----------------------
        ray = mi.Ray3f(dr.detach(ray))                # Current ray
        depth = mi.UInt32(0)                          # Depth of current vertex
        L = mi.Spectrum(0 if primal else state_in)    # Radiance accumulator
        δL = mi.Spectrum(δL if δL is not None else 0) # Differential/adjoint radiance
        β = mi.Spectrum(1)                            # Mirror-chain throughput
        active = mi.Bool(active)
        ray, si, valid, sdf, aovs = self.first_hit(scene, sampler, ray, active, feats, flags, primal)

        while dr.hint(active, max_iterations=self.max_depth,
                      label=f"draaw_v1 ({mode.name})"):
            bsdf = si.bsdf(ray)
            active_next = active & (depth + 1 < self.max_depth) & si.is_valid()
            sign = side_sign(bsdf, si, active_next)
            wi = flip_z(si.wi, sign)

            with dr.resume_grad(when=not primal):
                # ---------------------- Emission ----------------------
                Le = mi.Spectrum(0.0)
                if dr.hint(hit_em, mode="scalar"):
                    em_active = mi.Bool(active)
                    if dr.hint(self.hide_emitters, mode="scalar"):
                        em_active &= depth > 0
                    Le = β * si.emitter(scene).eval(si, em_active)

                # ------------------ Direct light and gather ------------------
                si_d, wi_d = si, wi
                if dr.hint(sdf is not None and not primal, mode="scalar"):
                    si_d = sdf.reattach(ray, si, active_next)     # SDF shape derivatives
                    wi_d = flip_z(si_d.wi, sign)
                mat = phong_material(bsdf, si, active_next, feats)
                Lr = β * self._direct(scene, sampler, si_d, mat, wi_d, sign, active_next, primal,
                                      every_emitter=True, sdf=sdf)
                if dr.hint(gather, mode="scalar"):
                    act_g = active_next & (depth + 2 < self.max_depth)
                    Lr += β * self._gather(scene, sampler, si, mat, sign, act_g, primal,
                                           feats, flags, sdf)
                f_mirror = mat.mirror * mat.tint

            # ------------------ Mirror recursion ------------------
            L = (L + Le + Lr) if primal else (L - Le - Lr)
            ray_next = si.spawn_ray(si.to_world(flip_z(mirror_dir(wi), sign)))
            β *= dr.detach(f_mirror)
            active_next &= dr.max(β) != 0
            si_next = scene.ray_intersect(ray_next, ray_flags=flags, coherent=False,
                                          active=active_next)
            if dr.hint(sdf is not None, mode="scalar"):
                si_next = sdf.intersect(ray_next, si_next, sampler, active_next)

            if dr.hint(not primal, mode="scalar"):
                with dr.resume_grad():
                    Lo = Lr + L * relative(f_mirror)
                    if dr.hint(sdf is not None, mode="scalar"):       # blended materials' weights
                        Lo = Lo * sdf.pick_weight(si_d, active_next)
                    δL = propagate_adjoint(mode, δL, Le + Lo)

            depth += 1
            active = active_next
            si = si_next
            ray = ray_next

        return (L if primal else δL), valid, aovs, L


def register() -> None:
    mi.register_integrator("draaw_v1", lambda props: DraawV1Integrator(props))
