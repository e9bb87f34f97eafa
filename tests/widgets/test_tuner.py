"""MaterialTuner headless: controls -> scene parameters and image; save -> reload; bad input.

No browser: ipywidgets run without a front end (their comms are inert); frames are rendered
synchronously with ``refresh()`` (``autostart=False``), except in the worker-thread test.
"""
from __future__ import annotations

import io
import json
import os
import time

import numpy as np
import pytest

import draaw_mi

W = pytest.importorskip("ipywidgets")
from draaw_mi.widgets import MaterialTuner  # noqa: E402

from conftest import tiny_description  # noqa: E402


def _decode(data: bytes) -> np.ndarray:
    from PIL import Image
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"), dtype=np.float32)


@pytest.fixture
def tuner(tmp_path):
    desc = tiny_description()
    path = tmp_path / "tiny.toml"
    import tomli_w
    path.write_text(tomli_w.dumps(desc))
    t = MaterialTuner(str(path), autostart=False, freeze=False, interactive_scale=1.0, max_spp=64,
                      frame_channel="image")
    yield t
    t.close()


def test_panel_has_every_draaw_parameter_for_every_material(tuner):
    for m in ("ball", "ground"):
        ctl = tuner.controls[m]
        for p in ("base_color", "roughness", "metallic", "specular", "reflection", "direct_to_scatter"):
            assert p in ctl, (m, p)
        assert ctl["roughness"].min == 0.0 and ctl["roughness"].max == 1.0
    assert [tuner.tabs.get_title(i) for i in range(6)] == ["Materials", "Render", "Light", "Camera", "Post", "Save"]


def test_slider_changes_scene_parameter_and_image(tuner):
    tuner.refresh(2)
    before = _decode(tuner.image.value)
    k = tuner.scene.key("ball.roughness")
    tuner.controls["ball"]["roughness"].value = 0.05
    tuner.controls["ball"]["metallic"].value = 1.0
    tuner.refresh(2)
    assert tuner.message.value == ""
    assert float(np.array(tuner.scene.params[k]).ravel()[0]) == pytest.approx(0.05)
    assert tuner.materials["ball"]["metallic"] == 1.0
    after = _decode(tuner.image.value)
    assert np.abs(after - before).max() > 20          # 8-bit levels: the sphere visibly changed
    assert tuner.last_frame.spp == 2                  # the mean restarted at the change


def test_colour_picker_and_text_field_agree(tuner):
    tuner.controls["ball"]["base_color"].value = "#ff0000"
    k = tuner.scene.key("ball.base_color")
    np.testing.assert_allclose(np.array(tuner.preview._pending[k]), [1.0, 0.0, 0.0])
    assert tuner.controls["ball"]["base_color_text"].value == "1, 0, 0"
    tuner.controls["ball"]["base_color_text"].value = "0.2, 0.4, 0.6"
    tuner.refresh()
    np.testing.assert_allclose(np.array(tuner.scene.params[k]).ravel(), [0.2, 0.4, 0.6], rtol=1e-6)
    assert tuner.controls["ball"]["base_color"].value == draaw_mi.widgets.tuning.linear_to_hex([0.2, 0.4, 0.6])


@pytest.mark.parametrize("field, value, match", [
    ("base_color_text", "1, x, 2", "is not a colour"),
    ("base_color_text", "1, 2", "three finite numbers"),
    ("base_color_text", "-1, 0, 0", "three finite numbers"),
    ("base_color_text", "1e40, 0, 0", "three finite numbers"),     # (float32: inf, NaN pixels)
])
def test_bad_text_value_shows_an_error_not_a_traceback(tuner, field, value, match):
    k = tuner.scene.key("ball.base_color")
    old = np.array(tuner.scene.params[k]).ravel().copy()
    tuner.controls["ball"][field].value = value           # must not raise
    assert "error" in tuner.message.value and match in tuner.message.value
    tuner.refresh()
    np.testing.assert_array_equal(np.array(tuner.scene.params[k]).ravel(), old)
    tuner.controls["ball"]["roughness"].value = 0.3       # the next good change clears it
    assert tuner.message.value == ""


def test_bad_files_and_post_json_show_errors(tuner):
    tuner.controls["ball"]["texture"].value = "no/such/file.png"
    tuner._guard(lambda: tuner._apply_textures("ball"))()
    assert "does not exist" in tuner.message.value
    tuner.post_panel.post_json.value = "[{'type': 'bloom'}"
    tuner._guard(lambda: tuner.post_panel.from_json(tuner.post_panel.post_json.value))()
    assert "post chain JSON" in tuner.message.value
    tuner._guard(lambda: tuner.post_panel.from_json('[{"type": "blom"}]'))()
    assert "blom" in tuner.message.value and tuner.post == []


def test_post_chain_editor_add_reorder_amount_remove(tuner):
    tuner.post_panel.edit(add="contrast")
    tuner.post_panel.edit(add="tint")
    assert [e["type"] for e in tuner.post] == ["contrast", "tint"]
    tuner.post_panel.edit(up=1)
    assert [e["type"] for e in tuner.post] == ["tint", "contrast"]
    tuner.post_panel.post_rows.children[1].children[0].value = 0.9       # the amount slider of "contrast"
    assert tuner.post[1]["amount"] == 0.9 and tuner.preview.post == tuner.post
    assert json.loads(tuner.post_panel.post_json.value) == tuner.post
    tuner.post_panel.edit(remove=0)
    assert [e["type"] for e in tuner.post] == ["contrast"]
    f = tuner.refresh()
    import mitsuba as mi
    expected = np.array(draaw_mi.post.apply(mi.TensorXf(f.raw), tuner.post))
    np.testing.assert_allclose(f.image, expected, rtol=1e-5, atol=1e-6)


def test_the_up_button_of_the_first_filter_leaves_the_chain_as_it_is(tuner):
    """The first row's "↑" (up=0) swapped the first and the last filters (chain[-1] and
    chain[0]); there is nothing above the first row, so the order stays."""
    for name in ("contrast", "tint", "lighten"):
        tuner.post_panel.edit(add=name)
    tuner.post_panel.edit(up=0)
    assert [e["type"] for e in tuner.post] == ["contrast", "tint", "lighten"]
    tuner.post_panel.edit(up=2)                                   # (the last row does move up)
    assert [e["type"] for e in tuner.post] == ["contrast", "lighten", "tint"]


def test_an_added_filter_starts_at_an_amount_that_shows(tuner):
    """"add" starts a filter at amount 0.5, except where the Post tab's start says otherwise:
    sRGB at amount 1.0 (half an encoding is neither linear nor encoded; the start was
    overwritten by the 0.5) and contrast at contrast 2.0 (1.0 is the identity)."""
    tuner.post_panel.edit(add="srgb")
    tuner.post_panel.edit(add="contrast")
    assert tuner.post[0]["type"] == "srgb" and tuner.post[0]["amount"] == 1.0, tuner.post
    assert tuner.post[1]["type"] == "contrast", tuner.post
    assert tuner.post[1]["amount"] == 0.5 and tuner.post[1]["contrast"] == 2.0, tuner.post


def test_camera_light_and_render_options(tuner):
    tuner.refresh()
    T0 = np.array(tuner.scene.params["sensor.to_world"].matrix)
    tuner.camera_panel.yaw.value = 30.0
    tuner.camera_panel.fov.value = 60.0
    tuner.refresh()
    assert np.abs(np.array(tuner.scene.params["sensor.to_world"].matrix) - T0).max() > 0.1
    assert float(np.array(tuner.scene.params["sensor.x_fov"]).ravel()[0]) == pytest.approx(60.0)
    cam = tuner.camera_panel.get_camera()
    r0 = np.linalg.norm(np.subtract([0.0, 1.0, 5.0], [0.0, 0.5, 0.0]))
    assert np.linalg.norm(np.subtract(cam["origin"], cam["target"])) == pytest.approx(r0, rel=1e-4)
    k = "point_light0.intensity.value"
    base = np.array(tuner.scene.params[k]).ravel().copy()
    tuner.lights_panel.light_scale.value = 2.0
    tuner.refresh()
    np.testing.assert_allclose(np.array(tuner.scene.params[k]).ravel(), base * 2, rtol=1e-6)
    tuner.controls_render["max_depth"].value = 2
    tuner.controls_render["version"].value = "v3"
    assert tuner.preview.max_depth == 2 and tuner.preview.version == "v3"
    assert tuner.refresh().spp == 1


def test_post_filters_added_change_the_image_and_params_entries_take_the_slider(tuner):
    """"add contrast" gave contrast 1.0 (the identity: the image moved by 1.5e-8 at any
    amount); a chain entry written with "params" showed amount 1.0 and refused its slider."""
    import mitsuba as mi
    rng = np.random.default_rng(1)
    img = mi.TensorXf(rng.uniform(0.05, 0.95, (8, 8, 3)).astype(np.float32))
    for name in ("contrast", "tint", "sharpen", "lighten"):
        tuner.post_panel.set_chain([])
        tuner.post_panel.edit(add=name)
        out = np.array(draaw_mi.post.apply(img, tuner.post))
        assert np.abs(out - np.array(img)).max() > 0.01, name
    tuner.post_panel.from_json('[{"type": "bloomV2", "params": {"amount": 0.2, "spread": 0.5}}]')
    slider = tuner.post_panel.post_rows.children[0].children[0]
    assert slider.value == pytest.approx(0.2)
    slider.value = 0.4
    assert tuner.message.value == "" and tuner.post[0]["amount"] == pytest.approx(0.4)
    assert tuner.post[0]["spread"] == pytest.approx(0.5)


def test_save_then_reload_gives_the_same_scene(tuner, tmp_path):
    tuner.controls["ball"]["roughness"].value = 0.12
    tuner.controls["ground"]["base_color_text"].value = "0.1, 0.6, 0.2"
    tuner.camera_panel.yaw.value = -25.0
    tuner.lights_panel.light_scale.value = 0.5
    tuner.post_panel.edit(add="contrast")
    tuner.refresh()
    out = str(tmp_path / "tuned.toml")
    tuner.save_panel.save_path.value = out
    tuner._guard(lambda: tuner.save(out))()
    assert "saved" in tuner.message.value
    again = draaw_mi.load_scene(out)
    assert again.settings["post"] == tuner.post
    for m, vals in tuner.materials.items():
        for p, v in vals.items():
            got = np.array(again.params[again.key(f"{m}.{p}")]).ravel()
            np.testing.assert_allclose(got, np.broadcast_to(v, got.shape), rtol=1e-6)
    for key in ("sensor.to_world", "point_light0.intensity.value", "constant_light1.radiance.value"):
        a, b = tuner.scene.params[key], again.params[key]
        a, b = (np.array(a.matrix), np.array(b.matrix)) if key.endswith("to_world") else (np.array(a), np.array(b))
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    # and the same image, rendered from both with one seed (box filter: bit-comparable)
    img_a = np.array(draaw_mi.render(tuner.scene, spp=4, seed=9, post=[]))
    img_b = np.array(draaw_mi.render(again, spp=4, seed=9, post=[]))
    np.testing.assert_allclose(img_a, img_b, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("fov, axis", [(150.0, "x"), (30.0, "y")])
def test_save_keeps_the_camera_and_snapped_lights(tmp_path, fov, axis):
    """A 150-degree camera (the slider stopped at 120: saving wrote 120), a vertical FOV (saved
    as the x FOV with fov_axis "y" kept: 56.4 degrees came back as 94) and point lights snapped
    to the orbited camera (saved where they were loaded)."""
    import tomli_w
    desc = tiny_description()
    desc["camera"].update(fov=fov, fov_axis=axis)
    path = tmp_path / "wide.toml"
    path.write_text(tomli_w.dumps(desc))
    t = MaterialTuner(str(path), autostart=False, freeze=False, interactive_scale=1.0, max_spp=4,
                      frame_channel="image")
    try:
        t.lights_panel.snap_light.value = True
        t.camera_panel.yaw.value = 30.0
        t.controls["ball"]["roughness"].value = 0.2
        t.refresh()
        out = str(tmp_path / "saved.toml")
        t.save(out)
        again = draaw_mi.load_scene(out)
        for key in ("sensor.x_fov", "sensor.to_world", "point_light0.position"):
            a, b = t.scene.params[key], again.params[key]
            a, b = (a.matrix, b.matrix) if key.endswith("to_world") else (a, b)
            np.testing.assert_allclose(np.array(b), np.array(a), rtol=1e-5, atol=1e-5, err_msg=key)
        if axis == "x":
            assert float(np.array(again.params["sensor.x_fov"]).ravel()[0]) == pytest.approx(fov)
    finally:
        t.close()


def test_a_scene_saved_to_another_folder_keeps_its_files(tmp_path):
    """A scene naming a texture relative to its folder, saved by the tuner two folders away:
    the written scene names the texture relative to its own folder and renders the same image
    (the name was copied as written, and the saved scene failed to load)."""
    import tomli_w
    (tmp_path / "a").mkdir()
    draaw_mi.write_png(str(tmp_path / "a" / "wood.png"), np.array([[[0.9, 0.3, 0.1], [0.1, 0.3, 0.9]]], np.float32))
    desc = tiny_description()
    desc["materials"]["ground"]["base_color"] = "wood.png"
    (tmp_path / "a" / "s.toml").write_text(tomli_w.dumps(desc))
    t = MaterialTuner(str(tmp_path / "a" / "s.toml"), autostart=False, freeze=False, interactive_scale=1.0)
    try:
        out = tmp_path / "b" / "c" / "tuned.toml"
        t.save(str(out))
        again = draaw_mi.load_scene(str(out))
        assert again.description["materials"]["ground"]["base_color"] == os.path.join("..", "..", "a", "wood.png")
        img_a = np.array(draaw_mi.render(t.scene, spp=4, seed=9, post=[]))
        img_b = np.array(draaw_mi.render(again, spp=4, seed=9, post=[]))
        np.testing.assert_allclose(img_a, img_b, rtol=1e-4, atol=1e-5)
    finally:
        t.close()


def test_reference_error_line_matches_numpy(tuner):
    tuner.refresh(3)
    ref = tuner.last_frame.image * 0.5
    t2 = MaterialTuner(tuner.scene, reference=ref, autostart=False, freeze=False, interactive_scale=1.0)
    try:
        f = t2.refresh()
        rmse = float(np.sqrt(np.mean((f.image - ref) ** 2)))
        assert f"RMSE {rmse:.4f}" in t2.error_label.value
        assert len(t2.error_image.value) > 100
        t2.controls_render["scale"].value = 0.5          # frames 16x12 against a 32x24 reference
        t2.refresh()
        assert "RMSE" not in t2.error_label.value and "32x24" in t2.error_label.value
    finally:
        t2.close()


def test_snippet_runs_and_reproduces_values(tuner, tmp_path, monkeypatch):
    """Run from another folder, on a scene the tuner was given at another resolution: the
    snippet named the file relative to the start folder, left the resolution out (256x256
    instead of the tuned size) and printed 4 figures (0.123456 became 0.1235)."""
    monkeypatch.chdir(os.path.dirname(tuner.scene.source))
    relative = os.path.basename(tuner.scene.source)
    t = MaterialTuner(draaw_mi.load_scene(relative, resolution=(16, 12)), autostart=False,
                      freeze=False, frame_channel="image")
    try:
        t.controls["ball"]["roughness"].value = 0.123456
        t.controls["ground"]["base_color_text"].value = "0.885809, 0.1, 0.2"
        code = t.snippet()
    finally:
        t.close()
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    ns: dict = {}
    exec(compile(code.replace("image = draaw_mi.render(", "image = (lambda *a, **k: None)("), "snippet", "exec"), ns)
    sc = ns["scene"]
    assert sc.resolution == (16, 12)
    assert float(np.array(sc.params[sc.key("ball.roughness")]).ravel()[0]) == np.float32(0.123456)
    np.testing.assert_array_equal(np.array(sc.params[sc.key("ground.base_color")]).ravel(),
                                  np.float32([0.885809, 0.1, 0.2]))


def test_worker_thread_pushes_jpeg_while_interacting_then_png_at_rest():
    t = MaterialTuner(draaw_mi.load_scene(tiny_description()), max_spp=4, rest_after=30.0, freeze=True,
                      frame_channel="image")
    try:
        assert t.preview.wait(spp=4, timeout=60) is not None
        t.controls["ball"]["metallic"].value = 0.5
        g = t.preview.generation
        assert t.preview.wait(g, spp=4, timeout=60) is not None
        import time
        time.sleep(0.2)                   # the callback of the last frame has finished
        mine = [(spp, fmt) for gen, spp, fmt in t.sent if gen == g]
        assert mine[0] == (0, "jpeg")                     # the half-resolution first frame
        assert mine[-1] == (4, "png")                     # budget reached: lossless
        assert all(fmt == "jpeg" for spp, fmt in mine[:-1])
        assert t.image.format == "png" and t.image.value[:4] == b"\x89PNG"
    finally:
        t.close()
    assert not t.preview.running


def _go_draaw_camera_to_world(position, theta, phi, fov_deg):
    """Camera-to-world matrix for a GO-Draaw camera, written from go-draaw-spec.md §2.8 and
    Mitsuba's look_at convention (columns: left = up x forward, up, forward, origin).
    GO-Draaw's image is the bilinear patch TL, TR = S(θ+F, φ), BL = S(θ, φ+F): its centre ray
    is (TR + BL) / 2, its image-up direction TL - BL (made orthogonal to the centre ray) and its
    image-right the side of TR - TL; Mitsuba's film runs along minus the first column, so that
    column is fwd x up where TR - TL points to up x fwd (sin φ > 0: a mirrored camera)."""
    def S(th, ph):
        return np.array([np.sin(ph) * np.cos(th), np.sin(ph) * np.sin(th), np.cos(ph)])
    F = np.radians(fov_deg)
    tl, tr, bl = S(theta, phi), S(theta + F, phi), S(theta, phi + F)
    fwd = (tr + bl) / np.linalg.norm(tr + bl)
    up = (tl - bl) - fwd * np.dot(tl - bl, fwd)
    up /= np.linalg.norm(up)
    left = np.cross(up, fwd)
    if np.dot(tr - tl, left) > 0:
        left = -left
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, up, fwd, position
    return m


def test_camera_path_moves_the_camera_to_each_keyframe(tuner):
    """Stepping the *path frame* slider puts the camera on that frame of the path: frames 0, 4
    and 9 of 10 between two keys are at u = j/9, i.e. key0 + (key1 - key0) s(j/9) with
    smoothstep s (the default interpolation, closed form here), and the sensor's to_world
    equals the GO-Draaw camera of that (x, y, z, θ, φ) built from the spec (helper above).
    Tolerance 1e-5: the float32 matrix of entries below 7 (a frame off by one is ~1e-2 away)."""
    keys = np.array([(0.0, 1.0, 6.0, -1.5708, 1.5708), (2.0, 1.5, 5.0, -1.2, 1.5)])
    path = tuner.load_camera_path([tuple(k) for k in keys], frames=10)
    assert len(path) == 10 and tuner.camera_panel.path_frame.max == 9 and not tuner.camera_panel.path_play.disabled
    fov = float(tuner.camera_panel.fov.value)
    assert fov == pytest.approx(40.0)                        # the scene's x_fov
    for j in (4, 9, 0):                                      # 0 last: the slider really moves back
        tuner.camera_panel.path_frame.value = j
        tuner.refresh()
        t = j / 9
        x, y, z, theta, phi = keys[0] + (keys[1] - keys[0]) * t * t * (3 - 2 * t)
        m = np.array(tuner.scene.params["sensor.to_world"].matrix).reshape(4, 4)
        np.testing.assert_allclose(m, _go_draaw_camera_to_world((x, y, z), theta, phi, fov), rtol=0, atol=1e-5,
                                   err_msg=f"path frame {j}")
    # (frames / 60 s at 60 fps: 123 frames came out 122)
    assert len(tuner.load_camera_path([tuple(k) for k in keys], frames=123)) == 123 == tuner.camera_panel.path_frame.max + 1
    tuner._guard(lambda: tuner.load_camera_path("no/such/path.json"))()
    assert "camera path" in tuner.message.value


def test_texture_file_and_resolution_scale_reload_the_scene(tuner, tmp_path):
    import matplotlib.image
    tex = tmp_path / "checker.png"
    checker = (np.indices((8, 8)).sum(axis=0) % 2).astype(np.float32)
    matplotlib.image.imsave(str(tex), np.dstack([checker, 0.2 + 0 * checker, 1 - checker]))
    tuner.controls["ball"]["roughness"].value = 0.2                 # survives the reload
    tuner.controls["ball"]["texture"].value = str(tex)
    tuner._guard(lambda: tuner._apply_textures("ball"))()
    assert tuner.message.value == ""
    assert "ball.base_color.data" in tuner.scene.params            # now a bitmap texture
    assert tuner.controls["ball"]["base_color"].disabled
    assert float(np.array(tuner.scene.params["ball.roughness.value"]).ravel()[0]) == pytest.approx(0.2)
    tuner.controls_render["scale"].value = 0.5
    f = tuner.refresh()
    assert f.image.shape == (12, 16, 3) and tuner.scene.resolution == (16, 12)
    out = str(tmp_path / "t.toml")
    tuner.save(out)
    again = draaw_mi.load_scene(out)
    assert again.resolution == (32, 24) and "ball.base_color.data" in again.params


def test_snap_light_to_camera_moves_point_lights(tuner):
    tuner.lights_panel.snap_light.value = True
    tuner.camera_panel.yaw.value = 40.0
    tuner.refresh()
    origin = np.array(tuner.scene.params["sensor.to_world"].matrix).reshape(4, 4)[:3, 3]
    np.testing.assert_allclose(np.array(tuner.scene.params["point_light0.position"]).ravel(), origin, atol=1e-5)


def test_missing_ipywidgets_is_one_clear_error(monkeypatch):
    """Without ipywidgets the tuner is one clear error; the widget-free helpers still import."""
    import importlib
    import sys
    monkeypatch.setitem(sys.modules, "ipywidgets", None)
    for name in [m for m in sys.modules if m.startswith("draaw_mi.widgets")]:
        monkeypatch.delitem(sys.modules, name)
    widgets = importlib.import_module("draaw_mi.widgets")
    assert widgets.tuning.linear_to_hex([1.0, 1.0, 1.0]) == "#ffffff"
    with pytest.raises(draaw_mi.DraawError, match=r"pip install 'draaw-mi\[notebooks\]'"):
        from draaw_mi.widgets import MaterialTuner  # noqa: F401


@pytest.mark.parametrize("channel", ["image", "rfb"])
def test_close_releases_every_widget_and_the_scene(tmp_path, channel):
    """A closed tuner leaves no widget in ipywidgets' registry (rows of the post chain that
    were replaced included) and its scene's draaw materials die with it: a live material
    would enlarge the BSDF calls of every later render in the kernel."""
    import gc
    import ipywidgets
    from draaw_mi.materials.draaw_bsdf import LIVE_INSTANCES
    if channel == "rfb":
        pytest.importorskip("jupyter_rfb")
    registry = ipywidgets.widgets.widget._instances
    gc.collect()
    n_widgets, n_bsdfs = len(registry), len(list(LIVE_INSTANCES))
    t = MaterialTuner(draaw_mi.load_scene(tiny_description()), autostart=False, freeze=False,
                      frame_channel=channel)
    assert (t.canvas is not None) == (channel == "rfb")
    t.post_panel.edit(add="contrast")
    t.post_panel.edit(add="tint")
    t.post_panel.edit(remove=0)                      # two rebuilds of the rows
    assert len(registry) > n_widgets and len(list(LIVE_INSTANCES)) > n_bsdfs
    t.close()
    del t
    gc.collect()
    assert len(registry) == n_widgets
    assert len(list(LIVE_INSTANCES)) == n_bsdfs


def test_light_controls_survive_a_reload_without_compounding(tuner):
    """Intensity ×2, then a reload (resolution), then a colour change: the light is the
    loaded value × 2, not × 4 (the reloaded scene's scaled lights became the base), and
    what save() writes is × 2 too."""
    k = "point_light0.intensity.value"
    base = np.array(tuner.scene.params[k]).ravel().copy()
    tuner.lights_panel.light_scale.value = 2.0
    tuner.controls_render["scale"].value = 0.5                     # reloads the scene
    tuner.lights_panel.light_color.value = "#ffffff"
    tuner.lights_panel.light_scale.value = 2.0 + 1e-9                           # any light change re-applies
    tuner.refresh()
    np.testing.assert_allclose(np.array(tuner.scene.params[k]).ravel(), base * 2, rtol=1e-6)
    assert tuner.document()["lights"][0]["intensity"] == pytest.approx(40.0 * 2.0)
    tuner.controls_render["scale"].value = 1.0                     # a second reload
    assert tuner.document()["lights"][0]["intensity"] == pytest.approx(40.0 * 2.0)
    np.testing.assert_allclose(np.array(tuner.scene.params[k]).ravel(), base * 2, rtol=1e-6)


def test_a_texture_that_does_not_load_is_not_kept(tuner, tmp_path):
    """A file that exists but is no image: one red error, and the tuner goes on as before
    (the bad path blocked every later reload and went into save())."""
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    tuner.controls["ball"]["texture"].value = str(bad)
    tuner._guard(lambda: tuner._apply_textures("ball"))()
    assert "error" in tuner.message.value
    assert tuner._textures == {} and "base_color" in tuner.materials["ball"]
    tuner.controls_render["scale"].value = 0.5                     # a reload works
    assert tuner.scene.resolution == (16, 12)
    assert tuner.document()["materials"]["ball"]["base_color"] == pytest.approx([0.8, 0.3, 0.2])


def test_a_frame_that_fails_is_shown_in_red_and_a_change_recovers(tuner, monkeypatch):
    """The worker's render error reaches the panel (it kept its last frame without a word);
    the next change renders again."""
    tuner.preview.start()
    try:
        from draaw_mi.rendering.session import Session
        real = Session.render_pass
        monkeypatch.setattr(Session, "render_pass",
                            lambda *a, **k: (_ for _ in ()).throw(RuntimeError("kernel exploded")))
        g = tuner.preview.update({"ball.roughness": 0.3})
        deadline = time.time() + 30
        # (until the changed frame fails: a frame in flight before the change may have failed
        # first, said so, and had its error cleared by the change)
        while (tuner.preview.error is None or "render failed" not in tuner.message.value) \
                and time.time() < deadline:
            time.sleep(0.02)
        assert "render failed: kernel exploded" in tuner.message.value
        assert tuner.preview.error is not None
        monkeypatch.setattr(Session, "render_pass", real)
        g = tuner.preview.update({"ball.roughness": 0.4})
        f = tuner.preview.wait(g, spp=2, timeout=30)
        assert f is not None and f.spp >= 2 and tuner.preview.error is None
    finally:
        tuner.preview.stop()


def test_the_error_line_of_an_srgb_chain_compares_the_linear_mean(tuner):
    """With a chain that ends in srgb the shown image is display-encoded; the reference is
    linear, so the error uses the linear mean (RMSE 0.27 for a reference equal to it)."""
    tuner.preview.configure(post=[{"type": "srgb"}])
    f = tuner.refresh(2)
    tuner.reference = f.raw.copy()
    tuner._show(f)
    assert "RMSE 0.0000" in tuner.error_label.value


def test_bad_tuner_arguments_fail_at_once(tuner, capsys):
    """A reference of another size (the error line then never showed), a budget below one
    sample; a version outside the dropdown's list is shown as chosen (the dropdown said v4
    while the preview rendered volpath); a script's tuner prints nothing."""
    w, h = tuner.scene.resolution
    with pytest.raises(draaw_mi.DraawError, match=f"expected the scene's {w}x{h}"):
        MaterialTuner(tuner.scene, reference=np.zeros((h + 1, w, 3), np.float32), autostart=False)
    with pytest.raises(draaw_mi.DraawError, match="max_spp"):
        MaterialTuner(tuner.scene, max_spp=0, autostart=False)
    capsys.readouterr()
    t = MaterialTuner(tuner.scene, version="prb", autostart=False, freeze=False)
    try:
        assert t.controls_render["version"].value == "prb" and t.preview.version == "prb"
        assert capsys.readouterr().out == ""           # (jupyter_rfb printed RFBOutputContext())
    finally:
        t.close()


def test_a_panel_stopped_by_a_newer_one_refuses_changes():
    """A second tuner of one scene stops the first (its panel says so). A slider moved in the
    first then cleared that message, wrote into the scene the newer panel shows and rendered
    nothing: the first panel's values and the scene parted ways."""
    scene = draaw_mi.load_scene(tiny_description())
    first = MaterialTuner(scene, freeze=False, interactive_scale=1.0, max_spp=2, frame_channel="image")
    second = None
    try:
        assert first.preview.wait(spp=1, timeout=60) is not None
        second = MaterialTuner(scene, freeze=False, interactive_scale=1.0, max_spp=2, frame_channel="image")
        deadline = time.time() + 30
        while first.status.value != "stopped" and time.time() < deadline:
            time.sleep(0.05)
        assert first.status.value == "stopped" and "newer preview" in first.message.value
        key = scene.key("ball.roughness")
        held = np.array(scene.params[key]).ravel().copy()
        first.controls["ball"]["roughness"].value = 0.05
        assert "no longer changes the scene" in first.message.value
        assert first.materials["ball"]["roughness"] != 0.05
        np.testing.assert_array_equal(np.array(scene.params[key]).ravel(), held)
        second.controls["ball"]["roughness"].value = 0.07          # the newer panel works
        assert second.message.value == ""
    finally:
        first.close()
        if second is not None:
            second.close()
