"""Look-at cameras and area lights (draaw_mi.scene.camera.check_look_at) that Mitsuba can build:
it builds the look-at in float32, left = normalize(cross(up, target - origin))."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi import SceneError

from conftest import tiny_description

# straight down in float32 (0.30000001 and 0.3 are one float32), along up [0, 1, 0]; float64
# sees them 1e-8 apart, an angle of 3e-9 rad, which a 1e-9 tolerance passed: a NaN to_world
DOWN = {"origin": [0.3, 3.0, 0.3], "target": [0.3, 0.0, 0.30000001], "up": [0.0, 1.0, 0.0]}


def _with_camera(cam):
    d = tiny_description(resolution=[8, 6], spp=1)
    d["camera"] = dict(cam, fov=40)
    return d


def _with_area_light(position, target, up):
    d = tiny_description(resolution=[8, 6], spp=1)
    d["lights"] = [{"type": "area", "name": "panel", "position": position, "target": target, "up": up,
                    "intensity": 5.0}]
    return d


def test_an_up_within_float32s_rounding_of_the_view_is_refused():
    """0.30000003 is one float32 step above 0.3: the view is 1e-8 rad from up, far below
    what the rounding of 0.3 and 3 can move it; Mitsuba's camera would roll by chance."""
    with pytest.raises(SceneError, match=r"camera.up: .* is parallel to the view direction .* within "
                                         r"float32's rounding"):
        draaw_mi.load_scene(_with_camera(dict(DOWN, target=[0.3, 0.0, 0.30000003])))


def test_an_up_parallel_to_the_view_in_float32_is_refused():
    with pytest.raises(SceneError, match=r"^<dict>: camera.up: \[0.0, 1.0, 0.0\] is parallel to the view "
                                         r"direction \[0.0, -3.0, 0.0\] \(in float32"):
        draaw_mi.load_scene(_with_camera(DOWN))
    with pytest.raises(SceneError, match=r"^<dict>: lights\[0\].up: \[0.0, 1.0, 0.0\] is parallel"):
        draaw_mi.load_scene(_with_area_light(DOWN["origin"], DOWN["target"], DOWN["up"]))


@pytest.mark.parametrize("origin, target", [([0.3, 3.0, 0.3], [0.3, 0.0, 0.3 + 6e-5]),
                                            ([0.0, 5.0, 1e-5], [0.0, 0.0, 0.0])])
def test_a_view_beyond_float32s_rounding_gives_a_finite_camera(origin, target):
    """A target 6e-5 off the vertical under a camera 3 up (2e-5 rad from up), and a camera
    looking down from [0, 5, 1e-5] at the origin (2e-6 rad, exact in float32, which a fixed
    1e-5 rad tolerance refused). Mitsuba's to_world is finite, its forward column the view
    direction and its up column at right angles to it (tolerance: float32 roundings of unit
    vectors)."""
    cam = dict(DOWN, origin=origin, target=target)
    scene = draaw_mi.load_scene(_with_camera(cam))
    m = np.array(scene.mi_scene.sensors()[0].world_transform().matrix)[..., 0]
    assert np.isfinite(m).all()
    view = np.subtract(cam["target"], cam["origin"])
    np.testing.assert_allclose(m[:3, 2], view / np.linalg.norm(view), atol=1e-6)
    assert abs(m[:3, 1] @ m[:3, 2]) < 1e-6 and abs(np.linalg.norm(m[:3, 1]) - 1) < 1e-6
    light = draaw_mi.load_scene(_with_area_light(cam["origin"], cam["target"], cam["up"]))
    m = np.array(mi.traverse(light.mi_scene)["panel.to_world"].matrix)[..., 0]
    assert np.isfinite(m).all()
    np.testing.assert_allclose(m[:3, 2], view / np.linalg.norm(view), atol=1e-6)   # it faces its target


@pytest.mark.parametrize("up,said", [([0, 0, 0], "is the zero vector;"),
                                     ([0, 1e-50, 0], "is the zero vector in float32;")])
def test_a_zero_up_is_said_to_be_zero(up, said):
    """A zero up said "is parallel to the view direction"."""
    with pytest.raises(SceneError, match=r"camera.up: \[.*\] " + said):
        draaw_mi.load_scene(_with_camera({"origin": [0, 1, 5], "target": [0, 0.5, 0], "up": up}))
    with pytest.raises(SceneError, match=r"lights\[0\].up: \[.*\] " + said):
        draaw_mi.load_scene(_with_area_light([0, 3, 0], [0, 0, 0], up))


@pytest.mark.parametrize("s, said", [(1e-4, "closer than its near_clip 0.01"), (1e4, "beyond its far_clip 10000"),
                                     (1.0, None)])
def test_a_scene_the_clip_planes_hide_is_said(s, said):
    """A floor and a ball drawn at 1e-4 or 1e4 of the usual size, the camera scaled with
    them: the default clip planes (0.01, 1e4) hid every shape, and the image was plain sky
    with every gradient 0, without a word; now a RuntimeWarning says which plane and what to
    set, and with that setting the shapes are in view (the image is not the sky's 0.5)."""
    import warnings
    d = tiny_description(resolution=[8, 6], spp=1)
    d["shapes"] = [{"type": "rectangle", "name": "floor", "scale": 3 * s, "rotate": {"axis": [1, 0, 0], "angle": -90}},
                   {"type": "sphere", "name": "ball", "center": [0, 0.5 * s, 0], "radius": 0.5 * s}]
    d["lights"] = [{"type": "constant", "intensity": 0.5}]
    d.pop("materials", None)
    d["camera"] = {"origin": [0, s, 4 * s], "target": [0, 0.5 * s, 0], "fov": 45}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = draaw_mi.load_scene(d)
    msgs = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    if said is None:
        assert not [m for m in msgs if "camera:" in m], msgs
        return
    assert len(msgs) == 1 and said in msgs[0] and "the image shows none of it" in msgs[0], msgs
    assert np.allclose(np.array(draaw_mi.render(scene, version="path", spp=1, post=[])), 0.5)
    d["camera"].update(near_clip=1e-3 * s, far_clip=100 * s)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        fixed = draaw_mi.load_scene(d)
    assert not np.allclose(np.array(draaw_mi.render(fixed, version="path", spp=1, post=[])), 0.5)


def _camera_warnings(d):
    import warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = draaw_mi.load_scene(d)
    return scene, [str(w.message) for w in caught if "camera:" in str(w.message)]


@pytest.mark.parametrize("room", [
    [{"type": "sphere", "name": "room", "center": [0, 0.5, 0], "radius": 3.0}],
    [{"type": "box", "name": "outer", "center": [0, 0.5, 0], "size": [6, 6, 6]},
     {"type": "box", "name": "inner", "center": [0, 0.5, 0], "size": [5, 5, 5]},
     {"type": "subtraction", "name": "room", "children": ["outer", "inner"]}]])
def test_a_camera_inside_an_sdf_room_is_not_said_to_clip_it(room):
    """The clip check measured the SDF objects' hidden proxies (one point at the SDF box's
    centre, here the camera's position) and warned "every shape is within 0 of the camera
    ... near_clip (e.g. 0)", a value the loader refuses; the SDF objects' own boxes are
    measured, and the room is drawn (no pixel is the sky's 0.5)."""
    d = tiny_description(resolution=[8, 6], spp=1)
    d.update(shapes=[], sdf=room, lights=[{"type": "constant", "intensity": 0.5}])
    d["camera"] = {"origin": [0, 0.5, 0], "target": [0, 0.5, -1], "fov": 60}
    scene, said = _camera_warnings(d)
    assert not said, said
    img = np.array(draaw_mi.render(scene, version="v4", spp=1, seed=0, post=[]))
    assert np.all(img[..., :3] < 0.45), img[..., :3].max()


def test_an_sdf_object_the_near_plane_hides_is_said_with_a_value_the_loader_takes():
    """A ball 1e-3 across, 2e-3 from the camera, with the default near_clip 0.01: said, with
    a near_clip > 0 that loads without the warning and shows the ball."""
    import re
    d = tiny_description(resolution=[8, 6], spp=1)
    d.update(shapes=[], lights=[{"type": "constant", "intensity": 0.5}],
             sdf=[{"type": "sphere", "name": "ball", "center": [0, 0, -2e-3], "radius": 5e-4}])
    d["camera"] = {"origin": [0, 0, 0], "target": [0, 0, -1], "fov": 30}
    _, said = _camera_warnings(d)
    assert len(said) == 1 and "closer than its near_clip 0.01" in said[0], said
    value = float(re.search(r"near_clip \(e\.g\. ([^)]+)\)", said[0]).group(1))
    assert value > 0
    d["camera"]["near_clip"] = value
    scene, said = _camera_warnings(d)
    assert not said, said
    img = np.array(draaw_mi.render(scene, version="v4", spp=1, seed=0, post=[]))
    assert img[3, 4, 0] < 0.45                     # the ball, not the sky


def test_shapes_at_the_camera_are_said_without_a_near_clip_of_0():
    """Every box a point at the camera: no near_clip shows it (the warning offered 0, which
    the loader refuses)."""
    from draaw_mi.scene.camera import clipped_away
    said = clipped_away([0, 0, 0], 0.01, 1e4, [([0, 0, 0], [0, 0, 0])])
    assert said.startswith("every shape is within 0 of the camera") and "e.g." not in said, said
    assert clipped_away([0, 0, 0], 0.01, 1e4, [([0, 0, 0], [1e-3, 0, 0])]).endswith("near_clip (e.g. 1e-06)")
