"""Progressive preview: running mean, reset on change, no recompilation, worker thread, lock."""
from __future__ import annotations

import os
import time

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.batch.frame import kernel_signature
from draaw_mi.errors import DraawError, ParameterError
from draaw_mi.rendering.preview import Preview
from draaw_mi.rendering.passes import pass_seeds
from draaw_mi.rendering.session import Session, session_of

from conftest import SCENES, tiny_description


def _ir(entry) -> str:
    ir = entry.get("ir")
    return ir.getvalue() if hasattr(ir, "getvalue") else str(ir)


def _direct(scene, seeds, version="v4", depth=4):
    """Independent mean of 1-spp renders with Mitsuba's own mi.render (no preview code), with
    the scene's own integrator (V4's light selection is learned once per integrator)."""
    integ = session_of(scene).integrator(version, depth)
    return np.mean([np.array(mi.render(scene.mi_scene, integrator=integ, seed=s, spp=1)) for s in seeds], axis=0)


def test_running_mean_equals_mean_of_independent_frames():
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="v4", max_depth=4, freeze=False, seed=3)
    frames = [pv.step() for _ in range(4)]
    assert [f.spp for f in frames] == [1, 2, 3, 4] and len({f.generation for f in frames}) == 1
    seeds = [pass_seeds(3, i + 2)[-1] for i in range(4)]
    assert len(set(seeds)) == 4
    np.testing.assert_allclose(frames[-1].raw, _direct(scene, seeds)[..., :3], rtol=1e-5, atol=1e-6)
    assert not np.allclose(frames[0].raw, frames[-1].raw)        # frames really differ


@pytest.mark.parametrize("freeze", [False, True])
def test_change_resets_the_mean_and_shows_the_new_value_without_recompiling(freeze):
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="v4", max_depth=4, freeze=freeze, seed=1)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        # a first change and its frames: whatever runs once after any change compiles here
        # (the measured change below must compile nothing: a slider drag's second step)
        pv.update({"ball.base_color": [0.5, 0.5, 0.2], "ball.roughness": 0.3})
        for _ in range(3):
            pv.step()
        before = pv.frame.raw.copy()
        # V4 learns its light selection with the scene as first rendered; the preview's own
        # integrator did at its first frame, the reference's learns here, before the change too
        _direct(scene, [0])
        seen = {kernel_signature(k) for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}
        g = pv.update({"ball.base_color": [0.1, 0.2, 0.9], "ball.roughness": 0.1})
        f = pv.step()
        f2 = pv.step()
        after = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    # Compiled again = code never seen before. A kernel Dr.Jit re-specialised to a new buffer
    # alignment (same code, new hash: a small kernel, by the order earlier tests left memory
    # in) is not a recompile of the preview's; a new value baked into the code would be.
    new_code = [k for k in after if not k["cache_hit"] and kernel_signature(k) not in seen]
    assert new_code == [], [(k["size"], k["operation_count"], _ir(k)[:3000]) for k in new_code]
    assert max(after, key=lambda k: k["execution_time"])["cache_hit"]   # the render: the same kernel
    assert f.generation == g and f.spp == 1 and f2.spp == 2
    # the new frame is the new parameter's image: compare with an independent render
    k = scene.key("ball.base_color")
    assert np.allclose(np.array(scene.params[k]).ravel(), [0.1, 0.2, 0.9])
    seed = pass_seeds(1, pv._frame_index + 1)[-1]
    np.testing.assert_allclose(f2.raw * 2 - f.raw, _direct(scene, [seed])[..., :3], rtol=1e-4, atol=1e-5)
    assert np.abs(f2.raw - before).max() > 0.05


def test_frozen_and_plain_frames_are_identical_after_camera_changes():
    a = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=True, seed=2)
    b = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False, seed=2)
    T = mi.ScalarTransform4f().look_at(origin=[1.5, 1.2, 4.5], target=[0, 0.5, 0], up=[0, 1, 0])
    for pv in (a, b):
        pv.step()
        pv.update({"sensor.to_world": T, "sensor.x_fov": 55.0})
        pv.step()
    np.testing.assert_array_equal(a.frame.raw, b.frame.raw)


def test_interactive_first_frame_is_low_resolution_and_not_accumulated():
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="v4", max_depth=4, freeze=False, interactive_scale=0.5)
    f0 = pv.step()
    assert f0.interactive and f0.spp == 0 and f0.image.shape == (24, 32, 3)
    assert np.array_equal(f0.image[0::2, 0::2], f0.image[1::2, 1::2])   # 2x2 blocks
    f1 = pv.step()
    assert not f1.interactive and f1.spp == 1
    pv.update({"ball.metallic": 0.9})
    assert pv.step().interactive


@pytest.mark.parametrize("values, match", [
    ({"ball.roughness": 1.5}, r"ball.roughness=1.5; expected a number in \[0.0, 1.0\]"),
    ({"ball.roughness": float("nan")}, "finite"),
    ({"ball.base_color": [1e40, 0.5, 0.5]}, "in float32"),      # (inf in the scene: NaN pixels)
    ({"ball.base_color": [0.1, 0.2]}, "3 numbers"),
    ({"ball.base_color": [0.1, -0.2, 0.3]}, ">= 0"),
    ({"ball.roughnes": 0.3}, "did you mean"),
    # (a frame of NaN was published without a word)
    ({"sensor.to_world": "nan_transform"}, r"Preview.update: sensor.to_world: .*a transform or matrix with NaN"),
    ({"sensor.to_world": "nan_matrix"}, r"Preview.update: sensor.to_world: .*a transform or matrix with NaN"),
])
def test_bad_values_are_rejected_before_rendering(values, match):
    if values.get("sensor.to_world") == "nan_transform":
        values = {"sensor.to_world": mi.ScalarTransform4f(np.full((4, 4), np.nan))}
    elif values.get("sensor.to_world") == "nan_matrix":           # (a matrix, not a transform)
        m = np.eye(4)
        m[0, 3] = np.nan
        values = {"sensor.to_world": mi.ScalarMatrix4f(m)}
    pv = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False)
    g = pv.generation
    with pytest.raises(DraawError, match=match):
        pv.update(values)
    assert pv.generation == g and pv._pending == {}


def test_worker_thread_refines_resets_and_stops():
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="v4", max_depth=4, max_spp=6, freeze=True)
    got = []
    pv.on_frame(lambda f: got.append((f.generation, f.spp)))
    pv.start()
    try:
        f = pv.wait(spp=6, timeout=60)
        assert f is not None and f.spp == 6
        time.sleep(0.3)
        assert pv.spp == 6 and pv.running                     # idle at max_spp, not spinning
        g = pv.update({"ball.roughness": 0.9})
        f = pv.wait(g, spp=2, timeout=60)
        assert f is not None and f.generation == g
        assert all(spp >= 1 for gen, spp in got)
        spps = [spp for gen, spp in got if gen == g]
        assert spps[:2] == [1, 2]                             # the mean restarted
    finally:
        pv.stop()
    assert not pv.running


def test_worker_respects_the_scene_render_lock():
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="v4", max_depth=4, max_spp=1000, freeze=False)
    pv.start()
    try:
        assert pv.wait(spp=2, timeout=60) is not None
        with session_of(scene).lock:
            time.sleep(0.2)                  # a frame in flight may finish; then it must wait
            n = pv.spp
            time.sleep(0.5)
            assert pv.spp == n
        assert pv.wait(spp=n + 2, timeout=60) is not None
    finally:
        pv.stop()


def test_a_new_preview_of_a_scene_stops_the_running_one():
    """A notebook cell run again makes a second panel of the same scene: its worker stops the
    first one, which is told why (PreviewSuperseded, shown in its panel); a preview of another
    scene keeps running, and the first one takes the scene back when started again."""
    from draaw_mi.rendering.preview import PreviewSuperseded
    scene, other_scene = draaw_mi.load_scene(tiny_description()), draaw_mi.load_scene(tiny_description())
    a = Preview(scene, version="v4", max_depth=2, max_spp=10 ** 6, freeze=False)
    c = Preview(other_scene, version="v4", max_depth=2, max_spp=10 ** 6, freeze=False)
    b = Preview(scene, version="v4", max_depth=2, max_spp=10 ** 6, freeze=False)
    errors = []
    a.on_error(errors.append)
    try:
        a.start()
        c.start()
        assert a.wait(spp=2, timeout=60) is not None
        b.start()
        assert not a.running and b.running and c.running
        assert len(errors) == 1 and isinstance(errors[0], PreviewSuperseded) and a.error is errors[0]
        n = a.spp
        assert b.wait(spp=3, timeout=60) is not None and a.spp == n      # a no longer renders
        a.start()
        assert a.running and not b.running
    finally:
        for p in (a, b, c):
            p.stop()


def test_denoised_preview_uses_the_guides():
    """The denoised frame is OIDN called directly on the frame's mean, with the albedo and
    normal AOVs found by their channel names in a render's channel list (not the slices the
    preview uses), HDR, quality "high"."""
    pyoidn = pytest.importorskip("pyoidn")
    from draaw_mi.rendering.denoiser import aux_channels
    scene = draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"), resolution=(48, 48))
    pv = Preview(scene, denoise=True, freeze=False, max_depth=4)
    f = pv.step()
    assert f.denoised and f.image.shape == (48, 48, 3) and np.isfinite(f.image).all()
    assert not np.array_equal(f.image, f.raw)
    _, info = draaw_mi.render(scene, spp=1, max_depth=4, aovs=["albedo", "normal"], post=[], return_info=True)
    idx = aux_channels(info["channels"])
    acc = pv._acc.astype(np.float32)
    assert acc.shape[2] == len(info["channels"])
    ref = pyoidn.denoise(np.ascontiguousarray(np.maximum(f.raw, 0)),
                         albedo=np.ascontiguousarray(np.clip(acc[..., idx["albedo"]], 0, 1)),
                         normal=np.ascontiguousarray(np.clip(acc[..., idx["normal"]], -1, 1)),
                         hdr=True, quality="high")
    np.testing.assert_allclose(f.image, np.asarray(ref), rtol=1e-5, atol=1e-6)


def test_configure_rejects_unknown_options():
    pv = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False)
    with pytest.raises(ParameterError, match="max_dept"):
        pv.configure(max_dept=3)
    with pytest.raises(ParameterError, match="interactive_scale"):
        Preview(pv.scene, interactive_scale=0)
    with pytest.raises(ParameterError, match="interactive_scale"):      # (a raw ValueError before)
        Preview(pv.scene, interactive_scale="x")
    with pytest.raises(ParameterError, match="interactive_scale"):
        pv.configure(interactive_scale=None)
    # a bad chain or depth is refused by the call (it failed at the first frame, on the
    # render thread, or rendered black), and the preview keeps its settings
    with pytest.raises(ParameterError, match=r"Preview: post chain\[0\]: unknown filter type 'blom'; did you mean 'bloom'"):
        Preview(pv.scene, post=[{"type": "blom"}])
    for depth in ("3", -2, True, 2.5):
        with pytest.raises(ParameterError, match=r"Preview: max_depth=.*expected an integer >= -1"):
            Preview(pv.scene, max_depth=depth)
    with pytest.raises(ParameterError, match=r"Preview.configure: post chain\[0\]"):
        pv.configure(post=[{"type": "blom"}])
    with pytest.raises(ParameterError, match=r"Preview.configure: max_depth=2.5"):
        pv.configure(max_depth=2.5)
    assert pv.max_depth == 4 and pv.post == []


def test_a_post_chain_ending_in_srgb_is_shown_as_it_is():
    """A preview whose chain ends in ``srgb`` publishes display-encoded frames: they are shown
    clipped, not encoded a second time (the tuner's image was washed out)."""
    from draaw_mi.widgets import tuning
    pv = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False,
                 post=[{"type": "srgb"}])
    f = pv.step()
    assert f.encoded
    shown = tuning.to_uint8(f.image, f.encoded)
    once = tuning.to_uint8(f.raw)                                   # numpy's encoding, once
    assert np.abs(shown.astype(int) - once).max() <= 1
    assert np.abs(tuning.to_uint8(f.image).astype(int) - once).max() > 20    # twice
    pv.configure(post=[{"type": "srgb"}, {"type": "srgb", "inverse": True}])
    assert not pv.step().encoded


def test_a_frame_failing_while_the_values_change_does_not_spoil_the_next_mean(monkeypatch):
    """A frame fails after update() bumped the generation: the worker must not mark the new
    generation as finished (it did: the next frame accumulated onto spp = max_spp, reporting
    9 spp at 0.11x the brightness, or the worker idled)."""
    pv = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False,
                 max_spp=8, seed=5)
    real = Session.render_pass
    calls = []

    def failing_once(self, *a, **k):
        if not calls:
            calls.append(1)
            pv.update({"ball.roughness": 0.3})                 # the user moves a slider meanwhile
            raise RuntimeError("transient")
        return real(self, *a, **k)
    monkeypatch.setattr(Session, "render_pass", failing_once)
    pv.start()
    try:
        f = pv.wait(spp=8, timeout=60)
        assert f is not None and f.spp == 8 and pv.error is None
        assert pv.frame.generation == pv._generation
    finally:
        pv.stop()


def test_a_scene_without_a_description_previews_at_full_size():
    """An XML file or mi.Scene cannot be reloaded at another size: the first frame after a
    change is then a full-size one (a reduced one raised on every change: a blank tuner)."""
    d = mi.cornell_box()
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 16
    pv = Preview(draaw_mi.load_scene(mi.load_dict(d)), version="v4", max_depth=3, freeze=False,
                 interactive_scale=0.5)
    f = pv.step()
    assert f is not None and not f.interactive and f.image.shape == (16, 16, 3)


def test_configure_is_all_or_nothing_and_rescales_the_interactive_frame():
    pv = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False,
                 interactive_scale=0.5)
    assert pv.step().image.shape == (24, 32, 3) and pv._lo.resolution == (16, 12)
    pv.configure(interactive_scale=0.25)
    assert pv.step().interactive and pv._lo.resolution == (8, 6)   # (kept 16x12 before)
    with pytest.raises(ParameterError, match="interactive_scale"):
        pv.configure(interactive_scale=2.0)
    with pytest.raises(DraawError, match="v9"):
        pv.configure(version="v9", max_depth=2)
    assert pv.version == "v4" and pv.max_depth == 4                # nothing half-applied


def test_a_worker_that_outlives_stop_is_not_doubled_by_start(monkeypatch):
    """stop() gave up waiting for a slow frame and forgot the thread, so start() ran a second
    worker beside it."""
    import threading
    pv = Preview(draaw_mi.load_scene(tiny_description()), version="v4", max_depth=4, freeze=False,
                 max_spp=4)
    real = pv._finish

    def slow(*args, **kwargs):
        time.sleep(0.5)
        return real(*args, **kwargs)
    monkeypatch.setattr(pv, "_finish", slow)
    pv.start()
    time.sleep(0.1)
    pv.stop(timeout=0.01)
    pv.start()
    try:
        workers = [t for t in threading.enumerate() if t.name == "draaw-mi-preview" and t.is_alive()]
        assert len(workers) == 1
        assert pv.wait(spp=4, timeout=60) is not None                # and it goes on working
    finally:
        pv.stop()


def test_the_preview_hides_emitters_as_the_scene_asks():
    """``render.hide_emitters`` holds in the preview too: it equals the mean of Mitsuba renders
    with an integrator that hides them (the preview showed them: the Cornell box's ceiling
    light at max 18.4 against 1.86); here the sky seen directly is hidden."""
    desc = tiny_description()
    desc["render"]["hide_emitters"] = True
    scene = draaw_mi.load_scene(desc)
    pv = Preview(scene, version="v4", max_depth=4, freeze=False, seed=3)
    frames = [pv.step() for _ in range(2)]
    seeds = [pass_seeds(3, i + 2)[-1] for i in range(2)]
    integ = session_of(scene).integrator("v4", 4, True)
    ref = np.mean([np.array(mi.render(scene.mi_scene, integrator=integ, seed=s, spp=1)) for s in seeds], axis=0)
    np.testing.assert_allclose(frames[-1].raw, ref[..., :3], rtol=1e-5, atol=1e-6)
    shown = _direct(scene, seeds)
    sky = np.all(np.abs(shown - 0.2) < 1e-6, axis=2)   # pixels that see the sky (0.2) directly
    assert sky.sum() > 20 and np.all(frames[-1].raw[sky] == 0)


@pytest.mark.parametrize("bad", [0, -3, 2.5, True])
def test_a_refinement_budget_below_one_sample_is_refused(bad):
    with pytest.raises(ParameterError, match="max_spp"):
        Preview(draaw_mi.load_scene(tiny_description()), max_spp=bad)


def test_a_preview_with_a_version_that_cannot_see_the_scene_fails_clearly():
    scene = draaw_mi.load_scene(os.path.join(SCENES, "sdf_csg.toml"), resolution=(16, 12))
    with pytest.raises(DraawError, match=r"\[\[sdf\]\] objects"):
        Preview(scene, version="path")


def test_the_budget_is_checked_on_configure_too_and_takes_numpy_integers():
    pv = Preview(draaw_mi.load_scene(tiny_description()), max_spp=np.int64(8), freeze=False)
    assert pv.max_spp == 8
    for bad in (0, 2.5):
        with pytest.raises(ParameterError, match="max_spp"):
            pv.configure(max_spp=bad)
    assert pv.max_spp == 8


def test_mitsubas_path_previews_denoised_colour_only():
    """denoise=True with Mitsuba's path (no AOVs to guide OIDN): the colour alone is denoised,
    as render(denoise=True) does (it raised "AOVs (albedo,normal) come from the draaw
    versions" although no AOV was asked for)."""
    pytest.importorskip("pyoidn")
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="path", max_depth=4, denoise=True, freeze=False, seed=3)
    f = pv.step()
    assert f.denoised
    np.testing.assert_allclose(f.image, draaw_mi.denoise(np.ascontiguousarray(f.raw)), rtol=1e-5, atol=1e-6)


def test_an_sdf_object_moved_in_the_preview_renders_as_a_scene_built_that_way():
    """``sdf.NODE.PARAM`` keys reach the tracer (the preview wrote only ``mi.traverse`` keys),
    a centre given as a list too (it was made a colour, which the next frame refused, dropping
    the change); a bad value is refused by the call, not by the render thread."""
    def described(radius):
        d = tiny_description()
        d["sdf"] = [{"type": "sphere", "name": "blob", "material": "ball", "center": [0.8, 0.4, 0.3],
                     "radius": radius}]
        return d
    scene = draaw_mi.load_scene(described(0.3))
    pv = Preview(scene, version="v4", max_depth=3, freeze=False, seed=4)
    pv.step()
    with pytest.raises(ParameterError, match="Preview.update: sdf.blob.radius: .*expected a number > 0"):
        pv.update({"sdf.blob.radius": 0.0})
    pv.update({"sdf.blob.radius": 0.45, "sdf.blob.center": [0.7, 0.45, 0.3]})
    f, f2 = pv.step(), pv.step()
    seed = pass_seeds(4, pv._frame_index + 1)[-1]
    # V4 learns its light selection with the scene as first rendered (radius 0.3), so the
    # reference learns there too, then moves the sphere as a user would
    other = draaw_mi.load_scene(described(0.3))
    old = _direct(other, [seed], depth=3)[..., :3]
    other.sdf.set("blob.radius", 0.45)
    other.sdf.set("blob.center", [0.7, 0.45, 0.3])
    session_of(other).scene_changed()
    ref = _direct(other, [seed], depth=3)[..., :3]
    np.testing.assert_allclose(f2.raw * 2 - f.raw, ref, rtol=1e-4, atol=1e-5)
    assert np.abs(ref - old).max() > 0.05                  # the radius shows in this image


def test_to_uint8_rounds_to_the_nearest_level():
    """Frames are rounded to the nearest 8-bit level, as numpy's encoding gives them (they were
    cut: up to one level darker)."""
    from draaw_mi.widgets import tuning
    from draaw_mi.io import srgb_encode
    x = np.array([[[0.0, 0.2140, 1.0], [0.5, 0.02, 0.9]]], np.float32)     # 0.2140 encodes to 0.5
    ref = np.round(np.clip(srgb_encode(x), 0, 1) * 255).astype(np.uint8)
    assert np.array_equal(tuning.to_uint8(x), ref)
    assert np.array_equal(tuning.to_uint8(np.full((1, 1, 3), 0.5, np.float32), encoded=True), [[[128] * 3]])


def test_a_frame_callback_that_stops_the_preview_stops_it_quietly():
    """stop() from an on_frame callback runs on the worker itself: it must not join its own
    thread (which raised 'cannot join current thread', shown as the frame's error), and the
    samples taken stay what ``spp`` says (an error set it to max_spp)."""
    scene = draaw_mi.load_scene(tiny_description())
    pv = Preview(scene, version="v4", max_depth=2, max_spp=1000, freeze=False)
    errors = []
    pv.on_error(errors.append)
    pv.on_frame(lambda f: pv.stop() if f.spp >= 3 else None)
    pv.start()
    deadline = time.perf_counter() + 60
    while pv.running and time.perf_counter() < deadline:
        time.sleep(0.05)
    try:
        assert not pv.running
        assert errors == [] and pv.error is None
        assert pv.spp == 3
    finally:
        pv.stop()


def test_after_scenes_change_the_preview_records_anew(monkeypatch, no_collections):
    """Once a scene is made or let go, a preview's frames do not replay the recording made
    before (a replay can call the freed scene's objects): the next frame records anew, the
    later ones replay it."""
    scene = draaw_mi.load_scene(tiny_description(resolution=[16, 16]))
    calls = []
    real = mi.render
    monkeypatch.setattr(mi, "render", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    pv = Preview(scene, version="v4", max_depth=3, max_spp=10**6)
    for _ in range(4):
        pv.step()
    n = len(calls)
    pv.step()
    assert len(calls) == n                                   # replayed
    other = draaw_mi.load_scene(tiny_description(resolution=[8, 8]))
    del other
    for _ in range(3):
        pv.step()
    assert len(calls) == n + 1                               # recorded anew once, replayed
