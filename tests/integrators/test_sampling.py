"""Russian roulette of draaw_v4 (draaw_mi/integrators/sampling.py)."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi  # noqa: F401
import drjit as dr
import mitsuba as mi

from draaw_mi.integrators.sampling import roulette, survival_probability


def test_survival_probability():
    q = survival_probability(mi.Float(0.0, 0.05, 0.2, 0.5, 3.0), mi.Float(1.0), 0.25, 0.05)
    assert np.allclose(np.array(q), [0.05, 0.2, 0.8, 1.0, 1.0])
    q = survival_probability(mi.Float(0.1), mi.Float(1.5), 0.25, 0.05)      # eta^2 counts
    assert np.allclose(np.array(q), [0.9])


def _run(b, depth, rr_depth, n=200_000, seed=3):
    rng = mi.PCG32(size=n, initstate=seed)
    beta = mi.Color3f(b, 0.5 * b, 0.1 * b)
    beta2, active = roulette(beta, mi.Float(1.0), mi.UInt32(depth), rr_depth, 0.25, 0.05,
                             rng.next_float32(), mi.Bool(True))
    w = np.array(dr.select(active, beta2.x, 0.0))
    return w, np.array(active)


def test_roulette_keeps_expectation_and_spares_strong_paths():
    w, act = _run(0.05, depth=3, rr_depth=2)           # weak path: q = 0.2
    assert 0.17 < act.mean() < 0.23
    se = w.std() / np.sqrt(w.size)
    assert abs(w.mean() - 0.05) < 4 * se                # unbiased: E[beta'] = beta
    assert np.allclose(w[act], 0.05 / 0.2, rtol=1e-5)
    w, act = _run(0.6, depth=3, rr_depth=2)            # above the threshold: never stopped
    assert act.all() and np.allclose(w, 0.6)
    w, act = _run(0.05, depth=0, rr_depth=2)           # before rr_depth: never stopped
    assert act.all() and np.allclose(w, 0.05)


@pytest.mark.parametrize("depth, rr_depth, stopped", [
    (0, 1, True), (1, 2, True), (0, 2, False), (2, 4, False), (3, 4, True)])
def test_roulette_starts_once_the_path_has_rr_depth_segments(depth, rr_depth, stopped):
    """``depth`` counts the bounces before this one, so the vertex at ``depth`` ends segment
    ``depth + 1``: with ``rr_depth = 2`` (V4's default) the roulette may stop a weak path at
    its second vertex, never at its first (V4's parameter table: "path depth (number of
    segments) from which Russian roulette may stop paths: never on the first bounce")."""
    w, act = _run(0.05, depth=depth, rr_depth=rr_depth, n=20_000)
    if stopped:
        assert 0.15 < act.mean() < 0.25                   # q = 0.2
    else:
        assert act.all() and np.allclose(w, 0.05)


def test_power_selection_follows_the_emitters_power():
    from draaw_mi.bench import suite as ss
    from draaw_mi.integrators.sampling import PowerSelection
    scene = ss.load("many_lights", 8)
    sel = PowerSelection.of(scene)
    assert sel is not None
    pmf = sel.pmf_np
    assert abs(pmf.sum() - 1.0) < 1e-6                        # stored as float32
    strong = pmf > 2.0 * np.median(pmf)
    assert strong.sum() == 4                                  # the four 40x lights
    ratio = pmf[strong].mean() / pmf[~strong].mean()
    assert 25.0 < ratio < 60.0                                # 40x the power, colours vary
    # the pdf looked up from an emitter pointer is its own selection probability
    ptrs = scene.emitters_dr()
    got = np.array(sel.pmf(ptrs, mi.Bool(True)))
    assert np.allclose(got, pmf, rtol=1e-6)
    assert PowerSelection.of(ss.load("metal_018", 8)) is None  # one emitter: uniform is exact


def test_emitter_powers_match_closed_forms():
    """``emitter_powers`` (the mean of ``sample_ray``'s weights) against each light's power:
    a point light's 4 pi I; a spot's I times the integral of Mitsuba's falloff (1 inside the
    beam, linear in the angle out to the cutoff) over its cone, by scipy; an area light's
    pi L A, and pi A times the mean of its radiance texture; an environment is inf. Counting
    a spot as a point light (4 pi I, as before) reads it 25x too bright."""
    from scipy.integrate import quad
    from draaw_mi.integrators.sampling import emitter_powers
    T = mi.ScalarTransform4f
    texture = np.random.default_rng(3).uniform(0.0, 4.0, (8, 8, 3)).astype(np.float32)
    scene = mi.load_dict({
        "type": "scene",
        "point": {"type": "point", "position": [0, 2, 0], "intensity": 3.0},
        "spot": {"type": "spot", "intensity": 5.0, "cutoff_angle": 30.0, "beam_width": 10.0,
                 "to_world": T().look_at(origin=[1, 2, 0], target=[0, 0, 0], up=[0, 0, 1])},
        "panel": {"type": "rectangle", "to_world": T().translate([0, 3, 0]).scale([0.5, 2.0, 1.0]),
                  "emitter": {"type": "area", "radiance": 7.0}},
        "poster": {"type": "rectangle", "to_world": T().translate([3, 0, 0]),
                   "emitter": {"type": "area", "radiance": {"type": "bitmap", "raw": True,
                                                             "bitmap": mi.Bitmap(texture)}}},
        "sky": {"type": "constant", "radiance": 1.0}})
    names = [e.get_shape().id() if e.get_shape() else e.id() for e in scene.emitters()]
    got = dict(zip(names, emitter_powers(scene)))
    c, b = np.radians(30.0), np.radians(10.0)
    falloff = lambda t: (1.0 if t <= b else (c - t) / (c - b)) * np.sin(t)  # noqa: E731
    cone = 2 * np.pi * quad(falloff, 0.0, c, points=[b])[0]
    lum = texture @ np.array([0.2126, 0.7152, 0.0722])
    want = {"point": 4 * np.pi * 3.0, "spot": 5.0 * cone, "panel": np.pi * 7.0 * 4.0,
            "poster": np.pi * 4.0 * lum.mean()}
    for name, w in want.items():
        assert got[name] == pytest.approx(w, rel=0.02), name
    assert got["sky"] == np.inf


def test_power_selection_samples_its_pmf_and_reuses_the_sample():
    """sample_index (a CDF search on the table's own arrays, so a dr.freeze recording can take
    them as inputs) against numpy's searchsorted: same index for every x, and the reused
    sample is x's position inside the chosen interval."""
    from draaw_mi.integrators.sampling import PowerSelection
    scene = mi.load_dict({"type": "scene", "s": {"type": "sphere"},
                          **{f"p{i}": {"type": "point", "position": [i, 3, 0],
                                       "intensity": {"type": "rgb", "value": v}}
                             for i, v in enumerate([1.0, 10.0, 0.5, 3.0, 0.0])}})
    sel = PowerSelection.of(scene)
    assert sel is not None
    x = np.linspace(0, 1, 10001, endpoint=False).astype(np.float32)
    idx, u, pmf = sel.sample_index(mi.Float(x), mi.Bool(True))
    idx, u, pmf = np.array(idx), np.array(u), np.array(pmf)
    cdf = np.array(sel.cdf)
    want = np.minimum(np.searchsorted(cdf, x, side="right"), len(cdf) - 1)
    assert np.array_equal(idx, want)
    p = np.array(sel.pmf_dr)
    from draaw_mi.integrators.sampling import POWER_UNIFORM_SHARE
    # a dark light keeps an even share of the table (its gradient needs samples)
    assert p[4] == pytest.approx(POWER_UNIFORM_SHARE / 5, rel=1e-5)
    np.testing.assert_allclose(p, 0.95 * np.array([1.0, 10.0, 0.5, 3.0, 0.0]) / 14.5 + 0.01, rtol=1e-5)
    assert np.allclose(pmf, p[idx])
    lo = np.concatenate([[0.0], cdf[:-1]])[idx]
    assert np.allclose(u, np.clip((x - lo) / p[idx], 0, 1), atol=1e-4)
    assert (u >= 0).all() and (u < 1).all()


def test_mis_weight_is_the_power_heuristic_without_overflow():
    """w = a^2 / (a^2 + b^2), also for pdfs whose squares overflow float32 (a tiny or grazing
    area light: 1e20 gave inf / inf and a weight of 0 instead of 1)."""
    from draaw_mi.integrators.common import mis_weight
    a = mi.Float([1.0, 1.0, 2.0, 0.0, 1e20, 1e20, 1e-30])
    b = mi.Float([1.0, 0.0, 1.0, 1.0, 1.0, 1e20, 1e-30])
    w = np.array(mis_weight(a, b))
    np.testing.assert_allclose(w, [0.5, 1.0, 0.8, 0.0, 1.0, 0.5, 0.5], rtol=1e-6)


@pytest.mark.parametrize("n", [0.0, 3.0, 20.0])
def test_phong_glossy_samples_follow_their_pdf(n):
    """V1/V2's glossy lobe samples cos^n around the mirror direction: with wi along the normal
    the sampled cosine has the mean (n + 1) / (n + 2) of the pdf (n + 1) / (2 pi) cos^n (an
    exponent off by one in the warp gave 0.667 instead of 0.5 at n = 0), and the pdf returned
    is that density."""
    import drjit as dr
    from draaw_mi.integrators.phong import PhongMaterial, phong_sample
    N = 200_000
    one, zero = mi.Color3f(1.0), mi.Color3f(0.0)
    mat = PhongMaterial(kd=zero, ks=one, n=mi.Float(n), mirror=mi.Float(0.0), tint=one, scatter=mi.Float(1.0))
    rng = np.random.default_rng(int(n))
    u = rng.random((3, N)).astype(np.float32)
    wi = dr.zeros(mi.Vector3f, N) + mi.Vector3f(0, 0, 1)
    wo, is_mirror, pdf, _ = phong_sample(mat, wi, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    cos = np.array(wo.z)
    assert not np.array(is_mirror).any()
    assert abs(cos.mean() - (n + 1) / (n + 2)) < 4 * cos.std() / np.sqrt(N)
    np.testing.assert_allclose(np.array(pdf), (n + 1) / (2 * np.pi) * cos ** n, rtol=2e-4, atol=1e-8)


def test_the_legacy_models_lobes_from_a_draaw_material():
    """V1/V2's Lambert and Phong albedos from a draaw material of metallic 0.5 and a coloured
    base: ks = lerp(0.08 specular, base, metallic), kd = base (1 - metallic) (1 - max(ks))
    (the tests' materials were metallic 0 or 1, where min(ks) and max(ks) agree or kd = 0)."""
    from draaw_mi.integrators.phong import phong_material
    from draaw_mi.integrators.features import FEATURE_NAMES
    base, metal, spec = np.array([0.9, 0.2, 0.1]), 0.5, 0.5
    bsdf = mi.load_dict({"type": "draaw", "base_color": base.tolist(), "metallic": metal, "specular": spec,
                         "roughness": 0.5})
    feats = dict.fromkeys(FEATURE_NAMES, False)
    feats["draaw_materials"] = True
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0, 0, 1)
    mat = phong_material(mi.BSDFPtr(bsdf), si, mi.Bool(True), feats)
    ks = (1 - metal) * 0.08 * spec + metal * base
    np.testing.assert_allclose(np.array(mat.ks).ravel(), ks, rtol=1e-5)
    np.testing.assert_allclose(np.array(mat.kd).ravel(), base * (1 - metal) * (1 - ks.max()), rtol=1e-5)


@pytest.mark.parametrize("roughness", [0.5, 0.8])
def test_the_legacy_phong_exponent_follows_the_roughness(roughness):
    """V1/V2's Phong exponent from a draaw roughness r is n = 2 / alpha^2 - 2 with
    alpha^2 = r^4 + 1e-6 (PhongMaterial's docs; Walter et al.'s Beckmann-Phong match):
    30.0 at r = 0.5 and 2.88 at r = 0.8 (an offset of -1 gave 31.0 and 3.88)."""
    from draaw_mi.integrators.phong import phong_material
    from draaw_mi.integrators.features import FEATURE_NAMES
    bsdf = mi.load_dict({"type": "draaw", "roughness": roughness})
    feats = dict.fromkeys(FEATURE_NAMES, False)
    feats["draaw_materials"] = True
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0, 0, 1)
    n = np.array(phong_material(mi.BSDFPtr(bsdf), si, mi.Bool(True), feats).n).ravel()
    np.testing.assert_allclose(n, [2.0 / (roughness ** 4 + 1e-6) - 2.0], rtol=1e-5)


def test_v3s_own_draaw_lobe_is_schlick_cook_torrance_of_the_draaw_parameters():
    """V3's Beckmann lobe F D G / (4 cos_i) with the draaw model's parameters, in numpy:
    f0 = lerp(0.08 specular, base, metallic), f90 = min(1, 50 f0), alpha = sqrt(r^4 + 1e-6);
    D and G are Mitsuba's Beckmann at that alpha. Grazing directions, where f90 weighs."""
    from draaw_mi.integrators.draaw_lobes import draaw_params, draaw_spec_eval
    base, spec, metal, rough = np.array([0.8, 0.4, 0.2]), 0.5, 0.25, 0.5
    bsdf = mi.load_dict({"type": "draaw", "base_color": base.tolist(), "specular": spec,
                         "metallic": metal, "roughness": rough})
    rng = np.random.default_rng(4)
    n = 512
    def dirs(cos_lo, cos_hi):
        c = rng.uniform(cos_lo, cos_hi, n)
        phi = rng.uniform(0, 2 * np.pi, n)
        s = np.sqrt(1 - c * c)
        return np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=1)
    wi, wo = dirs(0.05, 0.3), dirs(0.05, 1.0)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*wi.T)
    active = mi.Bool(np.ones(n, bool))
    p = draaw_params(bsdf, si, active)
    value = np.array(draaw_spec_eval(p, mi.MicrofacetType.Beckmann, si.wi, mi.Vector3f(*wo.T), active)).T
    f0 = (1 - metal) * 0.08 * spec + metal * base
    f90 = np.minimum(1.0, 50 * f0)
    alpha = np.sqrt(rough ** 4 + 1e-6)
    h = wi + wo
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    distr = mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, alpha, False)
    hv, wiv, wov = (mi.Vector3f(*a.T) for a in (h, wi, wo))
    dg = np.array(distr.eval(hv) * distr.G(wiv, wov, hv))
    m = 1 - np.clip(np.sum(wi * h, axis=1), 0, 1)
    F = f0[None] + (f90 - f0)[None] * (m ** 5)[:, None]
    ref = F * (dg / (4 * wi[:, 2]))[:, None]
    np.testing.assert_allclose(value, ref, rtol=2e-4, atol=1e-6)
    assert (m ** 5).max() > 0.3                      # grazing: f90 decides much of F


def test_a_light_that_cannot_sample_rays_leaves_selection_uniform(monkeypatch):
    """An emitter plugin without ``sample_ray`` (one's own, in Python) made the power estimate,
    and so every V4 render of its scene, raise; its powers are now unknown (inf) and the
    choice uniform, as for an environment."""
    from draaw_mi.integrators.sampling import PowerSelection, emitter_powers

    def no_rays(*args, **kwargs):
        raise RuntimeError("Emitter::sample_ray(): not implemented!")
    scene = mi.load_dict({"type": "scene",
                          **{f"p{i}": {"type": "point", "position": [i, 3, 0], "intensity": 1.0 + 9 * i}
                             for i in range(2)}})
    assert PowerSelection.of(scene) is not None
    monkeypatch.setattr(mi.EmitterPtr, "sample_ray", no_rays)
    assert np.isinf(emitter_powers(scene)).all()
    assert PowerSelection.of(scene) is None
