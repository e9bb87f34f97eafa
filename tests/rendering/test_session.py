"""The render session (draaw_mi.rendering.session): one per scene, the one place a pass is
rendered, and its lifetime (close, the context manager, the hook at interpreter exit)."""
from __future__ import annotations

import gc
import threading
import time
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from conftest import tiny_description
from draaw_mi.guard import RENDER_GUARD
from draaw_mi.rendering import session as S
from draaw_mi.rendering.preview import Preview
from draaw_mi.rendering.session import Session, apply_post, close_all, session_of


@pytest.fixture
def scene():
    return draaw_mi.load_scene(tiny_description())


def test_one_session_per_scene_and_it_goes_with_the_scene():
    a = draaw_mi.load_scene(tiny_description())
    b = draaw_mi.load_scene(tiny_description())
    assert session_of(a) is session_of(a) and session_of(a) is not session_of(b)
    gone = weakref.ref(session_of(a))
    del a
    gc.collect()
    assert gone() is None                     # the session holds its scene weakly


def test_a_pass_is_the_image_mi_render_gives(scene):
    """A traced pass is ``mi.render`` with the session's integrator, bit for bit; a replayed
    one the same image (to float rounding), for ints and opaque seeds alike."""
    session = session_of(scene)
    integ = session.integrator("v4", 4)
    direct = np.array(mi.render(scene.mi_scene, integrator=integ, spp=4, seed=7))
    traced = np.array(session.render_pass(integ, 4, 7, freeze=False))
    assert np.array_equal(traced, direct) and direct.mean() > 0
    for seed in (7, dr.opaque(mi.UInt32, 7)):
        replayed = np.array(session.render_pass(integ, 4, seed, freeze=True))
        assert np.allclose(replayed, direct, rtol=1e-5, atol=1e-6)
    assert (id(integ), 4) in session.recordings


def test_a_differentiable_pass_carries_gradients(scene):
    session = session_of(scene)
    integ = session.integrator("v4", 3)
    p = scene.params
    key = scene.key("ball.roughness")
    dr.enable_grad(p[key])
    p.update()
    img = session.render_pass(integ, 4, 1, params=p)
    dr.backward(dr.mean(img.array))
    assert session.recordings == {}            # a differentiable pass is traced, never recorded
    g = dr.grad(p[key])
    assert np.isfinite(np.array(g)).all() and float(np.abs(np.array(g)).max()) > 0


def test_close_stops_the_workers_and_lets_go_of_recordings_and_integrators(scene):
    pv = Preview(scene, version="v4", max_depth=3, max_spp=100000)
    pv.start()
    try:
        assert pv.wait(spp=2, timeout=60) is not None
        session = session_of(scene)
        assert session.workers() == [pv] and session.recordings
        t0 = time.perf_counter()
        session.close()
        assert time.perf_counter() - t0 < 5 and not pv.running
        assert session.recordings == {} and session.workers() == []
        assert session_of(scene) is not session               # a closed session is not reused
        # but the lock is the scene's: a thread holding it across the close still excludes
        # the renders that come after
        assert session_of(scene).lock is session.lock
        assert session_of(draaw_mi.load_scene(tiny_description())).lock is not session.lock
        img = np.array(draaw_mi.render(scene, version="v4", spp=2, seed=1))      # renders again
        assert np.isfinite(img).all() and img.mean() > 0
    finally:
        pv.stop()


def test_the_context_manager_and_close_all_stop_workers():
    a = draaw_mi.load_scene(tiny_description())
    b = draaw_mi.load_scene(tiny_description())
    with session_of(a) as session:
        pa = Preview(a, version="v2", max_depth=2, max_spp=100000)
        pa.start()
        assert pa.wait(spp=1, timeout=60) is not None and session.workers() == [pa]
    assert not pa.running
    pb = Preview(b, version="v2", max_depth=2, max_spp=100000)
    pb.start()
    assert pb.wait(spp=1, timeout=60) is not None
    close_all()                                   # what the interpreter's exit runs
    assert not pb.running


def test_a_second_preview_of_a_scene_supersedes_the_first_through_the_session(scene):
    first = Preview(scene, version="v2", max_depth=2, max_spp=100000)
    second = Preview(scene, version="v2", max_depth=2, max_spp=100000)
    first.start()
    try:
        assert first.wait(spp=1, timeout=60) is not None
        second.start()
        assert not first.running and second.running
        assert second in session_of(scene).workers()
    finally:
        first.stop()
        second.stop()


def test_a_draaw_integrator_called_directly_waits_for_the_guard(scene):
    """``mi.render`` with a draaw integrator renders under RENDER_GUARD: while another thread
    holds the guard (a preview's frame, a recording), it waits instead of running beside it."""
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 3})
    np.array(mi.render(scene.mi_scene, integrator=integ, spp=1, seed=0))          # traced once
    done = threading.Event()

    def render():
        mi.render(scene.mi_scene, integrator=integ, spp=1, seed=1)
        done.set()
    with RENDER_GUARD:
        t = threading.Thread(target=render)
        t.start()
        assert not done.wait(0.5)              # held up by the guard
    assert done.wait(60)
    t.join()


def test_a_version_that_cannot_see_the_scene_is_refused(tmp_path):
    desc = tiny_description()
    desc["sdf"] = [{"type": "sphere", "name": "blob", "center": [1.5, 0.5, 0], "radius": 0.3}]
    sdf_scene = draaw_mi.load_scene(desc)
    session = session_of(sdf_scene)
    assert session.holds() == {"sdf": True, "media": False}
    session.check_version_sees("v4")
    with pytest.raises(draaw_mi.RenderError, match=r"\[\[sdf\]\] objects, which Mitsuba's 'path' cannot see"):
        session.check_version_sees("path")


def test_freeze_rules(scene, monkeypatch):
    session = session_of(scene)
    assert session.freezes(16) and not session.freezes(32) and session.freezes(32, True)
    assert not session.freezes(1, False)
    monkeypatch.setattr(S, "FREEZE", False)
    assert not session.freezes(1, True)


def test_apply_post_leaves_aov_channels_alone():
    img = mi.TensorXf(np.full((2, 2, 6), 0.25, np.float32))
    out = np.array(apply_post(img, [{"type": "contrast", "contrast": 2.0}], ["R", "G", "B", "N.X", "N.Y", "N.Z"]))
    assert np.array_equal(out[..., 3:], np.full((2, 2, 3), 0.25, np.float32))
    assert not np.allclose(out[..., :3], 0.25)


def test_the_session_says_what_it_holds(scene):
    session = session_of(scene)
    session.integrator("v1", 2)
    assert repr(session) == f"Session[{scene.source}, 1 integrators, 0 recordings, 0 workers]"
    assert isinstance(session, Session) and session.scene is scene


CLOSE_BESIDE_A_PREVIEW = """
import os, random, sys, threading, time
import draaw_mi
from draaw_mi.rendering.preview import Preview
from draaw_mi.rendering.session import session_of
random.seed(1)
scene = draaw_mi.load_scene({"render": {"resolution": [32, 32], "filter": "box"},
    "materials": {"m": {"roughness": 0.5}}, "shapes": [{"type": "sphere", "material": "m"}],
    "lights": [{"type": "constant"}], "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
pv = Preview(scene, version="v4", max_depth=3, interactive_scale=0.5, max_spp=100000)
pv.start()
assert pv.wait(spp=1, timeout=60) is not None
closes = 0
def watchdog():
    time.sleep(40)
    print("hung after", closes, "closes", flush=True)
    os._exit(3)
threading.Thread(target=watchdog, daemon=True).start()
t0 = time.time()
while time.time() - t0 < SECONDS:
    pv.update({"m.roughness": random.uniform(0.1, 0.9)})   # the next frame renders the reduced copy
    time.sleep(random.uniform(0, 0.01))
    lo = pv._lo
    if lo is not None:
        session_of(lo).close(timeout=1)                     # what close_all does at exit
        closes += 1
pv.stop()
print("ok", closes, flush=True)
"""


def test_closing_a_session_beside_a_refining_preview_never_deadlocks():
    """The preview renders its reduced copy holding the scene's lock and the copy's, then the
    guard; Session.close takes the lock, then the guard. A frame that took a lock after the
    guard -- or the lock of a session made anew after a close, which another thread then
    closed -- deadlocked against close, and so against close_all at exit. A few seconds of
    changes and closes found it (within 1 to 10 s)."""
    import subprocess
    import sys

    from conftest import ROOT
    script = CLOSE_BESIDE_A_PREVIEW.replace("SECONDS", "8")
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0 and out.stdout.startswith("ok"), (out.stdout, out.stderr[-2000:])
    assert int(out.stdout.split()[1]) > 50          # it closed the copy's session many times


def _interrupted_in_a_kernel(*a, **k):
    """What ``mi.render`` raises when Ctrl-C reaches its ``dr.custom`` operation."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as e:
        raise RuntimeError("drjit.custom(<_RenderOp>): error while performing a custom "
                           "differentiable operation. (see above).") from e


@pytest.mark.parametrize("freeze", [False, True])
def test_ctrl_c_during_a_pass_leaves_as_a_keyboard_interrupt(scene, monkeypatch, freeze):
    """Ctrl-C in a render's kernel reached the user as Dr.Jit's RuntimeError (the CLI printed
    two tracebacks and exited 1, not "interrupted" and 130); other errors stay as they are."""
    session = session_of(scene)
    integ = session.integrator("v4", 4)
    monkeypatch.setattr(S.mi, "render", _interrupted_in_a_kernel)
    with pytest.raises(KeyboardInterrupt):
        session.render_pass(integ, 4, 1, freeze=freeze)
    monkeypatch.setattr(S.mi, "render", lambda *a, **k: (_ for _ in ()).throw(RuntimeError("other")))
    with pytest.raises(RuntimeError, match="other"):
        session.render_pass(integ, 4, 1, freeze=False)


def test_the_cli_says_interrupted_and_exits_130_when_a_render_is_interrupted(tmp_path, monkeypatch, capsys):
    import tomli_w
    from draaw_mi.cli import main
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(tiny_description()))
    monkeypatch.setattr(S.mi, "render", _interrupted_in_a_kernel)
    assert main(["render", str(path), "-o", str(tmp_path / "a.exr"), "--no-progress"]) == 130
    err = capsys.readouterr().err
    assert err == "draaw-mi: interrupted\n" and not (tmp_path / "a.exr").exists()


def _interrupted_init(cls, monkeypatch):
    """Ctrl-C landing in ``cls``'s Python constructor while Mitsuba makes the plugin (Mitsuba
    raises a RuntimeError that names the KeyboardInterrupt only in its text)."""
    made = cls.__init__

    def init(self, props):
        made(self, props)
        raise KeyboardInterrupt
    monkeypatch.setattr(cls, "__init__", init)


def test_ctrl_c_while_an_integrator_or_a_scene_is_made_leaves_as_a_keyboard_interrupt(monkeypatch):
    """(were RenderError "cannot create integrator 'draaw_v4': KeyboardInterrupt:" and
    SceneError "<dict>: KeyboardInterrupt:", which an ``except DraawError`` loop swallowed)"""
    from draaw_mi.integrators.v4 import DraawV4Integrator
    from draaw_mi.materials.draaw_bsdf import DraawBSDF
    scene = draaw_mi.load_scene(tiny_description())
    with monkeypatch.context() as m:
        _interrupted_init(DraawV4Integrator, m)
        with pytest.raises(KeyboardInterrupt):
            draaw_mi.render(scene, spp=1, version="v4", max_depth=2)
    with monkeypatch.context() as m:
        _interrupted_init(DraawBSDF, m)
        with pytest.raises(KeyboardInterrupt):
            draaw_mi.load_scene(tiny_description())
    with pytest.raises(draaw_mi.errors.RenderError, match="no option 'sdf_bands'"):
        session_of(scene).integrator("v4", 2, sdf_bands=1.0)          # (other errors as they were)


def test_the_cli_exits_130_when_the_integrator_is_interrupted_as_it_is_made(tmp_path, monkeypatch, capsys):
    import tomli_w
    from draaw_mi.cli import main
    from draaw_mi.integrators.v4 import DraawV4Integrator
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(tiny_description()))
    _interrupted_init(DraawV4Integrator, monkeypatch)
    assert main(["render", str(path), "-o", str(tmp_path / "a.exr"), "--no-progress", "--version", "v4"]) == 130
    assert capsys.readouterr().err == "draaw-mi: interrupted\n"


@pytest.mark.parametrize("plugin", ["path", "prb"])
def test_a_declared_mitsuba_integrator_renders_with_its_own_settings(tmp_path, plugin):
    """An XML file's path integrator with rr_depth 1 rendered with a new plugin's rr_depth 5."""
    path = tmp_path / "s.xml"
    path.write_text(
        f'<scene version="3.0.0"><integrator type="{plugin}"><integer name="max_depth" value="3"/>'
        '<integer name="rr_depth" value="1"/></integrator><sensor type="perspective">'
        '<film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>'
        '</sensor><shape type="sphere"/><emitter type="constant"/></scene>')
    scene = draaw_mi.load_scene(str(path))
    own = scene.mi_scene.integrator()
    session = session_of(scene)
    s = scene.settings
    assert s["version"] == plugin and session.integrator(plugin, s["max_depth"], s["hide_emitters"]) is own
    # another depth, hide_emitters or option: a plugin of its own
    assert session.integrator(plugin, 2, s["hide_emitters"]) is not own
    assert session.integrator(plugin, s["max_depth"], True) is not own
    assert session.integrator(plugin, s["max_depth"], s["hide_emitters"], rr_depth=2) is not own
    img = np.array(draaw_mi.render(scene, seed=0))
    assert img.shape == (8, 8, 3) and np.isfinite(img).all()
