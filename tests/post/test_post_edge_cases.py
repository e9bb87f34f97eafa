"""Hard inputs stay finite: black, constant, HDR up to 1e6, 1×1 and 2×2 images, multipass 10,
chromatic-aberration shifts larger than the image; gradients stay finite too."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi.post as post
from draaw_mi.errors import ParameterError
from post_helpers import CASES, FILTER_NAMES, hdr_image

BOUNDARY_FILTERS = ["bloom", "bloom_v2", "sharpen", "chromatic_aberration", "edge_detection",
                    "crt"]


def _images():
    rng = np.random.default_rng(30)
    return {
        "black": np.zeros((8, 9, 3), np.float32),
        "constant": np.full((8, 9, 3), 0.37, np.float32),
        "hdr1e6": (rng.random((8, 9, 3)) ** 4 * 1e6).astype(np.float32),
        "1x1": np.full((1, 1, 3), 0.8, np.float32),
        "2x2": hdr_image(seed=31, shape=(2, 2)),
        "1x5rgba": hdr_image(seed=32, shape=(1, 5), channels=4),
    }


IMAGES = _images()


def _finite(t):
    a = t.numpy()
    assert np.all(np.isfinite(a)), f"{np.sum(~np.isfinite(a))} non-finite values"
    return a


@pytest.mark.parametrize("name", FILTER_NAMES)
@pytest.mark.parametrize("image", list(IMAGES))
@pytest.mark.parametrize("multipass", [1, 10])
def test_finite_outputs(name, image, multipass):
    img = IMAGES[image]
    out = _finite(getattr(post, name)(img, multipass=multipass))
    assert out.shape == img.shape


@pytest.mark.parametrize("name", BOUNDARY_FILTERS)
@pytest.mark.parametrize("boundary", post.BOUNDARIES)
def test_tiny_images_every_boundary(name, boundary):
    for shape in [(1, 1), (2, 2), (1, 3)]:
        _finite(getattr(post, name)(hdr_image(seed=33, shape=shape), boundary=boundary))


@pytest.mark.parametrize("boundary", post.BOUNDARIES)
@pytest.mark.parametrize("shift", [9.0, 100.5, 12345.25])
def test_aberration_shift_larger_than_image(boundary, shift):
    img = hdr_image(seed=34, shape=(3, 4))
    out = _finite(post.chromatic_aberration(img, shift, boundary=boundary))
    np.testing.assert_array_equal(out[..., 1], img[..., 1])          # green never moves
    if boundary == "zero":
        assert np.all(out[..., 0] == 0) and np.all(out[..., 2] == 0)
    if boundary == "nearest":
        np.testing.assert_array_equal(out[..., 0], np.repeat(img[:, :1, 0], 4, axis=1))
        np.testing.assert_array_equal(out[..., 2], np.repeat(img[:, -1:, 2], 4, axis=1))
    if boundary == "wrap" and shift == 9.0:                          # 9 = 2·4 + 1
        np.testing.assert_array_equal(out[..., 0], np.roll(img[..., 0], 1, axis=1))


@pytest.mark.parametrize("name", ["sharpen", "edge_detection", "chromatic_aberration"])
def test_constant_image_is_a_fixed_point(name):
    img = IMAGES["constant"]
    np.testing.assert_allclose(getattr(post, name)(img).numpy(), img, rtol=0, atol=1e-6)


def test_hdr_values_survive_without_clamps():
    img = IMAGES["hdr1e6"]
    out = _finite(post.apply(img, [
        {"type": "bloom", "clamp": False, "multipass": 10}, {"type": "sharpen"},
        {"type": "edgeDetection"}, {"type": "crt", "clamp": False},
        {"type": "log", "clamp": False}, {"type": "srgb"}]))
    assert out.max() > 1.0
    out = _finite(post.apply(img, [{"type": "sharpen", "multipass": 10},
                                   {"type": "edgeDetection", "multipass": 10}]))
    assert out.max() > 1e6


@pytest.mark.parametrize("name", FILTER_NAMES)
@pytest.mark.parametrize("image", ["black", "hdr1e6", "1x1"])
def test_finite_gradients(name, image):
    x = mi.TensorXf(IMAGES[image])
    dr.enable_grad(x)
    y = getattr(post, name)(x, multipass=2)
    dr.backward(dr.sum(y.array) * 1e-6)
    g = dr.grad(x).numpy()
    assert np.all(np.isfinite(g)), f"{name} on {image}: non-finite gradient"


@pytest.mark.parametrize("scale", [1e19, 1e27, 1e36])
def test_edges_of_very_bright_pixels_do_not_overflow(scale):
    """Sobel magnitudes squared their gradients: a uniform 1e27 image came out all Inf (it has
    no edges) and random pixels times 1e19 had Inf edges. Lights may be as bright as float32
    allows, and so may pixels. Against the float64 reference."""
    import reference
    flat = np.full((6, 7, 3), scale, np.float32)
    assert np.allclose(_finite(post.edge_detection(flat)), flat, rtol=1e-6, atol=0)   # (float32 taps)
    img = (np.random.default_rng(5).random((6, 7, 3)) * scale / 100).astype(np.float32)
    out = _finite(post.edge_detection(img))
    want = reference.edge_detection(img.astype(np.float64))
    assert np.allclose(out, want, rtol=1e-5, atol=0), np.abs(out / want - 1).max()


def _with_bad_pixels(channels=3):
    img = hdr_image(seed=35, shape=(13, 17), channels=channels)
    img[6, 8, 0] = np.nan
    img[2, 3, 1] = np.inf
    img[11, 15, 2] = -np.inf
    return img


@pytest.mark.parametrize("name", FILTER_NAMES)
def test_non_finite_input_values_read_as_zero(name):
    """A user's image with NaN/inf pixels: every filter (function, class and chain) gives
    what it gives on the image with those values set to 0 (numpy's nan_to_num, the
    reference), so nothing non-finite spreads; without the guard a bloom spread one NaN over
    13 x 13 pixels."""
    img = _with_bad_pixels(channels=4)
    img[0, 0, 3] = np.nan                                  # alpha passes through as it is
    clean = img.copy()                                     # (the colour's bad values only)
    clean[..., :3] = np.nan_to_num(img[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    want = getattr(post, name)(clean).numpy()[..., :3]
    params = CASES[name][-1]
    got = getattr(post, name)(img).numpy()
    np.testing.assert_array_equal(got[..., :3], want)
    np.testing.assert_array_equal(got[..., 3], img[..., 3])
    chain = post.apply(img, [{"type": name, **params}]).numpy()
    np.testing.assert_array_equal(chain[..., :3], getattr(post, name)(clean, **params).numpy()[..., :3])
    assert np.all(np.isfinite(chain[..., :3]))


def test_non_finite_input_values_get_zero_gradient():
    x = mi.TensorXf(_with_bad_pixels())
    dr.enable_grad(x)
    y = post.apply(x, [{"type": "bloom", "clamp": False}, {"type": "sharpen"},
                       {"type": "crt", "clamp": False}])
    dr.backward(dr.sum(y.array))
    g = dr.grad(x).numpy()
    assert np.all(np.isfinite(g))
    assert g[6, 8, 0] == 0 and g[2, 3, 1] == 0 and g[11, 15, 2] == 0
    assert np.count_nonzero(g) > 0.9 * g.size


def test_an_encoded_rgba_png_stores_the_colour_not_the_premultiplied_one(tmp_path):
    """A chain ending in ``srgb`` on a film's RGBA (colour premultiplied by alpha): its PNG
    equals the linear image's PNG (which write_png encodes itself). The curve had encoded
    ``c a``: a pixel an eighth covered was stored 34 where it is 101."""
    import matplotlib.image
    from draaw_mi.io import write_png
    img = np.zeros((4, 5, 4), np.float32)
    img[..., :3] = 0.35
    img[..., 3] = np.linspace(0.0, 1.0, 20).reshape(4, 5)
    img[..., :3] *= img[..., 3:]                      # premultiplied, as a film holds it
    write_png(str(tmp_path / "linear.png"), img)
    write_png(str(tmp_path / "encoded.png"), post.apply(img, [{"type": "srgb"}]), encoded=True)
    a = np.round(matplotlib.image.imread(str(tmp_path / "linear.png")) * 255)
    b = np.round(matplotlib.image.imread(str(tmp_path / "encoded.png")) * 255)
    assert np.abs(a - b).max() <= 1, np.abs(a - b).max()
    assert b[0, 1, 0] > 150                           # 0.35 encoded: 160, however little covered


def test_eight_bit_images_of_any_kind_are_refused():
    """An 8-bit ``mi.Bitmap`` or PIL image was read as values up to 255 (a numpy uint8 array
    was refused); ``None`` raised Dr.Jit's own TypeError."""
    from PIL import Image
    for img in (mi.Bitmap(np.full((2, 2, 3), 200, np.uint8)), Image.new("RGB", (2, 2), (200, 200, 200)),
                np.full((2, 2, 3), 200, np.uint8)):
        with pytest.raises(ParameterError, match="must be a float array.*got dtype uint8"):
            post.srgb(img)
    with pytest.raises(ParameterError, match="must be an mi.TensorXf or a float numpy array, got NoneType"):
        post.apply(None, [{"type": "srgb"}])
    assert post.srgb(mi.Bitmap(np.full((2, 2, 3), 0.5, np.float32))).shape == (2, 2, 3)


def test_crt_of_values_near_float_max_is_finite():
    """``lerp(blur * glow, centre, base)`` read inf - inf = NaN where blur * glow overflowed."""
    img = np.full((5, 5, 3), 0.5, np.float32)
    img[2, 2] = 3e38
    assert np.all(np.isfinite(post.crt(img, radius=3.0).numpy()))
    assert np.all(np.isfinite(post.crt(np.full((3, 3, 3), 3e38, np.float32)).numpy()))


def test_display_encoded_counts_the_grades_and_not_a_zero_amount():
    """GO-Draaw stores the ``log`` grade's values as its 8-bit pixels (white: 128): a PNG
    encoded them again (188). An ``srgb`` at amount 0 does nothing and was counted."""
    assert post.display_encoded([{"type": "log"}]) and post.display_encoded([{"type": "linear"}])
    assert not post.display_encoded([{"type": "srgb", "amount": 0.0}])
    assert not post.display_encoded([{"type": "log"}, {"type": "srgb", "inverse": True}])
    with pytest.warns(RuntimeWarning, match="srgb at amount=0.5 leaves values between"):
        assert post.display_encoded([{"type": "srgb", "amount": 0.5}])


def test_parameter_messages_say_what_a_colour_may_be():
    """A bad colour said "a number in [0, inf) (each component)" (not that 3 numbers, one,
    '#rrggbb' or {r, g, b} are taken); a seed's bound read 2.14748e+09; a choice listed the
    valid names twice."""
    with pytest.raises(ParameterError, match=r"'color' must be a colour: 3 numbers in \[0, inf\), one number, "
                                             r"'#rrggbb' or \{'r': .., 'g': .., 'b': ..\}, got 'red'"):
        post.load_chain([{"type": "tint", "color": "red"}])
    with pytest.raises(ParameterError, match=r"'seed' must be an integer in \[0, 2147483647\], got -1$"):
        post.load_chain([{"type": "crt", "seed": -1}])
    with pytest.raises(ParameterError, match=r"must be one of 'reflect', .*'zero', got 'x'$"):
        post.load_chain([{"type": "bloom", "boundary": "x"}])



def test_display_curves_of_rgba_stay_finite_and_agree_with_opaque_pixels():
    """An infinite alpha made srgb's c / a * a read 0 * inf = NaN, which a bloom then spread
    over the image; the grades, counted as display curves, act on the colour itself as srgb
    does (a pixel an eighth covered was stored 4 where the opaque one is 9)."""
    img = np.full((3, 3, 4), 0.5, np.float32)
    img[1, 1, 3] = np.inf
    out = post.apply(img, [{"type": "srgb"}, {"type": "bloom", "threshold": 0.0}]).numpy()
    assert np.all(np.isfinite(out[..., :3]))
    for name in ("srgb", "linear", "log"):
        px = np.array([[[0.02, 0.02, 0.02, 1.0], [0.02 * 0.125, 0.02 * 0.125, 0.02 * 0.125, 0.125]]], np.float32)
        got = getattr(post, name)(px).numpy()
        straight = got[0, 1, :3] / 0.125
        np.testing.assert_allclose(straight, got[0, 0, :3], rtol=1e-5, err_msg=name)


@pytest.mark.parametrize("name", ["srgb", "linear", "log"])
def test_display_curves_of_a_subnormal_alpha_stay_finite(name):
    """A pixel of subnormal alpha (flushed to 0 in the vector kernel) read c / a = inf and
    came out NaN in images of more than one pixel (a 4x8 RGBA image: 96 NaN of 96), and
    alpha below ~1e-19 had a gradient of -inf (a^2 underflowed): it now counts as uncovered."""
    for a in (1e-38, 1e-41, 1e-20):
        img = np.zeros((4, 8, 4), np.float32)
        img[..., 3] = a
        img[..., :3] = 0.5 * a
        t = mi.TensorXf(img)
        dr.enable_grad(t)
        out = getattr(post, name)(t)
        dr.backward(dr.sum(out.array))
        assert np.all(np.isfinite(out.numpy())), (name, a)
        assert np.all(np.isfinite(dr.grad(t).numpy())), (name, a)

