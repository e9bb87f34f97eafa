"""The ``draaw`` model as V3 evaluates and samples it itself: the parameters read through the
BSDF's attributes (with the formulas of ``draaw_mi/materials/draaw_bsdf.py``), the
Cook-Torrance lobe with a chosen NDF (GGX or Beckmann) and its Smith G, and the plain-NDF
sampler (a cosine | ``D(m) cos(theta_m)`` mixture)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..materials.draaw_bsdf import clamp_st
from .common import lum, safe_div

# Smallest GGX alpha of the draaw BSDF (its default ``alpha_min``): alpha = sqrt(r^4 + a_min^2).
ALPHA_MIN = 1e-3


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
