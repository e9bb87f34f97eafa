"""The tuner's Light and Render panels against the scene they drive: an environment map's
intensity and tint (in the preview and in what is saved), un-snapping point lights, refused
changes putting their control back, and the max-depth slider showing any scene's depth.

Each test compares the preview's Mitsuba parameters, or its sky pixels, with numbers made
here (numpy) or with the saved scene loaded again.
"""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi

pytest.importorskip("ipywidgets")
from draaw_mi.widgets import MaterialTuner  # noqa: E402

from conftest import tiny_description  # noqa: E402

GREY = 188                      # the environment image's 8-bit sRGB value
TINT = [1.0, 0.5, 0.25]


def _srgb_decode(v):            # (the sRGB curve, written out: the reference for Mitsuba's)
    v = np.asarray(v, np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _env_png(path, image=None):
    from PIL import Image
    Image.fromarray(np.full((8, 16, 3), GREY, np.uint8) if image is None else image).save(path)
    return str(path)


def _env_scene(env, **light):
    """A small sphere in the middle and sky everywhere else, lit by the environment map."""
    return {"render": {"resolution": [16, 16], "filter": "box", "max_depth": 3, "spp": 4},
            "materials": {"m": {"roughness": 0.5}},
            "shapes": [{"type": "sphere", "material": "m", "radius": 0.3}],
            "lights": [{"type": "envmap", "file": env, **light}],
            "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 40}}


def _tuner(scene, **kw):
    return MaterialTuner(scene, autostart=False, freeze=False, frame_channel="image", max_spp=4, **kw)


# --------------------------------------------------------------------------- the scene file
def test_an_envmap_colour_tints_the_image_as_a_pretinted_file_does(tmp_path):
    """``color`` on an envmap light was accepted and dropped. Now the render equals that of
    the same image tinted with numpy and written as EXR (same texels, same sampling)."""
    rng = np.random.default_rng(3)
    img = rng.integers(20, 255, size=(8, 16, 3), dtype=np.uint8)
    png = _env_png(tmp_path / "env.png", img)
    exr = str(tmp_path / "tinted.exr")
    draaw_mi.io.write_exr(exr, (_srgb_decode(img) * TINT).astype(np.float32))
    tinted = draaw_mi.load_scene(_env_scene(png, color=TINT, intensity=1.5))
    reference = draaw_mi.load_scene(_env_scene(exr, intensity=1.5))
    plain = draaw_mi.load_scene(_env_scene(png, intensity=1.5))
    a, b, c = (np.array(draaw_mi.render(s, spp=8, seed=2, version="path", post=[]))[..., :3]
               for s in (tinted, reference, plain))
    assert np.isfinite(a).all()
    np.testing.assert_allclose(a, b, rtol=2e-4, atol=1e-5)
    assert np.abs(a - c).max() > 0.1                     # (the tint is not a no-op)


# --------------------------------------------------------------------------- the tuner
def test_envmap_intensity_and_colour_reach_the_preview_and_what_is_saved(tmp_path):
    """The intensity slider did nothing to an envmap in the preview (Save scaled it: the
    saved scene rendered 4x brighter than the panel showed)."""
    env = _env_png(tmp_path / "env.png")
    t = _tuner(draaw_mi.load_scene(_env_scene(env)))
    try:
        t.refresh()
        t.lights_panel.light_scale.value = 4.0
        t.lights_panel.light_color.value = "#ff8040"
        frame = t.refresh()
        col = np.array(draaw_mi.widgets.tuning.hex_to_linear("#ff8040"))
        sky = frame.raw[0, 0, :3]                          # a corner: the sky seen directly
        np.testing.assert_allclose(sky, _srgb_decode(GREY) * 4.0 * col, rtol=1e-3)
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        p, q = t.scene.params, saved.params
        assert float(np.array(p["envmap_light0.scale"]).ravel()[0]) == pytest.approx(4.0)
        for key in ("envmap_light0.scale", "envmap_light0.data"):
            np.testing.assert_allclose(np.array(p[key]), np.array(q[key]), rtol=1e-5)
        # a second intensity change keeps the tint (the texels are sent only when it changes)
        t.lights_panel.light_scale.value = 2.0
        sky2 = t.refresh().raw[0, 0, :3]
        np.testing.assert_allclose(sky2, sky / 2.0, rtol=1e-3)
    finally:
        t.close()


def test_the_intensity_slider_scales_an_unnamed_envmap_of_an_xml_scene(tmp_path):
    """An XML scene's environment map has no name (``object_<address>.scale``): it is found
    as an emitter's parameter, not by the lights of a scene file."""
    env = _env_png(tmp_path / "env.png")
    xml = tmp_path / "s.xml"
    xml.write_text(f"""<scene version="3.0.0">
  <emitter type="envmap"><string name="filename" value="{env}"/><float name="scale" value="2"/></emitter>
  <shape type="sphere"><float name="radius" value="0.3"/><bsdf type="diffuse"/></shape>
  <sensor type="perspective"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film></sensor></scene>""")
    t = _tuner(str(xml))
    try:
        (key,) = [k for k in t.scene.params.keys() if k.endswith(".scale")]
        t.lights_panel.light_scale.value = 0.5
        frame = t.refresh()
        assert float(np.array(t.scene.params[key]).ravel()[0]) == pytest.approx(1.0)
        np.testing.assert_allclose(frame.raw[0, 0, :3], _srgb_decode(GREY) * 1.0, rtol=1e-3)
    finally:
        t.close()


def test_unsnapping_puts_point_lights_back_where_the_scene_had_them(tmp_path):
    t = _tuner(draaw_mi.load_scene(tiny_description()))
    try:
        key = "point_light0.position"
        start = np.array(t.scene.params[key]).ravel().copy()
        t.lights_panel.snap_light.value = True
        t.camera_panel.yaw.value = 30.0
        t.refresh()
        assert np.abs(np.array(t.scene.params[key]).ravel() - start).max() > 0.5
        t.lights_panel.snap_light.value = False
        t.refresh()
        np.testing.assert_allclose(np.array(t.scene.params[key]).ravel(), start, atol=1e-6)
        assert t.document()["lights"][0]["position"] == pytest.approx(start.tolist())
    finally:
        t.close()


def test_a_refused_change_puts_its_control_back(tmp_path):
    """A version the scene cannot render: the dropdown showed it while the preview kept the
    old one. A refused text field keeps what was typed (to be corrected)."""
    t = _tuner(draaw_mi.load_scene("scenes/sdf_csg.toml", resolution=(24, 16)))
    try:
        before = t.preview.version
        t.controls_render["version"].value = "path"
        assert "cannot see" in t.message.value
        assert t.controls_render["version"].value == before == t.preview.version
        t.controls_render["version"].value = "v3"          # the control still works
        assert t.preview.version == "v3" and t.message.value == ""
        m = next(iter(t.controls))
        t.controls[m]["base_color_text"].value = "red-ish"
        assert "error" in t.message.value
        assert t.controls[m]["base_color_text"].value == "red-ish"
    finally:
        t.close()


@pytest.mark.parametrize("depth", [-1, 0, 40])
def test_the_max_depth_slider_shows_the_scenes_depth(depth):
    """Unbounded (-1), 0 and 40 showed as 1, 1 and 16 while the preview used the scene's."""
    desc = tiny_description(max_depth=depth)
    t = _tuner(draaw_mi.load_scene(desc))
    try:
        slider = t.controls_render["max_depth"]
        assert slider.value == depth == t.preview.max_depth
        slider.value = 5
        slider.value = -1
        assert t.preview.max_depth == -1
    finally:
        t.close()


def test_a_saved_snap_to_camera_light_loads_again(tmp_path):
    """A scene light with ``snap_to_camera = true`` got a ``position`` beside it when saved
    with the snap box ticked, and the scene file refuses the two together."""
    desc = tiny_description()
    desc["lights"][0] = {"type": "point", "snap_to_camera": True, "intensity": 40.0}
    t = _tuner(draaw_mi.load_scene(desc))
    try:
        t.lights_panel.snap_light.value = True
        t.camera_panel.yaw.value = 25.0
        t.refresh()
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        np.testing.assert_allclose(np.array(saved.params["point_light0.position"]).ravel(),
                                   np.array(t.scene.params["point_light0.position"]).ravel(), atol=1e-5)
    finally:
        t.close()


def test_a_snap_to_camera_light_follows_the_orbit_with_the_box_unticked(tmp_path):
    """A scene light with ``snap_to_camera = true`` stayed where the loaded camera was while
    the box was unticked, so the preview lit the scene from elsewhere than a render of the
    saved scene (whose light follows the saved camera). Now it follows the camera; a light
    with a position stays put until the box is ticked."""
    desc = tiny_description()
    fixed = dict(desc["lights"][0])
    desc["lights"] = [{"type": "point", "snap_to_camera": True, "intensity": 40.0, "name": "head"},
                      dict(fixed, name="lamp")]
    t = _tuner(draaw_mi.load_scene(desc))
    try:
        lamp = np.array(t.scene.params["lamp.position"]).ravel().copy()
        assert not t.lights_panel.snap_light.value
        t.camera_panel.yaw.value = 40.0
        t.refresh()
        head = np.array(t.scene.params["head.position"]).ravel()
        np.testing.assert_allclose(head, t.camera_panel.camera_now()[0], atol=1e-5)
        assert np.abs(head - np.asarray(desc["camera"]["origin"], float)).max() > 0.5
        np.testing.assert_allclose(np.array(t.scene.params["lamp.position"]).ravel(), lamp, atol=1e-6)
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        for key in ("head.position", "lamp.position"):       # the preview's lights are the file's
            np.testing.assert_allclose(np.array(saved.params[key]).ravel(),
                                       np.array(t.scene.params[key]).ravel(), atol=1e-5)
        t.lights_panel.snap_light.value = True                            # ticked: both at the camera,
        t.lights_panel.snap_light.value = False                           # unticked: the lamp back, the head stays
        np.testing.assert_allclose(np.array(t.scene.params["lamp.position"]).ravel(), lamp, atol=1e-6)
        np.testing.assert_allclose(np.array(t.scene.params["head.position"]).ravel(), head, atol=1e-5)
    finally:
        t.close()


@pytest.mark.parametrize("target", [None, [0.3, 0.0, -0.2]])
def test_a_snap_to_camera_spot_light_follows_the_orbit(tmp_path, target):
    """The same for a spot light (its frame, ``to_world``): at the camera, aimed at its own
    target or, without one, at the camera's; what the preview has is what is saved."""
    desc = tiny_description()
    spot = {"type": "spot", "snap_to_camera": True, "intensity": 60.0, "cutoff_angle": 30.0, "name": "torch"}
    if target is not None:
        spot["target"] = target
    desc["lights"] = [spot, {"type": "constant", "intensity": 0.1}]
    t = _tuner(draaw_mi.load_scene(desc))
    try:
        def frame(scene):
            return np.array(scene.params["torch.to_world"].matrix, dtype=np.float64).reshape(4, 4)
        start = frame(t.scene)
        t.camera_panel.yaw.value = -35.0
        t.camera_panel.pitch.value = 10.0
        t.refresh()
        now = frame(t.scene)
        eye, cam_target, _ = t.camera_panel.camera_now()
        np.testing.assert_allclose(now[:3, 3], eye, atol=1e-5)             # at the camera
        aim = np.asarray(cam_target if target is None else target, float) - eye
        np.testing.assert_allclose(now[:3, 2], aim / np.linalg.norm(aim), atol=1e-5)   # shining there
        assert np.abs(now - start).max() > 0.3
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        np.testing.assert_allclose(frame(saved), now, atol=1e-5)
    finally:
        t.close()


def test_an_orbit_into_a_smoke_box_is_refused_before_the_lights_follow():
    """Zooming the camera into a [[volumes]] smoke box: refused with the scene file's message,
    the slider goes back, and snapped point lights stay where the camera still is (they moved
    to the refused camera)."""
    desc = tiny_description()
    desc["volumes"] = [{"name": "fog", "mode": "smoke", "density": [[[1.0]]],
                        "bounds": [[-1.5, -0.5, -1.5], [1.5, 2.5, 1.5]]}]
    t = _tuner(draaw_mi.load_scene(desc))
    try:
        key = "point_light0.position"
        t.lights_panel.snap_light.value = True
        t.refresh()
        placed = np.array(t.scene.params[key]).ravel().copy()
        to_world = np.array(t.scene.params["sensor.to_world"].matrix).copy()
        t.camera_panel.distance.value = 0.1                     # 0.5 units from the target: inside the box
        assert "inside smoke volume 'fog'" in t.message.value
        assert t.camera_panel.distance.value == 1.0
        t.refresh()
        np.testing.assert_array_equal(np.array(t.scene.params["sensor.to_world"].matrix), to_world)
        np.testing.assert_array_equal(np.array(t.scene.params[key]).ravel(), placed)
    finally:
        t.close()
