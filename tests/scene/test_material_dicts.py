"""``[materials.NAME]`` tables (draaw_mi.scene.material_dicts), from a review: a plain Mitsuba
BSDF's numbers are held to the ranges where it renders right; a draaw material's texture
files are range-checked naming the scene key and the file, and a colour file's small
overshoot below 0 is read as 0 (as a ``diffuse`` reflectance's is let through); a nested
checkerboard's values are checked; the scene-file default of ``two_sided`` is documented."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import SceneError

BASE = {"render": {"resolution": [8, 8], "spp": 1}, "camera": {"origin": [0, 0, 3], "target": [0, 0, 0]},
        "shapes": [{"type": "sphere", "material": "m"}], "lights": [{"type": "constant"}]}
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _load(materials):
    return draaw_mi.load_scene(dict(BASE, materials=materials))


@pytest.mark.parametrize("table, match", [
    # int_ior = 0 rendered ~82% NaN pixels; metallic = 3 brighter than its light
    ({"type": "dielectric", "int_ior": 0.0}, r"materials\.m\.int_ior: 0\.0 is out of range; expected > 0"),
    ({"type": "dielectric", "ext_ior": -1.0}, r"materials\.m\.ext_ior: -1\.0 is out of range; expected > 0"),
    ({"type": "roughdielectric", "int_ior": 0.0}, r"materials\.m\.int_ior: 0\.0 is out of range"),
    ({"type": "roughconductor", "alpha": -0.2}, r"materials\.m\.alpha: -0\.2 is out of range; expected >= 0"),
    ({"type": "roughplastic", "alpha": -0.3}, r"materials\.m\.alpha: -0\.3 is out of range"),
    ({"type": "roughconductor", "alpha_u": -0.1, "alpha_v": 0.1}, r"materials\.m\.alpha_u: -0\.1"),
    ({"type": "roughconductor", "alpha": [[0.1, -0.5], [0.1, 0.1]]},
     r"materials\.m\.alpha: texture array has the value -0\.5 at pixel \(x=1, y=0\), channel 0; "
     r"expected finite values >= 0"),
    ({"type": "principled", "metallic": 3.0},
     r"materials\.m\.metallic: 3\.0 is out of range; expected a value in \[0\.0, 1\.0\]"),
    ({"type": "principled", "roughness": -0.5}, r"materials\.m\.roughness: -0\.5 is out of range"),
    ({"type": "principled", "clearcoat_gloss": 1.5}, r"materials\.m\.clearcoat_gloss: 1\.5 is out of range"),
    ({"type": "principledthin", "diff_trans": 2.5},
     r"materials\.m\.diff_trans: 2\.5 is out of range; expected a value in \[0\.0, 2\.0\]"),
])
def test_a_plain_bsdfs_numbers_are_held_to_their_ranges(table, match):
    with pytest.raises(SceneError, match=match):
        _load({"m": table})


def test_a_plain_bsdfs_numbers_in_range_load():
    for table in ({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}, {"type": "roughconductor", "alpha": 0.0},
                  {"type": "principled", "metallic": 1.0, "roughness": 0.0, "sheen": 1.0},
                  {"type": "principledthin", "diff_trans": 2.0}, {"type": "dielectric", "int_ior": "bk7"}):
        _load({"m": table})


def _exr(path, arr):
    draaw_mi.write_exr(str(path), np.asarray(arr, np.float32))
    return str(path)


@pytest.mark.parametrize("param, texel, expected", [("roughness", 1.5, r"in \[0, 1\]"),
                                                    ("metallic", -0.5, r"in \[0, 1\]"),
                                                    ("base_color", -0.5, r">= 0"),
                                                    ("normalmap", 3.0, r"in \[-0\.01, 1\.01\]")])
def test_a_draaw_texture_files_range_error_names_the_scene_key_and_the_file(tmp_path, param, texel, expected):
    """Of two materials, the one whose file is out of range is named, with the file and the
    first bad pixel (the BSDF's error named neither: "draaw BSDF: roughness=1.5 ...")."""
    arr = np.full((2, 3, 3), 0.5, np.float32)
    arr[1, 2, 0] = texel
    bad = _exr(tmp_path / "bad.exr", arr)
    ok = _exr(tmp_path / "ok.exr", np.full((2, 3, 3), 0.5))
    with pytest.raises(SceneError, match=rf"materials\.ball\.{param}: texture (file )?'{bad}' has the value "
                                         rf"{texel:g} at pixel \(x=2, y=1\), channel 0; "
                                         rf"expected finite values {expected}"):
        draaw_mi.load_scene(dict(BASE, materials={"floor": {param: ok}, "ball": {param: bad}},
                                 shapes=[{"type": "sphere", "material": "ball"},
                                         {"type": "rectangle", "material": "floor", "translate": [0, -1, 0]}]))


def test_a_draaw_constant_normal_map_out_of_range_names_the_scene_key():
    with pytest.raises(SceneError, match=r"materials\.m\.normalmap: \[2\.0, 2\.0, 2\.0\] has the component 2; "
                                         r"expected finite values in \[-0\.01, 1\.01\]"):
        _load({"m": {"normalmap": [2.0, 2.0, 2.0]}})
    _load({"m": {"normalmap": [-1.0, 0.0, 1.0], "normalmap_encoding": "signed"}})


def test_a_draaw_colour_files_small_overshoot_is_read_as_zero(tmp_path):
    """A resampled EXR's -1e-4 (Lanczos overshoot) loads for a draaw base_color as for a
    diffuse reflectance, stored as 0; below -0.01 it is refused for both, naming the file."""
    arr = np.full((4, 4, 3), 0.5, np.float32)
    arr[1, 2, 0] = -1e-4
    path = _exr(tmp_path / "bc.exr", arr)
    scene = _load({"m": {"base_color": path}})
    data = np.array(scene.params["m.base_color.data"])
    assert data.min() == 0.0 and data[1, 2, 0] == 0.0 and data[0, 0, 0] == 0.5
    _load({"m": {"type": "diffuse", "reflectance": path}})
    arr[1, 2, 0] = -0.5
    path = _exr(tmp_path / "bc2.exr", arr)
    for table in ({"base_color": path}, {"type": "diffuse", "reflectance": path}):
        with pytest.raises(SceneError, match=r"materials\.m\.(base_color|reflectance): texture '.*bc2\.exr' has "
                                             r"the value -0\.5 at pixel \(x=2, y=1\), channel 0; "
                                             r"expected finite values >= 0"):
            _load({"m": table})


@pytest.mark.parametrize("table, match", [
    ({"roughness": {"type": "checkerboard", "color0": float("nan"), "color1": 0.5}}, r"roughness=nan"),
    ({"metallic": {"type": "checkerboard", "color0": 7.0, "color1": -3.0}}, r"metallic=7"),
])
def test_a_nested_checkerboards_values_are_checked_at_load(table, match):
    with pytest.raises(SceneError, match=match):
        _load({"m": table})


def test_the_scene_file_default_of_two_sided_is_documented():
    """A scene file's draaw material is two-sided, the plugin's default one-sided: both
    guides say so (the plugin reference's false was all they said)."""
    import mitsuba as mi
    scene = _load({"m": {"roughness": 0.3}})
    assert "two_sided=True" in str(scene.mi_scene.shapes()[0].bsdf())
    assert "two_sided=False" in str(mi.load_dict({"type": "draaw"}))
    for guide in ("material.md", "scenes.md"):
        text = " ".join(open(os.path.join(ROOT, "docs", "guides", guide), encoding="utf-8").read().split())
        assert "draaw` materials are two-sided" in text and "`two_sided = false`" in text, guide


@pytest.mark.parametrize("material, key", [({"roughness": [[0.4]]}, "roughness"),
                                           ({"base_color": [[[0.5, 0.5, 0.5], [0.2, 0.2, 0.2]]]}, "base_color"),
                                           ({"type": "diffuse", "reflectance": [[0.4]]}, "reflectance")])
def test_a_texture_below_2x2_texels_takes_new_values(material, key):
    """A 1x1 (or 1-row) texture loaded and rendered, then every new value failed: the CLI's
    --set with a traceback and exit 1, a fit or the preview in Mitsuba's words ("must be at
    least 2x2 pixels in size"); a mesh's 4x1 palette likewise. Its one-texel axis is repeated
    to two: it takes new values, and renders as the texture given (a copy of each texel
    beside it; here as the constant of its mean, the same lookups)."""
    desc = {"render": {"resolution": [8, 8], "filter": "box"}, "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
            "materials": {"m": material}, "shapes": [{"type": "sphere", "material": "m"}],
            "lights": [{"type": "constant"}]}
    scene = draaw_mi.load_scene(desc)
    k = scene.key(f"m.{key}")
    texels = np.array(scene.params[k])
    assert texels.shape[:2] == (2, 2)
    img = np.array(draaw_mi.render(scene, spp=16, seed=1))
    if key != "base_color":                   # a 1x1 texture renders as its constant
        const = np.array(draaw_mi.render(draaw_mi.load_scene(
            {**desc, "materials": {"m": {**material, key: 0.4}}}), spp=16, seed=1))
        # (the same samples; V4 specialises its kernel to a constant roughness, so pixels of
        # the draaw one differ by up to 0.02 where the means agree to 2e-6)
        assert abs(img.mean() - const.mean()) < 1e-4 * const.mean()
        assert key == "roughness" or np.allclose(img, const, atol=1e-6)
    scene.params[k] = type(scene.params[k])(texels * 0.5)           # (Mitsuba had refused this)
    scene.params.update()
    assert np.isfinite(np.array(draaw_mi.render(scene, spp=1))).all()
    if "type" not in material:                 # the draaw plugin given the array itself
        import mitsuba as mi
        bsdf = mi.load_dict({"type": "draaw", key: mi.TensorXf(np.array(material[key], np.float32))})
        assert np.array(mi.traverse(bsdf)[f"{key}.data"]).shape[:2] == (2, 2)


def test_a_meshs_one_row_palette_texture_loads_and_takes_new_values(tmp_path):
    """An OBJ whose MTL maps a 4x1 palette PNG (common in exported models): a refusal of
    textures below 2x2 had stopped it loading; it renders its palette's colours across the quad
    and its texels take new values."""
    import mitsuba as mi
    mi.Bitmap(np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0]]], np.uint8)).write(str(tmp_path / "pal.png"))
    (tmp_path / "quad.mtl").write_text("newmtl pal\nKd 1 1 1\nmap_Kd pal.png\n")
    (tmp_path / "quad.obj").write_text("mtllib quad.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
                                       "vt 0.1 0.5\nvt 0.9 0.5\nvt 0.9 0.5\nvt 0.1 0.5\nusemtl pal\n"
                                       "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    scene = draaw_mi.load_scene({"render": {"resolution": [16, 16], "filter": "box"},
                                 "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
                                 "shapes": [{"name": "q", "file": str(tmp_path / "quad.obj")}],
                                 "lights": [{"type": "constant", "intensity": 1.0}]})
    row = np.array(draaw_mi.render(scene, version="v4", spp=4, seed=0))[8, 4:13:4, :3]
    assert np.ptp(row, axis=0).max() > 0.3              # the palette's colours, not one colour
    assert row[1, 2] > row[1, 0] and row[2, 0] > row[2, 2]            # blue mid-way, yellow to the right
    key = next(k for k in scene.params.keys() if k.endswith("base_color.data"))
    scene.params[key] = type(scene.params[key])(np.array(scene.params[key]) * 0.5)
    scene.params.update()                                               # (Mitsuba had refused a 4x1 map)
