"""Every filter against its independent numpy/scipy reference (tests/post/reference.py).

Random HDR images (values up to 4) in float32 for draaw_mi, the same values in float64 for the
reference; the acceptance bound is max |difference| <= 1e-5.
"""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi.post as post
from post_helpers import LARGE, case_params, hdr_image, ref

TOL = 1e-5
CASES = case_params()


def _compare(name, params, img):
    out = getattr(post, name)(img, **params)
    expected = getattr(ref, name)(img.astype(np.float64), **params)
    got = out.numpy()
    assert got.shape == expected.shape
    assert np.all(np.isfinite(got))
    err = np.abs(got - expected).max()
    assert err <= TOL, f"{name}{params}: max |diff| = {err:.3g}"
    return got


@pytest.mark.parametrize("name,params", [c[:2] for c in CASES], ids=[c[2] for c in CASES])
def test_matches_reference(name, params):
    _compare(name, params, hdr_image(seed=1))


@pytest.mark.parametrize("name", list(post.FILTERS))
def test_matches_reference_rgba_alpha_untouched(name):
    img = hdr_image(seed=2, channels=4)
    got = _compare(name, {"amount": 0.8}, img)
    assert np.array_equal(got[..., 3], img[..., 3])


@pytest.mark.parametrize("name,params", [
    ("bloom", {}), ("bloom_v2", {"spread": 2.5, "boundary": "mirror"}),
    ("sharpen", {"boundary": "nearest"}),
    ("chromatic_aberration", {"shift": 3.3, "boundary": "zero"}),
    ("chromatic_aberration", {"shift": 2.5, "boundary": "wrap"}),
    ("chromatic_aberration", {"shift": 1.75, "boundary": "mirror"}),
    ("edge_detection", {"distance": 2.0, "boundary": "wrap"}),
    ("crt", {}), ("crt", {"boundary": "mirror", "radius": 9.0}),
    ("crt", {"boundary": "wrap", "radius": 12.0, "seed": 3}),
    ("crt", {"boundary": "zero", "radius": 20.0, "clamp": False}),
])
def test_matches_reference_larger_image(name, params):
    """Offsets smaller than the image take the single-reflection boundary formulas."""
    _compare(name, params, hdr_image(seed=3, shape=LARGE))


def test_chain_matches_reference():
    entries = [("contrast", {"contrast": 1.2}), ("tint", {"color": (1.0, 0.8, 0.6)}),
               ("bloom", {"amount": 0.5, "clamp": False}), ("bloom_v2", {"amount": 0.5}),
               ("sharpen", {"amount": 0.5}), ("color_mapping", {"levels": 32, "amount": 0.5}),
               ("chromatic_aberration", {"amount": 0.5}), ("edge_detection", {"amount": 0.2}),
               ("lighten", {"amount": 0.5}), ("crt", {"amount": 0.5}), ("srgb", {})]
    img = hdr_image(seed=4, channels=4)
    out = post.apply(img, [{"type": n, **p} for n, p in entries]).numpy()
    expected = ref.chain(img.astype(np.float64), entries)
    assert np.abs(out - expected).max() <= TOL
    assert np.array_equal(out[..., 3], img[..., 3])


def test_crt_scan_lines_of_a_tall_image_match_the_reference():
    """From 480 rows on, a scan line spans two or more rows (period H // 480 + 1): every other
    test image is shorter, where the period is 1 and a wrong period formula still agrees."""
    _compare("crt", {"radius": 2.0}, hdr_image(seed=5, shape=(480, 3)))


@pytest.mark.parametrize("name", ["bloom", "bloom_v2"])
def test_pixels_at_the_threshold_bloom(name):
    """Pixels whose luminance is the threshold glow ("at or above"): at threshold 0 the black
    pixels of an image take the glow of their bright neighbours too (with ``<=`` in place of
    ``<`` none did)."""
    img = hdr_image(seed=11)
    img[::2] = 0.0                                             # every other row exactly black
    got = _compare(name, {"threshold": 0.0, "clamp": False, "multipass": 1}, img)
    assert got[::2].min() > 0.0                                # (the reference says so too)


def test_quantised_values_are_fixed_points_for_every_level_count():
    """``color_mapping(color_mapping(x)) == color_mapping(x)`` bit for bit for N = 1..40 and
    some larger counts on a
    dense grid, and the levels are the float64 reference's: float32's ``x N`` rounds a
    quantised ``k / N`` just below ``k`` for 218 of 1001 inputs at N = 100 without the
    2^-22 tolerance, and repeated passes drifted down by levels (0.99 -> 0.97 at multipass 3)."""
    x = np.linspace(0.0, 1.0, 1001, dtype=np.float32)
    img = np.repeat(x[:, None, None], 3, axis=2)              # (1001, 1, 3)
    for n in [*range(1, 41), 64, 99, 100, 127, 255, 256]:
        once = post.color_mapping(img, n).numpy()
        np.testing.assert_array_equal(post.color_mapping(once, n).numpy(), once, err_msg=f"levels={n}")
        want = ref.color_mapping(img.astype(np.float64), n)[:, 0, 0]
        np.testing.assert_array_equal(np.round(once[:, 0, 0] * np.float64(n)), np.round(want * n),
                                      err_msg=f"levels={n}")
    np.testing.assert_array_equal(post.color_mapping(img, 100, multipass=3).numpy(),
                                  post.color_mapping(img, 100).numpy())


def test_quantised_hdr_values_are_fixed_points_up_to_2_5e6_levels():
    """HDR values up to c N = 2.55e6 are fixed points too: k * (1/N), which Dr.Jit made of a
    division by the literal N, rounded 6 of these levels (k past 2^21) off k / N, and a
    second pass moved them a level up."""
    x = np.linspace(0.0, 10000.0, 12288, dtype=np.float32)
    img = np.repeat(x[:, None, None], 3, axis=2)
    once = post.color_mapping(img, 255).numpy()
    np.testing.assert_array_equal(post.color_mapping(once, 255).numpy(), once)

