"""AOVs: depth (linear and log), shading normal, albedo; OpenEXR-style channel names."""
from __future__ import annotations

import numpy as np
import pytest

from integrators_helpers import VERSIONS, integrator, mi, rs

CHANNELS = ["depth.Z", "depth_log.Z", "N.X", "N.Y", "N.Z", "albedo.R", "albedo.G", "albedo.B"]


@pytest.fixture(scope="module")
def scene():
    d = rs.feature_scene(res=12, spp=1, texture=True, normalmap=True, envmap=True)
    d["sensor"]["to_world"] = mi.ScalarTransform4f().look_at([0.0, 1.2, 4.0], [0.0, 0.9, 0.0],
                                                           [0, 1, 0])   # sky in the top rows
    d["ball"]["bsdf"]["base_color"] = {"type": "rgb", "value": [0.8, 0.5, 0.3]}
    d["box"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.3, 0.4]}}
    return mi.load_dict(d)


def aov_image(scene, kind, **props):
    return np.array(mi.render(scene, integrator=integrator(kind, aovs="all", **props),
                              spp=1, seed=3))


@pytest.mark.parametrize("kind", VERSIONS)
def test_aov_channels_match_mitsuba_aov_integrator(scene, kind):
    img = aov_image(scene, kind)
    assert img.shape == (12, 12, 3 + len(CHANNELS))
    ref = np.array(mi.render(scene, integrator=mi.load_dict(
        {"type": "aov", "aovs": "dd.y:depth,nn:sh_normal"}), spp=1, seed=3))
    depth, nrm = img[..., 3], img[..., 5:8]
    hit = ref[..., 0] > 0
    assert hit.any() and (~hit).any()
    assert np.allclose(depth, ref[..., 0], rtol=1e-4, atol=1e-5)
    assert np.allclose(img[..., 4], np.log1p(depth), rtol=1e-4, atol=1e-5)
    assert np.allclose(nrm[hit], ref[..., 1:4][hit], atol=1e-4)
    assert np.allclose(np.linalg.norm(nrm[hit], axis=-1), 1.0, atol=1e-4)
    assert not img[~hit][:, 3:].any()             # misses: all AOVs 0


def test_albedo_aov(scene):
    """draaw: base_color (ball, floor); other BSDFs: their diffuse reflectance (box)."""
    img = aov_image(scene, "draaw_v4")
    alb = img[..., 8:11].reshape(-1, 3)
    hit = img[..., 3].reshape(-1) > 0
    known = np.array([[0.8, 0.5, 0.3], [0.2, 0.3, 0.4], [0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])
    dist = np.abs(alb[:, None, :] - known[None]).max(-1)
    assert (dist.min(1) < 1e-5).all()                       # every pixel is one of them
    for k in range(3):
        assert (dist[hit, k] < 1e-5).any(), known[k]        # and each material shows
    assert not alb[~hit].any()


def test_albedo_aov_of_another_bsdf_is_clipped_to_one():
    """A non-draaw BSDF's diffuse reflectance above 1 (a raw texture) gives an albedo clipped
    to [0, 1] (the documented range; it came through as 1.5)."""
    d = rs.feature_scene(res=12, spp=1)
    d["sensor"]["to_world"] = mi.ScalarTransform4f().look_at([0.0, 1.2, 4.0], [0.0, 0.9, 0.0], [0, 1, 0])
    texels = mi.TensorXf(np.tile(np.float32([1.5, 0.5, 0.2]), (2, 2, 1)))
    d["box"]["bsdf"] = {"type": "diffuse", "reflectance": {"type": "bitmap", "data": texels, "raw": True}}
    alb = aov_image(mi.load_dict(d), "draaw_v1")[..., 8:11].reshape(-1, 3)
    box = np.abs(alb - [1.0, 0.5, 0.2]).max(-1) < 1e-5
    assert box.sum() >= 4 and alb.max() <= 1.0


def test_all_versions_give_the_same_aovs(scene):
    base = aov_image(scene, "draaw_v4")[..., 3:]
    for kind in ("draaw_v1", "draaw_v2", "draaw_v3"):
        assert np.allclose(aov_image(scene, kind)[..., 3:], base, atol=1e-5), kind


def test_aovs_in_film_bitmap_names(scene):
    integ = integrator("draaw_v4", aovs="depth,normal")
    mi.render(scene, integrator=integ, spp=1)
    text = str(scene.sensors()[0].film().bitmap().struct_())
    for c in ("depth.Z", "N.X", "N.Y", "N.Z"):
        assert f" {c};" in text


@pytest.mark.parametrize("light", ["rectangle", "sphere"])
@pytest.mark.parametrize("kind", VERSIONS)
def test_depth_behind_a_hidden_emitter_is_measured_from_the_camera(kind, light):
    """With hide_emitters the camera ray goes on through an area light: its depth was
    measured from the light (short by the camera-to-light distance, 3 here), and through a
    sphere light from its far side. Reference: Mitsuba's aov integrator on the scene
    without the light."""
    T = mi.ScalarTransform4f
    d = {"type": "scene", "wall": {"type": "rectangle", "to_world": T().translate([0, 0, -1]).scale(3),
                                   "bsdf": {"type": "diffuse"}},
         "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}}
    ref = np.array(mi.render(mi.load_dict(d), integrator=mi.load_dict({"type": "aov", "aovs": "dd.y:depth"}),
                             spp=1, seed=3))[..., 0]
    d["light"] = {"type": "rectangle", "to_world": T().translate([0, 0, 1]).scale(0.5),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 1.0}}}
    if light == "sphere":
        d["light"] = {"type": "sphere", "center": [0, 0, 1], "radius": 0.6, "emitter": d["light"]["emitter"]}
    scene = mi.load_dict(d)
    img = np.array(mi.render(scene, integrator=integrator(kind, aovs="depth", hide_emitters=True),
                             spp=1, seed=3))
    to_light = np.array(mi.render(scene, integrator=mi.load_dict({"type": "aov", "aovs": "dd.y:depth"}),
                                  spp=1, seed=3))[..., 0]
    assert (np.abs(to_light - ref) > 0.5).sum() >= 4 and (ref > 0).all()     # the light is in view
    np.testing.assert_allclose(img[..., 3], ref, rtol=1e-4)
