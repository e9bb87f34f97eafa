"""fit(): recovery of known parameters, hard targets, robustness, kernel reuse, CLI (fits that
read and write files: test_fit_files.py).

Default tests run at 32x32 (a few seconds each). References are rendered with Mitsuba's own
``path`` integrator, so every recovery test also checks that the fitting integrator and
``path`` agree in expectation. Tolerances are about four standard deviations of the fitted
value over fit seeds, measured at these settings (noted per test); the 128x128 accuracy checks
of issue 6 (0.02) are ``slow`` and recorded by benchmarks/fit_accuracy.py.
"""
from __future__ import annotations

import os

import drjit as dr
import matplotlib.image
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.errors import DraawError
from draaw_mi.fitting.params import FitParam as _Param
from draaw_mi.fitting.views import view_loss as _loss

from conftest import SCENES

RES = 32
P = ["target.roughness", "target.metallic"]
START = {"target.roughness": 0.5, "target.metallic": 0.5}


def _version():
    from draaw_mi import integrators
    return "v4" if "draaw_v4" in getattr(integrators, "PLUGINS", []) else "prb"


@pytest.fixture(scope="module")
def fit_scene():
    return draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(RES, RES))


def _set(scene, values):
    p = scene.params
    for name, value in values.items():
        p[scene.key(name)] = value
    p.update()


def _reference(scene, rough, metal, spp=1024, seed=1234):
    _set(scene, {"target.roughness": rough, "target.metallic": metal})
    ref = np.array(draaw_mi.render(scene, version="path", spp=spp, seed=seed))
    _set(scene, START)
    return ref


def _fit(scene, ref, **kw):
    kw.setdefault("version", _version())
    kw.setdefault("spp", 16)
    kw.setdefault("iterations", 100)
    return draaw_mi.fit(scene, ref, kw.pop("params", P), init=kw.pop("init", START), progress=False, **kw)


def _all_finite(res):
    return (np.isfinite(res.losses).all() and np.isfinite(res.image).all()
            and all(np.isfinite(np.ravel(list(h["values"].values()))).all() for h in res.history))


# ---------------------------------------------------------------------------------- recovery
def test_recovers_roughness_and_metallic(fit_scene):
    # 10 seeds at these settings: roughness 0.2516 +- 0.003, metallic 0.799 +- 0.0125 (80 it.)
    ref = _reference(fit_scene, 0.25, 0.8)
    res = _fit(fit_scene, ref)
    assert abs(res.values["target.roughness"] - 0.25) < 0.015
    assert abs(res.values["target.metallic"] - 0.8) < 0.04
    assert res.kernel_compiles == 0          # kernels compiled in the first two iterations only
    # The loss is dominated by 16-spp noise at the end; it still falls clearly.
    assert np.mean(res.losses[-10:]) < 0.5 * np.mean(res.losses[:3])


def test_a_run_stopped_by_the_learning_rate_decay_is_not_converged(fit_scene):
    """20 iterations: the cosine decay stops the parameters while they still move steadily
    towards the truth (roughness 0.29 for 0.25, metallic clipped at 1.0 for 0.8); their last
    two eighths differ by less than tol, which was reported as converged."""
    ref = _reference(fit_scene, 0.25, 0.8)
    res = _fit(fit_scene, ref, iterations=20)
    assert not res.converged
    assert abs(res.values["target.roughness"] - 0.25) > 0.02     # indeed not there yet


@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_small_roughness_is_not_trapped_below_the_alpha_clamp(fit_scene):
    """Regression: with linear roughness, Adam overshot 0.05 into the flat region below the
    alpha clamp (gradient ~ roughness^3) and stayed at 0. Log space + a floor fix it."""
    ref = _reference(fit_scene, 0.06, 0.9)
    res = _fit(fit_scene, ref, iterations=120)
    assert 0.04 < res.values["target.roughness"] < 0.08
    assert min(h["values"]["target.roughness"] for h in res.history) >= 0.019 - 1e-6
    assert abs(res.values["target.metallic"] - 0.9) < 0.04


_NEAR_MIRROR_METAL = [pytest.mark.slow, pytest.mark.xfail(strict=True, reason=(
    "measured: the 32x32 fit of roughness 0.02 / metallic 1 ends at roughness 0.052, whose image "
    "differs from the truth's beyond Monte Carlo noise (9.5 % of pixel channels at |z| > 3, max "
    "|z| 21): not 'alike at this resolution'; a fitter limitation, not fixed in issue 9"))]


@pytest.mark.parametrize("rough,metal", [pytest.param(0.02, 1.0, marks=_NEAR_MIRROR_METAL),
                                         pytest.param(0.5, 0.0, marks=pytest.mark.slow),
                                         (1.0, 1.0), (0.02, 0.0)])
def test_hard_targets_stay_finite_and_in_range(fit_scene, rough, metal):
    ref = _reference(fit_scene, rough, metal, spp=256)
    res = _fit(fit_scene, ref, spp=8, iterations=80, lr=0.08)
    assert _all_finite(res)
    for h in res.history:
        for v in h["values"].values():
            assert 0.0 <= v <= 1.0
    assert abs(res.values["target.metallic"] - metal) < 0.03
    if rough == 0.02:
        # At 32x32 a pixel spans ~0.016 rad of reflected direction, more than the GGX lobe of any
        # roughness below ~0.1 (fits end at 0.05-0.07; 128x128 resolves them, see
        # benchmarks/fit_cases.md). So instead of a tolerance on the value, check the claim:
        # the fitted material renders the true image within Monte Carlo noise (per-pixel z).
        fitted = _images(fit_scene, res.values["target.roughness"], res.values["target.metallic"])
        truth = _images(fit_scene, rough, metal)
        se = np.sqrt(fitted.var(0, ddof=1) / len(fitted) + truth.var(0, ddof=1) / len(truth))
        z = (fitted.mean(0) - truth.mean(0))[se > 1e-6] / se[se > 1e-6]
        assert np.mean(np.abs(z) > 3) < 0.02 and abs(z.mean()) < 0.3, (res.values, np.abs(z).max())
        assert res.values["target.roughness"] < 0.1
    else:
        assert abs(res.values["target.roughness"] - rough) < 0.03


def _images(scene, rough, metal, k=6, spp=256):
    _set(scene, {"target.roughness": rough, "target.metallic": metal})
    out = np.stack([np.array(draaw_mi.render(scene, version="path", spp=spp, seed=900 + i)) for i in range(k)])
    _set(scene, START)
    return out.astype(np.float64)


@pytest.mark.parametrize("fast_math", [True, False])
def test_near_mirror_fit_is_finite_with_and_without_fast_math(fit_scene, fast_math):
    ref = _reference(fit_scene, 0.0, 1.0, spp=64)            # roughness exactly 0
    with dr.scoped_set_flag(dr.JitFlag.FastMath, fast_math):
        res = _fit(fit_scene, ref, spp=4, iterations=15, lr=0.2)
    assert _all_finite(res)
    assert all(0.0 <= h["values"]["target.roughness"] <= 1.0 for h in res.history)


@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_exposure_fit_is_insensitive_to_a_global_scale(fit_scene):
    ref = _reference(fit_scene, 0.3, 0.6) * 1.5
    res = _fit(fit_scene, ref, exposure="fit")
    assert abs(res.exposure_stops - np.log2(1.5)) < 0.02
    assert abs(res.values["target.metallic"] - 0.6) < 0.04
    assert abs(res.values["target.roughness"] - 0.3) < 0.02
    assert "exposure_stops" in res.history[-1]


def test_exposure_scale_estimate_is_unbiased_under_noise():
    """<ref, ref> / <img, ref> is unbiased for a noisy render (the least-squares <img, ref> /
    <img, img> used before is biased low by the pixel variance: 2 / (1 + 0.09 / E[t^2]) ~ 1.8
    here); the loss is that of the scaled render."""
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.1, 1.0, (64, 64, 3)).astype(np.float32)
    ref = mi.TensorXf(truth * 2.0)
    scales = []
    for _ in range(8):
        noisy = truth + rng.normal(0, 0.3, truth.shape).astype(np.float32)
        lv, s = _loss(mi.TensorXf(noisy), ref, "l2", "fit")
        scales.append(float(s[0]))
        expected = np.mean((noisy.astype(np.float64) * scales[-1] - truth * 2.0) ** 2)
        assert float(lv[0]) == pytest.approx(expected, rel=1e-4)
        lv1, _ = _loss(mi.TensorXf(noisy), ref, "l1", "fit")
        assert float(lv1[0]) == pytest.approx(np.mean(np.abs(noisy * scales[-1] - truth * 2.0)), rel=1e-4)
    se = np.std(scales, ddof=1) / np.sqrt(len(scales))
    assert abs(np.mean(scales) - 2.0) < 4 * se + 1e-4, (np.mean(scales), se)
    assert se < 0.01                                        # and the check has power against -0.2


def test_noisy_reference_and_colour(fit_scene):
    """A colour fitted from grey (0.5, 0.5, 0.5) with the roughness, to a noisy reference of
    the scene's own blue (0.06, 0.22, 0.75). Measured over 3 fit seeds (40 iterations): every
    channel within 0.004-0.026 of the truth (from 0.25-0.44 at the start); the scene holds
    the fitted colour afterwards."""
    rng = np.random.default_rng(0)
    truth = np.array(fit_scene.params[fit_scene.key("target.base_color")]).ravel()
    ref = _reference(fit_scene, 0.4, 0.3, spp=16)             # a noisy (16 spp) reference
    ref = ref + rng.normal(0, 0.02, ref.shape).astype(np.float32)
    _set(fit_scene, {"target.metallic": 0.3})             # (not fitted here: its true value)
    try:
        res = _fit(fit_scene, ref, params=["target.roughness", "target.base_color"], spp=4, iterations=40,
                   init={"target.roughness": 0.5, "target.base_color": [0.5, 0.5, 0.5]})
        assert np.isfinite(res.losses).all()
        fitted = np.array(res.values["target.base_color"])
        assert fitted.shape == (3,)
        np.testing.assert_allclose(fitted, truth, atol=0.05)
        held = np.array(fit_scene.params[fit_scene.key("target.base_color")]).ravel()
        np.testing.assert_allclose(held, fitted, rtol=1e-6)
    finally:
        _set(fit_scene, {"target.base_color": mi.Color3f(*map(float, truth)), **START})


@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_noisy_reference_is_recovered(fit_scene):
    # A 32x32, 32-spp reference holds little information: over 8 reference realisations the
    # fits scatter with sd 0.016 (roughness) and 0.033 (metallic) around means 0.406 / 0.296.
    rng = np.random.default_rng(1)
    ref = _reference(fit_scene, 0.4, 0.3, spp=32) + rng.normal(0, 0.02, (RES, RES, 3)).astype(np.float32)
    res = _fit(fit_scene, ref)
    assert _all_finite(res)
    assert abs(res.values["target.roughness"] - 0.4) < 0.05
    assert abs(res.values["target.metallic"] - 0.3) < 0.1


@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_l1_loss_recovers_with_render_averaging(fit_scene):
    """The l1 loss is non-linear in the render (it targets the median of the noisy pixel, not
    the mean), so fit() averages renders for it by default (``smooth``)."""
    ref = _reference(fit_scene, 0.3, 0.6)
    res = _fit(fit_scene, ref, loss="l1")
    assert _all_finite(res)
    assert abs(res.values["target.roughness"] - 0.3) < 0.03
    assert abs(res.values["target.metallic"] - 0.6) < 0.05


# ---------------------------------------------------------------------- composite fits
@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_two_materials_jointly():
    scene = draaw_mi.load_scene(os.path.join(SCENES, "fit_two_spheres.toml"), resolution=(RES, RES))
    truth = {"left.roughness": 0.2, "left.metallic": 0.9, "right.roughness": 0.6, "right.metallic": 0.1}
    _set(scene, truth)
    ref = np.array(draaw_mi.render(scene, version="path", spp=1024, seed=5))
    res = _fit(scene, ref, params=list(truth), init={k: 0.5 for k in truth}, iterations=120)
    for k, v in truth.items():
        assert abs(res.values[k] - v) < 0.05, (k, res.values[k], v)


@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_two_views(fit_scene):
    views = [{"origin": [0.0, 0.7, 3.2], "target": [0.0, 0.5, 0.0], "fov": 30.0},
             {"origin": [2.4, 1.9, 1.8], "target": [0.0, 0.3, 0.0], "fov": 34.0}]
    from draaw_mi.fitting.views import view_sensors as _views
    _set(fit_scene, {"target.roughness": 0.7, "target.metallic": 0.3})
    integ = mi.load_dict({"type": "path", "max_depth": fit_scene.settings["max_depth"]})
    refs = [np.array(mi.render(fit_scene.mi_scene, sensor=s, integrator=integ, spp=1024, seed=9 + i))
            for i, s in enumerate(_views(fit_scene, views))]
    res = _fit(fit_scene, refs, views=views, iterations=80)
    assert res.image.shape == (RES, RES, 3)
    assert abs(res.values["target.roughness"] - 0.7) < 0.04
    assert abs(res.values["target.metallic"] - 0.3) < 0.04


@pytest.mark.slow      # ~50-85 s: make test-all runs it
def test_post_chain_inside_the_loss(fit_scene):
    chain = [{"type": "bloom", "threshold": 0.3, "intensity": 1.1, "amount": 0.5},
             {"type": "contrast", "contrast": 1.3}]
    ref = np.array(draaw_mi.post.apply(_reference(fit_scene, 0.3, 0.6), chain))
    res = _fit(fit_scene, ref, post=chain)
    assert _all_finite(res)
    assert res.kernel_compiles == 0
    assert abs(res.values["target.roughness"] - 0.3) < 0.03
    assert abs(res.values["target.metallic"] - 0.6) < 0.05
    # the final image is a post-processed render: close to the post-processed reference
    assert np.median(np.abs(res.image - ref)) < 0.05


# ------------------------------------------------------------------- parameters, errors
def test_log_space_roughness_parameter(fit_scene):
    prm = _Param("target.roughness.value", "target.roughness", mi.Float(0.5), fit_scene)
    assert prm.space == "log" and abs(prm.lo - 0.6 * np.sqrt(1e-3)) < 1e-9 and prm.hi == 1.0
    u = prm.to_latent(0.0)                   # clamped up to the floor
    assert abs(float(dr.exp(u)[0]) - prm.lo) < 1e-6
    assert abs(float(prm.from_latent(prm.to_latent(0.37))[0]) - 0.37) < 1e-6
    metal = _Param("target.metallic.value", "target.metallic", mi.Float(0.5), fit_scene)
    assert metal.space == "linear" and (metal.lo, metal.hi) == (0.0, 1.0)


def test_fit_leaves_the_fitted_values_in_the_scene(fit_scene):
    ref = _reference(fit_scene, 0.35, 0.5, spp=64)
    res = _fit(fit_scene, ref, spp=4, iterations=5)
    p = fit_scene.params
    assert abs(float(p["target.roughness.value"][0]) - res.values["target.roughness"]) < 1e-6
    assert not dr.grad_enabled(p["target.roughness.value"])
    _set(fit_scene, START)


def test_a_stratified_sampler_fits_with_a_count_it_takes():
    """multijitter renders 35 samples when asked for 32 (and logs it at every iteration): the
    fit says once that it uses 30 and does."""
    scene = draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(16, 16),
                                sampler="multijitter")
    ref = np.array(draaw_mi.render(scene, version="path", spp=16, seed=3))
    with pytest.warns(RuntimeWarning, match="takes 30 samples per pixel, not spp=32; fitting with 30"):
        res = draaw_mi.fit(scene, ref, P, version="v4", spp=32, iterations=2, progress=False)
    assert np.isfinite(res.losses).all()


def test_a_parameter_its_plugin_declares_non_differentiable_is_refused():
    """A point light's position (Mitsuba: NonDifferentiable; its samples carry no gradient):
    its gradient was 0 in every version, so a fit kept the starting value without a word."""
    d = {"shapes": [{"type": "sphere", "material": "m"}], "materials": {"m": {"base_color": [0.5, 0.5, 0.5]}},
         "lights": [{"type": "point", "name": "pl", "position": [0, 3, 3], "intensity": 20}],
         "render": {"resolution": [8, 8], "spp": 4}}
    scene = draaw_mi.load_scene(d)
    ref = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(DraawError, match=r"fit: parameter 'pl.position' .* declared non-differentiable"):
        draaw_mi.fit(scene, ref, ["pl.position"], iterations=1, spp=4, progress=False)
    res = draaw_mi.fit(scene, ref, ["pl.intensity"], iterations=2, spp=4, progress=False)
    assert np.isfinite(res.losses).all()


def test_an_8_bit_texture_fits_from_a_toml_scene_and_is_refused_from_an_xml_one(tmp_path):
    """A TOML/dict scene reads a PNG as linear floats: its roughness map is fitted (it was
    refused: Mitsuba kept the integers, which have no gradient). Mitsuba still keeps an XML
    scene's PNG as integers: the error says so and what to use instead."""
    from PIL import Image
    Image.fromarray(np.full((4, 4), 128, np.uint8)).save(tmp_path / "rough.png")
    d = {"shapes": [{"type": "sphere", "material": "m"}],
         "materials": {"m": {"base_color": [0.5, 0.5, 0.5], "roughness": str(tmp_path / "rough.png")}},
         "lights": [{"type": "point", "position": [0, 3, 3], "intensity": 20}],
         "render": {"resolution": [8, 8], "spp": 4}}
    res = draaw_mi.fit(draaw_mi.load_scene(d), np.zeros((8, 8, 3), np.float32), ["m.roughness"],
                       iterations=2, spp=4, progress=False)
    fitted = np.asarray(res.values["m.roughness"])
    assert fitted.shape == (4, 4, 1) and np.all((fitted >= 0) & (fitted <= 1)) and np.any(fitted != np.float32(128 / 255))
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><integrator type="path"/><sensor type="perspective"><film type="hdrfilm">'
        '<integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>'
        '<bsdf type="draaw" id="m"><texture type="bitmap" name="roughness"><string name="filename" '
        'value="rough.png"/><boolean name="raw" value="true"/></texture></bsdf>'
        '<shape type="sphere"><ref id="m"/></shape><emitter type="constant"/></scene>')
    with pytest.raises(DraawError, match=r"8-bit image texture.*float image \(EXR\), or load the scene from a TOML"):
        draaw_mi.fit(draaw_mi.load_scene(str(tmp_path / "s.xml")), np.zeros((8, 8, 3), np.float32),
                     ["m.roughness"], iterations=1, spp=4, progress=False)


def test_a_parameter_without_any_gradient_is_reported():
    """A material no camera ray reaches gets a zero gradient in every iteration: the fit says
    so (after 5 iterations) instead of returning its starting value as a fitted one; the
    visible material's parameter is not named."""
    import warnings
    d = {"shapes": [{"type": "sphere", "material": "m"}, {"type": "sphere", "material": "hidden",
                                                         "center": [0, 0, -20]}],
         "materials": {"m": {"base_color": [0.5, 0.5, 0.5]}, "hidden": {"base_color": [0.2, 0.5, 0.5]}},
         "lights": [{"type": "point", "position": [0, 3, 3], "intensity": 20}],
         "camera": {"origin": [0, 0, 5], "target": [0, 0, 0]}, "render": {"resolution": [8, 8], "spp": 4}}
    ref = np.zeros((8, 8, 3), np.float32)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        draaw_mi.fit(draaw_mi.load_scene(d), ref, ["m.roughness", "hidden.roughness"], iterations=6, spp=4,
                     progress=False)
    said = [str(w.message) for w in caught if str(w.message).startswith("fit:")]
    assert len(said) == 1 and said[0].startswith("fit: hidden.roughness got a zero gradient in all of the first 5")


def test_bad_arguments(fit_scene):
    ref = np.zeros((RES, RES, 3), np.float32)
    with pytest.raises(DraawError, match="loss='l3'"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness"], loss="l3", progress=False)
    with pytest.raises(DraawError, match="no parameter 'target.rough'"):
        draaw_mi.fit(fit_scene, ref, ["target.rough"], iterations=1, progress=False)
    with pytest.raises(DraawError, match="not differentiable"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness"], version="path", iterations=1, progress=False)
    with pytest.raises(DraawError, match="2 reference"):
        draaw_mi.fit(fit_scene, [ref, ref], ["target.roughness"], iterations=1, progress=False)
    with pytest.raises(DraawError, match="NaN"):
        draaw_mi.fit(fit_scene, ref * np.nan, ["target.roughness"], iterations=1, progress=False)
    with pytest.raises(DraawError, match="iterations=0"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness"], iterations=0, progress=False)
    with pytest.raises(DraawError, match="twice"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness", "target.roughness.value"], iterations=1, progress=False)
    with pytest.raises(DraawError, match="init names"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness"], init={"target.metallic": 0.1}, iterations=1,
                     progress=False)
    with pytest.raises(DraawError, match="average_last"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness"], average_last=0, iterations=1, progress=False)
    smoke = draaw_mi.load_scene(os.path.join(SCENES, "smoke.toml"), resolution=(8, 8))
    with pytest.raises(DraawError, match="participating media, which Mitsuba's 'prb'"):
        draaw_mi.fit(smoke, np.zeros((8, 8, 3), np.float32), ["plume.albedo"], version="prb", iterations=1,
                     progress=False)
    with pytest.raises(DraawError, match=r"init target.roughness=1.5; expected values in \[0.0, 1.0\]"):
        draaw_mi.fit(fit_scene, ref, ["target.roughness"], init={"target.roughness": 1.5}, iterations=1,
                     progress=False)


def test_cli_fit_writes_scene_and_plot(tmp_path, fit_scene, capsys):
    ref = _reference(fit_scene, 0.35, 0.5, spp=64)
    ref_path = str(tmp_path / "ref.exr")
    draaw_mi.write_exr(ref_path, ref)
    out, plot = tmp_path / "fitted.toml", tmp_path / "fit.png"
    rc = main(["fit", os.path.join(SCENES, "fit_sphere.toml"), "--reference", ref_path, "--param",
               "target.roughness", "--iterations", "8", "--spp", "4", "--version", _version(),
               "--lr", "0.1", "--seed", "3", "-o", str(out), "--plot", str(plot)])
    assert rc == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    fitted = draaw_mi.load_scene(str(out))
    r = float(np.array(fitted.params["target.roughness.value"]).ravel()[0])
    # the written value is the one printed, and the 8 steps of lr 0.1 (log space) moved it from
    # the start (0.5) to the truth (0.35); library fits with these arguments end at 0.340 +- 0.003
    # (Adam's first steps are sign-like, so runs are not bit-identical)
    assert f"target.roughness = {round(r, 5)}" in printed
    assert abs(r - 0.35) < 0.04, r
    png = matplotlib.image.imread(str(plot))
    assert png.shape[0] > 200 and png[..., :3].std() > 0.05
    capsys.readouterr()
    assert main(["fit", os.path.join(SCENES, "fit_sphere.toml"), "--reference", ref_path, "--param",
                 "target.metallic", "--iterations", "4", "--spp", "4", "--exposure", "fit"]) == 0
    assert "exposure = " in capsys.readouterr().out
    assert main(["fit", os.path.join(SCENES, "fit_sphere.toml"), "--reference", ref_path,
                 "--param", "nomat.roughness", "--iterations", "2"]) == 2


# ----------------------------------------------------------------------------- slow
@pytest.mark.slow
@pytest.mark.parametrize("rough,metal", [(0.05, 0.05), (0.05, 0.95), (0.95, 0.05), (0.95, 0.95), (0.25, 0.8)])
def test_accuracy_128(rough, metal):
    """Issue 6 acceptance at full size: within 0.02 from (0.5, 0.5); benchmarks/fit_accuracy.py
    records the timed table."""
    scene = draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(128, 128))
    ref = _reference(scene, rough, metal, spp=2048, seed=77)
    res = _fit(scene, ref, iterations=150)
    assert abs(res.values["target.roughness"] - rough) < 0.02
    assert abs(res.values["target.metallic"] - metal) < 0.02


def test_a_view_without_fov_has_the_scene_cameras():
    """A ``views`` table without ``fov`` took [camera]'s default (40 degrees) whatever the
    scene's was; the scene's own camera written as a view now renders the scene's image."""
    from conftest import tiny_description
    from draaw_mi.fitting.views import view_sensors as _views
    desc = tiny_description()
    desc["camera"].update(fov=25.0, fov_axis="y")          # (a 32x24 film: x_fov is 32.9)
    scene = draaw_mi.load_scene(desc)
    x_fov = float(np.array(scene.params["sensor.x_fov"]).ravel()[0])
    assert x_fov == pytest.approx(2 * np.degrees(np.arctan(32 / 24 * np.tan(np.radians(12.5)))), rel=1e-5)
    view = {k: desc["camera"][k] for k in ("origin", "target")}
    (sensor,) = _views(scene, [view])
    assert float(np.array(mi.traverse(sensor)["x_fov"]).ravel()[0]) == pytest.approx(x_fov, rel=1e-5)
    integ = mi.load_dict({"type": "path", "max_depth": 3})
    own, as_view = (np.array(mi.render(scene.mi_scene, sensor=s, integrator=integ, spp=4, seed=1))
                    for s in (scene.mi_scene.sensors()[0], sensor))
    np.testing.assert_allclose(as_view, own, atol=1e-5)
    (wide,) = _views(scene, [dict(view, fov=60.0)])                  # a given fov is kept
    assert float(np.array(mi.traverse(wide)["x_fov"]).ravel()[0]) == pytest.approx(60.0)
    with pytest.raises(draaw_mi.DraawError, match=r"views\[0\] has fov_axis but no fov"):
        _views(scene, [dict(view, fov_axis="y")])


def test_loss_formulas_and_the_masked_exposure_scale():
    """Each loss against its formula in numpy, and the exposure scale from the unmasked pixels
    only (a clipped pixel 4x too bright in the render must not pull the scale)."""
    rng = np.random.default_rng(3)
    ref = rng.uniform(0.1, 1.0, (4, 5, 3))
    img = ref * 0.5
    img[0, 0] *= 4.0                                               # the clipped pixel
    mask = np.ones_like(ref)
    mask[0, 0] = 0.0
    T = lambda a: mi.TensorXf(a.astype(np.float32))                # noqa: E731
    lv, s = _loss(T(img), T(ref), "l2", "fit", mask=T(mask))
    assert float(s[0]) == pytest.approx(2.0, rel=1e-5)             # <r, r> / <img, r> over the mask
    assert float(lv[0]) == pytest.approx(np.mean(((img * 2.0 - ref) * mask) ** 2), abs=1e-7)
    lv, _ = _loss(T(img), T(ref), "relative_l2", "none")
    assert float(lv[0]) == pytest.approx(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2)), rel=1e-5)
    lv, _ = _loss(T(img), T(ref), "l1", "none")
    assert float(lv[0]) == pytest.approx(np.mean(np.abs(img - ref)), rel=1e-5)


@pytest.mark.parametrize("level,loss", [(0.0, 0.25), (-0.1, 0.36)], ids=["black", "negative"])
def test_the_exposure_scale_is_one_for_a_render_without_a_positive_match(level, loss):
    """A render whose dot product with the reference is not positive (all black: 0; all
    -0.1: < 0) has no exposure scale: it stays 1 and the loss is the plain one, mean((level -
    0.5)^2) against a reference of 0.5 (the scale was inf: a NaN loss, or -5: a zero loss for
    a render of the wrong sign)."""
    T = lambda a: mi.TensorXf(np.asarray(a, np.float32))          # noqa: E731
    lv, s = _loss(T(np.full((4, 4, 3), level)), T(np.full((4, 4, 3), 0.5)), "l2", "fit")
    assert float(s[0]) == 1.0
    assert float(lv[0]) == pytest.approx(loss, rel=1e-6)
