"""Unbiased adaptive sampling (draaw_mi/integrators/adaptive_sampling.py) and its use by draaw_v4.

V4 renders an independent-sampler scene stratified by default, uniformly
(``integrators/stratify.py``, ``test_stratify.py``); here its adaptive renders are asked for
with ``stratify`` off (a scene's first render that decides on guiding renders adaptively too)."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

import draaw_mi  # noqa: F401
import mitsuba as mi

from draaw_mi.integrators import adaptive_sampling as ads
from draaw_mi.integrators import glints
from draaw_mi.bench import reference_scenes as rs


def test_allocate_follows_the_standard_deviation():
    var = np.zeros((4, 4))
    var[0, 0], var[0, 1] = 1.0, 4.0
    m = ads.allocate(var, budget=16 * 20, m_min=2, seed=1, smooth=False)
    assert m.min() >= 2 and m.dtype == np.uint32         # (4 bytes a pixel: 1024^2 maps stay small)
    assert abs(m.sum() - 320) <= 4                        # stochastic rounding keeps the total
    extra = m - 2
    assert abs(extra[0, 1] / extra[0, 0] - 2.0) < 0.1      # sd ratio 2 -> twice the samples
    assert extra[1:].sum() == 0
    flat = ads.allocate(np.zeros((3, 3)), budget=27, m_min=1, seed=0)
    assert np.all(flat == 3)                               # nothing known: uniform

    # with a cost per sample: same variance, 4x the cost -> half the extra samples, and the
    # total cost is the budget
    var = np.ones((1, 2))
    cost = np.array([[1.0, 4.0]])
    m = ads.allocate(var, budget=5.0 * 1000, m_min=1, seed=2, smooth=False, cost=cost)
    assert abs((m - 1)[0, 0] / (m - 1)[0, 1] - 2.0) < 0.02
    assert abs(float((m * cost).sum()) - 5000.0) <= 5.0


def _scene(res=8, spp=4):
    return mi.load_dict(rs.feature_scene(res=res, spp=spp, constant=True))


def test_v4_adaptive_keeps_every_pixels_expectation_on_a_wide_film(monkeypatch):
    """V4 at 64 spp (adaptive: a pilot, then samples by estimated error) against Mitsuba's
    ``path`` on a 12x8 film, per pixel over independent seeds: a mix-up of width and height in
    the sample-to-pixel mapping (invisible on square films) moves light between pixels."""
    from integrators_helpers import check_same_expectation, seed_stack

    calls = []
    real = ads.render_adaptive
    monkeypatch.setattr(ads, "render_adaptive", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    scene = mi.load_dict(rs.feature_scene(res=(12, 8), spp=4, constant=True))
    v4 = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    path = mi.load_dict({"type": "path", "max_depth": 3})
    a = seed_stack(scene, v4, 64, range(8))
    assert len(calls) == 8 and a.shape == (8, 8, 12, 3)        # adaptive was used, (H, W) kept
    check_same_expectation(a, seed_stack(scene, path, 64, range(100, 108)))


def test_v4_uses_adaptive_sampling_from_64_spp(monkeypatch):
    calls = []
    real = ads.render_adaptive

    def spy(*a, **k):
        calls.append(a[4])
        return real(*a, **k)

    monkeypatch.setattr(ads, "render_adaptive", spy)
    scene = _scene(8)
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    img = mi.render(scene, integrator=integ, spp=64, seed=1)
    assert calls == [64] and img.shape == (8, 8, 3)
    mi.render(scene, integrator=integ, spp=16, seed=1)
    off = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "adaptive": False, "stratify": False})
    mi.render(scene, integrator=off, spp=64, seed=1)
    assert calls == [64]
    a = np.array(mi.render(scene, integrator=integ, spp=64, seed=4))
    b = np.array(mi.render(scene, integrator=integ, spp=64, seed=4))
    assert np.allclose(a, b, rtol=1e-5, atol=1e-7)         # same seed, same image (up to
    #                                                        the order of atomic adds)


@pytest.mark.parametrize("sampler", ["multijitter", "ldsampler"])
def test_stratifying_samplers_render_uniformly(monkeypatch, sampler):
    """With a stratifying sampler V4 renders every pixel with the scene's sampler at the asked
    spp (adaptive sampling measured 1.25-1.48x the variance x time there): no adaptive call,
    and the image is the uniform render's, bit for bit."""
    calls = []
    monkeypatch.setattr(ads, "render_adaptive", lambda *a, **k: calls.append(1))
    d = rs.feature_scene(res=8, spp=4, constant=True)
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 64}
    scene = mi.load_dict(d)
    assert not ads.supported(scene.sensors()[0])
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    off = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "adaptive": False, "stratify": False})
    a = np.array(mi.render(scene, integrator=integ, spp=64, seed=2))
    b = np.array(mi.render(scene, integrator=off, spp=64, seed=2))
    assert calls == [] and np.array_equal(a, b) and a.mean() > 0
    assert ads.supported(_scene(8).sensors()[0])          # the independent sampler: adaptive


def test_allocation_cap_bounds_a_pixel_share():
    """One pixel whose pilot saw a rare bright sample: uncapped it takes most of the budget,
    capped at 4x the mean score it takes at most its bounded share."""
    var = np.ones((8, 8))
    var[3, 3] = 1e6
    free = ads.allocate(var, budget=64 * 60, m_min=30, seed=1, smooth=False)
    capped = ads.allocate(var, budget=64 * 60, m_min=30, seed=1, smooth=False, score_cap=4.0)
    extra = 64 * 60 - 64 * 30
    cap = 4.0 * (63 * 1.0 + 1000.0) / 64                      # 4x the mean score (sd)
    bound = 30 + extra * cap / (63 + cap) + 1
    assert free[3, 3] > extra * 0.9 and capped[3, 3] <= bound < free[3, 3]
    assert capped.min() >= 30 and abs(int(capped.sum()) - 64 * 60) <= 64


def test_adaptive_lowers_the_error_where_noise_is_uneven():
    """Half the view is the (noise-free) sky: adaptive sampling moves those samples to the
    noisy half and reaches a lower MSE than uniform sampling at the same spp."""
    d = rs.feature_scene(res=16, spp=4, constant=True)
    d["sensor"]["to_world"] = mi.ScalarTransform4f().look_at(origin=[0.0, 1.2, 4.0],
                                                           target=[0.0, 1.2, 0.0], up=[0, 1, 0])
    scene = mi.load_dict(d)
    ref = np.array(mi.render(scene, integrator=mi.load_dict({"type": "path", "max_depth": 4}),
                             spp=4096, seed=99))
    on = mi.load_dict({"type": "draaw_v4", "max_depth": 4, "stratify": False})
    off = mi.load_dict({"type": "draaw_v4", "max_depth": 4, "adaptive": False, "stratify": False})
    e_on = np.mean([np.mean((np.array(mi.render(scene, integrator=on, spp=64, seed=s)) - ref) ** 2)
                    for s in range(6)])
    e_off = np.mean([np.mean((np.array(mi.render(scene, integrator=off, spp=64, seed=s)) - ref) ** 2)
                     for s in range(6)])
    assert e_on < 0.85 * e_off, (e_on, e_off)


@pytest.mark.parametrize("light,bsdf,expected", [
    ({"type": "point", "position": [0, 2, 2]}, {"type": "draaw", "roughness": 0.05, "metallic": 1.0}, True),
    ({"type": "point", "position": [0, 2, 2]}, {"type": "roughconductor", "alpha": 0.03}, True),
    ({"type": "point", "position": [0, 2, 2]}, {"type": "draaw", "roughness": 0.3}, False),
    ({"type": "point", "position": [0, 2, 2]}, {"type": "conductor"}, False),      # delta lobe
    ({"type": "constant"}, {"type": "draaw", "roughness": 0.05, "metallic": 1.0}, False),
])
def test_glint_scenes_render_without_adaptive_sampling(monkeypatch, light, bsdf, expected):
    """Delta lights over near-mirror surfaces make glints a small pilot cannot see: those
    scenes (and only those) skip adaptive sampling."""
    d = {"type": "scene", "light": light,
         "floor": {"type": "rectangle", "bsdf": bsdf},
         "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
             origin=[0, 1, 3], target=[0, 0, 0], up=[0, 1, 0]),
             "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}}
    scene = mi.load_dict(d)
    assert glints.has_glints(scene) is expected
    calls = []
    real = ads.render_adaptive
    monkeypatch.setattr(ads, "render_adaptive", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    img = mi.render(scene, integrator=mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False}), spp=64, seed=1)
    assert np.isfinite(np.array(img)).all()
    assert (len(calls) == 1) is (not expected)


def test_allocation_without_any_variance_is_uniform():
    """A pilot that saw no variance at all (a black image): one count per pixel, the budget
    spread evenly (this returned a bare number before, and the main pass raised)."""
    m = ads.allocate(np.zeros((4, 6)), budget=24 * 10 * 2.0, m_min=5, seed=0, cost=np.full((4, 6), 2.0))
    assert m.shape == (4, 6) and (m == 10).all()


def test_the_cost_aware_cap_is_the_closed_form():
    """allocate() with a cost per sample and a score cap against its closed form in numpy:
    scores s = sd / sqrt(cost) capped at cap x the cost-weighted mean score, extra samples
    proportional to s, a total cost of the budget. (With a uniform cost the plain mean of the
    scores gives the same cap; here it gave [1576, 51, 51, 51].)"""
    var = np.array([[100.0, 1.0, 1.0, 1.0]])
    cost = np.array([[1.0, 10.0, 10.0, 10.0]])
    m = ads.allocate(var, budget=3100.0, m_min=1, seed=0, smooth=False, cost=cost, score_cap=4.0)
    s = np.sqrt(var) / np.sqrt(cost)
    s = np.minimum(s, 4.0 * (s * cost).sum() / cost.sum())
    want = 1 + (3100.0 - cost.sum()) * s / (s * cost).sum()
    assert np.all(np.abs(m - want) < 1.0), (m, want)     # stochastic rounding of want


@pytest.mark.parametrize("change", ["thinlens", "rgba"])
def test_v4_adaptive_renders_what_the_uniform_render_does(change):
    """At 64 spp V4 samples adaptively with its own camera rays: a thin-lens camera's
    aperture sample (dropped, the image came out pinhole-sharp) and an RGBA film's alpha (an
    empty background's 0; as 1 it read opaque) are the uniform render's, per pixel over seeds.
    The alpha of the pixels a shape covers in part has the noise of all the samples (it was
    the 4-sample pilot's alone: 15x the uniform render's variance)."""
    from integrators_helpers import check_same_expectation, seed_stack

    d = rs.feature_scene(res=10, spp=4)
    if change == "thinlens":
        d["sensor"] = dict(d["sensor"], type="thinlens", aperture_radius=0.3, focus_distance=1.0)
    else:
        d["sensor"]["film"]["pixel_format"] = "rgba"
        d["sensor"]["to_world"] = mi.ScalarTransform4f().look_at([0.0, 1.0, 4.0], [0.0, 1.2, 0.0], [0, 1, 0])
    scene = mi.load_dict(d)
    on = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    off = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "adaptive": False, "stratify": False})
    said = pytest.warns(RuntimeWarning, match="emission splitting is off: the camera samples a lens") \
        if change == "thinlens" else contextlib.nullcontext()
    with said:                           # (what stays off is said once per render)
        a, b = seed_stack(scene, on, 64, range(10)), seed_stack(scene, off, 64, range(100, 110))
    check_same_expectation(a, b)
    if change == "rgba":
        background = (b[..., 3] == 0).all(0)
        assert background.any() and (a[..., 3].max(0)[background] == 0).all()
        partly = (b[..., 3].min(0) < 1) & ~background         # the floor's far edge
        assert partly.sum() >= 5
        ratio = a[..., 3].var(0, ddof=1)[partly].sum() / b[..., 3].var(0, ddof=1)[partly].sum()
        assert ratio < 3.0, ratio


@pytest.mark.parametrize("name, adapts", [("doorway", False), ("metal_018", True)])
def test_a_pilot_whose_halves_disagree_renders_uniformly(monkeypatch, name, adapts):
    """The room lit through a doorway: the pilot's even and odd samples put the noise in
    different pixels (agreement 0.1-0.2 at 32x32), so the main pass is uniform; a glossy
    sphere under an area light (0.86-0.89) gets its map. Allocating on the doorway's map
    anyway cost 1.8x the error of a uniform render on the glossy-panel scene at 128x128."""
    from draaw_mi.bench import suite as ss
    calls = []
    real = ads.allocate
    monkeypatch.setattr(ads, "allocate", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    scene = ss.load(name, 32)
    img = mi.render(scene, integrator=mi.load_dict({"type": "draaw_v4", "max_depth": 5, "stratify": False}), spp=64, seed=3)
    assert np.isfinite(np.array(img)).all()
    assert bool(calls) == adapts, calls


@pytest.mark.parametrize("rfilter", ["box", "gaussian"])
def test_an_adaptive_render_keeps_its_passes_in_drjit(rfilter):
    """NumPy memory of a 128x128 adaptive render (tracemalloc's peak): 57 bytes a pixel, the
    float32 maps the allocation reads and its temporaries. Reading the pilot's fourteen
    per-pixel sums back as float64 (and stacking and dividing them) took 177, which made a
    1024x1024 CLI render peak at 1.9x ``path``'s resident memory."""
    import tracemalloc
    d = rs.cornell_draaw(res=128, spp=4)
    d["sensor"]["film"]["rfilter"] = {"type": rfilter}
    scene = mi.load_dict(d)
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 4, "stratify": False})
    mi.render(scene, integrator=integ, spp=64, seed=0)          # (the edge map, compiled kernels)
    tracemalloc.start()
    try:
        img = ads.render_adaptive(integ, scene, scene.sensors()[0], 1, 64, False)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert img.shape == (128, 128, 3) and np.isfinite(np.array(img)).all()
    assert peak / 128 ** 2 < 100, peak / 128 ** 2
