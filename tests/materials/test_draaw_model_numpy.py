"""The ``draaw`` BSDF's dielectric lobe and coloured metals against an independent numpy
implementation of design.md §3 (the model in ``draaw_mi/materials/draaw_bsdf.py``'s docstring):

    f cos_o = kd / pi * (1 - F(cos_i)) (1 - F(cos_o)) / (1 - F_avg) * cos_o
            + F(<wi, h>) D(h) G1(wi) G1(wo) / (4 cos_i)
    kd = base (1 - metallic), F0 = lerp(0.08 specular, base, metallic), F90 = min(1, 50 F0),
    F_avg = F0 + (F90 - F0) / 21, alpha = sqrt(roughness^4 + alpha_min^2), GGX D, Smith G1.

Existing tests compare the plugin with Mitsuba's ``diffuse`` (specular = metallic = 0) and
``roughconductor`` (white metal, F = 1); these cover what they cannot: Fresnel-weighted
dielectric highlights, the diffuse-Fresnel coupling, coloured F0 and the F90 clamp.
"""
from __future__ import annotations

import zlib

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi  # noqa: F401  (registers the plugin)


def _schlick(f0, f90, c):
    return f0 + (f90 - f0) * np.clip(1 - c, 0, 1)[..., None] ** 5


def _ggx_d(h, a2):
    c2 = h[:, 2] ** 2
    return a2 / (np.pi * (c2 * (a2 - 1) + 1) ** 2)


def _g1(v, h, a2):
    c2 = v[:, 2] ** 2
    tan2 = (1 - c2) / c2
    g = 2 / (1 + np.sqrt(1 + a2 * tan2))
    return np.where(np.sum(v * h, 1) * v[:, 2] > 0, g, 0.0)


def model(base, roughness, metallic, specular, wi, wo, alpha_min=1e-3, f90_clamp=True, coupling=True):
    """numpy f * cos(theta_o), (N, 3), for local directions in the upper hemisphere
    (``f90_clamp`` / ``coupling`` False: the model without those parts, to show they matter)."""
    base = np.asarray(base, float)
    f0 = (1 - metallic) * 0.08 * specular + metallic * base
    f90 = np.minimum(1.0, 50 * f0) if f90_clamp else np.ones(3)
    kd = base * (1 - metallic)
    f_avg = f0 + (f90 - f0) / 21
    ci, co = wi[:, 2], wo[:, 2]
    couple = (1 - _schlick(f0, f90, ci)) * (1 - _schlick(f0, f90, co)) / (1 - f_avg) if coupling else 1.0
    diffuse = kd / np.pi * couple * co[:, None]
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    a2 = roughness ** 4 + alpha_min ** 2
    spec = _schlick(f0, f90, np.sum(wi * h, 1)) * (_ggx_d(h, a2) * _g1(wi, h, a2) * _g1(wo, h, a2) / (4 * ci))[:, None]
    return diffuse + spec


def _directions(rng, n):
    """Upper-hemisphere directions, half of them clustered near the mirror direction of wi so
    that the highlight is sampled too."""
    def hemi(k):
        v = rng.normal(size=(k, 3))
        v[:, 2] = np.abs(v[:, 2]) + 0.05
        return v / np.linalg.norm(v, axis=1, keepdims=True)
    wi = hemi(n)
    wo = hemi(n)
    near = wi * np.array([-1, -1, 1]) + rng.normal(scale=0.15, size=(n, 3))
    near[:, 2] = np.abs(near[:, 2]) + 0.02
    near /= np.linalg.norm(near, axis=1, keepdims=True)
    wo[: n // 2] = near[: n // 2]
    return wi, wo


def _plugin_eval(props, wi, wo):
    bsdf = mi.load_dict({"type": "draaw", **props})
    n = len(wi)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*[wi[:, k].astype(np.float32) for k in range(3)])
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    si.uv = mi.Point2f(0.5, 0.5)
    wo_m = mi.Vector3f(*[wo[:, k].astype(np.float32) for k in range(3)])
    return np.array(bsdf.eval(mi.BSDFContext(), si, wo_m), dtype=np.float64).T      # (3, N) -> (N, 3)


CASES = {
    # name: (base_color, roughness, metallic, specular)
    "dielectric_rough": ([0.8, 0.3, 0.1], 0.6, 0.0, 0.5),
    "dielectric_glossy_high_specular": ([0.2, 0.5, 0.9], 0.25, 0.0, 1.0),
    "dielectric_no_specular_f90_zero": ([0.7, 0.7, 0.2], 0.4, 0.0, 0.0),
    "coloured_metal": ([0.95, 0.64, 0.54], 0.35, 1.0, 0.5),
    "coloured_metal_dark_channel": ([0.9, 0.5, 0.004], 0.5, 1.0, 0.5),    # F0 = 0.004: F90 = 0.2
    "half_metal": ([0.3, 0.8, 0.4], 0.45, 0.5, 0.7),
    "near_mirror_alpha_clamp": ([0.6, 0.6, 0.6], 0.03, 0.0, 0.5),
    # (base, roughness, metallic, specular, alpha_min): the clamp set on the material, not 1e-3
    "near_mirror_own_alpha_min": ([0.6, 0.6, 0.6], 0.05, 1.0, 0.5, 0.05),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_eval_matches_numpy_model(case):
    base, rough, metal, spec, *own = CASES[case]
    # (a fixed seed per case: hash() of a string changes with every interpreter)
    rng = np.random.default_rng(zlib.crc32(case.encode()))
    wi, wo = _directions(rng, 4000)
    props = {"base_color": {"type": "rgb", "value": base}, "roughness": rough, "metallic": metal, "specular": spec}
    if own:
        props["alpha_min"] = own[0]
    got = _plugin_eval(props, wi, wo)
    want = model(base, rough, metal, spec, wi, wo, **({"alpha_min": own[0]} if own else {}))
    assert np.isfinite(got).all()
    scale = np.abs(want).max()
    assert scale > 0.05                                   # the case exercises a visible lobe
    err = np.abs(got - want)
    # float32 plugin vs float64 numpy: relative 1e-3, absolute 1e-5 of the lobe's peak
    assert np.all(err <= 1e-3 * np.abs(want) + 1e-5 * scale), (case, err.max(), np.argmax(err.max(1)))


@pytest.mark.parametrize("case,variant", [("coloured_metal_dark_channel", {"f90_clamp": False}),
                                          ("dielectric_no_specular_f90_zero", {"f90_clamp": False}),
                                          ("dielectric_rough", {"coupling": False}),
                                          ("near_mirror_own_alpha_min", {"alpha_min": 1e-3})])
def test_the_comparison_sees_f90_clamp_and_coupling(case, variant):
    """The same comparison against the model without the F90 clamp, without the diffuse-
    Fresnel coupling or with the default alpha_min instead of the material's fails clearly:
    the test can tell these parts of §3 apart."""
    base, rough, metal, spec, *own = CASES[case]
    wi, wo = _directions(np.random.default_rng(5), 2000)
    props = {"base_color": {"type": "rgb", "value": base}, "roughness": rough, "metallic": metal, "specular": spec}
    if own:
        props["alpha_min"] = own[0]
    got = _plugin_eval(props, wi, wo)
    wrong = model(base, rough, metal, spec, wi, wo, **variant)
    assert np.abs(got - wrong).max() > 0.01 * np.abs(got).max()
