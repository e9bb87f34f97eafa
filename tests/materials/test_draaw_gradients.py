"""Gradients of the draaw BSDF through Mitsuba's `prb` integrator agree with central finite
differences of the same renders (common random numbers, several seeds, within 3 standard
errors), for roughness, metallic, specular and base_color (design.md §3; guide §2, pitfall 13).
"""
from __future__ import annotations

import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

from _draaw_helpers import cornell

RES, DEPTH = 32, 3


def _scene(material):
    return cornell(RES, DEPTH, integrator="prb", override={"type": "draaw", **material})


def _value(v):
    """A (directional) scalar from a parameter gradient: Float -> float, Color3f -> sum."""
    return float(np.sum(np.array(v, dtype=np.float64)))


def ad_vs_fd(scene, key, seeds, spp, h):
    """(AD per seed, FD per seed) of the image mean w.r.t. params[key] (all channels at once
    for a colour)."""
    p = mi.traverse(scene)
    v0 = type(p[key])(p[key])
    ad, fd = [], []
    for seed in seeds:
        dr.enable_grad(p[key])
        p.update()
        img = mi.render(scene, p, spp=spp, seed=seed, seed_grad=seed + 7919)
        dr.backward(dr.mean(img, axis=None))
        ad.append(_value(dr.grad(p[key])))
        dr.disable_grad(p[key])
        dr.clear_grad(p[key])
        vals = []
        for sign in (+1.0, -1.0):
            p[key] = v0 + sign * h
            p.update()
            vals.append(dr.mean(mi.render(scene, spp=spp, seed=seed), axis=None).item())
        p[key] = type(v0)(v0)
        p.update()
        fd.append((vals[0] - vals[1]) / (2.0 * h))
    return np.array(ad), np.array(fd)


DIELECTRIC = {"base_color": [0.7, 0.6, 0.5], "roughness": 0.4, "metallic": 0.3, "specular": 0.5}
METAL = {"base_color": [0.9, 0.8, 0.6], "roughness": 0.3, "metallic": 1.0}

CASES = [
    # (material, parameter, fd step, spp)
    (DIELECTRIC, "roughness", 0.02, 128),
    (DIELECTRIC, "metallic", 0.02, 64),
    (DIELECTRIC, "specular", 0.05, 64),
    (DIELECTRIC, "base_color", 0.02, 64),
    (METAL, "roughness", 0.02, 256),
]


@pytest.mark.parametrize("material,name,h,spp", CASES,
                         ids=[f"{'metal' if c[0] is METAL else 'dielectric'}-{c[1]}" for c in CASES])
def test_prb_gradient_matches_finite_differences(material, name, h, spp):
    scene = _scene(material)
    key = f"mat.{name}.value"
    ad, fd = ad_vs_fd(scene, key, seeds=range(6), spp=spp, h=h)
    assert np.all(np.isfinite(ad)) and np.all(np.isfinite(fd))
    k = len(ad)
    se = np.sqrt(ad.var(ddof=1) / k + fd.var(ddof=1) / k)
    print(f"{key}: AD {ad.mean():+.6f} +- {ad.std(ddof=1) / np.sqrt(k):.6f}  "
          f"FD {fd.mean():+.6f} +- {fd.std(ddof=1) / np.sqrt(k):.6f}  z {(ad.mean() - fd.mean()) / se:+.2f}")
    assert abs(ad.mean() - fd.mean()) <= 3.0 * se, (key, ad, fd)
    # the comparison has power: the noise is small against the gradient itself
    assert se < 0.25 * abs(fd.mean()), (key, ad, fd)


def _grad_at(scene, key, value, seed=1, spp=16):
    p = mi.traverse(scene)
    v0 = type(p[key])(p[key])
    p[key] = dr.opaque(mi.Float, value)
    dr.enable_grad(p[key])
    p.update()
    img = mi.render(scene, p, spp=spp, seed=seed, seed_grad=seed + 1)
    dr.backward(dr.mean(img, axis=None))
    g = _value(dr.grad(p[key]))
    dr.disable_grad(p[key])
    dr.clear_grad(p[key])
    p[key] = v0
    p.update()
    return np.array(img), g


@pytest.mark.parametrize("key,outside,bound", [("mat.roughness.value", 1.3, 1.0),
                                               ("mat.metallic.value", -0.2, 0.0)])
def test_out_of_range_value_has_the_bounds_gradient(key, outside, bound):
    """Values pushed out of range by an optimiser are clamped when evaluated, with a
    straight-through gradient (design.md §3 / module doc): the render and the gradient are
    those at the bound, and the gradient is finite and non-zero (an optimiser on a bound is
    not stuck)."""
    scene = _scene(DIELECTRIC)
    img_out, g_out = _grad_at(scene, key, outside)
    img_b, g_b = _grad_at(scene, key, bound)
    assert np.all(np.isfinite(img_out)) and np.isfinite(g_out)
    np.testing.assert_array_equal(img_out, img_b)
    assert g_out != 0.0
    np.testing.assert_allclose(g_out, g_b, rtol=1e-4)


def test_clamped_value_renders_like_the_bound():
    """roughness = 1.3 set through traverse renders exactly like roughness = 1."""
    scene = _scene(DIELECTRIC)
    p = mi.traverse(scene)
    p["mat.roughness.value"] = dr.opaque(mi.Float, 1.3)
    p.update()
    a = np.array(mi.render(scene, spp=8, seed=3))
    p["mat.roughness.value"] = dr.opaque(mi.Float, 1.0)
    p.update()
    b = np.array(mi.render(scene, spp=8, seed=3))
    np.testing.assert_array_equal(a, b)
