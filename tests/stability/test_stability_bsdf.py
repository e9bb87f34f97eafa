"""Stability of the draaw BSDF at the edges of its domain: finite values, pdfs, weights and
gradients, and the documented behaviour (zero below the horizon, energy <= 1)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from stability_helpers import bsdf_si, fast_math

N = 4096


def _dirs(kind: str, rng) -> np.ndarray:
    u = rng.random((N, 2))
    phi = 2 * np.pi * u[:, 0]
    if kind == "hemisphere":
        ct = u[:, 1]
    elif kind == "grazing":
        ct = np.full(N, 1e-6)
    elif kind == "normal":
        return np.tile([0.0, 0.0, 1.0], (N, 1))
    elif kind == "below":
        ct = -u[:, 1]
    elif kind == "exact_horizon":
        ct = np.zeros(N)
    st = np.sqrt(np.maximum(0, 1 - ct ** 2))
    return np.stack([st * np.cos(phi), st * np.sin(phi), ct], 1)


def _bsdf(**kw):
    d = {"type": "draaw", "base_color": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    d.update(kw)
    return mi.load_dict(d)


def _all(bsdf, wi, wo, s1, s2):
    ctx = mi.BSDFContext()
    si = bsdf_si(len(wi), wi)
    wo_v = mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2])
    f, pdf = bsdf.eval_pdf(ctx, si, wo_v)
    bs, w = bsdf.sample(ctx, si, mi.Float(s1), mi.Point2f(s2[:, 0], s2[:, 1]))
    return [np.array(x) for x in (f, pdf, bs.pdf, w, bs.wo)]


CASES = [
    # (name, bsdf kwargs, wi kind, wo kind, expected)
    ("roughness_0", {"roughness": 0.0, "metallic": 1.0}, "hemisphere", "hemisphere", "finite"),
    ("roughness_1e-8", {"roughness": 1e-8, "metallic": 0.5}, "hemisphere", "hemisphere", "finite"),
    ("roughness_1", {"roughness": 1.0, "metallic": 0.0}, "hemisphere", "hemisphere", "finite"),
    ("grazing_wi", {"roughness": 0.05, "metallic": 1.0}, "grazing", "hemisphere", "finite"),
    ("grazing_wo", {"roughness": 0.05, "metallic": 0.0}, "hemisphere", "grazing", "finite"),
    ("exact_horizon", {"roughness": 0.5}, "exact_horizon", "hemisphere", "zero"),
    ("below_horizon_wi", {"roughness": 0.5}, "below", "hemisphere", "zero"),
    ("below_horizon_wo", {"roughness": 0.5}, "hemisphere", "below", "zero_eval"),
    ("normal_incidence", {"roughness": 0.0, "metallic": 1.0}, "normal", "normal", "finite"),
    ("no_fresnel", {"specular": 0.0, "metallic": 0.0, "roughness": 0.0}, "hemisphere", "hemisphere", "finite"),
    ("black_metal", {"metallic": 1.0, "base_color": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}, "hemisphere",
     "hemisphere", "finite"),
]


@pytest.mark.parametrize("fm", [True, False], ids=["fastmath", "nofastmath"])
@pytest.mark.parametrize("name,kw,wik,wok,expected", CASES, ids=[c[0] for c in CASES])
def test_bsdf_edge_cases(name, kw, wik, wok, expected, fm):
    rng = np.random.default_rng(len(name))
    with fast_math(fm):
        bsdf = _bsdf(**kw)
        wi, wo = _dirs(wik, rng), _dirs(wok, rng)
        f, pdf, spdf, w, swo = _all(bsdf, wi, wo, rng.random(N), rng.random((N, 2)))
    for arr, label in ((f, "eval"), (pdf, "pdf"), (spdf, "sample pdf"), (w, "weight"), (swo, "sampled wo")):
        assert np.isfinite(arr).all(), f"{name}: non-finite {label}"
    assert (pdf >= 0).all() and (f >= 0).all() and (w >= 0).all()
    if expected == "zero":               # light arriving from below (or exactly along) the surface
        assert np.all(f == 0) and np.all(pdf == 0) and np.all(w == 0)
    if expected == "zero_eval":
        assert np.all(f == 0) and np.all(pdf == 0)
    # documented: energy conservation, the albedo (mean sample weight) of a white material <= 1
    albedo = w.mean(axis=1)
    tol = 4 * w.std(axis=1) / np.sqrt(w.shape[1]) + 1e-3
    assert np.all(albedo <= 1.0 + tol), f"{name}: albedo {albedo} > 1"


def test_wi_equals_minus_wo():
    rng = np.random.default_rng(3)
    wi = _dirs("hemisphere", rng)
    f, pdf, *_ = _all(_bsdf(roughness=0.0, metallic=1.0), wi, -wi, rng.random(N), rng.random((N, 2)))
    assert np.all(f == 0) and np.all(pdf == 0)


@pytest.mark.parametrize("param,value", [("roughness", 0.0), ("roughness", 1.0), ("metallic", 0.0),
                                         ("metallic", 1.0), ("specular", 0.0)])
def test_gradients_at_parameter_bounds_are_finite(param, value):
    bsdf = _bsdf(roughness=0.3, metallic=0.5)
    p = mi.traverse(bsdf)
    key = f"{param}.value"
    p[key] = value
    dr.enable_grad(p[key])
    p.update()
    rng = np.random.default_rng(1)
    wi, wo = _dirs("hemisphere", rng), _dirs("hemisphere", rng)
    si = bsdf_si(N, wi)
    f = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo[:, 0], wo[:, 1], wo[:, 2]))
    dr.backward(dr.sum(f, axis=None))
    g = np.array(dr.grad(p[key]))
    assert np.isfinite(g).all()
    if (param, value) == ("roughness", 0.0):
        # documented: alpha = sqrt(roughness^4 + alpha_min^2) is flat at roughness 0 (as alpha =
        # roughness^2 is in every metallic/roughness model), so the derivative is exactly 0 there
        assert np.all(g == 0)
    else:
        assert np.any(g != 0)   # the straight-through clamp: an optimiser on a bound is not stuck


@pytest.mark.parametrize("encoding,value", [("unsigned", [0.5, 0.5, 0.5]), ("unsigned", [0.5, 0.5, 0.0]),
                                            ("signed", [0.0, 0.0, -1.0]), ("signed", [0.0, 0.0, 0.0])])
def test_degenerate_normal_maps_fall_back(encoding, value):
    nm = np.tile(np.array(value, np.float32), (2, 2, 1))
    bsdf = _bsdf(normalmap={"type": "bitmap", "data": mi.TensorXf(nm), "raw": True},
                 normalmap_encoding=encoding, roughness=0.2)
    rng = np.random.default_rng(2)
    f, pdf, spdf, w, swo = _all(bsdf, _dirs("hemisphere", rng), _dirs("hemisphere", rng), rng.random(N),
                                rng.random((N, 2)))
    for arr in (f, pdf, spdf, w, swo):
        assert np.isfinite(arr).all()



@pytest.mark.parametrize("encoding,value,match", [
    ("signed", [1e30, 0.0, 1.0], "above 1.01"), ("signed", [np.inf, 0.0, 1.0], "not finite"),
    ("unsigned", [0.5, 1.5, 1.0], "above 1.01"), ("unsigned", [0.5, -0.2, 1.0], "below -0.01"),
    ("unsigned", [np.nan, 0.5, 1.0], "not finite")])
def test_a_normal_map_outside_its_encoding_is_refused_at_load(encoding, value, match):
    """A texel of 1e30 or Inf overflowed the normalisation: 77 of 256 pixels black in V3/V4
    (NaN and zero-length texels fell back to the geometric normal)."""
    nm = np.tile(np.array([0.5, 0.5, 1.0] if encoding == "unsigned" else [0.0, 0.0, 1.0], np.float32),
                 (4, 4, 1))
    nm[1, 2] = value
    with pytest.raises(Exception, match=rf"normalmap=.*{match}"):
        _bsdf(normalmap={"type": "bitmap", "data": mi.TensorXf(nm), "raw": True},
              normalmap_encoding=encoding)
    nm[1, 2] = [1.003, -0.002, 1.0]                 # resampling overshoot: accepted (both encodings)
    _bsdf(normalmap={"type": "bitmap", "data": mi.TensorXf(nm), "raw": True}, normalmap_encoding=encoding)
