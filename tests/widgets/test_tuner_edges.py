"""MaterialTuner edge cases from a review: edits made outside the panel survive the resolution
slider and Save; load settings are kept; a refused orbit puts its sliders back; XML cameras;
the resolution slider's aspect ratio; Preview.reset shows new values at once; bad arguments."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi

W = pytest.importorskip("ipywidgets")
from draaw_mi.widgets import MaterialTuner  # noqa: E402

from conftest import tiny_description  # noqa: E402

LIGHT = "point_light0.intensity.value"


def _tuner(scene, **kw):
    opts = dict(autostart=False, freeze=False, interactive_scale=1.0, max_spp=4, frame_channel="image")
    opts.update(kw)
    return MaterialTuner(scene, **opts)


def test_a_light_set_outside_the_panel_survives_reload_and_save(tmp_path):
    sc = draaw_mi.load_scene(tiny_description())
    sc.params[LIGHT] = draaw_mi.scene.value_like(sc.params[LIGHT], [5.0, 5.0, 5.0], LIGHT)
    sc.params.update()
    t = _tuner(sc)
    try:
        t.controls_render["scale"].value = 0.5           # a reload from the document
        assert np.allclose(np.array(t.scene.params[LIGHT]).ravel(), 5.0)     # (was the file's 40)
        t.lights_panel.light_scale.value = 2.0
        t.refresh(1)
        assert np.allclose(np.array(t.scene.params[LIGHT]).ravel(), 10.0)
        light = t.document()["lights"][0]          # (intensity 80: the file's 40 times 2)
        assert np.allclose(light["intensity"] * np.asarray(light.get("color", 1.0)), 10.0), light
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        assert np.allclose(np.array(saved.params[LIGHT]).ravel(), 10.0)
    finally:
        t.close()


def test_an_sdf_value_set_through_the_preview_survives_reload_and_save(tmp_path):
    d = tiny_description()
    d["sdf"] = [{"type": "sphere", "name": "blob", "material": "ball", "center": [1.2, 0.5, 0.0], "radius": 0.3}]
    t = _tuner(draaw_mi.load_scene(d))
    try:
        t.preview.update({"sdf.blob.radius": 0.2})
        t.refresh(1)
        t.controls_render["scale"].value = 0.5
        assert float(np.array(t.scene.all_params["sdf.blob.radius"]).ravel()[0]) == pytest.approx(0.2)
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        assert float(np.array(saved.all_params["sdf.blob.radius"]).ravel()[0]) == pytest.approx(0.2)
        # what the file says already is not written again (no churn in a saved file)
        assert t.save_panel.outside_edits().keys() == {"sdf.blob.radius"}
    finally:
        t.close()


def test_load_settings_are_kept_by_the_resolution_slider_and_save(tmp_path):
    sc = draaw_mi.load_scene(tiny_description(), filter="gaussian", sampler="stratified")
    t = _tuner(sc)
    try:
        t.controls_render["scale"].value = 0.5
        assert (t.scene.settings["filter"], t.scene.settings["sampler"]) == ("gaussian", "stratified")
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        assert (saved.settings["filter"], saved.settings["sampler"]) == ("gaussian", "stratified")
    finally:
        t.close()


def test_a_refused_orbit_puts_the_sliders_back():
    d = tiny_description()
    d["volumes"] = [{"name": "fog", "mode": "smoke", "bounds": [[-0.5, 1.4, -0.5], [0.5, 2.4, 0.5]],
                     "procedural": {"type": "plume", "seed": 3, "resolution": [8, 8, 8]}}]
    d["camera"] = {"origin": [0.0, 5.0, 0.01], "target": [0.0, 0.0, 0.0], "fov": 40}
    t = _tuner(draaw_mi.load_scene(d))
    try:
        before = t.camera_panel.camera_now()[0]
        t.camera_panel.zoom(0.35)                                   # origin (0, 1.75, ~0): inside the smoke
        assert "smoke" in t.message.value
        assert t.camera_panel.distance.value == 1.0                  # (stayed at 0.35)
        assert np.allclose(t.document()["camera"]["origin"], before)
        t.camera_panel.zoom(0.9)                                    # a move that is allowed still moves
        assert t.camera_panel.distance.value == pytest.approx(0.9)
        # a camera path whose last frame is inside the smoke: that frame is refused and the
        # camera stays the frame before's (it took the refused one, which Save then wrote)
        t.load_camera_path([(0.0, 4.0, 3.0, 0.0, -1.9), (0.0, 1.9, 0.0, 0.0, -1.9)], frames=4)
        assert t.message.value == ""
        before = dict(t.camera)
        t.camera_panel.path_frame.value = t.camera_panel.path_frame.max
        assert "smoke" in t.message.value
        assert t.camera == before
        np.testing.assert_allclose(t.document()["camera"]["origin"], before["origin"])
    finally:
        t.close()


XML = """<scene version="3.0.0">
  <sensor type="perspective"{sid}><float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/>
      <rfilter type="box"/></film></sensor>
  <shape type="sphere"><bsdf type="diffuse"/></shape>
  <emitter type="constant"/>
</scene>
"""


@pytest.mark.parametrize("sid", [' id="cam"', ""])
def test_the_fov_slider_finds_an_xml_sensor(tmp_path, sid):
    path = tmp_path / "s.xml"
    path.write_text(XML.format(sid=sid))
    t = _tuner(str(path), version="path")
    try:
        assert t.camera_panel.fov.value == pytest.approx(60.0)        # (40, the default)
        t.camera_panel.fov.value = 30.0                               # ("no parameter 'sensor.x_fov'")
        t.refresh(1)
        assert t.message.value == ""
        from draaw_mi.scene.camera import sensor_keys
        assert float(np.array(t.scene.params[sensor_keys(t.scene)[1]]).ravel()[0]) == pytest.approx(30.0)
    finally:
        t.close()


def test_the_resolution_slider_keeps_the_aspect_ratio():
    from draaw_mi.widgets import scaled_resolution
    assert scaled_resolution((32, 24), 0.25) == (11, 8)          # (8x8)
    assert scaled_resolution((6, 6), 1.0) == (6, 6)              # (8x8 at scale 1)
    assert scaled_resolution((640, 480), 0.5) == (320, 240)
    assert scaled_resolution((32, 8), 0.25) == (32, 8)           # the short side is 8 already


def test_preview_reset_shows_an_outside_change_in_its_first_frame():
    from draaw_mi.rendering.preview import Preview
    sc = draaw_mi.load_scene(tiny_description())
    pv = Preview(sc, version="v4", max_spp=4, freeze=False, interactive_scale=0.5)
    key = sc.key("ball.base_color")
    pv.step()
    sc.params[key] = draaw_mi.scene.value_like(sc.params[key], [0.0, 0.0, 1.0], key)
    sc.params.update()
    pv.reset()
    first = pv.step()                                  # the low-resolution first frame
    assert first.interactive
    r, g, b = first.image.reshape(-1, 3).mean(0)
    assert b > r, (r, g, b)                            # (the old red ball: r 0.25 > b 0.20)


@pytest.mark.parametrize("kw,match", [({"interactive_scale": "half"}, "interactive_scale"),
                                      ({"rest_after": "x"}, "rest_after"), ({"denoise": "no"}, "denoise"),
                                      ({"freeze": "no"}, "freeze")])
def test_bad_arguments_are_named(kw, match):
    with pytest.raises(draaw_mi.errors.DraawError, match=match):
        _tuner(tiny_description(), **kw)


def test_the_light_controls_scale_emitting_shapes_in_the_saved_file_as_in_the_preview(tmp_path):
    d = tiny_description()
    d["shapes"].append({"type": "rectangle", "name": "panel", "emission": 5.0, "translate": [0, 3, 0],
                        "rotate": {"axis": [1, 0, 0], "angle": 90}})
    t = _tuner(draaw_mi.load_scene(d))
    try:
        t.lights_panel.light_scale.value = 2.0
        t.lights_panel.light_color.value = "#ff0000"
        t.refresh(1)
        key = "panel.emitter.radiance.value"
        shown = np.array(t.scene.params[key]).ravel()
        assert np.allclose(shown, [10.0, 0.0, 0.0]), shown
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        assert np.allclose(np.array(saved.params[key]).ravel(), shown, atol=1e-5)   # (5, 5, 5)
    finally:
        t.close()


def test_a_panel_made_again_on_the_same_file_stops_the_old_one(tmp_path):
    import tomli_w
    from draaw_mi.rendering.preview import PreviewSuperseded
    path = tmp_path / "tiny.toml"
    path.write_text(tomli_w.dumps(tiny_description()))
    first = _tuner(str(path), autostart=True, max_spp=100000)
    second = None
    try:
        assert first.preview.running
        second = _tuner(str(path), autostart=True, max_spp=100000)     # the cell run again
        assert second.preview.running
        assert not first.preview.running                                # (it went on rendering)
        assert isinstance(first.preview.error, PreviewSuperseded)
        other = tmp_path / "other.toml"
        other.write_text(tomli_w.dumps(tiny_description()))
        third = _tuner(str(other), autostart=True, max_spp=100000)    # another file: both run
        try:
            assert second.preview.running and third.preview.running
        finally:
            third.close()
    finally:
        first.close()
        if second is not None:
            second.close()


def test_wait_returns_once_the_panel_shows_the_frame():
    t = _tuner(tiny_description(), autostart=True, max_spp=4, interactive_scale=0.5)
    try:
        for value in (0.2, 0.6, 0.3):
            t.controls["ball"]["roughness"].value = value
            f = t.preview.wait(t.preview.generation, spp=4)
            assert f is not None and f.spp == 4
            assert t.last_frame is f, (t.last_frame.spp, f.spp)      # (8 of 8 read the frame before)
    finally:
        t.close()


def test_a_camera_near_the_pole_stays_where_it_is(tmp_path):
    from draaw_mi.widgets import tuning
    cam = {"origin": [0.0, 6.0, 0.06], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0]}
    o, _, _ = tuning.orbit(cam, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(o, cam["origin"], atol=1e-12)          # ((0, 5.9994, 0.1047))
    o, _, _ = tuning.orbit(cam, 30.0, 0.0, 1.0)                       # a yaw keeps its elevation
    assert o[1] == pytest.approx(6.0, abs=1e-6) and np.hypot(o[0], o[2]) == pytest.approx(0.06, abs=1e-6)
    d = tiny_description()
    d["camera"] = {"origin": [0.0, 6.0, 0.06], "target": [0.0, 0.0, 0.0], "fov": 60}
    t = _tuner(d)
    try:
        np.testing.assert_allclose(t.document()["camera"]["origin"], [0.0, 6.0, 0.06], atol=1e-9)
    finally:
        t.close()


def test_the_resolution_slider_resizes_an_xml_scene(tmp_path):
    """An XML scene has no description to rebuild: the slider loads it again at the new size,
    as ``with_resolution`` does (it had failed with "only TOML/JSON/dict scenes can be written
    back" and snapped back)."""
    path = tmp_path / "s.xml"
    path.write_text(XML.format(sid=""))
    t = _tuner(draaw_mi.load_scene(str(path), resolution=(32, 24)), version="path")
    try:
        t.controls_render["scale"].value = 0.5
        assert t.message.value == "" and t.scene.resolution == (16, 12)
        assert np.isfinite(np.asarray(draaw_mi.render(t.scene, version="path", spp=2))).all()
    finally:
        t.close()


def test_review_inputs_of_the_panels(tmp_path, monkeypatch):
    """The save box's ``~`` is the home folder (it made a folder named ``~``); the spp budget
    box shows a budget above 2^16 as given (it showed 65536); a camera path beyond float32 is
    refused (it rendered black, then could not be saved)."""
    from draaw_mi.errors import ParameterError
    from draaw_mi.scene.camera_path import as_keyframes
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    t = _tuner(tiny_description(), max_spp=100000)
    try:
        assert t.controls_render["max_spp"].value == 100000
        assert t.save("~/tuned.toml") == str(home / "tuned.toml")
        assert (home / "tuned.toml").is_file() and not (tmp_path / "~").exists()
    finally:
        t.close()
    with pytest.raises(ParameterError, match=r"keyframe 1 .*within float32"):
        as_keyframes([[0, 0, 5, 0, 0], [1e308, 0, 5, 0, 0]])


def test_a_panel_made_again_from_the_same_dict_stops_the_old_one():
    """A cell ``MaterialTuner({...})`` run again: the old panel went on refining beside the new
    one (two preview threads); a dict's content now names it as a file's path does. Another
    dict runs beside it."""
    from draaw_mi.rendering.preview import PreviewSuperseded
    first = _tuner(tiny_description(), autostart=True, max_spp=100000)
    second = third = None
    try:
        second = _tuner(tiny_description(), autostart=True, max_spp=100000)
        assert second.preview.running and not first.preview.running
        assert isinstance(first.preview.error, PreviewSuperseded)
        other = tiny_description()
        other["render"]["spp"] = 3
        third = _tuner(other, autostart=True, max_spp=100000)
        assert second.preview.running and third.preview.running
    finally:
        for t in (first, second, third):
            if t is not None:
                t.close()


def test_a_closed_session_is_said_by_the_panel():
    """Closing the scene's session (``close_all()``, a ``with`` block) stopped the panel without
    a word, and its controls went on taking changes that nothing rendered."""
    from draaw_mi.rendering.session import close_all
    t = _tuner(tiny_description(), autostart=True, max_spp=100000)
    try:
        assert t.preview.running
        close_all()
        assert not t.preview.running
        assert "session was closed" in t.message.value
        t.controls["ball"]["roughness"].value = 0.77
        assert "no longer changes the scene" in t.message.value
        assert float(np.asarray(t.scene.params["ball.roughness.value"]).ravel()[0]) != pytest.approx(0.77)
    finally:
        t.close()


def test_a_reload_stops_the_worker_before_it_builds_a_scene_and_goes_on_if_it_fails():
    """A scene built (document() loads the file's) or freed while the worker records a frame
    killed the process: the worker is stopped first; a reload that fails leaves the old
    preview refining."""
    t = _tuner(tiny_description(), autostart=True, max_spp=100000)
    try:
        first, seen = t.preview, []
        document = t.document

        def spy(*a):
            seen.append(first.running)
            return document(*a)
        t.document = spy
        t.controls_render["scale"].value = 0.5
        assert seen == [False]                         # (was True: built beside the frame)
        assert t.preview is not first and t.preview.running and first.scene is None

        def broken(*a):
            raise draaw_mi.errors.DraawError("no document")
        t.document = broken
        second = t.preview
        t.controls_render["scale"].value = 0.25
        assert "no document" in t.message.value
        assert t.preview is second and second.running  # (was stopped for good)
    finally:
        t.close()


def test_a_failed_frame_says_its_innermost_error_and_a_later_frame_clears_it():
    """Dr.Jit wraps an integrator's error in "drjit.custom(...): error while performing a
    custom differentiable operation. (see above)" -- nothing is above in a panel; the red
    line stayed next to the good frames that followed."""
    t = _tuner(tiny_description())
    try:
        try:
            try:
                raise ValueError("ball.roughness: NaN in the BSDF")
            except ValueError as e:
                raise RuntimeError("drjit.custom(<_RenderOp>): error while performing a custom "
                                   "differentiable operation. (see above).") from e
        except RuntimeError as e:
            err = e
        t.preview._error_callbacks[0](err)
        assert "NaN in the BSDF" in t.message.value and "see above" not in t.message.value
        t.preview.update({"ball.roughness": 0.4})
        t.refresh(1)
        assert t.message.value == "" and "spp" in t.status.value
    finally:
        t.close()


def test_a_replaced_previews_error_is_not_shown():
    """(a reload's old preview, stopped in its frame, reported a failure next to the new
    preview's frames)"""
    t = _tuner(tiny_description())
    try:
        old_error, old_frame = t.preview._error_callbacks[0], t.preview._callbacks[0]
        t.controls_render["scale"].value = 0.5
        t.refresh(1)
        shown = t.frames_shown
        old_error(RuntimeError("the old scene's frame failed"))
        old_frame(t.last_frame)
        assert t.message.value == "" and t.frames_shown == shown
    finally:
        t.close()


def test_a_closed_panel_still_saves_its_values_and_refuses_changes_in_words(tmp_path):
    """close() frees the scenes; document(), save() and snippet() had failed after it with
    "'NoneType' object has no attribute 'settings'" / "'source'", and a slider with
    "'NoneType' object has no attribute 'key'" out of the preview."""
    d = tiny_description()
    d["sdf"] = [{"type": "sphere", "name": "blob", "material": "ball", "center": [1.2, 0.5, 0.0], "radius": 0.3}]
    t = _tuner(draaw_mi.load_scene(d, filter="gaussian"))
    t.controls["ball"]["roughness"].value = 0.35
    t.lights_panel.light_scale.value = 2.0
    t.preview.update({"sdf.blob.radius": 0.2})
    t.refresh(1)
    dest = str(tmp_path / "sub" / "tuned.toml")
    before, snippet = t.document(dest), t.snippet()
    t.close()
    assert t.document(dest) == before and t.snippet() == snippet
    saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
    assert float(np.array(saved.all_params["sdf.blob.radius"]).ravel()[0]) == pytest.approx(0.2)
    assert float(np.array(saved.params["ball.roughness.value"]).ravel()[0]) == pytest.approx(0.35)
    assert saved.settings["filter"] == "gaussian"
    t.controls["ball"]["roughness"].value = 0.6           # refused in red, not raised
    assert "panel was closed" in t.message.value and "new MaterialTuner" in t.message.value
    assert t.materials["ball"]["roughness"] == pytest.approx(0.35)
    for call, who in ((lambda: t.refresh(1), "MaterialTuner.refresh"),
                      (lambda: t.load_camera_path([(0, 1, 5, 0, 0), (1, 1, 5, 0, 0)]), "MaterialTuner.load_camera_path")):
        with pytest.raises(draaw_mi.errors.DraawError, match=f"{who}: this panel was closed.*new MaterialTuner"):
            call()
    with pytest.raises(draaw_mi.errors.DraawError, match="panel was closed.*'mi_scene' is not kept"):
        t.save_panel.base_scene.mi_scene
    t.close()                                              # (again: nothing to do)
    assert t.document(dest) == before


def test_the_depth_slider_survives_the_rebuild_of_an_xml_scene():
    """The resolution slider rebuilds an XML scene with with_resolution, and its preview took
    the file's max_depth (6) while the slider still showed the tuned one."""
    import os
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    sc = draaw_mi.load_scene(os.path.join(root, "scenes", "mitsuba_cbox.xml"), defines={"res": 16, "spp": 4})
    t = _tuner(sc, version="v4")
    try:
        t.controls_render["max_depth"].value = 2
        t.controls_render["scale"].value = 0.5
        assert t.preview.scene.resolution == (8, 8) and t.preview.max_depth == 2
    finally:
        t.close()


def test_a_refused_change_on_a_closed_panel_is_put_back_on_its_control(tmp_path):
    """A closed (or superseded) panel refused a change in red but left it on the control, and
    an orbit moved the sliders before the refusal: save() then wrote values the preview never
    showed."""
    t = _tuner(draaw_mi.load_scene(tiny_description()))
    before = t.document()
    yaw, fov, scale = t.camera_panel.yaw.value, t.camera_panel.fov.value, t.lights_panel.light_scale.value
    t.close()
    t.camera_panel.fov.value = 90.0
    t.lights_panel.light_scale.value = 8.0
    t.camera_panel.drag_start()
    t.camera_panel.drag_orbit(60.0, 20.0)
    t.camera_panel.zoom(2.0)
    assert "panel was closed" in t.message.value
    assert (t.camera_panel.yaw.value, t.camera_panel.fov.value, t.lights_panel.light_scale.value) == (yaw, fov, scale)
    assert t.document() == before


@pytest.mark.parametrize("frames", [0, 2.7, True, "10", 10 ** 9])
def test_a_camera_paths_frames_are_an_integer_in_range(frames):
    """frames went on as seconds at 1 fps ("duration=0"), 2.7 was rounded, 1e9 allocated 7.5 GiB."""
    t = _tuner(draaw_mi.load_scene(tiny_description()))
    try:
        with pytest.raises(draaw_mi.errors.DraawError, match=r"load_camera_path: frames=.*expected an integer in \[2, "):
            t.load_camera_path([(0, 1, 5, 0, 0), (1, 1, 5, 0, 0)], frames)
    finally:
        t.close()



def test_a_superseded_panel_keeps_its_camera_when_a_path_is_loaded():
    """A superseded panel's path step set its camera and then had its orbit refused: the
    sliders went back, the camera did not, and save() wrote the path's camera."""
    import time
    from draaw_mi.rendering.preview import PreviewSuperseded
    sc = draaw_mi.load_scene(tiny_description(resolution=[8, 8]))
    old = MaterialTuner(sc, max_spp=1, frame_channel="image", interactive_scale=1.0)
    new = MaterialTuner(sc, max_spp=1, frame_channel="image", interactive_scale=1.0)
    try:
        deadline = time.time() + 60
        while not isinstance(old.preview.error, PreviewSuperseded) and time.time() < deadline:
            time.sleep(0.05)
        before = list(old.camera_panel.current()["origin"])
        keys = [(0, 0, 9, 0, 0), (3, 0, 9, 0, 0)]
        with pytest.raises(draaw_mi.errors.DraawError, match=r"load_camera_path: stopped: a newer preview"):
            old.load_camera_path(keys, frames=2)
        old.camera_panel.load_camera_path(keys, frames=2)       # (the panel's own: its orbit refused)
        assert list(old.camera_panel.current()["origin"]) == before
    finally:
        old.close()
        new.close()
