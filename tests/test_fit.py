"""fit(): recovery of known parameters, hard targets, robustness, kernel reuse, CLI."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.errors import DraawError

from conftest import SCENES

RES = 32


def _version():
    from draaw_mi import integrators
    return "v4" if "draaw_v4" in getattr(integrators, "PLUGINS", []) else "prb"


@pytest.fixture(scope="module")
def fit_scene():
    return draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(RES, RES))


def _reference(scene, rough, metal, spp=256, seed=1234):
    p = scene.params
    p["target.roughness.value"], p["target.metallic.value"] = rough, metal
    p.update()
    ref = np.array(draaw_mi.render(scene, version="path", spp=spp, seed=seed))
    p["target.roughness.value"], p["target.metallic.value"] = 0.5, 0.5
    p.update()
    return ref


def test_recovers_roughness_and_metallic(fit_scene):
    ref = _reference(fit_scene, 0.25, 0.8)
    res = draaw_mi.fit(fit_scene, ref, ["target.roughness", "target.metallic"], version=_version(), spp=8,
                       iterations=80, lr=0.05, progress=False)
    assert abs(res.values["target.roughness"] - 0.25) < 0.06
    assert abs(res.values["target.metallic"] - 0.8) < 0.06
    assert res.losses[-1] < 0.5 * res.losses[0]
    assert res.kernel_compiles == 0          # kernels compiled in the first iteration only


@pytest.mark.parametrize("rough,metal", [(0.02, 1.0), (0.5, 0.0), (0.9, 1.0)])
def test_hard_targets_stay_finite_and_in_range(fit_scene, rough, metal):
    ref = _reference(fit_scene, rough, metal, spp=64)
    res = draaw_mi.fit(fit_scene, ref, ["target.roughness", "target.metallic"], version=_version(), spp=4,
                       iterations=12, lr=0.1, progress=False)
    for h in res.history:
        assert np.isfinite(h["loss"])
        for v in h["values"].values():
            assert 0.0 <= v <= 1.0
    assert np.isfinite(res.image).all()


def test_exposure_fit_is_insensitive_to_a_global_scale(fit_scene):
    ref = _reference(fit_scene, 0.3, 0.6) * 1.5
    res = draaw_mi.fit(fit_scene, ref, ["target.metallic"], version=_version(), spp=8, iterations=40,
                       lr=0.05, exposure="fit", progress=False, init={"target.metallic": 0.3})
    assert abs(res.exposure_stops - np.log2(1.5)) < 0.1
    assert abs(res.values["target.metallic"] - 0.6) < 0.1


def test_noisy_reference_and_colour(fit_scene):
    rng = np.random.default_rng(0)
    ref = _reference(fit_scene, 0.4, 0.3, spp=16)             # a noisy (16 spp) reference
    ref = ref + rng.normal(0, 0.02, ref.shape).astype(np.float32)
    res = draaw_mi.fit(fit_scene, ref, ["target.roughness", "target.base_color"], version=_version(), spp=4,
                       iterations=10, progress=False)
    assert np.isfinite(res.losses).all()
    assert len(res.values["target.base_color"]) == 3 and all(0 <= c <= 1 for c in res.values["target.base_color"])


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


def test_cli_fit_writes_scene_and_plot(tmp_path, fit_scene, capsys):
    ref = _reference(fit_scene, 0.35, 0.5, spp=64)
    ref_path = str(tmp_path / "ref.exr")
    draaw_mi.write_exr(ref_path, ref)
    out, plot = tmp_path / "fitted.toml", tmp_path / "fit.png"
    rc = main(["fit", os.path.join(SCENES, "fit_sphere.toml"), "--reference", ref_path, "--param",
               "target.roughness", "--iterations", "8", "--spp", "4", "--version", _version(),
               "-o", str(out), "--plot", str(plot)])
    assert rc == 0, capsys.readouterr().err
    fitted = draaw_mi.load_scene(str(out))
    r = float(np.array(fitted.params["target.roughness.value"]).ravel()[0])
    assert 0.0 <= r <= 1.0 and r != 0.5
    assert plot.stat().st_size > 1000
    assert main(["fit", os.path.join(SCENES, "fit_sphere.toml"), "--reference", ref_path,
                 "--param", "nomat.roughness", "--iterations", "2"]) == 2
