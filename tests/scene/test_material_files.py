"""Image files, arrays and numpy values of a ``[materials.NAME]`` table of the draaw BSDF
(draaw_mi.scene.material_dicts): 8/16-bit files read as linear floats (sRGB-decoded for a
colour, raw for data), unreadable files and normal maps of the wrong channel count refused
naming the file or the field, numpy values taken as the numbers and lists they hold."""
from __future__ import annotations

import copy
import warnings

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import DraawError, RenderError
from draaw_mi.scene.values import value_like

from conftest import tiny_description


def _srgb_decode(code8):
    """IEC 61966-2-1 decoding of an 8-bit sRGB code (independent of Mitsuba's)."""
    c = np.asarray(code8, np.float64) / 255
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _png(path, value, channels):
    from PIL import Image
    a = np.full((4, 4, channels), value, np.uint8)
    Image.fromarray(a[..., 0] if channels == 1 else a).save(path)
    return str(path)


def _scene(ball, res=(12, 10)):
    d = tiny_description(resolution=list(res))
    d["materials"]["ball"] = dict({"roughness": 0.4, "base_color": [0.5, 0.5, 0.5]}, **ball)
    return d


def _render(scene):
    return np.array(draaw_mi.render(scene, spp=4, seed=3))


def test_8_bit_files_are_float_textures_that_render_as_before_and_take_float_values(tmp_path):
    """An 8-bit PNG was kept as TensorXu8: ``params[...] = 0.9`` truncated every texel to 0 (a
    mirror; a base colour of 0.2 rendered as black). Read as linear floats, the texels are the
    decoded values (sRGB for the colour, code/255 for the roughness), the render equals the
    one of arrays of those values (as Mitsuba's integer texture rendered it: the same image to
    3e-8; a constant, not spatially varying, is sampled otherwise), and a float written in
    stays that float (the render equals the arrays')."""
    base = _png(tmp_path / "base.png", 188, 3)
    rough = _png(tmp_path / "rough.png", 102, 1)
    scene = draaw_mi.load_scene(_scene({"base_color": base, "roughness": rough}))
    p = scene.params
    assert type(p["ball.base_color.data"]).__name__ == "TensorXf"
    np.testing.assert_allclose(np.array(p["ball.base_color.data"]), _srgb_decode(188), atol=1e-6)
    np.testing.assert_allclose(np.array(p["ball.roughness.data"]), 102 / 255, atol=1e-6)
    arrays = draaw_mi.load_scene(_scene({"base_color": np.full((4, 4, 3), _srgb_decode(188)),
                                         "roughness": np.full((4, 4), 102 / 255)}))
    np.testing.assert_allclose(_render(scene), _render(arrays), rtol=0, atol=1e-6)

    p["ball.roughness.data"] = mi.TensorXf(np.full((4, 4, 1), 0.9, np.float32))
    p["ball.base_color.data"] = value_like(p["ball.base_color.data"], np.full((4, 4, 3), 0.2), "ball.base_color.data")
    p.update()
    np.testing.assert_allclose(np.array(p["ball.roughness.data"]), 0.9, atol=1e-6)
    set_by_hand = draaw_mi.load_scene(_scene({"base_color": np.full((4, 4, 3), 0.2),
                                              "roughness": np.full((4, 4), 0.9)}))
    # (a scene rendered again after an update differs from a fresh one by up to 1e-4; the
    # truncated texels of an integer texture render a mirror, tenths apart)
    np.testing.assert_allclose(_render(scene), _render(set_by_hand), rtol=0, atol=1e-3)


def test_an_integer_texture_takes_no_float_values():
    """(An XML scene's PNG, which Mitsuba keeps as integers.) value_like gave a TensorXu8 of
    zeros for 0.2."""
    current = mi.TensorXu8(np.full((4, 4, 3), 128, np.uint8))
    with pytest.raises(RenderError, match=r"m.base_color.data.*TensorXu8.*takes no new values"):
        value_like(current, np.full((4, 4, 3), 0.2), "m.base_color.data")


def test_a_texture_is_filled_by_one_number_or_one_per_channel():
    current = mi.TensorXf(np.zeros((2, 3, 3), np.float32))
    np.testing.assert_array_equal(np.array(value_like(current, [0.1, 0.2, 0.3], "k")),
                                  np.broadcast_to(np.float32([0.1, 0.2, 0.3]), (2, 3, 3)))
    np.testing.assert_array_equal(np.array(value_like(current, 0.5, "k")), np.full((2, 3, 3), 0.5, np.float32))
    with pytest.raises(RenderError, match=r"k is a texture of shape \(2, 3, 3\); give one number or 3"):
        value_like(current, [0.1, 0.2], "k")


def test_a_bitmap_table_reads_a_data_map_raw_by_default(tmp_path):
    """``roughness = {type = "bitmap", filename = ...}`` was sRGB-decoded (102/255 = 0.4 read
    as 0.133); ``raw = false`` still decodes, and the table's filter_type is kept."""
    rough = _png(tmp_path / "rough.png", 102, 1)
    table = {"type": "bitmap", "filename": rough, "filter_type": "nearest"}
    scene = draaw_mi.load_scene(_scene({"roughness": table}))
    np.testing.assert_allclose(np.array(scene.params["ball.roughness.data"]), 102 / 255, atol=1e-6)
    scene = draaw_mi.load_scene(_scene({"roughness": dict(table, raw=False)}))
    np.testing.assert_allclose(np.array(scene.params["ball.roughness.data"]), _srgb_decode(102), atol=1e-6)


@pytest.mark.parametrize("channels", [1, 2])
def test_a_normal_map_of_one_or_two_channels_is_refused(tmp_path, channels):
    """A grey height map was looked up as (h, h, h): it tilted every normal (55 degrees for 0.7)."""
    path = _png(tmp_path / "h.png", 180, 1) if channels == 1 else str(tmp_path / "ya.png")
    if channels == 2:
        from PIL import Image
        Image.fromarray(np.full((4, 4, 2), 180, np.uint8), mode="LA").save(path)
    with pytest.raises(DraawError, match=r"normalmap.*has 1 channel\(s\); a normal map has 3.*height or bump"):
        draaw_mi.load_scene(_scene({"normalmap": path}))


def test_the_draaw_plugin_refuses_a_grey_normal_map():
    grey = {"type": "bitmap", "data": mi.TensorXf(np.full((4, 4, 1), 0.7, np.float32)), "raw": True}
    with pytest.raises(Exception, match=r"normalmap has 1 channel\(s\); expected a 3-channel"):
        mi.load_dict({"type": "draaw", "normalmap": grey})


def test_unreadable_texture_files_are_named(tmp_path):
    """A corrupt PNG gave Mitsuba's "[FileStream] ... seek to offset 18446744073709551614"; a
    5-channel EXR "The texture needs a known pixel format", naming neither file nor field."""
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png at all")
    with pytest.raises(DraawError, match=r"materials.ball.base_color: texture '.*bad.png' cannot be read as an image"):
        draaw_mi.load_scene(_scene({"base_color": str(bad)}))
    multi = mi.Bitmap(np.full((4, 4, 5), 0.5, np.float32), pixel_format=mi.Bitmap.PixelFormat.MultiChannel,
                      channel_names=["a", "b", "c", "d", "e"])
    multi.write(str(tmp_path / "multi.exr"))
    with pytest.raises(DraawError, match=r"materials.ball.roughness: texture '.*multi.exr' has 5 channels"):
        draaw_mi.load_scene(_scene({"roughness": str(tmp_path / "multi.exr")}))


def test_numpy_numbers_and_triples_are_taken_as_numbers_and_lists():
    """np.array([0.5, 0.5, 0.5]) as a base colour and np.array(0.4) as a roughness failed in
    Mitsuba ("Bitmap raw tensor has dimension 1, expected 3")."""
    as_lists = _render(draaw_mi.load_scene(_scene({"base_color": [0.5, 0.2, 0.1], "roughness": 0.4})))
    as_numpy = _render(draaw_mi.load_scene(_scene({"base_color": np.array([0.5, 0.2, 0.1]),
                                                   "roughness": np.array(0.4)})))
    np.testing.assert_array_equal(as_numpy, as_lists)


def test_a_bitmap_value_is_refused_with_what_to_give():
    """It failed in a deepcopy: "TypeError: cannot pickle 'Bitmap' object"."""
    d = _scene({})
    d["materials"]["ball"]["base_color"] = mi.Bitmap(np.full((4, 4, 3), 0.5, np.float32))
    with pytest.raises(DraawError, match=r"materials.ball.base_color: a mi.Bitmap; give its linear values"):
        draaw_mi.load_scene(d)


def test_integer_arrays_are_refused_and_colours_above_one_warn():
    """A uint8 array from PIL and a float array on the 0-255 scale were taken as linear values
    without a word (the constant [200, 200, 200] warns)."""
    with pytest.raises(DraawError, match=r"materials.ball.base_color: an array of uint8 values; expected "
                                         r"linear floats.*divide by 255"):
        draaw_mi.load_scene(_scene({"base_color": np.full((4, 4, 3), 200, np.uint8)}))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        draaw_mi.load_scene(_scene({"base_color": np.full((4, 4, 3), 200.0)}))
        draaw_mi.load_scene(_scene({"base_color": copy.deepcopy(np.full((4, 4, 3), 0.9))}))
    said = [str(w.message) for w in caught if "reflects more light" in str(w.message)]
    assert len(said) == 1 and "values up to 200" in said[0], said
