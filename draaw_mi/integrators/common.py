"""Machinery shared by the ``draaw_v1`` .. ``draaw_v4`` integrators.

* :class:`DraawIntegrator` -- the common base (a Mitsuba ``RBIntegrator``, i.e. path-replay
  differentiable): property validation, the AOV outputs and the per-render feature flags.
* Emitter sampling with a differentiable re-evaluation of the emitted radiance.
* The legacy *Phong family* model of V1/V2 (Lambert + normalised Phong + mirror), built from
  the ``draaw`` BSDF's knobs or, for other BSDFs, from their diffuse reflectance.
* For V3: the integrator's own plain-NDF sampler of the ``draaw`` model (cosine | ``D(m)
  cos(theta_m)`` mixture, GGX or Beckmann) and the Beckmann Cook-Torrance lobe; the
  parameters are read through the BSDF's attributes with the formulas of
  ``draaw_mi/materials/draaw_bsdf.py``.

AOVs (property ``aovs``, a comma-separated list, or ``"all"``); channel names as in OpenEXR:

=============  ==============================  ===============================================
``depth``      ``depth.Z``                     distance from the camera to the first hit
                                               along the ray (0 on a miss); GO-Draaw "Lin"
``depth_log``  ``depth_log.Z``                 ``ln(1 + depth)`` (0 on a miss); GO-Draaw "Log"
``normal``     ``N.X``, ``N.Y``, ``N.Z``       world-space shading normal (0 on a miss)
``albedo``     ``albedo.R``, ``albedo.G``,     ``draaw``: ``base_color``; other BSDFs: their
               ``albedo.B``                    diffuse reflectance clipped to [0, 1]
=============  ==============================  ===============================================

AOVs are taken at the first surface the camera ray hits (with ``hide_emitters``: the first
one that is not an area emitter) and are not differentiated (their adjoints are ignored).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError, suggest
from ..materials.draaw_bsdf import clamp_st
from .features import detect_features

RBIntegrator = mi.ad.integrators.common.RBIntegrator

AOV_CHANNELS: dict[str, tuple[str, ...]] = {
    "depth": ("depth.Z",),
    "depth_log": ("depth_log.Z",),
    "normal": ("N.X", "N.Y", "N.Z"),
    "albedo": ("albedo.R", "albedo.G", "albedo.B"),
}

INV_PI = 1.0 / math.pi
INV_TWO_PI = 0.5 / math.pi
LUM = (0.2126, 0.7152, 0.0722)
# Smallest GGX alpha of the draaw BSDF (its default ``alpha_min``): alpha = sqrt(r^4 + a_min^2).
ALPHA_MIN = 1e-3
# Largest Phong exponent of the legacy model (roughness below ~0.12 gives this lobe).
PHONG_MAX_EXPONENT = 1e4


def lum(c: mi.Color3f) -> mi.Float:
    """Rec. 709 luminance of an RGB colour."""
    return LUM[0] * c.x + LUM[1] * c.y + LUM[2] * c.z


def mis_weight(pdf_a: mi.Float, pdf_b: mi.Float) -> mi.Float:
    """Power-heuristic weight of strategy ``a`` (detached; 0 where not finite), as
    ``1 / (1 + (b/a)^2)``: squaring the pdfs themselves overflowed above 1.8e19 (a tiny or
    grazing area light) and gave inf / inf, weight 0 instead of 1."""
    ok = pdf_a > 0
    r = pdf_b / dr.select(ok, pdf_a, 1.0)
    w = dr.select(ok, dr.rcp(1.0 + dr.square(r)), 0.0)
    return dr.detach(dr.select(dr.isfinite(w), w, 0.0))


def safe_div(a, b, ok=None):
    """``a / b`` where ``ok`` (default ``b != 0``), else 0; never divides by 0."""
    if ok is None:
        ok = b != 0
    return dr.select(ok, a / dr.select(ok, b, 1.0), 0.0)


def separate_adjoints(mode) -> None:
    """Call between two ``dr.backward_from`` of one ``sample()``: in backward mode, evaluate
    the first one's gradient scatters before the second is traced. In one kernel, Dr.Jit 1.5
    (LLVM, two threads) lost part of a texture's gradient at random: V2's base_color texture
    gave 0.108-0.144 for one seed over six runs, and 0 in some (scalar parameters, a plain
    reduction, were not affected)."""
    if mode == dr.ADMode.Backward:
        dr.eval()


def parse_int(props: mi.Properties, plugin: str, name: str, default: int, low: int,
              allow_minus_one: bool = False) -> int:
    """Read an integer property and check ``value >= low`` (or ``-1`` where allowed)."""
    value = props.get(name, default)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"{plugin}: {name}={value!r}; expected an integer")
    if value < low and not (allow_minus_one and value == -1):
        extra = " or -1 (unbounded)" if allow_minus_one else ""
        raise ParameterError(f"{plugin}: {name}={value}; expected an integer >= {low}{extra}")
    return value


def parse_bool(props: mi.Properties, plugin: str, name: str, default: bool) -> bool:
    """Read a boolean property (the string "false" was read as True by ``bool()``)."""
    value = props.get(name, default)
    if not isinstance(value, bool):
        raise ParameterError(f"{plugin}: {name}={value!r}; expected a boolean (true or false)")
    return value


def parse_float(props: mi.Properties, plugin: str, name: str, default: float) -> float:
    """Read a number property (``True`` was read as 1.0, a string failed in ``float()``)."""
    value = props.get(name, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{plugin}: {name}={value!r}; expected a number")
    return float(value)


def parse_aovs(plugin: str, spec) -> tuple[str, ...]:
    """``"depth, normal"`` / ``"all"`` / ``""`` -> tuple of AOV names (validated, ordered)."""
    if spec is None:
        return ()
    if not isinstance(spec, str):
        raise ParameterError(f"{plugin}: aovs={spec!r}; expected a comma-separated string "
                             f"of {', '.join(AOV_CHANNELS)} or 'all'")
    names = [s.strip() for s in spec.split(",") if s.strip()]
    if names == ["all"]:
        return tuple(AOV_CHANNELS)
    out = []
    for n in names:
        if n not in AOV_CHANNELS:
            raise ParameterError(f"{plugin}: aovs entry {n!r} is unknown"
                                 f"{suggest(n, list(AOV_CHANNELS) + ['all'])}")
        if n not in out:
            out.append(n)
    return tuple(n for n in AOV_CHANNELS if n in out)


class DraawIntegrator(RBIntegrator):
    """Base class of the draaw render versions (not registered itself)."""

    PLUGIN = "draaw"

    def __init__(self, props: mi.Properties):
        parse_int(props, self.PLUGIN, "max_depth", 6, 0, allow_minus_one=True)
        parse_int(props, self.PLUGIN, "rr_depth", 5, 1)
        super().__init__(props)
        self.aovs = parse_aovs(self.PLUGIN, props.get("aovs", ""))
        # SDF sphere-tracer knobs (sdf_epsilon, sdf_max_steps, sdf_relaxation; draaw_mi.sdf)
        from ..sdf.tracer import TracerOptions
        self.sdf_tracer = TracerOptions.from_props(props, self.PLUGIN)

    # ------------------------------------------------------------------ interface
    def aov_names(self) -> list[str]:
        return [c for n in self.aovs for c in AOV_CHANNELS[n]]

    def features(self, scene: mi.Scene) -> dict[str, bool]:
        """Scene features (``detect_features``) plus this integrator's own AOV request."""
        f = detect_features(scene)
        f["aovs"] = bool(self.aovs)
        return f

    def sdf_hook(self, scene: mi.Scene, feats: dict[str, bool]):
        """The scene's SDF hook (``draaw_mi.sdf.integration.SDFHook``) or ``None`` when it has
        no SDF objects (then no SDF code is traced into the kernel)."""
        if not feats.get("sdf"):
            return None
        from ..sdf.integration import hook
        return hook(self, scene, feats)

    def to_string(self) -> str:
        depth = -1 if self.max_depth == 0xFFFFFFFF else self.max_depth
        return (f"{type(self).__name__}[max_depth={depth}, hide_emitters={self.hide_emitters}, "
                f"aovs={list(self.aovs)}{self._extra_repr()}]")

    def _extra_repr(self) -> str:
        return ""

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def ray_flags(feats: dict[str, bool]) -> mi.RayFlags:
        """Surface-interaction fields the scene needs: all of them only for textures / normal
        maps (uv, dp/du); otherwise position, normals and shading frame."""
        if feats["textures"] or feats["normal_maps"]:
            return mi.RayFlags.All
        return mi.RayFlags.ShadingFrame

    def eval_aovs(self, si: mi.SurfaceInteraction3f, bsdf: mi.BSDFPtr, active: mi.Bool,
                  feats: dict[str, bool], cam_origin=None) -> list[mi.Float]:
        """AOV channel values at the camera ray's first hit ``si`` (primal only);
        ``cam_origin``: where the camera ray started, when it may have been continued from a
        hidden emitter (:meth:`trace_camera`): depth is measured from there, not from the
        emitter (or, through a sphere light, from the emitter's far side)."""
        valid = active & si.is_valid()
        t = si.t if cam_origin is None else dr.norm(si.p - cam_origin)
        out: list[mi.Float] = []
        for name in self.aovs:
            if name == "depth":
                out.append(dr.select(valid, t, 0.0))
            elif name == "depth_log":
                out.append(dr.select(valid, dr.log(1.0 + dr.select(valid, t, 0.0)), 0.0))
            elif name == "normal":
                n = si.sh_frame.n
                out += [dr.select(valid, n.x, 0.0), dr.select(valid, n.y, 0.0),
                        dr.select(valid, n.z, 0.0)]
            elif name == "albedo":
                alb = mi.Color3f(0.0)
                if feats["other_materials"]:
                    alb = dr.clip(bsdf.eval_diffuse_reflectance(si, valid), 0.0, 1.0)
                if feats["draaw_materials"]:
                    has = valid & bsdf.has_attribute("albedo", valid)
                    alb = dr.select(has, bsdf.eval_attribute("albedo", si, has), alb)
                alb = dr.select(valid, alb, 0.0)
                out += [alb.x, alb.y, alb.z]
        return out

    def trace_camera(self, scene: mi.Scene, ray: mi.Ray3f, active: mi.Bool,
                     feats: dict[str, bool]):
        """First intersection of the camera rays: ``(ray, pi, valid, cam_origin)``.

        With ``hide_emitters``, area emitters are skipped (as Mitsuba's ``path`` / ``prb``
        do): ``ray`` then starts on the last skipped emitter, and ``cam_origin`` is the camera
        rays' own origin, for depth AOVs (None when nothing can be skipped). ``valid`` (the
        alpha channel) is set where the ray hits a surface, or everywhere when a visible
        environment is shown.
        """
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
        cam_origin = None
        if self.hide_emitters and feats["area_lights"]:
            skip = active & pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711
            si_skip = pi.compute_surface_interaction(ray, mi.RayFlags.Minimal, skip)
            ray_skip = si_skip.spawn_ray(ray.d)
            pi_after = self.skip_area_emitters(scene, ray_skip, True, skip)
            cam_origin = mi.Point3f(ray.o)
            pi = dr.select(skip, pi_after, pi)
            ray = dr.select(skip, ray_skip, ray)
        valid = active & pi.is_valid()
        if feats["environment"] and not self.hide_emitters:
            valid = mi.Bool(active)
        return ray, pi, valid, cam_origin

    def zero_aovs(self) -> list[mi.Float]:
        return [mi.Float(0.0) for _ in self.aov_names()]

    def camera_aovs(self, scene: mi.Scene, ray: mi.Ray3f, active: mi.Bool, feats: dict[str, bool],
                    sdf=None) -> list[mi.Float]:
        """AOVs of the camera ray's first surface, for ``sample()`` bodies that follow the ray
        their own way (through media): the first intersection, a medium's null boundary
        included, as Mitsuba's ``aov`` integrator reports it (a medium has no depth, normal
        or albedo of its own). Nothing is traced when no AOV is asked for."""
        if not self.aovs:
            return []
        ray, pi, _, cam_origin = self.trace_camera(scene, mi.Ray3f(dr.detach(ray)), active, feats)
        si = pi.compute_surface_interaction(ray, ray_flags=self.ray_flags(feats), active=active)
        if sdf is not None:
            si = sdf.intersect(ray, si, None, active)      # (no random numbers: the largest weight)
        return self.eval_aovs(si, si.bsdf(ray), active, feats, cam_origin)


# ---------------------------------------------------------------------------------------
#  Emitters
# ---------------------------------------------------------------------------------------

def sample_emitter(scene: mi.Scene, si: mi.SurfaceInteraction3f, sample: mi.Point2f,
                   active: mi.Bool, primal: bool, sdf=None):
    """Sample one emitter direction with a shadow ray (detached); in the differential phases
    re-evaluate the emitted radiance with AD (call under ``dr.resume_grad(when=not primal)``).

    Returns ``(ds, weight, active)``: ``weight`` = radiance / pdf (0 if occluded);
    ``active`` is cleared where the sample is invalid or occluded. ``sdf``: the scene's SDF
    hook (SDF objects occlude the shadow ray; in the differential phases the sample's
    direction and distance factor follow an SDF point's re-attached position).
    """
    with dr.suspend_grad():
        ds, em_weight = scene.sample_emitter_direction(si, sample, True, active)
    active = active & (ds.pdf != 0.0)
    if sdf is not None:
        blocked = sdf.occluded(si, ds, active)
        active &= ~blocked
        em_weight = dr.select(blocked, 0.0, em_weight)
    if not primal:
        # (with SDFs the point's motion enters through sdf.emitter_geometry instead)
        em_val = scene.eval_emitter_direction(si if sdf is None else dr.detach(si), ds, active)
        em_weight = dr.replace_grad(em_weight, safe_div(em_val, dr.detach(ds.pdf), active))
        if sdf is not None:
            ds, em_weight = sdf.emitter_geometry(si, ds, em_weight, active)
    return ds, em_weight, active


def emitter_sample_one(emitter: mi.Emitter, scene: mi.Scene, si: mi.SurfaceInteraction3f,
                       sample: mi.Point2f, active: mi.Bool, primal: bool, sdf=None):
    """Like :func:`sample_emitter` for one given emitter (used to light from every emitter)."""
    with dr.suspend_grad():
        ds, em_weight = emitter.sample_direction(si, sample, active)
        active = active & (ds.pdf != 0.0)
        occluded = scene.ray_test(si.spawn_ray_to(ds.p), active)
        if sdf is not None:
            occluded |= sdf.occluded(si, ds, active & ~occluded)
        active &= ~occluded
    if not primal:
        em_val = emitter.eval_direction(si if sdf is None else dr.detach(si), ds, active)
        em_weight = dr.replace_grad(em_weight, safe_div(em_val, dr.detach(ds.pdf), active))
        if sdf is not None:
            ds, em_weight = sdf.emitter_geometry(si, ds, em_weight, active)
    return ds, dr.select(active, em_weight, 0.0), active


# ---------------------------------------------------------------------------------------
#  Local frames
# ---------------------------------------------------------------------------------------

def side_sign(bsdf: mi.BSDFPtr, si: mi.SurfaceInteraction3f, active: mi.Bool) -> mi.Float:
    """-1 where a two-sided BSDF is seen from its back (shade in the mirrored frame), else 1."""
    back = active & (mi.Frame3f.cos_theta(si.wi) < 0)
    back &= mi.has_flag(bsdf.flags(), mi.BSDFFlags.BackSide)
    return dr.select(back, -1.0, 1.0)


def flip_z(v: mi.Vector3f, sign: mi.Float) -> mi.Vector3f:
    return mi.Vector3f(v.x, v.y, v.z * sign)


# ---------------------------------------------------------------------------------------
#  Legacy Phong-family model (V1, V2)
# ---------------------------------------------------------------------------------------

class PhongMaterial:
    """Per-lane parameters of the legacy model at a surface point.

    ``kd``      Lambert albedo, ``base_color * (1 - metallic) * (1 - max(ks))``
    ``ks``      Phong albedo, ``lerp(0.08 * specular, base_color, metallic)``
    ``n``       Phong exponent ``2 / alpha^2 - 2`` with ``alpha = sqrt(r^4 + 1e-6)``, <= 1e4
    ``mirror``  mirror weight (``reflection``) and ``tint = lerp(1, base_color, metallic)``
    ``scatter`` weight of indirect diffuse light (``direct_to_scatter``)
    Energy: ``(1 - mirror) (kd + ks) + mirror * tint <= 1`` per channel (base_color <= 1).
    Other BSDFs: ``kd`` = their diffuse reflectance clipped to [0, 1], no Phong, no mirror.
    """

    def __init__(self, kd, ks, n, mirror, tint, scatter):
        self.kd, self.ks, self.n = kd, ks, n
        self.mirror, self.tint, self.scatter = mirror, tint, scatter


def phong_material(bsdf: mi.BSDFPtr, si: mi.SurfaceInteraction3f, active: mi.Bool,
                   feats: dict[str, bool]) -> PhongMaterial:
    """Read the legacy model's parameters (differentiable when AD is on)."""
    kd = mi.Color3f(0.0)
    ks = mi.Color3f(0.0)
    n = mi.Float(1.0)
    mirror = mi.Float(0.0)
    tint = mi.Color3f(1.0)
    scatter = mi.Float(1.0)
    is_draaw = mi.Bool(False)
    if feats["draaw_materials"]:
        is_draaw = active & bsdf.has_attribute("direct_to_scatter", active)
        # straight-through clamps, as the draaw BSDF's: a plain clip gave no gradient at a
        # bound (reflection and metallic sit at 0 by default, and a fit never left them)
        base = clamp_st(bsdf.eval_attribute("base_color", si, is_draaw), 0.0, 1.0)
        rough = clamp_st(bsdf.eval_attribute_1("roughness", si, is_draaw), 0.0, 1.0)
        metal = clamp_st(bsdf.eval_attribute_1("metallic", si, is_draaw), 0.0, 1.0)
        spec = clamp_st(bsdf.eval_attribute_1("specular", si, is_draaw), 0.0, 1.0)
        refl = clamp_st(bsdf.eval_attribute_1("reflection", si, is_draaw), 0.0, 1.0)
        d2s = clamp_st(bsdf.eval_attribute_1("direct_to_scatter", si, is_draaw), 0.0, 1.0)
        ks_d = dr.lerp(mi.Color3f(0.08 * spec), base, metal)
        kd_d = base * (1.0 - metal) * (1.0 - dr.max(ks_d))
        alpha2 = dr.square(dr.square(rough)) + 1e-6          # alpha^2, alpha = sqrt(r^4 + 1e-6)
        # the floor at 0 only absorbs the 1e-6 (-2e-6 at roughness 1): straight through, or
        # roughness 1 had no gradient (an optimiser at the bound stayed there); the cap on
        # sharp lobes stays a plain clip, where the image does not change either
        n_d = dr.minimum(clamp_st(2.0 / alpha2 - 2.0, 0.0, None), PHONG_MAX_EXPONENT)
        kd = dr.select(is_draaw, kd_d, kd)
        ks = dr.select(is_draaw, ks_d, ks)
        n = dr.select(is_draaw, n_d, n)
        mirror = dr.select(is_draaw, refl, mirror)
        tint = dr.select(is_draaw, dr.lerp(mi.Color3f(1.0), base, metal), tint)
        scatter = dr.select(is_draaw, d2s, scatter)
    if feats["other_materials"]:
        other = active & ~is_draaw
        kd_o = dr.clip(bsdf.eval_diffuse_reflectance(si, other), 0.0, 1.0)
        kd = dr.select(other, kd_o, kd)
    return PhongMaterial(kd, ks, n, mirror, tint, scatter)


def phong_lobe(n: mi.Float, cos_r: mi.Float) -> mi.Float:
    """Normalised Phong lobe ``(n + 2) / (2 pi) * max(0, cos_r)^n`` (safe at cos_r <= 0)."""
    ok = cos_r > 0
    c = dr.select(ok, dr.minimum(cos_r, 1.0), 1.0)
    return dr.select(ok, (n + 2.0) * INV_TWO_PI * dr.power(c, n), 0.0)


def mirror_dir(wi: mi.Vector3f) -> mi.Vector3f:
    return mi.Vector3f(-wi.x, -wi.y, wi.z)


def phong_eval(mat: PhongMaterial, wi: mi.Vector3f, wo: mi.Vector3f, active: mi.Bool):
    """(diffuse, glossy) parts of ``f * cos(theta_o)`` of the smooth lobes, each already
    multiplied by ``1 - mirror``; local directions in the upper hemisphere."""
    cos_o = mi.Frame3f.cos_theta(wo)
    ok = active & (mi.Frame3f.cos_theta(wi) > 0) & (cos_o > 0)
    w = (1.0 - mat.mirror) * dr.select(ok, cos_o, 0.0)
    diffuse = mat.kd * (w * INV_PI)
    glossy = mat.ks * (w * phong_lobe(mat.n, dr.dot(mirror_dir(wi), wo)))
    return diffuse, glossy


def phong_lobe_probs(mat: PhongMaterial):
    """Probabilities (diffuse, glossy, mirror) of sampling each lobe (detached)."""
    m = dr.detach(mat.mirror)
    wd = (1.0 - m) * lum(dr.detach(mat.kd)) * dr.detach(mat.scatter)
    wg = (1.0 - m) * lum(dr.detach(mat.ks))
    wm = m * lum(dr.detach(mat.tint))
    total = wd + wg + wm
    ok = total > 0
    inv = dr.select(ok, 1.0 / dr.select(ok, total, 1.0), 0.0)
    return wd * inv, wg * inv, wm * inv


def phong_smooth_pdf(mat: PhongMaterial, p_d, p_g, wi: mi.Vector3f, wo: mi.Vector3f):
    """Solid-angle pdf of the diffuse + glossy part of the lobe mixture."""
    n = dr.detach(mat.n)
    cos_r = dr.dot(mirror_dir(wi), wo)
    pdf_g = dr.select(cos_r > 0, (n + 1.0) * INV_TWO_PI *
                      dr.power(dr.select(cos_r > 0, dr.minimum(cos_r, 1.0), 1.0), n), 0.0)
    pdf_d = mi.warp.square_to_cosine_hemisphere_pdf(wo)
    return p_d * pdf_d + p_g * pdf_g


def phong_sample(mat: PhongMaterial, wi: mi.Vector3f, s1: mi.Float, s2: mi.Point2f):
    """Sample the lobe mixture. Returns ``(wo, is_mirror, pdf_smooth, p_mirror)``: ``wo`` in
    the (upper-hemisphere) local frame; ``pdf_smooth`` is the mixture pdf of smooth lobes."""
    p_d, p_g, p_m = phong_lobe_probs(mat)
    is_mirror = s1 >= p_d + p_g
    is_glossy = (s1 >= p_d) & ~is_mirror
    n = dr.detach(mat.n)
    # glossy: cos^n lobe around the mirror direction
    cos_a = dr.power(dr.maximum(s2.x, 1e-30), 1.0 / (n + 1.0))
    sin_a = dr.safe_sqrt(1.0 - dr.square(cos_a))
    sp, cp = dr.sincos(2.0 * math.pi * s2.y)
    r = mirror_dir(wi)
    wo_g = mi.Frame3f(r).to_world(mi.Vector3f(sin_a * cp, sin_a * sp, cos_a))
    wo_d = mi.warp.square_to_cosine_hemisphere(s2)
    wo = dr.select(is_mirror, r, dr.select(is_glossy, wo_g, wo_d))
    pdf = phong_smooth_pdf(mat, p_d, p_g, wi, wo)
    return wo, is_mirror, pdf, p_m


# ---------------------------------------------------------------------------------------
#  The draaw model, evaluated and NDF-sampled by the integrator (V3)
# ---------------------------------------------------------------------------------------

def schlick(f0, f90, cos_theta):
    m = dr.clip(1.0 - cos_theta, 0.0, 1.0)
    m2 = dr.square(m)
    return f0 + (f90 - f0) * (m2 * m2 * m)


class DraawParams:
    """``kd``, ``f0``, ``f90``, ``alpha`` of the draaw model at a surface point (see
    ``draaw_bsdf.py``): ``kd = base (1 - metallic)``, ``f0 = lerp(0.08 specular, base,
    metallic)``, ``f90 = min(1, 50 f0)``, ``alpha = sqrt(roughness^4 + 1e-3^2)``."""

    def __init__(self, kd, f0, f90, alpha):
        self.kd, self.f0, self.f90, self.alpha = kd, f0, f90, alpha


def draaw_params(bsdf: mi.BSDFPtr, si: mi.SurfaceInteraction3f, active: mi.Bool) -> DraawParams:
    base = clamp_st(bsdf.eval_attribute("base_color", si, active), 0.0, None)
    rough = clamp_st(bsdf.eval_attribute_1("roughness", si, active), 0.0, 1.0)
    metal = clamp_st(bsdf.eval_attribute_1("metallic", si, active), 0.0, 1.0)
    spec = clamp_st(bsdf.eval_attribute_1("specular", si, active), 0.0, 1.0)
    alpha = dr.sqrt(dr.square(dr.square(rough)) + ALPHA_MIN ** 2)
    f0 = dr.lerp(mi.Color3f(0.08 * spec), base, metal)
    return DraawParams(base * (1.0 - metal), f0, dr.minimum(1.0, 50.0 * f0), alpha)


def _half(wi, wo):
    h = wi + wo
    h_len = dr.norm(h)
    ok = h_len > 1e-12
    return dr.select(ok, h / dr.select(ok, h_len, 1.0), mi.Vector3f(0, 0, 1))


def draaw_spec_eval(p: DraawParams, mtype: mi.MicrofacetType, wi: mi.Vector3f,
                    wo: mi.Vector3f, active: mi.Bool) -> mi.Color3f:
    """Cook-Torrance lobe ``F D G / (4 cos_i)`` (= f * cos(theta_o)) of the draaw model with
    NDF ``mtype`` and its Smith G (local directions, upper hemisphere); the diffuse lobe is
    left to the BSDF's own ``eval`` (see ``DraawV3Integrator``)."""
    cos_i = mi.Frame3f.cos_theta(wi)
    cos_o = mi.Frame3f.cos_theta(wo)
    ok = active & (cos_i > 0) & (cos_o > 0)
    h = _half(wi, wo)
    F = schlick(p.f0, p.f90, dr.dot(wi, h))
    distr = mi.MicrofacetDistribution(mtype, p.alpha, False)
    value = F * (distr.eval(h) * distr.G(wi, wo, h) / (4.0 * dr.select(ok, cos_i, 1.0)))
    return dr.select(ok & dr.isfinite(value.x + value.y + value.z), value, 0.0)


def draaw_spec_probability(p: DraawParams, cos_i: mi.Float) -> mi.Float:
    """Probability of the glossy lobe (as the draaw BSDF picks it; depends on wi only)."""
    w_spec = lum(schlick(p.f0, p.f90, cos_i))
    w_diff = lum(p.kd) * (1.0 - w_spec)
    total = w_spec + w_diff
    # clipped into [0, 1]: a base colour above 1 makes w_diff negative (see the draaw BSDF)
    return dr.detach(dr.clip(dr.select(total > 0, w_spec / dr.select(total > 0, total, 1.0), 0.5), 0.0, 1.0))


def draaw_ndf_sample(p: DraawParams, mtype: mi.MicrofacetType, wi: mi.Vector3f,
                     s1: mi.Float, s2: mi.Point2f, active: mi.Bool):
    """Sample the mixture (cosine hemisphere | plain NDF ``D(m) cos(theta_m)``, reflected).

    Returns ``(wo, pdf, glossy)`` (detached, local frame, ``wi`` in the upper hemisphere)."""
    p = DraawParams(*(dr.detach(x) for x in (p.kd, p.f0, p.f90, p.alpha)))
    cos_i = mi.Frame3f.cos_theta(wi)
    p_spec = draaw_spec_probability(p, cos_i)
    glossy = s1 < p_spec
    distr = mi.MicrofacetDistribution(mtype, p.alpha, False)
    m, _ = distr.sample(mi.Vector3f(0, 0, 1), s2)
    wo = dr.select(glossy, mi.reflect(wi, m), mi.warp.square_to_cosine_hemisphere(s2))
    return wo, draaw_ndf_pdf(p, mtype, p_spec, wi, wo, active), glossy


def draaw_ndf_pdf(p: DraawParams, mtype: mi.MicrofacetType, p_spec: mi.Float,
                  wi: mi.Vector3f, wo: mi.Vector3f, active: mi.Bool) -> mi.Float:
    """Mixture pdf of :func:`draaw_ndf_sample` (0 below the horizon)."""
    cos_o = mi.Frame3f.cos_theta(wo)
    ok = active & (mi.Frame3f.cos_theta(wi) > 0) & (cos_o > 0)
    h = _half(wi, wo)
    distr = mi.MicrofacetDistribution(mtype, p.alpha, False)
    dot_oh = dr.abs(dr.dot(wo, h))
    pdf_s = safe_div(distr.pdf(wi, h), 4.0 * dot_oh)
    pdf = (1.0 - p_spec) * mi.warp.square_to_cosine_hemisphere_pdf(wo) + p_spec * pdf_s
    return dr.detach(dr.select(ok & dr.isfinite(pdf), pdf, 0.0))


def relative(f: mi.Color3f) -> mi.Color3f:
    """``dr.replace_grad(1, f / detach(f))`` that is 1 (and has no gradient) where f == 0."""
    fd = dr.detach(f)
    return dr.replace_grad(mi.Color3f(1.0), f / dr.select(fd != 0, fd, 1.0))
