"""OrbitCanvas (jupyter_rfb) headless: frames from another thread reach the event loop, mouse
events move the tuner's camera by the documented amounts.

No browser: the canvas's ``send`` is replaced by a recorder and its "visible view" flag is set
by hand, which is what the front end would do; events are the dicts jupyter_rfb's front end
sends (``type``, ``x``, ``y``, ``button``, ``buttons``, ``dy``).
"""
from __future__ import annotations

import asyncio
import math
import threading
import time

import numpy as np
import pytest

import draaw_mi

pytest.importorskip("ipywidgets")
pytest.importorskip("jupyter_rfb")
from draaw_mi.widgets.orbit_canvas import DEGREES_PER_WIDTH, MIN_DISPLAY, WHEEL_RATE, OrbitCanvas  # noqa: E402
from draaw_mi.widgets import MaterialTuner  # noqa: E402
from draaw_mi.widgets import tuning  # noqa: E402

from conftest import tiny_description  # noqa: E402


def _press(x, y, button=1):
    return {"type": "pointer_down", "x": x, "y": y, "button": button, "buttons": (button,), "modifiers": ()}


def _move(x, y, buttons=(1,)):
    return {"type": "pointer_move", "x": x, "y": y, "button": 0, "buttons": buttons, "modifiers": ()}


def _release(x, y):
    return {"type": "pointer_up", "x": x, "y": y, "button": 1, "buttons": (), "modifiers": ()}


@pytest.fixture
def tuner():
    t = MaterialTuner(draaw_mi.load_scene(tiny_description()), autostart=False, freeze=False,
                      interactive_scale=1.0, frame_channel="rfb")
    yield t
    t.close()


def _origin(t):
    t.refresh()                     # the preview applies pending parameter values per frame
    return np.array(t.scene.params["sensor.to_world"].matrix).reshape(4, 4)[:3, 3]


def test_a_drag_orbits_the_camera_by_the_documented_angle(tuner):
    assert tuner.canvas.size == tuner.scene.resolution
    k = MIN_DISPLAY // max(tuner.canvas.size)          # a small preview is shown enlarged
    assert tuner.canvas.css_width == f"{tuner.canvas.size[0] * k}px" and k > 1
    w = tuner.canvas.size[0] * k                       # the drag is in CSS pixels
    tuner.canvas.handle_event(_press(10, 10))
    tuner.canvas.handle_event(_move(10, 10, buttons=()))     # Chromium: a stale move after the press
    tuner.canvas.handle_event(_move(10 + w / 4, 10))         # a quarter width right: -45 degrees
    tuner.canvas.handle_event(_move(10 + w / 4, 10 + w / 8))   # and an eighth down: +22.5 degrees
    tuner.canvas.handle_event(_release(10 + w / 4, 10 + w / 8))
    assert tuner.message.value == ""
    assert tuner.camera_panel.yaw.value == pytest.approx(-DEGREES_PER_WIDTH / 4)
    assert tuner.camera_panel.pitch.value == pytest.approx(DEGREES_PER_WIDTH / 8)
    # the scene's camera is the closed-form orbit of the scene's camera by those angles
    want, _, _ = tuning.orbit(tuner.camera, -DEGREES_PER_WIDTH / 4, DEGREES_PER_WIDTH / 8, 1.0)
    np.testing.assert_allclose(_origin(tuner), want, atol=1e-5)
    # dragging right moves the camera to the viewer's left (the scene turns right under the
    # pointer): up x view direction, from the scene's own camera
    o, t, up = (np.asarray(tuner.camera[k], float) for k in ("origin", "target", "up"))
    # independently of tuning.orbit: the distance is kept, the elevation above the target's
    # horizon rises by the pitch and the azimuth about up turns by the yaw
    up = up / np.linalg.norm(up)
    d0, d1 = o - t, _origin(tuner) - t
    assert np.linalg.norm(d1) == pytest.approx(np.linalg.norm(d0), rel=1e-5)
    elevation = [np.degrees(np.arcsin(np.dot(d, up) / np.linalg.norm(d))) for d in (d0, d1)]
    assert elevation[1] - elevation[0] == pytest.approx(DEGREES_PER_WIDTH / 8, abs=1e-3)
    flat = [d - np.dot(d, up) * up for d in (d0, d1)]
    turn = np.degrees(np.arctan2(np.dot(np.cross(flat[0], flat[1]), up), np.dot(flat[0], flat[1])))
    assert abs(turn) == pytest.approx(DEGREES_PER_WIDTH / 4, abs=1e-3)
    left = np.cross(up, t - o)
    assert np.dot(_origin(tuner) - o, left) > 0.1 * np.linalg.norm(left) * np.linalg.norm(t - o)
    # a second drag continues from where the first ended; moves without the button are ignored
    tuner.canvas.handle_event(_move(500, 500, buttons=()))
    tuner.canvas.handle_event(_press(0, 0))
    tuner.canvas.handle_event(_move(-w / 4, 0))
    assert tuner.camera_panel.yaw.value == pytest.approx(0.0, abs=1e-9)
    assert tuner.camera_panel.pitch.value == pytest.approx(DEGREES_PER_WIDTH / 8)
    tuner.canvas.handle_event(_release(-w / 4, 0))
    tuner.canvas.handle_event(_move(w, w))                   # released: nothing moves
    assert tuner.camera_panel.yaw.value == pytest.approx(0.0, abs=1e-9)


def test_the_release_position_ends_the_drag(tuner):
    """The browser holds a drag's last move back for 20 ms but sends the release at once: the
    release's position must count, or the camera stops short of where the button went up."""
    w = tuner.canvas._view_width
    tuner.canvas.handle_event(_press(0, 0))
    tuner.canvas.handle_event(_move(w / 8, 0))
    tuner.canvas.handle_event(_release(w / 4, 0))
    assert tuner.camera_panel.yaw.value == pytest.approx(-DEGREES_PER_WIDTH / 4)


def test_a_scene_without_a_camera_table_has_no_orbit():
    """A Mitsuba scene has no [camera] table to orbit about: the canvas shows the default
    cursor and ignores drags and the wheel, without an error in the panel."""
    import mitsuba as mi
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=16, height=16)
    t = MaterialTuner(draaw_mi.load_scene(mi.load_dict(d)), autostart=False, freeze=False,
                      frame_channel="rfb")
    try:
        assert t.camera is None and t.canvas.cursor == "default"
        t.canvas.handle_event(_press(0, 0))
        t.canvas.handle_event(_move(8, 8))
        t.canvas.handle_event({"type": "wheel", "dx": 0.0, "dy": 100.0, "x": 1, "y": 1})
        t.canvas.handle_event({"type": "double_click", "x": 1, "y": 1, "button": 1, "buttons": ()})
        assert t.canvas.cursor == "default" and t.message.value == ""
        assert (t.camera_panel.yaw.value, t.camera_panel.pitch.value, t.camera_panel.distance.value) == (0.0, 0.0, 1.0)
    finally:
        t.close()


def test_pitch_is_clamped_and_yaw_wraps(tuner):
    w = tuner.canvas._view_width
    tuner.canvas.handle_event(_press(0, 0))
    tuner.canvas.handle_event(_move(-3 * w, 5 * w))          # +540 degrees yaw, far past the pole
    assert tuner.camera_panel.pitch.value == tuner.camera_panel.pitch.max == 85.0
    assert tuner.camera_panel.yaw.value == pytest.approx(-180.0)            # 540 degrees, wrapped into [-180, 180)
    assert np.isfinite(_origin(tuner)).all()


def test_the_wheel_scales_the_distance_and_a_double_click_resets(tuner):
    t = np.asarray(tuner.camera["target"], float)
    r0 = np.linalg.norm(_origin(tuner) - t)
    tuner.canvas.handle_event({"type": "wheel", "dx": 0.0, "dy": 100.0, "x": 5, "y": 5, "buttons": (),
                               "modifiers": ()})
    assert tuner.camera_panel.distance.value == pytest.approx(math.exp(100 * WHEEL_RATE))
    assert np.linalg.norm(_origin(tuner) - t) == pytest.approx(r0 * math.exp(100 * WHEEL_RATE), rel=1e-5)
    for _ in range(50):                                      # far out: stops at the slider's end
        tuner.canvas.handle_event({"type": "wheel", "dx": 0.0, "dy": 100.0, "x": 5, "y": 5})
    assert tuner.camera_panel.distance.value == tuner.camera_panel.distance.max
    tuner.canvas.handle_event(_press(0, 0))
    tuner.canvas.handle_event(_move(30, 20))
    tuner.canvas.handle_event(_release(30, 20))
    tuner.canvas.handle_event({"type": "double_click", "x": 1, "y": 1, "button": 1, "buttons": ()})
    assert (tuner.camera_panel.yaw.value, tuner.camera_panel.pitch.value, tuner.camera_panel.distance.value) == (0.0, 0.0, 1.0)
    want, _, _ = tuning.orbit(tuner.camera)
    np.testing.assert_allclose(_origin(tuner), want, atol=1e-5)


def test_a_huge_or_non_finite_wheel_step_is_clamped_or_ignored(tuner):
    """exp(WHEEL_RATE * 1e6) raised OverflowError out of the event handler."""
    tuner.canvas.handle_event({"type": "wheel", "dx": 0.0, "dy": 1e6, "x": 5, "y": 5})
    assert tuner.camera_panel.distance.value == tuner.camera_panel.distance.max
    tuner.canvas.handle_event({"type": "wheel", "dx": 0.0, "dy": float("nan"), "x": 5, "y": 5})
    assert tuner.camera_panel.distance.value == tuner.camera_panel.distance.max
    assert np.isfinite(_origin(tuner)).all()


def test_a_resized_view_changes_the_degrees_per_pixel(tuner):
    tuner.canvas.handle_event({"type": "resize", "width": 360.0, "height": 270.0, "ratio": 1.0})
    tuner.canvas.handle_event(_press(0, 0))
    tuner.canvas.handle_event(_move(36, 0))
    assert tuner.camera_panel.yaw.value == pytest.approx(-DEGREES_PER_WIDTH * 36 / 360)


def test_frames_are_the_preview_in_srgb_jpeg_while_changing_png_at_rest(tuner):
    tuner.preview.configure(max_spp=4)
    n0 = len(tuner.sent)
    tuner.rest_after = 1e9                                  # never at rest (a first compile is slow)
    f = tuner.refresh()
    np.testing.assert_array_equal(tuner.canvas.get_frame(), tuning.to_uint8(f.image))
    assert tuner.canvas.quality == 80 and f.spp < 4
    tuner.rest_after = 0.0                                  # now at rest: lossless ...
    tuner.refresh()
    tuner.canvas.get_frame()
    assert tuner.canvas.quality == 100
    f = tuner.refresh()                                     # ... at most every LOSSLESS_EVERY s
    tuner.canvas.get_frame()
    assert tuner.canvas.quality == 80 and f.spp < 4
    while f.spp < 4:                                        # and the last frame of the budget
        f = tuner.refresh()
    tuner.canvas.get_frame()
    assert tuner.canvas.quality == 100
    fmts = [fmt for *_, fmt in list(tuner.sent)[n0:]]
    assert fmts[:3] == ["jpeg", "png", "jpeg"] and fmts[-1] == "png" and set(fmts[2:-1]) == {"jpeg"}
    tuner.rest_after = 1e9                                  # a change after a PNG: JPEG again
    tuner.controls["ball"]["roughness"].value = 0.3
    tuner.refresh()
    tuner.canvas.get_frame()
    assert tuner.canvas.quality == 80


def test_a_frame_pushed_from_another_thread_is_sent_on_the_loop():
    """jupyter_rfb draws only from the running loop of the calling thread: a push from the
    preview's worker thread must hand the draw to the loop the canvas was made on."""
    sent = []

    async def main():
        c = OrbitCanvas((8, 4))
        got = asyncio.Event()

        def send(msg, buffers=None):
            sent.append((msg, buffers, time.perf_counter()))
            got.set()
        c.send = send
        c._has_visible_views = True                         # what the front end reports
        await asyncio.sleep(0.05)                           # (a draw attempt of its own, no frame)
        img = np.full((4, 8, 3), 200, np.uint8)
        pushed = []

        def worker():                                       # pushes while the loop is idle
            time.sleep(0.1)
            pushed.append(time.perf_counter())
            c.push(img)
        th = threading.Thread(target=worker)
        th.start()
        try:                                                # an idle loop: only a wake-up helps
            await asyncio.wait_for(got.wait(), 2.0)
        except asyncio.TimeoutError:
            pass
        th.join()
        delay = sent[0][2] - pushed[0] if sent else float("inf")
        c._frame_feedback = {"index": 1, "timestamp": 0.0, "localtime": 0.0}   # the browser's ack
        await asyncio.sleep(0.45)                           # jupyter_rfb's lossless redraw (0.3 s)
        c.close()
        return c, delay

    c, delay = asyncio.run(main())
    assert c.frames_pushed == 1 and delay < 0.5            # sent at once, not at the next wake-up
    kinds = [m["mimetype"] for m, _, _ in sent if m.get("type") == "framebufferdata"]
    assert kinds[:1] == ["image/jpeg"] and kinds[-1] == "image/png", kinds


def test_a_canvas_made_off_the_loop_draws_from_the_first_browser_event():
    """Made where no loop runs (a thread, a script), the canvas learns the kernel's loop from
    the browser's first event (a resize, which arrives on it) and draws the waiting frame."""
    c = OrbitCanvas((8, 4))
    sent = []
    c.send = lambda msg, buffers=None: sent.append(msg)
    c.push(np.full((4, 8, 3), 90, np.uint8))               # no loop yet: kept, not drawn

    async def main():
        c._has_visible_views = True
        await asyncio.sleep(0.05)
        before = len(sent)
        c.handle_event({"type": "resize", "width": 8.0, "height": 4.0, "ratio": 1.0})
        await asyncio.sleep(0.05)
        return before

    before = asyncio.run(main())
    c.close()
    assert before == 0 and [m["type"] for m in sent][:1] == ["framebufferdata"]


def test_bad_sizes_and_images_are_one_clear_error():
    with pytest.raises(draaw_mi.DraawError, match=r"OrbitCanvas: size=\(0, 4\)"):
        OrbitCanvas((0, 4))
    with pytest.raises(draaw_mi.DraawError, match=r"quality=100; expected 1..99"):
        OrbitCanvas((4, 4), quality=100)                    # lossless is push(..., lossless=True)
    c = OrbitCanvas((4, 4))
    try:
        with pytest.raises(draaw_mi.DraawError, match="expected \\(H, W, 3\\) uint8"):
            c.push(np.zeros((4, 4, 3), np.float32))
    finally:
        c.close()


def test_rfb_channel_without_jupyter_rfb_is_one_clear_error(monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "jupyter_rfb", None)
    monkeypatch.delitem(sys.modules, "draaw_mi.widgets.orbit_canvas", raising=False)
    with pytest.raises(draaw_mi.DraawError, match=r"pip install 'draaw-mi\[notebooks\]'"):
        MaterialTuner(draaw_mi.load_scene(tiny_description()), autostart=False, frame_channel="rfb")
    t = MaterialTuner(draaw_mi.load_scene(tiny_description()), autostart=False, freeze=False)
    try:
        assert t.canvas is None and t.image is not None                 # "auto" falls back
    finally:
        t.close()


@pytest.mark.parametrize("kw, match", [
    ({"size": (4, 4), "quality": "x"}, r"quality='x'; expected 1..99"),
    ({"size": (4, 4), "quality": True}, r"quality=True; expected 1..99"),
    ({"size": (4, 4, 4)}, r"size=\(4, 4, 4\); expected \(width, height\)"),
    ({"size": ("a", 4)}, r"size=\('a', 4\); expected \(width, height\)"),
    ({"size": None}, r"size=None; expected \(width, height\)"),
    ({"size": "12"}, r"size='12'; expected \(width, height\)"),
    ({"size": (float("inf"), 4)}, r"size=\(inf, 4\); expected \(width, height\)"),
    ({"size": (4, 4), "quality": float("inf")}, r"quality=inf; expected 1..99"),
])
def test_unparsable_arguments_are_one_clear_error_and_leave_no_broken_widget(monkeypatch, kw, match):
    """'x' and a 3-tuple raised a bare ValueError before the widget was made, and the
    half-made widget then failed in ``__del__`` ("Exception ignored ... NoneType & int")."""
    import gc
    import sys
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    with pytest.raises(draaw_mi.DraawError, match=match):
        OrbitCanvas(**kw)
    gc.collect()
    assert unraisable == []


def test_a_mirrored_go_draaw_camera_stays_mirrored_through_zoom_drag_and_save(tmp_path):
    """A GO-Draaw camera at sin φ > 0 shows the mirror image of any look-at camera's view (a
    to_world of determinant -1): the wheel keeps it (the glowing ball stays at the left, where
    GO-Draaw's patch has it; unmirrored it jumps to column ~25 of 32), a drag to the right
    still turns the scene under the pointer (the camera moves to the image's left: the first
    column of the mirrored to_world, as for a look-at camera), and Save writes a look-at camera
    with mirror = true that loads as the same sensor."""
    from conftest import bright_column, glowing_ball, go_draaw_patch_point
    theta, phi, fov = 0.3, 1.2, 45.0
    ball = go_draaw_patch_point([0, 0, 0], theta, phi, fov, 0.2, 0.5, 3.0)
    scene = draaw_mi.load_scene(glowing_ball({"position": [0.0, 0.0, 0.0], "angles": [theta, phi], "fov": fov},
                                             ball))
    t = MaterialTuner(scene, autostart=False, freeze=False, interactive_scale=1.0, frame_channel="rfb")

    def to_world():
        t.refresh()
        return np.array(t.scene.params["sensor.to_world"].matrix).reshape(4, 4)
    try:
        m0 = to_world()
        assert np.linalg.det(m0[:3, :3]) == pytest.approx(-1.0, abs=1e-5)
        t.canvas.handle_event({"type": "wheel", "dx": 0.0, "dy": 200.0, "x": 5, "y": 5, "buttons": (),
                               "modifiers": ()})
        assert t.camera_panel.distance.value > 1.0 and t.message.value == ""
        m1 = to_world()
        assert np.linalg.det(m1[:3, :3]) == pytest.approx(-1.0, abs=1e-5)
        assert bright_column(draaw_mi.render(t.scene, version="path")) < 12      # (u = 0.2: 6.4)
        w = t.canvas._view_width
        t.canvas.handle_event(_press(0, 0))
        t.canvas.handle_event(_move(w / 16, 0))
        t.canvas.handle_event(_release(w / 16, 0))
        assert t.message.value == ""
        m2 = to_world()
        assert np.linalg.det(m2[:3, :3]) == pytest.approx(-1.0, abs=1e-5)
        moved = m2[:3, 3] - m1[:3, 3]
        assert np.dot(moved, m1[:3, 0]) > 0.5 * np.linalg.norm(moved)          # to the image's left
        doc = t.document()
        assert doc["camera"]["mirror"] is True and "angles" not in doc["camera"]
        saved = draaw_mi.load_scene(t.save(str(tmp_path / "tuned.toml")))
        np.testing.assert_allclose(np.array(saved.params["sensor.to_world"].matrix).reshape(4, 4), m2,
                                   atol=1e-4)
    finally:
        t.close()
