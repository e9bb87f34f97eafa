"""fit(): what references it takes and how (channels, dtypes, sizes, display encoding), and
the arguments it refuses before rendering (seed, lr) or after a diverged run."""
from __future__ import annotations

import os

import matplotlib.image
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import DraawError, ParameterError
from draaw_mi.fitting.reference import display_encoded_post, load_reference
from draaw_mi.post import load_chain

from conftest import SCENES

P = ["target.roughness", "target.metallic"]


def _scene(res=(24, 24)):
    return draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=res)


def _truth(scene, rough=0.25, metal=0.8, spp=256, seed=5, chain=None):
    p = scene.params
    start = {k: float(p[scene.key(k)][0]) for k in P}
    p[scene.key("target.roughness")], p[scene.key("target.metallic")] = rough, metal
    p.update()
    img = draaw_mi.render(scene, version="path", spp=spp, seed=seed, post=chain)
    for k, v in start.items():
        p[scene.key(k)] = v
    p.update()
    return np.array(img)[..., :3]


# ---------------------------------------------------------------- display-encoded PNGs
def test_a_png_of_an_srgb_chain_is_compared_as_stored(tmp_path):
    """``render --post [srgb] --png ref.png`` stores the chain's output as it is; ``fit --post
    [srgb] --reference ref.png`` decoded it to linear and compared it with encoded renders:
    roughness 0.11 / metallic 1.0 "converged" for a truth of 0.2 / 0.9 (24x24). Now it is
    compared as stored: fit seeds 0-3 end at roughness 0.248-0.264, metallic 0.747-0.800 for
    a truth of 0.25 / 0.8 (tolerances about twice the largest distance)."""
    chain = [{"type": "srgb"}]
    scene = _scene()
    png = str(tmp_path / "ref.png")
    draaw_mi.write_png(png, _truth(scene, chain=chain), encoded=True)
    stored = matplotlib.image.imread(png)[..., :3]
    np.testing.assert_allclose(load_reference(png, encoded=True), stored, atol=1e-6)
    assert np.abs(load_reference(png) - stored).max() > 0.1          # decoded otherwise
    res = draaw_mi.fit(scene, png, P, post=load_chain(chain), iterations=60, spp=8, seed=0,
                       init={"target.roughness": 0.5, "target.metallic": 0.5}, progress=False)
    assert abs(res.values["target.roughness"] - 0.25) < 0.03, res.values
    assert abs(res.values["target.metallic"] - 0.8) < 0.1, res.values


def test_which_post_chains_end_display_encoded():
    assert display_encoded_post([{"type": "srgb"}]) and display_encoded_post(load_chain([{"type": "srgb"}]))
    assert not display_encoded_post([{"type": "srgb"}, {"type": "srgb", "inverse": True}])
    assert not display_encoded_post(lambda img: img)          # a function cannot say: decoded


# ---------------------------------------------------------------- EXR channels, arrays
def test_exr_channels_are_taken_by_name(tmp_path):
    rgb = np.array([0.9, 0.5, 0.1], np.float32)
    img = np.broadcast_to(rgb, (4, 6, 3)).copy()
    alpha = np.ones((4, 6, 1), np.float32)
    layered = str(tmp_path / "layered.exr")          # Blender's names: read A, B, G before
    draaw_mi.write_exr(layered, np.concatenate([img, alpha], axis=2),
                       channels=[f"ViewLayer.Combined.{c}" for c in "RGBA"])
    np.testing.assert_array_equal(load_reference(layered)[0, 0], rgb)
    grey = str(tmp_path / "ya.exr")                  # Y + A: a traceback from the loss before
    draaw_mi.write_exr(grey, np.concatenate([img[..., :1], alpha], axis=2), channels=["Y", "A"])
    np.testing.assert_array_equal(load_reference(grey)[0, 0], np.full(3, rgb[0]))
    two = str(tmp_path / "two_layers.exr")
    draaw_mi.write_exr(two, np.concatenate([img, img], axis=2),
                       channels=[f"{layer}.{c}" for layer in ("a", "b") for c in "RGB"])
    with pytest.raises(ParameterError, match="layers a, b: keep one"):
        load_reference(two)
    xyz = str(tmp_path / "xyz.exr")
    draaw_mi.write_exr(xyz, img, channels=["X", "Y", "Z"])
    with pytest.raises(ParameterError, match="has the channels X, Y, Z; expected R, G, B"):
        load_reference(xyz)


@pytest.mark.parametrize("array, match", [
    (np.zeros((4, 4, 3), np.uint8), "dtype uint8; expected float"),
    (np.zeros((4, 4, 3), bool), "dtype bool"),
    (np.zeros((3, 4, 5), np.float32), r"shape \(3, 4, 5\); expected .*channels last"),
    (np.zeros((4, 4, 2), np.float32), r"shape \(4, 4, 2\)"),
])
def test_arrays_that_are_no_linear_image_are_refused(array, match):
    with pytest.raises(ParameterError, match=match):
        load_reference(array)


def test_float_arrays_of_one_three_and_four_channels():
    a = np.random.default_rng(0).random((4, 5, 4)).astype(np.float32)
    np.testing.assert_array_equal(load_reference(a), a[..., :3])
    np.testing.assert_array_equal(load_reference(a[..., 0]), np.repeat(a[..., :1], 3, axis=2))


# ---------------------------------------------------------------- sizes
def test_a_reference_of_another_aspect_ratio_is_refused():
    scene = _scene()
    with pytest.raises(DraawError, match="is 48x24, the scene renders 24x24: another aspect ratio"):
        draaw_mi.fit(scene, np.zeros((24, 48, 3), np.float32), P, iterations=1, progress=False)


def test_a_smaller_reference_fits_at_its_size_and_the_scene_gets_the_values():
    """A 12x12 reference of a 24x24 scene is fitted at 12x12 (a reloaded copy of the scene);
    the caller's scene kept its starting values."""
    scene = _scene()
    ref = _truth(_scene((12, 12)), spp=64)
    before = float(scene.params[scene.key("target.roughness")][0])
    res = draaw_mi.fit(scene, ref, P, iterations=8, spp=4, progress=False)
    assert res.image.shape == (12, 12, 3) and scene.resolution == (24, 24)
    for name in P:
        assert abs(float(scene.params[scene.key(name)][0]) - res.values[name]) < 1e-6
    assert res.values["target.roughness"] != before


# ---------------------------------------------------------------- seed, lr, divergence
@pytest.mark.parametrize("kw, match", [
    (dict(seed=-1), r"seed=-1; expected an integer in \[0, 4294967295\]"),
    (dict(seed=2 ** 32), "seed=4294967296"),
    (dict(lr=float("inf")), "lr=inf; expected a positive finite number"),
    (dict(lr=float("nan")), "lr=nan"),
])
def test_bad_seed_and_lr_are_refused_before_rendering(kw, match):
    with pytest.raises(ParameterError, match=match):
        draaw_mi.fit(_scene(), np.zeros((24, 24, 3), np.float32), P, iterations=1, progress=False, **kw)


def test_the_largest_seed_fits():
    """seed 2**32 - 1 ran every iteration, then failed on the final render's seed + 12345."""
    res = draaw_mi.fit(_scene(), np.zeros((24, 24, 3), np.float32), P, iterations=1, spp=1,
                       seed=2 ** 32 - 1, progress=False)
    assert np.isfinite(res.image).all()


def test_a_diverged_fit_says_so_and_leaves_the_scene_as_it_was():
    """lr 1e30 on a light's radiance: NaN values were printed with exit status 0."""
    scene = _scene()
    key = scene.key("key.emitter.radiance")
    before = np.array(scene.params[key])
    ref = _truth(_scene(), spp=16)
    with pytest.raises(DraawError, match=r"key.emitter.radiance diverged to NaN/Inf .* try a smaller lr"):
        draaw_mi.fit(scene, ref, ["key.emitter.radiance"], lr=1e30, iterations=20, spp=2, progress=False)
    np.testing.assert_array_equal(np.array(scene.params[key]), before)
