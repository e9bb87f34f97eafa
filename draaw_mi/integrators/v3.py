"""``draaw_v3`` -- physically based path tracer, plain NDF sampling (GO-Draaw "V2M")."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError, suggest
from .common import (
    DraawIntegrator,
    flip_z,
    parse_float,
    propagate_adjoint,
    relative,
    safe_div,
    sample_emitter,
    side_sign,
    with_shared_parameters,
)
from .draaw_lobes import draaw_ndf_sample, draaw_params, draaw_spec_eval

DISTRIBUTIONS = {"ggx": mi.MicrofacetType.GGX, "beckmann": mi.MicrofacetType.Beckmann}


@with_shared_parameters
class DraawV3Integrator(DraawIntegrator):
    r"""
    .. _integrator-draaw_v3:

    draaw V3: physically based path tracer (:monosp:`draaw_v3`)
    ------------------------------------------------------------

    .. pluginparameters::

     * - max_depth
       - |int|
       - Longest path depth (-1: unbounded). 1 renders only directly visible emitters, 2 direct
         lighting, and so on (GO-Draaw "depth"). (Default: 6)

     * - distribution
       - |string|
       - Normal distribution of the ``draaw`` model's specular lobe: ``"ggx"`` (the ``draaw``
         BSDF itself) or ``"beckmann"`` (the thesis' Cook--Torrance variant, same alpha,
         Beckmann D with its Smith G). (Default: ``"ggx"``)

     * - glossy_alpha
       - |float|
       - Near-specular threshold: at a ``draaw`` vertex whose GGX alpha is below it, light
         from area / environment emitters reflected by the *glossy lobe* is found by BSDF
         sampling instead of emitter sampling (the diffuse lobe and delta lights still use
         emitter sampling). At a vertex of another BSDF, the same holds for the whole BSDF
         where its pdf in the mirror direction exceeds that of a GGX lobe of this alpha
         (:func:`near_specular`). 0 gives the textbook NEE-only estimator. (Default: 0.25,
         i.e. roughness < 0.5)

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

    The accuracy reference of the ladder: the ``draaw`` model of design.md §3 rendered by a
    plain, unbiased path tracer that is easy to check:

    - next-event estimation (one emitter sample with a shadow ray per vertex) and **no MIS**:
      every light path is counted by exactly one strategy, chosen per vertex and lobe before
      sampling. Emitters hit by BSDF-sampled rays count for camera rays, after delta bounces
      and, at near-specular ``draaw`` vertices (``glossy_alpha``), for the glossy lobe, whose
      light emitter sampling would find only with vanishing probability (with NEE alone a
      roughness-0.05 metal reflecting a sky stays black at any practical spp: unbiased, but
      heavy-tailed). Other BSDFs (Mitsuba's ``roughconductor``, ``principled``, ... in XML
      scenes) have no lobe V3 can split off: at their near-specular vertices (pdf in the
      mirror direction above a GGX lobe of alpha ``glossy_alpha``; a property of the vertex,
      not of the sample, so the choice keeps the estimator unbiased) all of their light from
      area / environment emitters is found by BSDF sampling. The emission found by a BSDF
      sample is evaluated in the same loop iteration (one-step look-ahead), so the path-replay
      adjoint can weight it by the glossy lobe alone;
    - BSDF sampling of ``draaw`` materials done by the integrator: a mixture of cosine
      hemisphere sampling and *plain* NDF sampling (``D(m) cos(theta_m)``, not the visible
      NDF), with the same lobe-selection probability as the BSDF; any other Mitsuba BSDF
      (dielectric, roughconductor, ...) is sampled through its own ``sample()``;
    - no Russian roulette: every path runs to ``max_depth`` or until it leaves the scene.

    With ``distribution="ggx"`` the ``draaw`` values come from the BSDF's ``eval`` (normal
    maps, ``two_sided`` and ``alpha_min`` included), so the expectation equals ``draaw_v4``
    and Mitsuba's ``path`` (tested per pixel). Other BSDFs: emitter sampling for their
    smooth lobes, BSDF sampling after their delta lobes. With ``"beckmann"`` the diffuse lobe still comes from the
    BSDF (``eval`` restricted to diffuse components) and the integrator evaluates the
    Cook--Torrance lobe itself from the BSDF's attributes (``base_color``, ``roughness``,
    ``metallic``, ``specular``; alpha = sqrt(roughness^4 + 1e-3^2), F0 = lerp(0.08
    specular, base, metallic), F90 = min(1, 50 F0), Beckmann D and its Smith G); that lobe
    ignores a ``draaw`` normal map.

    Differentiable by path replay (primal, forward and backward modes) with respect to BSDF
    and emitter parameters; no geometry / visibility gradients. Scenes with participating
    media are traced by :mod:`draaw_mi.integrators.volume` (density, albedo and ``g``
    gradients too).

    Deviations from GO-Draaw's V2M (``go-draaw-spec.md`` §3.3): GO-Draaw follows the light's
    mirror direction for "reflections" and bounces (view-independent), gathers neighbour
    albedo as indirect "radiance" without pdf or cosine, uses metallic as a scalar F0,
    applies (1 - F) and cos twice to the diffuse term, omits G and the 1/(4 cos cos)
    normalisation, tints every bounce by the light colour and lights shadows with 0.005.
    draaw_v3 uses the physically based ``draaw`` model (F0 = lerp(0.08 specular, base,
    metallic), Smith G, Fresnel-weighted Lambert) and an unbiased estimator; GO-Draaw's
    ``scatter`` and ``directToScatter`` knobs have no role here.

    .. tabs::

        .. code-tab:: python

            'type': 'draaw_v3',
            'max_depth': 8,
            'distribution': 'beckmann'
    """
    PLUGIN = "draaw_v3"

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        dist = props.get("distribution", "ggx")
        if dist not in DISTRIBUTIONS:
            raise ParameterError(f"draaw_v3: distribution={dist!r} is unknown"
                                 f"{suggest(str(dist), DISTRIBUTIONS)}")
        self.distribution = dist
        self.mtype = DISTRIBUTIONS[dist]
        self.glossy_alpha = parse_float(props, "draaw_v3", "glossy_alpha", 0.25)
        if not (0.0 <= self.glossy_alpha <= 1.0):
            raise ParameterError(f"draaw_v3: glossy_alpha={self.glossy_alpha}; expected a "
                                 "value in [0, 1]")

    def _extra_repr(self) -> str:
        return f", distribution={self.distribution!r}, glossy_alpha={self.glossy_alpha}"

    # ------------------------------------------------------------------ BSDF values
    def _eval(self, bsdf, si, wo, active, is_draaw, params, sign, feats, split):
        """``(f, f_glossy)``: ``f * cos(theta_o)`` of the whole BSDF and, for draaw lanes
        with ``split``, of its glossy lobe alone (0 elsewhere)."""
        ctx = mi.BSDFContext()
        if not feats["draaw_materials"]:
            return bsdf.eval(ctx, si, wo, active), mi.Spectrum(0.0)
        act_d = active & is_draaw
        if self.distribution == "ggx" and not split:
            return bsdf.eval(ctx, si, wo, active), mi.Spectrum(0.0)
        f_diffuse = bsdf.eval(_CTX_DIFFUSE, si, wo, act_d)
        if self.distribution == "ggx":
            f_glossy = bsdf.eval(_CTX_GLOSSY, si, wo, act_d)
        else:  # Beckmann: the BSDF's own diffuse lobe + the integrator's Cook-Torrance lobe
            f_glossy = draaw_spec_eval(params, self.mtype, flip_z(si.wi, sign),
                                       flip_z(wo, sign), act_d)
        f = f_diffuse + f_glossy
        if feats["other_materials"]:
            f = dr.select(is_draaw, f, bsdf.eval(ctx, si, wo, active & ~is_draaw))
            f_glossy = dr.select(is_draaw, f_glossy, 0.0)
        return f, f_glossy

    @dr.syntax
    def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):
        primal = mode == dr.ADMode.Primal
        if dr.hint(self.max_depth == 0, mode="scalar"):
            return mi.Spectrum(0.0), mi.Bool(False), self.zero_aovs(), mi.Spectrum(0.0)
        feats = self.features(scene)
        # ---- participating media (draaw_mi.integrators.volume), only when the scene has them
        if dr.hint(feats["media"], mode="scalar"):
            from . import volume  # (60 ms to import: paid by scenes with media only)
            return volume.sample(self, mode, scene, sampler, ray, δL, state_in, active,
                                 russian_roulette=False)
        # ---- end media
        flags = self.ray_flags(feats)
        has_nee = len(scene.emitters()) > 0
        hit_em = feats["hittable_lights"]
        delta_bsdf = feats["delta_bsdfs"]
        draaw_on = feats["draaw_materials"]
        other_on = feats["other_materials"]
        split = draaw_on and hit_em and self.glossy_alpha > 0
        # other BSDFs' near-specular vertices: BSDF sampling finds their light (near_specular)
        split_other = other_on and feats["other_glossy"] and hit_em and self.glossy_alpha > 0
        ctx = mi.BSDFContext()

        # --------------------- Configure loop state ----------------------
        ray = mi.Ray3f(dr.detach(ray))                # Current ray
        depth = mi.UInt32(0)                          # Depth of current vertex
        L = mi.Spectrum(0 if primal else state_in)    # Radiance accumulator
        δL = mi.Spectrum(δL if δL is not None else 0) # Differential/adjoint radiance
        β = mi.Spectrum(1)                            # Path throughput weight
        active = mi.Bool(active)                      # Active SIMD lanes
        ray, si, valid, sdf, aovs = self.first_hit(scene, sampler, ray, active, feats, flags, primal)

        # ------------- Emitters seen directly by the camera -------------
        # (differentiated after the loop: no AD graph may exist while it runs)
        si_cam = si
        cam_active = mi.Bool(active)
        show_em = hit_em and not self.hide_emitters
        if dr.hint(show_em, mode="scalar"):
            Le = si.emitter(scene).eval(si, active)
            L = (L + Le) if primal else (L - Le)

        active &= si.is_valid() & (1 < self.max_depth)

        while dr.hint(active, max_iterations=self.max_depth,
                      label=f"draaw_v3 ({mode.name})"):
            bsdf = si.bsdf(ray)

            # ------------------- Material of this vertex --------------------
            is_draaw = mi.Bool(draaw_on)
            if dr.hint(draaw_on and (other_on or feats["black_surfaces"]), mode="scalar"):
                # (a black surface, a TOML light's: no draaw lane, and with other BSDFs off
                # nothing samples a direction there, so the path ends on it)
                is_draaw = active & bsdf.has_attribute("direct_to_scatter", active)
            sign = mi.Float(1.0)
            params = None
            glossy_split = mi.Bool(False)    # glossy lobe's emitters found by BSDF sampling
            if dr.hint(draaw_on, mode="scalar"):
                sign = side_sign(bsdf, si, active & is_draaw)
                with dr.resume_grad(when=not primal and self.distribution != "ggx"):
                    params = draaw_params(bsdf, si, active & is_draaw)
                if dr.hint(split, mode="scalar"):
                    glossy_split = is_draaw & (dr.detach(params.alpha) < self.glossy_alpha)

            sharp_other = mi.Bool(False)     # another BSDF, near-specular here: no NEE
            if dr.hint(split_other, mode="scalar"):
                sharp_other = near_specular(bsdf, si, self.glossy_alpha, active & ~is_draaw)

            # ------------------ Emitter sampling (no MIS) -------------------
            Lr_dir = mi.Spectrum(0.0)
            if dr.hint(has_nee, mode="scalar"):
                active_em = mi.Bool(active)
                if dr.hint(delta_bsdf, mode="scalar"):
                    active_em &= mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                if dr.hint(split_other and not feats["delta_lights"], mode="scalar"):
                    active_em &= ~sharp_other          # (no light that NEE alone finds)
                with dr.resume_grad(when=not primal):
                    si_em = si
                    if dr.hint(sdf is not None and not primal, mode="scalar"):
                        si_em = sdf.reattach(ray, si, active_em)   # SDF shape derivatives
                    ds, em_w, active_em = sample_emitter(scene, si_em, sampler.next_2d(),
                                                          active_em, primal, sdf)
                    f_em, f_em_glossy = self._eval(bsdf, si_em, si_em.to_local(ds.d), active_em,
                                                   is_draaw, params, sign, feats, split)
                    Lr_dir = β * dr.select(glossy_split & ~ds.delta, f_em - f_em_glossy, f_em) * em_w
                    if dr.hint(split_other, mode="scalar"):
                        Lr_dir = dr.select(sharp_other & ~ds.delta, 0.0, Lr_dir)

            # ------------------ Detached BSDF sampling ----------------------
            s1 = sampler.next_1d()
            s2 = sampler.next_2d()
            wo = mi.Vector3f(0.0, 0.0, 1.0)
            pdf = mi.Float(0.0)
            f = mi.Spectrum(0.0)
            f_glossy = mi.Spectrum(0.0)
            delta = mi.Bool(False)
            if dr.hint(other_on, mode="scalar"):
                bs, bw = bsdf.sample(ctx, si, s1, s2, active & ~is_draaw)
                wo = mi.Vector3f(bs.wo)
                pdf = dr.select(bs.pdf > 0, bs.pdf, 0.0)
                f = bw * pdf                       # f * cos (= weight * pdf; pdf 1 for delta)
                if dr.hint(delta_bsdf, mode="scalar"):
                    delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
                    pdf = dr.select(delta, 1.0, pdf)
                    f = dr.select(delta, bw, f)
            if dr.hint(draaw_on, mode="scalar"):
                act_d = active & is_draaw
                wo_d, pdf_d, _ = draaw_ndf_sample(params, self.mtype, flip_z(si.wi, sign),
                                                  s1, s2, act_d)
                wo_d = flip_z(wo_d, sign)
                if dr.hint(feats["normal_maps"] and self.distribution == "ggx", mode="scalar"):
                    # a normal-mapped BSDF evaluates in its perturbed frame: sampling the NDF
                    # around the unperturbed normal puts near-zero pdfs under its glossy peak
                    # (roughness 0.1, a 17-degree tilt: image means 0.2 to 66 over seeds)
                    mapped = act_d & bsdf.has_attribute("normalmap", act_d)
                    bs_m, _ = bsdf.sample(ctx, si, s1, s2, mapped)
                    wo_d = dr.select(mapped, bs_m.wo, wo_d)
                    pdf_d = dr.select(mapped, dr.select(bs_m.pdf > 0, bs_m.pdf, 0.0), pdf_d)
                f_d, f_d_glossy = self._eval(bsdf, si, wo_d, act_d, is_draaw, params, sign,
                                             feats, split)
                wo = dr.select(is_draaw, wo_d, wo)
                pdf = dr.select(is_draaw, pdf_d, pdf)
                f = dr.select(is_draaw, dr.detach(f_d), f)
                f_glossy = dr.select(is_draaw, dr.detach(f_d_glossy), 0.0)
                delta &= ~is_draaw
            weight = safe_div(f, pdf, active & (pdf > 0))
            ray_next = si.spawn_ray(si.to_world(wo))
            # a path whose throughput reached 0 carries nothing more (else, with max_depth = -1
            # in a closed scene, it bounces on: 28 s for an 8x8 image that 1024 bounces make)
            active_next = active & (dr.max(weight) != 0) & (dr.max(β * weight) > 0)
            si_next = scene.ray_intersect(ray_next, ray_flags=flags, coherent=False,
                                          active=active_next)
            if dr.hint(sdf is not None, mode="scalar"):
                si_next = sdf.intersect(ray_next, si_next, sampler, active_next)

            # ---- Emitters found by BSDF sampling: after delta lobes, by the glossy
            # ---- lobe of near-specular draaw vertices and by near-specular other BSDFs
            # ---- (not sampled by NEE)
            Le_next = mi.Spectrum(0.0)
            if dr.hint(hit_em and (delta_bsdf or split or split_other), mode="scalar"):
                w_em = dr.select(delta | sharp_other, weight,
                                 dr.select(glossy_split, safe_div(f_glossy, pdf, pdf > 0), 0.0))
                em_act = active_next & (dr.max(w_em) != 0)
                with dr.resume_grad(when=not primal):
                    Le_next = β * w_em * si_next.emitter(scene).eval(si_next, em_act)

            L = (L + Lr_dir + Le_next) if primal else (L - Lr_dir - Le_next)

            # ------------------ Differential phase only ------------------
            if dr.hint(not primal, mode="scalar"):
                with dr.resume_grad():
                    si_f, wo_f = si, wo
                    if dr.hint(sdf is not None, mode="scalar"):       # SDF shape derivatives
                        si_f, wo_f = sdf.reattach_sampled(ray, si, wo, active_next)
                    f_ad, f_ad_glossy = self._eval(bsdf, si_f, wo_f, active_next, is_draaw, params,
                                                   sign, feats, split)
                    Lo = Lr_dir + L * relative(f_ad)
                    if dr.hint(hit_em and (split or split_other), mode="scalar"):
                        # (relative(f) is 1 where f is 0: after a delta lobe)
                        Lo += Le_next * relative(dr.select(glossy_split, f_ad_glossy, f_ad))
                    elif dr.hint(hit_em and delta_bsdf, mode="scalar"):
                        Lo += Le_next
                    if dr.hint(sdf is not None, mode="scalar"):       # blended materials' weights
                        Lo = Lo * sdf.pick_weight(si_f, active_next)
                    δL = propagate_adjoint(mode, δL, Lo)

            β *= weight
            depth += 1
            si = si_next
            ray = ray_next
            active = active_next & si.is_valid() & (depth + 1 < self.max_depth)

        if dr.hint(show_em and not primal, mode="scalar"):
            with dr.resume_grad():
                Le = si_cam.emitter(scene).eval(si_cam, cam_active)
                # (separate: the loop's backward_from ran first)
                δL = propagate_adjoint(mode, δL, Le, separate=True)

        return (L if primal else δL), valid, aovs, L


def near_specular(bsdf, si, glossy_alpha: float, active) -> mi.Bool:
    """Whether ``bsdf`` is near-specular at ``si`` for the incident direction ``si.wi``: its
    sampling pdf in the mirror direction exceeds that of a GGX lobe of alpha ``glossy_alpha``
    there, ``D(n) / (4 cos_i) = 1 / (4 pi alpha^2 cos_i)`` (times ``G1`` ~ 1 with visible
    normals). A roughconductor of alpha 0.01 has about 600 times that bound, one of alpha 0.5
    a quarter of it. It depends on the vertex alone (not on a sample), so choosing BSDF
    sampling over emitter sampling by it keeps V3 unbiased. Detached: the choice has no
    gradient.

    >>> import mitsuba as mi
    >>> mi.set_variant("llvm_ad_rgb")
    >>> si = dr.zeros(mi.SurfaceInteraction3f)
    >>> si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    >>> si.wi = mi.Vector3f(0.6, 0.0, 0.8)
    >>> [bool(near_specular(mi.load_dict({"type": "roughconductor", "alpha": a}), si, 0.25,
    ...                     True)[0]) for a in (0.01, 0.2, 0.5)]
    [True, True, False]
    """
    with dr.suspend_grad():
        wi = si.wi
        mirror = mi.Vector3f(-wi.x, -wi.y, wi.z)
        pdf = bsdf.pdf(mi.BSDFContext(), si, mirror, active)
        bound = 1.0 / (4.0 * dr.pi * glossy_alpha * glossy_alpha)
        return active & (dr.abs(wi.z) * pdf > bound)


_CTX_DIFFUSE = mi.BSDFContext(mi.TransportMode.Radiance, mi.BSDFFlags.Diffuse)
_CTX_GLOSSY = mi.BSDFContext(mi.TransportMode.Radiance, mi.BSDFFlags.Glossy)


def register() -> None:
    mi.register_integrator("draaw_v3", lambda props: DraawV3Integrator(props))
