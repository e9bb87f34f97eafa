"""I/O and optimiser hard cases: overflow, NaN/Inf, empty and huge values, poisoned gradients."""
from __future__ import annotations

import drjit as dr
import matplotlib.image
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi


@pytest.mark.parametrize("value,expected", [
    (1e39, np.inf), (-1e39, -np.inf), (3.0e38, np.float32(3.0e38)), (1e-45, np.float32(1e-45)), (0.0, 0.0),
])
def test_exr_float32_extremes(tmp_path, value, expected):
    img = np.full((2, 2, 3), value, dtype=np.float64)
    with np.errstate(over="ignore"):
        draaw_mi.write_exr(str(tmp_path / "x.exr"), img)
    back = draaw_mi.read_exr(str(tmp_path / "x.exr"))
    assert np.all(back == expected)


def test_exr_keeps_nan_png_sanitises_it(tmp_path):
    img = np.array([[[np.nan, np.inf, -np.inf], [0.5, 2.0, -1.0]]], np.float32)
    draaw_mi.write_exr(str(tmp_path / "n.exr"), img)
    back = draaw_mi.read_exr(str(tmp_path / "n.exr"))
    assert np.isnan(back[0, 0, 0]) and np.isposinf(back[0, 0, 1])      # EXR: data as is
    draaw_mi.write_png(str(tmp_path / "n.png"), img)
    png = matplotlib.image.imread(str(tmp_path / "n.png"))
    assert np.isfinite(png).all() and png[0, 0, 0] == 0 and png[0, 0, 1] == 1 and png[0, 1, 2] == 0


def test_half_exr_overflow_is_inf(tmp_path):
    img = np.full((1, 1, 3), 1e6, np.float32)                            # > 65504
    with pytest.warns(RuntimeWarning, match=r"write_exr: values beyond half's range \(\+-65504\) are stored as \+-inf"):
        draaw_mi.write_exr(str(tmp_path / "h.exr"), img, half=True)
    assert np.isposinf(draaw_mi.read_exr(str(tmp_path / "h.exr"))).all()


def test_one_nan_gradient_does_not_poison_the_fit(tiny_scene, monkeypatch):
    """fit() zeroes non-finite gradient entries before every Adam step (design.md §8).

    The NaN is injected into d(parameter)/d(latent) on the second iteration (value unchanged):
    a NaN in the render's adjoint would be dropped by Mitsuba's image block before it reaches
    the parameters, so the loss is not the place to inject it. Without the guard, Adam's moments
    turn NaN and every later iterate is projected onto a bound of the roughness range."""
    from draaw_mi.fitting.params import FitParam
    ref = np.array(draaw_mi.render(tiny_scene, version="path", spp=16))     # truth: roughness 0.4
    calls = {"n": 0}
    real = FitParam.from_latent

    def poisoned(self, u):
        v = real(self, u)
        if not dr.grad_enabled(u):
            return v
        calls["n"] += 1
        if calls["n"] == 2:                        # second iteration: a NaN derivative
            return dr.replace_grad(v, v * dr.select(mi.Bool(True), mi.Float(np.nan), 1.0))
        return v
    monkeypatch.setattr(FitParam, "from_latent", poisoned)
    res = draaw_mi.fit(tiny_scene, ref, ["ball.roughness"], version="v4", spp=2, iterations=5, progress=False)
    assert calls["n"] == 5, "fit() must map its latents through FitParam.from_latent (patched here)"
    vals = np.array([h["values"]["ball.roughness"] for h in res.history])
    assert np.isfinite(vals).all() and np.isfinite([h["loss"] for h in res.history]).all()
    # no jump: the iterates stay near the truth, far from the range's bounds (0.019, 1)
    assert np.all((vals > 0.25) & (vals < 0.6)), vals


def _image(tmp_path, name, bad=None, value=None, half=False):
    arr = np.full((8, 16, 3), 0.3, np.float32)
    if bad is not None:
        arr[bad] = value
    path = str(tmp_path / name)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)      # (an inf made on purpose: said)
        draaw_mi.write_exr(path, arr, half=half)
    return path


@pytest.mark.parametrize("value, shown", [(1e6, "inf"), (np.nan, "nan")])
def test_an_environment_map_with_a_bad_pixel_is_refused_at_load(tmp_path, value, shown):
    """A half-float HDRI stores a sun above 65504 as +Inf: it loaded, and V3 / V4 / path
    rendered Inf and NaN pixels. Small negative texels (resampling overshoot) rendered finite
    before and still load."""
    from conftest import tiny_description
    from draaw_mi.errors import SceneError
    sky = _image(tmp_path, "sky.exr", (2, 5, 1), value, half=True)
    d = tiny_description()
    d["lights"] = [{"type": "envmap", "file": sky}]
    with pytest.raises(SceneError, match=rf"lights\[0\]\.file: environment map .*sky.exr' has the "
                                         rf"value {shown} at pixel \(x=5, y=2\), channel 1"):
        draaw_mi.load_scene(d)
    d["lights"] = [{"type": "envmap", "file": _image(tmp_path, "ok.exr", (2, 5, 1), -3e-3, half=True)}]
    img = np.array(draaw_mi.render(draaw_mi.load_scene(d), version="v4", spp=2, seed=0, post=[]))
    assert np.isfinite(img).all() and img.mean() > 0


def test_textures_of_other_mitsuba_bsdfs_are_checked_like_the_draaw_ones(tmp_path):
    """A NaN texel of a ``diffuse`` reflectance rendered NaN in every version (the same file
    as a draaw base_color was refused); a negative one is no reflectance either."""
    from conftest import tiny_description
    from draaw_mi.errors import SceneError
    d = tiny_description()                              # resampling overshoot: loads
    d["materials"]["ground"] = {"type": "diffuse", "reflectance": _image(tmp_path, "over.exr", (0, 0, 0), -3e-3)}
    draaw_mi.load_scene(d)
    for name, value, shown in (("nan.exr", np.nan, "nan"), ("neg.exr", -1.0, "-1")):
        d = tiny_description()
        d["materials"]["ground"] = {"type": "diffuse", "reflectance": _image(tmp_path, name, (0, 0, 0), value)}
        with pytest.raises(SceneError, match=rf"materials\.ground\.reflectance: texture .*{name}' has "
                                             rf"the value {shown} at pixel \(x=0, y=0\)"):
            draaw_mi.load_scene(d)
    d["materials"]["ground"] = {"type": "diffuse", "reflectance": np.full((2, 2, 3), np.nan)}
    with pytest.raises(SceneError, match="reflectance: texture array has a non-finite"):
        draaw_mi.load_scene(d)


@pytest.mark.parametrize("table, key, shown", [
    ({"type": "plastic", "int_ior": float("nan")}, "int_ior", "nan"),
    ({"type": "roughconductor", "alpha": float("inf")}, "alpha", "inf"),
    ({"type": "roughdielectric", "alpha": 1e39}, "alpha", "1e\\+39"),
])
def test_a_plain_number_of_another_mitsuba_bsdf_must_be_finite(table, key, shown):
    """TOML allows nan and inf: a plastic's int_ior = nan loaded and rendered NaN pixels
    (78 of 192 values in path), while the same value as an array was refused."""
    from conftest import tiny_description
    from draaw_mi.errors import SceneError
    d = tiny_description()
    d["materials"]["ground"] = table
    with pytest.raises(SceneError, match=rf"materials\.ground\.{key}: {shown} is (not finite|beyond float32)"):
        draaw_mi.load_scene(d)


def test_an_integer_index_of_refraction_is_a_number():
    """``int_ior = 2`` (an integer in TOML) failed in Mitsuba: "The property "int_ior" has the
    wrong type (expected string, got integer)"; it is the number 2.0."""
    from conftest import tiny_description
    d = tiny_description()
    d["materials"]["ground"] = {"type": "roughplastic", "alpha": 0.2, "int_ior": 2}
    scene = draaw_mi.load_scene(d)
    plastic = [str(s.bsdf()) for s in scene.mi_scene.shapes() if "RoughPlastic" in str(s.bsdf())]
    # eta = int_ior / ext_ior, Mitsuba's default exterior being air (1.000277)
    assert len(plastic) == 1 and f"eta = [{2 / 1.000277:.6g}]" in plastic[0], plastic


def test_a_camera_target_float32_cannot_tell_from_its_origin_is_refused():
    """origin [1e4, 1, 0] and a target 1e-4 away are one point in float32: the camera
    transform was NaN and the image plain sky, without a word."""
    from conftest import tiny_description
    from draaw_mi.errors import SceneError
    d = tiny_description()
    d["camera"] = {"origin": [1e4, 1.0, 0.0], "target": [1e4 - 1e-4, 1.0, 0.0]}
    with pytest.raises(SceneError, match=r"camera\.target: is 0\.0001 from 'origin', too close .* float32"):
        draaw_mi.load_scene(d)
    d["camera"] = {"origin": [1e4, 1.0, 0.0], "target": [1e4 - 1.0, 1.0, 0.0]}    # 1 unit: fine
    sc = draaw_mi.load_scene(d)
    assert np.isfinite(np.array(sc.params["sensor.to_world"].matrix)).all()


@pytest.mark.parametrize("scale", [1e-4, 1e-3, 1e4])
def test_a_bare_mesh_of_any_size_is_framed_and_not_clipped(tmp_path, scale):
    """The automatic camera kept the default clip planes (0.01, 1e4): a mesh 1e-3 or 1e4
    across rendered as plain sky; the automatic light's intensity had a floor that made a mesh
    1e-4 across 5x too bright. Its image now equals the unit-size one."""
    import trimesh
    imgs = []
    for s in (1.0, scale):
        mesh = trimesh.creation.box(extents=(1.0, 0.6, 0.8))
        mesh.apply_scale(s)
        path = str(tmp_path / f"box_{s:g}.obj")
        mesh.export(path)
        sc = draaw_mi.load_scene(path, resolution=(24, 24))
        imgs.append(np.array(draaw_mi.render(sc, version="v4", spp=4, seed=0, post=[])))
    assert np.abs(imgs[0] - imgs[1]).max() < 1e-3 * max(imgs[0].max(), 1e-3) + 1e-4
    assert imgs[0].std() > 0.01                                   # the box is in the picture
