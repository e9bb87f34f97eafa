"""The legacy *Phong family* model of V1 and V2: Lambert + normalised Phong + mirror, built
from the ``draaw`` BSDF's knobs or, for other BSDFs, from their diffuse reflectance; its
evaluation, lobe choice, pdf and sampling."""
from __future__ import annotations

import math
import warnings

import drjit as dr
import mitsuba as mi

from ..materials.draaw_bsdf import DraawBSDF, clamp_st
from .common import INV_PI, INV_TWO_PI, lum
from .features import is_black, scene_shapes

# Largest Phong exponent of the legacy model (roughness below ~0.12 gives this lobe).
PHONG_MAX_EXPONENT = 1e4


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
        # straight-through clamps, as the draaw BSDF's: a plain clip gives no gradient at a
        # bound (reflection and metallic sit at 0 by default, and a fit would never leave them)
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
        # roughness 1 has no gradient (an optimiser at the bound would stay there); the cap on
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


def diffuse_only_bsdfs(scene: mi.Scene) -> list[str]:
    """The BSDFs of ``scene``, other than ``draaw``'s, of which the legacy model keeps the
    diffuse reflectance alone and drops glossy or delta lobes (a ``conductor`` or
    ``dielectric`` renders black, a ``roughconductor`` as a diffuse surface of its reflectance
    seen head-on, a ``plastic`` without its coat), each as ``"id (class)"``; a ``mask``'s
    cut-outs (its null lobe) V1 / V2 follow.

    >>> d = {"type": "scene", "a": {"type": "sphere", "bsdf": {"type": "conductor", "id": "gold"}},
    ...      "b": {"type": "sphere", "bsdf": {"type": "diffuse"}}}
    >>> diffuse_only_bsdfs(mi.load_dict(d))
    ['gold (SmoothConductor)']
    """
    found = []
    for shape in scene_shapes(scene):
        bsdf = shape.bsdf()
        if bsdf is None or isinstance(bsdf, DraawBSDF) or is_black(bsdf) or bsdf.class_name() == "Null":
            continue
        if bsdf.class_name() == "TwoSidedBRDF" and "DraawBSDF[" in str(bsdf):
            continue          # (it forwards the draaw attributes phong_material reads: read as draaw)
        flags = bsdf.flags()      # (not Null: a mask's cut-outs, which V1 / V2 follow)
        if any(mi.has_flag(flags, f) for f in (mi.BSDFFlags.Glossy, mi.BSDFFlags.DeltaReflection,
                                               mi.BSDFFlags.DeltaTransmission)):
            # (a dict's nested BSDF is named "bsdf", an XML one's nothing: named by the shape)
            own = bsdf.id() not in ("", "bsdf") and not bsdf.id().startswith("object_")
            name = (f"{bsdf.id()} ({bsdf.class_name()})" if own else
                    f"the {bsdf.class_name()} of {shape.id() or 'an unnamed shape'}")
            if name not in found:
                found.append(name)
    return found


def say_diffuse_only(integrator, scene) -> None:
    """V1 / V2's :meth:`~.common.DraawIntegrator.before_pass`: a ``RuntimeWarning``, once per
    integrator and set of BSDFs, that the legacy model reads Mitsuba's other BSDFs as their
    diffuse reflectance alone (an XML scene's metals and glass had rendered black without a
    word)."""
    looked = integrator.__dict__.setdefault("_diffuse_only_looked", set())
    if id(scene) in looked:                    # (once per scene: a walk over every shape)
        return
    looked.add(id(scene))
    names = diffuse_only_bsdfs(scene)
    said = integrator.__dict__.setdefault("_said_diffuse_only", set())
    if names and tuple(names) not in said:
        said.add(tuple(names))
        shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
        warnings.warn(f"{integrator.PLUGIN}: the legacy Phong model reads Mitsuba's BSDFs by their diffuse "
                      f"reflectance alone: {shown} lose their glossy or mirror lobes (a smooth conductor or "
                      "dielectric renders black, a rough one as a diffuse surface of its reflectance seen "
                      "head-on); render with v3 or v4, or give them draaw materials",
                      RuntimeWarning, stacklevel=5)
