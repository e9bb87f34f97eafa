"""V4's speed-ups under every pixel filter (``integrators/film_splat.py``): adaptive sampling
and emission splitting stay on under tent, gaussian, Lanczos and Mitchell filters and keep
``path``'s expectation with the same filter, pixel by pixel; what the film or the lens still
turns off is said once, as a RuntimeWarning, and by ``draaw-mi info``."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from integrators_helpers import check_same_expectation, integrator, mi, rs, seed_stack, z_summary, zscores

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.integrators import adaptive_sampling as ads
from draaw_mi.integrators import film_splat

from conftest import tiny_description

FILTERS = ["tent", "gaussian", "lanczos", "mitchell"]


def cornell(res: int, rfilter: str, **sensor):
    d = rs.cornell_draaw(res=res, spp=4)
    d["sensor"]["film"]["rfilter"] = {"type": rfilter}
    d["sensor"].update(sensor)
    return mi.load_dict(d)


def spy(monkeypatch, mod, name: str) -> list:
    """Replaces ``mod.name`` by a wrapper that appends ``name`` to the returned list per call."""
    calls = []
    real = getattr(mod, name)
    monkeypatch.setattr(mod, name, lambda *a, **k: (calls.append(name), real(*a, **k))[1])
    return calls


def light_and_panel(**film):
    """A square light of radiance 10 (about 8 pixels wide) before an empty background and a
    diffuse panel, seen through a tent-filtered 24x24 RGBA film (``film``: crop settings)."""
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 24, "pixel_format": "rgba",
                            "rfilter": {"type": "tent"}, **film}},
        "light": {"type": "rectangle", "to_world": T().scale(0.5),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [10.0, 10.0, 10.0]}}},
        "panel": {"type": "rectangle", "to_world": T().translate([-0.6, -0.6, -1.0]).scale(0.5),
                  "bsdf": {"type": "diffuse"}}})


def light_edges(scene) -> np.ndarray:
    """Pixels partly covered by the (filtered) light: from ``path`` at max_depth 1, 1024 spp."""
    img = np.array(mi.render(scene, integrator=integrator("path", max_depth=1), spp=1024,
                             seed=5))[..., :3].mean(-1)
    return (img > 0.03 * img.max()) & (img < 0.97 * img.max())


@pytest.mark.parametrize("spp, stratify, passes", [(16, True, ["render_uniform"]),
                                                   (128, True, ["render_uniform"]),
                                                   (128, False, ["render_adaptive"])],
                         ids=["stratified+split", "stratified128+split", "adaptive+split"])
@pytest.mark.parametrize("rfilter", FILTERS)
def test_v4_keeps_paths_expectation_under_the_filter(rfilter, spp, stratify, passes, monkeypatch):
    """The Cornell box with its light in view, per pixel over 10 seeds: the uniform
    (stratified) render whose split rays are splatted at their own positions, at 16 and 128
    spp; and (``stratify`` off) the adaptive
    render at 128 spp (pilot + uneven counts, each sample weighted by 1 / its pixel's count).
    Adding the split rays' emission to the camera sample's value instead (the box-filter
    rule) or dropping the 1 / count weight puts the light's edge pixels tens of errors off."""
    adaptive, uniform = spy(monkeypatch, ads, "render_adaptive"), spy(monkeypatch, film_splat, "render_uniform")
    scene = cornell(16, rfilter)
    K = 10
    ref = seed_stack(scene, integrator("path", max_depth=4), spp, range(K))
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=4, stratify=stratify), spp, range(200, 200 + K))
    used = adaptive + uniform
    assert used == passes * K, used
    assert np.isfinite(v4).all()
    check_same_expectation(ref, v4)
    # the light's edge pixels alone (where the split rays land), summed: within 4 errors
    edges = light_edges(scene)
    a, b = ref[:, edges].sum(1), v4[:, edges].sum(1)
    err = np.sqrt(a.var(0, ddof=1) / K + b.var(0, ddof=1) / K)
    assert (np.abs(a.mean(0) - b.mean(0)) < 4 * err).all(), (a.mean(0), b.mean(0), err)


def test_uneven_counts_keep_the_filtered_image():
    """``render_spp_map`` under a gaussian filter with a checkerboard of 8 and 32 samples per
    pixel (the spread adaptive sampling makes: at least half the uniform count, at most a few
    times the mean) against the uniform map: the same expectation per pixel. Without the
    per-sample weight 1 / count, dense pixels pull their neighbours' filtered values towards
    their own (z spread 1.6, 5 % beyond 3 sigma)."""
    scene = cornell(12, "gaussian")
    sensor = scene.sensors()[0]
    integ = integrator("draaw_v4", max_depth=3, emission_split=1)
    yy, xx = np.mgrid[:12, :12]
    uneven = np.where((xx + yy) % 2 == 0, 8, 32)
    K = 10
    a = np.stack([ads.render_spp_map(integ, scene, sensor, uneven, seed=s) for s in range(K)])
    b = np.stack([ads.render_spp_map(integ, scene, sensor, np.full((12, 12), 20), seed=100 + s)
                  for s in range(K)])
    check_same_expectation(a, b)


def test_the_speedups_lower_the_light_edges_error_under_a_gaussian_filter():
    """Emission splitting under Mitsuba's default filter: the light's edge pixels' variance at
    16 spp is a fraction of that with splitting off (it was the same before: gated)."""
    scene = cornell(24, "gaussian")
    edges = light_edges(scene)
    on = seed_stack(scene, integrator("draaw_v4", max_depth=2), 16, range(8))
    off = seed_stack(scene, integrator("draaw_v4", max_depth=2, emission_split=1), 16, range(8))
    v_on, v_off = on.var(0, ddof=1)[edges].mean(), off.var(0, ddof=1)[edges].mean()
    assert v_on < 0.5 * v_off, (v_on, v_off)


@pytest.mark.parametrize("rfilter", ["tent", "gaussian"])
def test_splitting_lowers_the_whole_images_error_under_a_filter(rfilter):
    """The whole image's variance at 16 spp with splitting against without, under a tent and
    a gaussian filter. The light's inner pixels next to its edges take samples of the edge
    pixels through the filter: with the split rays' emission divided by the camera samples'
    random weights (one film for both) their variance doubled and splitting was no gain
    there; with the emission in a block of its own (film_splat) it is."""
    scene = cornell(32, rfilter)
    on = seed_stack(scene, integrator("draaw_v4", max_depth=2), 16, range(8))
    off = seed_stack(scene, integrator("draaw_v4", max_depth=2, emission_split=1), 16, range(8))
    ratio = on.var(0, ddof=1).sum() / off.var(0, ddof=1).sum()
    # measured over three sets of 8 seeds: 0.10-0.15 (tent, gaussian); one film for both: 0.27-0.68
    assert ratio < 0.2, ratio


def test_the_film_holds_the_rendered_image():
    """Mitsuba scripts read ``sensor.film().bitmap()`` after ``mi.render``: under a tent filter
    with split rays (a uniform render) the film must hold the image the render returned
    (camera paths and the emission's own block together), not one of the two. (The
    adaptive render under a filter: the next test; under a box filter its image is formed
    outside the film.)"""
    scene = cornell(16, "tent")
    img = np.array(mi.render(scene, integrator=integrator("draaw_v4", max_depth=2), spp=16, seed=3))
    held = np.array(scene.sensors()[0].film().bitmap(), dtype=np.float64)
    np.testing.assert_allclose(held[..., :3], img[..., :3], rtol=1e-5, atol=1e-6)
    assert img[..., :3].max() > 1.0            # the light is in it


def test_an_adaptive_render_under_a_filter_fills_one_block_and_the_film(monkeypatch):
    """Under a tent filter the pilot and the main pass splat into one FilmSplat, which the
    film develops once and then holds, as after Mitsuba's own render. A pilot with its own
    block, developed and kept through the main pass, made a 1024x1024 CLI render peak at
    1.43x ``path``'s resident memory (issue 45 asks 1.25x); see also the next test."""
    made = []

    class Counted(film_splat.FilmSplat):
        def __init__(self, *a, **k):
            made.append(1)
            super().__init__(*a, **k)

    monkeypatch.setattr(ads, "FilmSplat", Counted)
    develops = spy(monkeypatch, Counted, "develop")
    adaptive = spy(monkeypatch, ads, "render_adaptive")
    scene = cornell(16, "tent")
    img = np.array(mi.render(scene, integrator=integrator("draaw_v4", max_depth=2, stratify=False),
                             spp=64, seed=3))
    assert adaptive and len(made) == 1 and len(develops) == 1, (adaptive, made, develops)
    held = np.array(scene.sensors()[0].film().bitmap(), dtype=np.float64)
    np.testing.assert_allclose(held[..., :3], img[..., :3], rtol=1e-5, atol=1e-6)


def test_an_adaptive_render_under_a_filter_peaks_near_paths_memory():
    """Dr.Jit's peak allocation (``malloc_watermark``, its cache of freed memory included) of
    a 256x256 V4 render at 64 spp under a tent filter against ``path``'s, same scene,
    compiled kernels. Measured: 2.69x (the pilot's four maps beside its eight sums, the
    block, the emission's block and the film's storage; 1.78x under a box filter). A pilot
    with a block of its own, developed and kept through the main pass, peaked at 3.40x."""
    import drjit as dr
    scene = cornell(256, "tent")
    peaks = {}
    for name in ("path", "draaw_v4"):
        integ = integrator(name, max_depth=3, **({"stratify": False} if name == "draaw_v4" else {}))
        mi.render(scene, integrator=integ, spp=64, seed=0)      # (compiled kernels, edge map)
        dr.flush_malloc_cache()
        dr.detail.malloc_clear_statistics()
        dr.eval(mi.render(scene, integrator=integ, spp=64, seed=1))
        peaks[name] = dr.detail.malloc_watermark(dr.JitBackend.LLVM)
    ratio = peaks["draaw_v4"] / peaks["path"]
    assert ratio < 3.0, (peaks, ratio)


def test_the_adaptive_render_runs_under_every_filter(monkeypatch):
    calls = spy(monkeypatch, ads, "render_adaptive")
    for f in ["box"] + FILTERS:
        img = mi.render(cornell(8, f), integrator=integrator("draaw_v4", max_depth=3, stratify=False), spp=64)
        assert np.isfinite(np.array(img)).all()
    assert len(calls) == 5


def _render_warnings(desc: dict, **options) -> list[str]:
    scene = draaw_mi.load_scene(desc)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        for _ in range(2):                  # two renders by one integrator: said once
            draaw_mi.render(scene, version="v4", spp=2, integrator_options=options or None)
    return [str(w.message) for w in seen if issubclass(w.category, RuntimeWarning)
            and "is off" in str(w.message)]


@pytest.mark.parametrize("name", ["box"] + FILTERS)
def test_no_filter_is_warned_about(name):
    assert _render_warnings(tiny_description(filter=name, resolution=[12, 8])) == []


def test_a_thin_lens_is_said_once_to_turn_emission_splitting_off():
    scene = cornell(8, "gaussian", type="thinlens", aperture_radius=0.05, focus_distance=3.9)
    integ = integrator("draaw_v4", max_depth=2)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        for _ in range(2):
            mi.render(scene, integrator=integ, spp=2)
    said = [str(w.message) for w in seen if "is off" in str(w.message)]
    assert len(said) == 1 and "emission splitting is off" in said[0], said
    with warnings.catch_warnings(record=True) as seen:     # asked off: nothing to say
        warnings.simplefilter("always")
        mi.render(scene, integrator=integrator("draaw_v4", max_depth=2, emission_split=1,
                                               adaptive=False), spp=2)
    assert not [w for w in seen if "is off" in str(w.message)]


def test_a_thin_lens_scene_renders_traced_without_a_recorders_message():
    """A recording of a thin lens's render failed at every first render ("Variable r170 ...
    was created before recording was started"), which every version said in a warning of
    Dr.Jit's internals before tracing it: such scenes are traced from the start."""
    from draaw_mi.rendering.frozen import freeze_supported
    d = rs.cornell_draaw(res=8, spp=4)
    d["sensor"].update(type="thinlens", aperture_radius=0.1, focus_distance=3.0)
    scene = draaw_mi.load_scene(d)
    assert not freeze_supported(scene.mi_scene)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        for version in ("path", "v1", "v4"):
            assert np.isfinite(np.array(draaw_mi.render(scene, version=version, spp=4))).all()
    assert not [w for w in seen if "freeze" in str(w.message)], [str(w.message) for w in seen]
    d["sensor"].update(type="perspective")
    del d["sensor"]["aperture_radius"], d["sensor"]["focus_distance"]
    assert freeze_supported(draaw_mi.load_scene(d).mi_scene)          # (a pinhole is recorded)


def test_info_says_what_the_sensor_gates(tmp_path, capsys):
    path = tmp_path / "g.json"
    path.write_text(json.dumps(tiny_description(filter="gaussian")))
    assert main(["info", str(path)]) == 0
    assert "v4 note" not in capsys.readouterr().out
    d = rs.cornell_draaw(res=8, spp=4)
    d["sensor"].update(type="thinlens", aperture_radius=0.1, focus_distance=3.0)
    from draaw_mi.integrators.features import sensor_gated_speedups
    said = sensor_gated_speedups(mi.load_dict(d).sensors()[0])
    assert said.startswith("emission splitting is off: the camera samples a lens aperture")


def test_a_film_that_samples_beyond_its_border_is_refused():
    """Mitsuba 3.9.1 writes a sample_border film's border samples past the end of its image
    block (Dr.Jit's debug mode: a write at 788 of 396 values, with its own path too): the heap
    was corrupted ("corrupted size vs. prev_size", a segfault at a later render)."""
    d = rs.cornell_draaw(res=8, spp=4)
    d["sensor"]["film"]["sample_border"] = True
    scene = mi.load_dict(d)
    with pytest.raises(draaw_mi.errors.RenderError, match=r"draaw_v4: the film samples beyond its border "
                                                          r"\(sample_border = true\).*set sample_border to false"):
        integrator("draaw_v4", max_depth=2).render(scene, spp=2)      # (as mi.render calls it)
    with pytest.raises(draaw_mi.errors.SceneError, match=r"<dict>: the film samples beyond its border"):
        draaw_mi.load_scene(d)


def test_a_crop_window_renders_adaptively_with_paths_expectation(monkeypatch):
    """A film cropped to its lower right 10x8 pixels under a tent filter: adaptive sampling
    renders the window (it used to refuse crop windows) and keeps ``path``'s expectation; a
    sample mapped without the crop offset would render the film's upper left corner."""
    calls = spy(monkeypatch, ads, "render_adaptive")
    d = rs.cornell_draaw(res=16, spp=4)
    d["sensor"]["film"].update(rfilter={"type": "tent"}, crop_offset_x=6, crop_offset_y=8,
                               crop_width=10, crop_height=8)
    scene = mi.load_dict(d)
    ref = seed_stack(scene, integrator("path", max_depth=3), 64, range(8))
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=3, stratify=False), 64, range(50, 58))
    assert len(calls) == 8 and v4.shape == ref.shape == (8, 8, 10, 3)
    check_same_expectation(ref, v4)


def test_split_rays_in_a_crop_window_with_alpha_keep_paths_expectation(monkeypatch):
    """A square light before an empty background and a dark panel, seen through a
    tent-filtered RGBA film cropped to 8x6 pixels round the light's corner, uniform (16 spp):
    the emission's own block shares the crop offset, and its image is scaled by the film's
    weights, which sit after alpha (alpha < weight where rays miss). The emission block placed
    at the film's origin, or scaled by the alpha channel, puts the light's edge pixels far off;
    a light projected without the crop offset is not split at all."""
    calls = spy(monkeypatch, film_splat, "render_uniform")
    scene = light_and_panel(crop_offset_x=4, crop_offset_y=6, crop_width=8, crop_height=6)
    K = 12
    ref = seed_stack(scene, integrator("path", max_depth=3), 16, range(K))
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=3), 16, range(300, 300 + K))
    assert len(calls) == K and v4.shape == ref.shape == (K, 6, 8, 4)
    alpha = ref[..., 3].mean(0)
    assert ref[..., :3].max() > 5.0 and alpha.min() < 0.5 < alpha.max()   # light, misses, hits
    check_same_expectation(ref, v4)


def test_an_adaptive_rgba_render_of_a_light_in_view_keeps_paths_expectation(monkeypatch):
    """A square light about 8 pixels wide before an empty background (a tent-filtered RGBA
    film, 24x24), rendered adaptively (samples weighted 1 / their pixel's count): every
    channel, alpha too, keeps ``path``'s expectation pixel by pixel. The light's inner pixels
    split no rays, so their emission is splatted with the sample's weight, and alpha with
    it; at the weight 1 of a uniform render neither weight shows (the emission unweighted
    made the light 27x too bright, alpha unweighted reached 64)."""
    calls = spy(monkeypatch, ads, "render_adaptive")
    scene = light_and_panel()
    K = 8
    ref = seed_stack(scene, integrator("path", max_depth=3), 64, range(K))
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=3, stratify=False), 64, range(400, 400 + K))
    assert len(calls) == K and v4.shape == ref.shape == (K, 24, 24, 4)
    inner = (ref[..., :3].mean(-1).min(0) > 9.9)          # every seed of every sample saw the light
    assert inner.sum() >= 16, inner.sum()
    assert np.isfinite(v4).all() and v4[..., 3].max() <= 1.0 + 1e-5
    # the noisy entries (the light's edges, alpha there, the panel) by their z-scores; the
    # background (0) and the light's inner pixels (its radiance, 10; alpha 1) have no noise
    # (float rounding apart: 1e-4 relative); the scene is grey, so R, G and B are one channel
    # counted once (three equal z-scores would triple each pixel's weight in their mean)
    quiet = np.maximum(ref.std(0), v4.std(0)) <= 1e-4 * np.maximum(1.0, np.abs(ref.mean(0)))
    assert np.array_equal(ref[..., 0], ref[..., 2]) and np.array_equal(v4[..., 0], v4[..., 2])
    grey = [0, 3]
    s = z_summary(zscores(ref[..., grey][:, ~quiet[..., grey]], v4[..., grey][:, ~quiet[..., grey]]))
    # (a tent sample lands in 4 pixels, so their z-scores are correlated: their mean's
    # spread over seed sets, 0.15, is about 2x that of independent ones; bound at 4 of it)
    assert s["n"] >= 100 and s["frac_gt3"] <= 0.02 and abs(s["mean"]) <= 0.6 and 0.7 <= s["std"] <= 1.4, s
    np.testing.assert_allclose(v4.mean(0)[quiet], ref.mean(0)[quiet], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(v4[:, inner, :3], 10.0, rtol=1e-4)


def test_aovs_under_a_filter_with_split_rays(monkeypatch):
    """AOVs beside the split rays' splats: the AOV channels are those of the render without
    splitting (same seed). A split splat that wrote zeros into too few channels would shift
    the AOVs into the weight channel."""
    calls = spy(monkeypatch, film_splat, "render_uniform")
    scene = cornell(24, "gaussian")
    on = np.array(mi.render(scene, integrator=integrator("draaw_v4", max_depth=3, aovs="depth,normal"),
                            spp=16, seed=2))
    off = np.array(mi.render(scene, integrator=integrator("draaw_v4", max_depth=3, aovs="depth,normal",
                                                          emission_split=1), spp=16, seed=2))
    assert calls == ["render_uniform"] and on.shape == off.shape == (24, 24, 7)
    np.testing.assert_allclose(on[..., 3:], off[..., 3:], rtol=1e-5, atol=1e-6)   # (atomics order)
    assert np.isfinite(on).all()        # (the colour's expectation: the tests above)


def test_a_small_render_under_a_filter_with_split_rays_is_recorded():
    """A 16x16 render under a tent filter with the light in view (split rays splatted through
    ``FilmSplat``) replays a ``dr.freeze`` recording: developing the blocks freed Dr.Jit's
    cache unconditionally, which Dr.Jit refuses while recording, so every such render fell
    back to tracing with a RuntimeWarning."""
    import warnings
    from draaw_mi.rendering.session import session_of
    d = rs.cornell_draaw(res=16, spp=4)
    d["sensor"]["film"]["rfilter"] = {"type": "tent"}
    scene = draaw_mi.load_scene(d)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for s in range(3):
            img = np.array(draaw_mi.render(scene, version="v4", spp=16, seed=s))
    assert not [w for w in said if "could not record" in str(w.message)], [str(w.message) for w in said]
    assert np.isfinite(img).all() and img[..., :3].max() > 1.0        # the light is in view
    assert any(getattr(getattr(r, "frozen", None), "n_recordings", 0) >= 1
               for r in session_of(scene).recordings.values())
