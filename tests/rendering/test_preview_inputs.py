"""Preview.update refuses what the scene cannot take, at once and in one line; a refused or
failed change never outlives itself (the preview and the scene go on with valid ones)."""
from __future__ import annotations

import time

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import ParameterError
from draaw_mi.limits import FOV_RANGE
from draaw_mi.rendering.preview import Preview

from conftest import tiny_description


def _preview(textured=False):
    desc = tiny_description(resolution=[8, 6])
    if textured:
        desc["materials"]["ball"]["base_color"] = np.full((4, 4, 3), 0.5, np.float32)
    return Preview(draaw_mi.load_scene(desc), version="v4", max_depth=3, freeze=False, seed=1)


def test_texels_of_the_wrong_shape_are_refused_and_the_preview_goes_on():
    """They were accepted; the next frame failed in params.update(), the value stayed queued in
    the scene's parameters and every later frame (and the user's own params.update()) failed.
    A colour fills the texture (a constant map of its shape)."""
    pv = _preview(textured=True)
    pv.step()
    with pytest.raises(ParameterError, match=r"Preview.update: ball.base_color: .*is a texture of shape "
                                             r"\(4, 4, 3\); give one number or 3"):
        pv.update({"ball.base_color": np.full((4, 4, 2), 0.5)})
    pv.update({"ball.roughness": 0.2, "ball.base_color": [1.0, 0.0, 0.0]})
    f = pv.step()
    assert pv.error is None and f is not None and np.isfinite(f.raw).all()
    pv.scene.params.update()                          # nothing left queued
    texels = np.array(pv.scene.params["ball.base_color.data"])
    assert texels.shape == (4, 4, 3) and np.all(texels == np.array([1.0, 0.0, 0.0], np.float32))


@pytest.mark.parametrize("value", [np.float32(7.0), np.float32("nan"), np.int64(-3), np.array(2.0)])
def test_numpy_scalars_are_range_checked(value):
    """np.float32(7) went around the check (only Python int/float were looked at)."""
    with pytest.raises(ParameterError, match=r"Preview.update: ball.roughness=.*expected"):
        _preview().update({"ball.roughness": value})


@pytest.mark.parametrize("key, value, match", [
    ("ball.roughness", [0.1, 0.2, 0.3], r"ball.roughness=\[0.1, 0.2, 0.3\]; expected a number in \[0.0, 1.0\]"),
    ("ball.roughness", np.full((4, 4, 1), np.nan), r"ball.roughness: 16 texel value\(s\) outside \[0, 1\]"),
    ("ball.base_color", np.full((4, 4, 3), -1.0), r"ball.base_color: 48 texel value\(s\) outside \[0, .*\(the first, -1\.0, at \[0, 0, 0\]\)")])
def test_a_scalar_gets_one_number_and_texels_are_range_checked(key, value, match):
    """Three numbers for a scalar parameter were accepted (the next frame failed on the worker
    thread: a 3-wide Float), one number in a list was refused as "expected 3 numbers"; a
    texture's texels went unchecked (NaN roughness texels were zeroed without a word: the
    same values in a scene file are refused)."""
    textured = np.asarray(value).ndim > 1
    pv = _preview(textured=textured)
    if textured and "roughness" in key:        # (the tiny scene's roughness is a constant)
        desc = tiny_description(resolution=[8, 6])
        desc["materials"]["ball"]["roughness"] = np.full((4, 4), 0.3, np.float32)
        pv = Preview(draaw_mi.load_scene(desc), version="v4", max_depth=3, freeze=False, seed=1)
    with pytest.raises(ParameterError, match="Preview.update: " + match):
        pv.update({key: value})
    pv.update({"ball.roughness": [0.25]} if not textured else {key: np.full(np.shape(value), 0.25)})
    f = pv.step()
    assert pv.error is None and f is not None and np.isfinite(f.raw).all()


def test_a_batch_with_a_bad_value_changes_nothing():
    """A string was refused later, on the worker thread, and the batch's valid roughness still
    reached the scene."""
    pv = _preview()
    key = pv.scene.key("ball.roughness")
    before = float(pv.scene.params[key][0])
    with pytest.raises(ParameterError, match=r"ball.metallic='0.3'; expected a number"):
        pv.update({"ball.roughness": 0.05, "ball.metallic": "0.3"})
    pv.step()
    assert float(pv.scene.params[key][0]) == before


@pytest.mark.parametrize("fov, ok", [(-10.0, False), (0.0, False), (400.0, False), (179.5, False),
                                      (FOV_RANGE[1], True), (30.0, True)])
def test_the_field_of_view_is_checked_as_scene_files_check_it(fov, ok):
    pv = _preview()
    if ok:
        pv.update({"sensor.x_fov": fov})
        assert pv.step() is not None and pv.error is None
    else:
        with pytest.raises(ParameterError, match="expected a field of view in"):
            pv.update({"sensor.x_fov": fov})


def test_a_change_that_fails_at_the_update_is_undone(monkeypatch):
    """A value past the checks that the scene's update refuses (put in the queue directly,
    its conversion skipped) fails one frame; the parameters get their old values back, so the
    next valid change renders."""
    import mitsuba as mi
    import draaw_mi.rendering.preview as preview_mod
    pv = _preview(textured=True)
    pv.step()
    key = pv.scene.key("ball.base_color")
    good = np.array(pv.scene.params[key])
    monkeypatch.setattr(preview_mod, "value_like", lambda current, value, key: value)
    pv._pending[key] = mi.TensorXf(np.zeros(3, np.float32))   # (ndim 1: update_inplace refuses)
    with pytest.raises(RuntimeError, match="dimension"):
        pv._apply_pending()
    monkeypatch.undo()
    np.testing.assert_array_equal(np.array(pv.scene.params[key]), good)
    pv.update({"ball.roughness": 0.3})
    assert pv.step() is not None and pv.error is None


def test_a_camera_transform_with_scale_is_refused_at_the_update():
    """Mitsuba's camera refuses a scaled to_world only when the frame renders, on the worker
    thread, in its own words; the values queued with it were dropped."""
    pv = _preview()
    try:
        m = np.array(pv.scene.params["sensor.to_world"].matrix, dtype=np.float64).reshape(4, 4)
        m[:3, :3] *= 2.0
        with pytest.raises(ParameterError, match=r"Preview.update: sensor.to_world: a camera transform with "
                                                 r"scale or shear.*expected a rigid transform"):
            pv.update({"sensor.to_world": mi.ScalarTransform4f(m)})
        m[:3, :3] /= 2.0
        pv.update({"sensor.to_world": mi.ScalarTransform4f(m)})     # rigid: taken
    finally:
        pv.close()


def test_a_closed_preview_says_so_from_every_method():
    """update, configure, key and check_camera_outside_smoke failed with AttributeError /
    TypeError after close(), where start and step said the preview was closed."""
    pv = _preview()
    pv.close()
    for who, call in (("Preview.update", lambda: pv.update({"ball.roughness": 0.3})),
                      ("Preview.configure", lambda: pv.configure(max_spp=2)),
                      ("Preview.key", lambda: pv.key("ball.roughness")),
                      ("Preview.check_camera_outside_smoke",
                       lambda: pv.check_camera_outside_smoke("x", np.eye(4)))):
        with pytest.raises(draaw_mi.errors.DraawError, match=f"{who}: this preview was closed"):
            call()


def test_an_error_callback_that_raises_does_not_stop_the_worker():
    """A raising on_error callback ended the worker thread: later changes never rendered."""
    pv = _preview()
    seen = []

    def bad_frame(frame):
        if frame.generation == 1:
            raise RuntimeError("frame callback bug")

    def bad_error(e):
        seen.append(e)
        raise ValueError("error callback bug")

    pv.on_frame(bad_frame)
    pv.on_error(bad_error)
    try:
        with pytest.warns(RuntimeWarning, match="on_error callback raised"):
            pv.start()
            g = pv.update({"ball.roughness": 0.3})
            deadline = time.time() + 60
            while not seen and time.time() < deadline:
                time.sleep(0.05)
        assert seen and pv.running
        g = pv.update({"ball.roughness": 0.5})
        assert pv.wait(g, spp=1, timeout=60) is not None
    finally:
        pv.close()

