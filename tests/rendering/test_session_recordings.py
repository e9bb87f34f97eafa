"""Recorded renders (the session's dr.freeze of mi.render, the seed an opaque value): when a pass
is replayed, what a replay follows, and that it gives the traced render's image."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import draaw_mi
from draaw_mi.rendering import frozen as F, session as S
from draaw_mi.rendering.session import Session, session_of
import drjit as dr
import mitsuba as mi

from draaw_mi.bench import reference_scenes as rs


@pytest.fixture(scope="module")
def scene():
    return draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))


def _record_afresh(scene, monkeypatch):
    """No recording of ``scene`` (they are kept per scene) or of a bare Mitsuba scene."""
    monkeypatch.setattr(session_of(scene), "recordings", {})


GC_DURING_RECORDING = """
import gc, sys
import draaw_mi, mitsuba as mi, numpy as np
sys.path.insert(0, "tests")
from conftest import tiny_description
holder = [draaw_mi.load_scene(tiny_description())]
draaw_mi.render(holder[0], version="v4", spp=4, seed=1, post=[])
holder[0].info["self"] = holder[0]                  # a cycle: only the collector frees it
real = mi.render
def dropping(*a, **k):
    holder.clear()                 # the old scene becomes garbage while the new render records
    gc.set_threshold(1, 1, 1)      # and the collector would run at almost every allocation
    return real(*a, **k)
mi.render = dropping
b = draaw_mi.load_scene(tiny_description(resolution=[16, 16]))
img = np.array(draaw_mi.render(b, version="v4", spp=4, seed=1, post=[]))
mi.render = real
gc.set_threshold(700, 10, 10)
gc.collect()
print("ok", np.isfinite(img).all())
"""


def test_a_scene_collected_while_another_records_does_not_abort():
    """Python's cycle collector freeing a dead scene's Dr.Jit memory in the middle of a
    dr.freeze recording aborted the process ("enqueue_host_func(): this function cannot be
    recorded!"; the test suite died so once recordings went with their scenes): the collector
    is paused while a frozen render runs. In a child process, since the failure is an abort."""
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", GC_DURING_RECORDING], cwd=root, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().endswith("ok True")
    # the mechanism itself, in this process: off inside (nested too), on again after
    import gc
    from draaw_mi.guard import COLLECTOR_PAUSED as _PAUSED
    assert gc.isenabled()
    with _PAUSED:
        with _PAUSED:
            assert not gc.isenabled()
        assert not gc.isenabled()
    assert gc.isenabled()


@pytest.mark.parametrize("version", ["v2", "v4"])
def test_a_scene_loaded_again_renders_as_the_first(version, monkeypatch, tmp_path):
    """A scene loaded again, with the same layout, while the first is freed: its frozen render
    is its own recording. Replaying the first scene's recording (Dr.Jit does not see that the
    Python BSDFs changed) rendered black every other load: image means 0.0475, 0, 0.0475, 0."""
    import gc
    import weakref
    import tomli_w
    monkeypatch.setattr(S, "FREEZE", True)
    path = tmp_path / "ball.toml"
    path.write_text(tomli_w.dumps({
        "render": {"resolution": [32, 32], "max_depth": 4, "filter": "box"},
        "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 30},
        "materials": {"m": {"base_color": [0.9, 0.9, 0.9], "roughness": 0.6, "metallic": 1.0}},
        "shapes": [{"type": "sphere", "material": "m", "radius": 1.0}],
        "lights": [{"type": "point", "position": [2, 2, 3], "intensity": 10}]}))
    images, gone = [], []
    for _ in range(6):
        s = draaw_mi.load_scene(str(path))
        draaw_mi.render(s, version="path", spp=4, seed=3, post=[])     # (as in the report)
        images.append(np.array(draaw_mi.render(s, version=version, spp=4, seed=3, post=[])))
        gone.append(weakref.ref(s))
    assert images[0].mean() > 0.01
    for img in images[1:]:
        assert np.array_equal(img, images[0])
    del s
    gc.collect()
    assert all(r() is None for r in gone)          # recordings go with their scene


@pytest.mark.parametrize("version", ["v1", "v4"])
def test_frozen_render_replays_without_tracing(scene, version, monkeypatch):
    calls = []
    real = mi.render

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(mi, "render", counting)
    _record_afresh(scene, monkeypatch)               # the first call is traced
    monkeypatch.setattr(S, "FREEZE", True)
    imgs = [np.array(draaw_mi.render(scene, version=version, spp=4, seed=s, post=[])) for s in (5, 6, 7)]
    n = len(calls)
    again = np.array(draaw_mi.render(scene, version=version, spp=4, seed=5, post=[]))
    other = np.array(draaw_mi.render(scene, version=version, spp=4, seed=8, post=[]))
    assert n >= 1                               # the counter sees the traced calls ...
    assert len(calls) == n                      # ... replayed: the Python integrator was not traced
    assert np.array_equal(again, imgs[0])       # same seed, same image
    assert not np.allclose(other, imgs[0])      # the opaque seed still changes the samples
    monkeypatch.setattr(S, "FREEZE", False)
    traced = np.array(draaw_mi.render(scene, version=version, spp=4, seed=5, post=[]))
    assert np.allclose(traced, imgs[0], rtol=1e-5, atol=1e-6)


def test_frozen_render_sees_parameter_changes(scene, monkeypatch):
    monkeypatch.setattr(S, "FREEZE", True)
    key = "light.emitter.radiance.value"
    p = scene.params
    v0 = mi.Color3f(p[key])
    a = [np.array(draaw_mi.render(scene, version="v4", spp=4, seed=3, post=[])) for _ in range(3)][-1]
    p[key] = 2.0 * v0
    p.update()
    try:
        b = np.array(draaw_mi.render(scene, version="v4", spp=4, seed=3, post=[]))
    finally:
        p[key] = v0
        p.update()
    assert a.mean() > 0
    assert np.allclose(b, 2.0 * a, rtol=1e-4, atol=1e-6)   # one light: the image is linear in it


@pytest.mark.filterwarnings("error::RuntimeWarning")     # a fallback to tracing fails it
@pytest.mark.parametrize("version", ["v1", "v4"])
def test_frozen_render_sees_material_changes(scene, version, monkeypatch):
    """A draaw BSDF keeps its constants as bare arrays in its instance dict: the recording
    must take them as inputs (a constant hidden from dr.freeze would replay its old value)."""
    key = next(k for k in scene.params.keys() if k.endswith(".roughness.value"))
    p = scene.params
    r0 = mi.Float(p[key])
    monkeypatch.setattr(S, "FREEZE", True)
    a = [np.array(draaw_mi.render(scene, version=version, spp=4, seed=3, post=[])) for _ in range(3)][-1]
    p[key] = 0.05 if r0[0] > 0.5 else 0.95
    p.update()
    try:
        frozen = np.array(draaw_mi.render(scene, version=version, spp=4, seed=3, post=[]))
        monkeypatch.setattr(S, "FREEZE", False)
        traced = np.array(draaw_mi.render(scene, version=version, spp=4, seed=3, post=[]))
    finally:
        p[key] = r0
        p.update()
    assert np.abs(traced - a).mean() > 1e-4                    # the change shows ...
    assert np.allclose(frozen, traced, rtol=1e-5, atol=1e-6)   # ... in the replay too


def test_large_or_many_spp_renders_are_not_frozen(scene):
    """render()'s rule ("small"): at most FREEZE_MAX_SPP samples and FREEZE_MAX_PIXELS pixels;
    the batch's and the preview's (True): any size, wherever the scene can be recorded."""
    session = session_of(scene)
    assert session.freezes(16) and not session.freezes(32)
    assert session.freezes(32, True) and not session.freezes(4, False)
    big = scene.with_resolution(256, 256)
    assert not session_of(big).freezes(4) and session_of(big).freezes(4, True)


def test_frozen_v4_many_lights_and_constant_sky(monkeypatch):
    """V4's scene-dependent choices are the same in a dr.freeze recording and a traced render:
    the constant-sky detection reads flags only, and the power table enters the recording as
    an input (render.freeze_render). Same seed, same image (to float rounding); before, a frozen
    render chose lights uniformly and these differed by whole sample values."""
    from draaw_mi.bench import suite as ss
    from draaw_mi.integrators.sampling import PowerSelection
    for name in ("many_lights", "constant_env"):
        scene = draaw_mi.load_scene(ss.build(name, 16, spp=4))
        if name == "many_lights":          # the case that matters: a non-uniform table
            assert PowerSelection.of(scene.mi_scene) is not None
        monkeypatch.setattr(S, "FREEZE", True)
        frozen = [np.array(draaw_mi.render(scene, version="v4", spp=16, seed=s, post=[],
                                           max_depth=3)) for s in (1, 2, 3)]
        monkeypatch.setattr(S, "FREEZE", False)
        traced = [np.array(draaw_mi.render(scene, version="v4", spp=16, seed=s, post=[],
                                           max_depth=3)) for s in (1, 2, 3)]
        for f, t in zip(frozen, traced):
            assert np.isfinite(f).all() and f.mean() > 0
            assert np.allclose(f, t, rtol=1e-5, atol=1e-6), (name, np.abs(f - t).max())


def test_frozen_replay_reads_a_new_power_table(monkeypatch):
    """A replay takes the table it is given: with the table of the same scene made uniform by
    hand, the frozen render changes exactly as the traced one does (a table baked into the
    recording would not change)."""
    from draaw_mi.bench import suite as ss
    from draaw_mi.integrators.sampling import PowerSelection
    scene = draaw_mi.load_scene(ss.build("many_lights", 16, spp=4))
    integ = session_of(scene).integrator("v4", 3)
    monkeypatch.setattr(S, "FREEZE", True)
    a = np.array(draaw_mi.render(scene, version="v4", spp=8, seed=4, post=[], max_depth=3))
    n = len(scene.mi_scene.emitters())
    flat = PowerSelection.from_power(scene.mi_scene, np.ones(n))
    key = integ.selection_key(scene.mi_scene)      # (an id-only match may be a dead scene's)
    assert key in integ._tables
    monkeypatch.setitem(integ._tables, key, (scene.mi_scene.emitters_dr(), flat, True))
    b = np.array(draaw_mi.render(scene, version="v4", spp=8, seed=4, post=[], max_depth=3))
    monkeypatch.setattr(S, "FREEZE", False)
    c = np.array(draaw_mi.render(scene, version="v4", spp=8, seed=4, post=[], max_depth=3))
    assert not np.allclose(a, b)                       # the new table was used ...
    assert np.allclose(b, c, rtol=1e-5, atol=1e-6)     # ... as a traced render uses it


def test_recording_holds_while_other_python_bsdfs_are_alive(scene, monkeypatch):
    """Dr.Jit fails a recording whose BSDF call meets a live Python BSDF that is not among its
    inputs (a draaw material of another scene, kept by a notebook or a cache); freeze_render
    passes every live draaw BSDF along, so the render still records and replays."""
    import warnings
    others = [mi.load_dict({"type": "draaw", "roughness": 0.3 + 0.1 * i}) for i in range(2)]
    calls = []
    real = mi.render
    monkeypatch.setattr(mi, "render", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    _record_afresh(scene, monkeypatch)
    monkeypatch.setattr(S, "FREEZE", True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)      # no fallback to tracing
        first = [np.array(draaw_mi.render(scene, version="v2", spp=2, seed=s, post=[])) for s in (1, 2)]
        n = len(calls)
        again = np.array(draaw_mi.render(scene, version="v2", spp=2, seed=1, post=[]))
    assert n >= 1 and len(calls) == n and np.array_equal(again, first[0])
    assert len(others) == 2


def test_a_failed_recording_falls_back_to_tracing(scene, monkeypatch):
    """A scene the recorder cannot hold is traced instead, with a warning, and gives the traced
    image (the fallback keeps renders working; the warning keeps it visible)."""
    def refuse(fn, **options):
        def frozen(*a, **k):
            raise RuntimeError("record(): stand-in failure")
        return frozen
    monkeypatch.setattr(F.dr, "freeze", refuse)
    _record_afresh(scene, monkeypatch)
    monkeypatch.setattr(S, "FREEZE", True)
    try:
        with pytest.warns(RuntimeWarning, match="traced from now on"):
            img = np.array(draaw_mi.render(scene, version="v1", spp=2, seed=9, post=[]))
        monkeypatch.setattr(S, "FREEZE", False)
        traced = np.array(draaw_mi.render(scene, version="v1", spp=2, seed=9, post=[]))
        assert np.allclose(img, traced, rtol=1e-5, atol=1e-6) and img.mean() > 0
    finally:
        session_of(scene).recordings.clear()      # (the refusing recorder's stand-ins)


def test_light_changes_refresh_the_power_table(monkeypatch):
    """V4's light-selection table follows light intensities changed between renders: after
    scene_changed (which the preview, the batch and the fitter call after params.update) the
    next render's table gives a light made 100x brighter a larger share; without a refresh it
    would keep sampling it as before (unbiased, but a poor table)."""
    from draaw_mi.bench import suite as ss
    scene = draaw_mi.load_scene(ss.build("many_lights", 8, spp=4))
    integ = session_of(scene).integrator("v4", 3)
    draaw_mi.render(scene, version="v4", spp=4, seed=1, post=[], max_depth=3)
    before = integ.emitter_selection(scene.mi_scene)
    key = "l1.emitter.radiance.value"                       # one of the weak lights
    shape = next(sh for sh in scene.mi_scene.shapes() if sh.id() == "l1")
    eid = int(np.array(dr.reinterpret_array(mi.UInt32, mi.EmitterPtr(shape.emitter())))[0])
    p = scene.params
    v0 = mi.Color3f(p[key])
    p[key] = 100.0 * v0
    p.update()
    try:
        assert integ.emitter_selection(scene.mi_scene) is before        # cached until told
        session_of(scene).scene_changed()
        img = np.array(draaw_mi.render(scene, version="v4", spp=4, seed=1, post=[], max_depth=3))
        after = integ.emitter_selection(scene.mi_scene)
    finally:
        p[key] = v0
        p.update()
        session_of(scene).scene_changed()
    pmf_before, pmf_after = np.array(before.pmf_by_id), np.array(after.pmf_by_id)
    assert pmf_after[eid] > 10 * pmf_before[eid] > 0 and np.isfinite(img).all()


def test_preview_parameter_changes_reach_scene_changed(monkeypatch):
    from draaw_mi.rendering import preview as P
    seen = []
    monkeypatch.setattr(Session, "scene_changed", lambda self: seen.append(self.scene))
    from conftest import tiny_description
    pv = P.Preview(draaw_mi.load_scene(tiny_description()), freeze=False)
    pv.update({"ball.roughness": 0.3})
    assert not seen
    pv.step()
    assert pv.scene in seen


def test_doctests():
    import doctest
    from draaw_mi.rendering import renderer
    for module, least in ((renderer, 3), (F, 3), (S, 3)):
        res = doctest.testmod(module)
        assert res.attempted >= least and res.failed == 0, module.__name__


def test_render_asks_freeze_support_once_per_scene_and_the_film_every_time(scene):
    """render() remembers per scene whether it may be frozen (media and SDF objects cannot
    appear after loading) but reads the film size each time (params can change it)."""
    smoke = draaw_mi.load_scene(str(Path(__file__).parents[2] / "scenes" / "smoke.toml"), resolution=(16, 16))
    for s in (scene, smoke):
        for spp in (4, 16, 32):
            assert session_of(s).freezes(spp) == Session(s).freezes(spp), (s.source, spp)
    assert session_of(scene).freezes(4) and not session_of(smoke).freezes(4, True)
    p = scene.params
    p["sensor.film.size"] = mi.ScalarVector2u(256, 256)       # over FREEZE_MAX_PIXELS
    p.update()
    try:
        assert not session_of(scene).freezes(4) and not Session(scene).freezes(4)
    finally:
        p["sensor.film.size"] = mi.ScalarVector2u(16, 16)
        p.update()
    assert session_of(scene).freezes(4)


def test_integrator_shortcut_follows_the_cache(scene, monkeypatch):
    """The same arguments give the same integrator, other arguments another; emptying the
    session's integrators (as a fresh start) also ends the shortcut to the old ones. Each
    scene's session has its own integrators (V4 keeps what it learns of its scene)."""
    session = session_of(scene)
    a = session.integrator("v4", 5)
    assert session.integrator("v4", 5) is a and session.integrator("draaw_v4", 5) is a
    assert session.integrator("v4", 4) is not a
    assert session.integrator("v4", 5, aovs=["albedo"]) is not a
    assert session.integrator("v4", 5, rr_depth=3) is not session.integrator("v4", 5, rr_depth=4)
    other = draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))
    assert session_of(other).integrator("v4", 5) is not a
    monkeypatch.setattr(session, "_integrators", {})
    fresh = session.integrator("v4", 5)
    assert fresh is not a and session.integrator("v4", 5) is fresh


def test_other_live_bsdfs_follows_bsdfs_made_and_dropped(scene):
    """The scene's own BSDFs are looked up once; BSDFs made later (a notebook's other scene)
    appear, and disappear again when dropped, with and without the cached lookup (other
    tests' BSDFs may still be alive: the uncached walk is the reference)."""
    import gc
    from draaw_mi.materials.draaw_bsdf import LIVE_INSTANCES
    ms = scene.mi_scene
    own = {id(sh.bsdf()) for sh in ms.shapes()}
    assert F.other_live_bsdfs(ms, session_of(scene)) == F.other_live_bsdfs(ms)
    extra = mi.load_dict({"type": "draaw", "roughness": 0.4})
    with_extra = F.other_live_bsdfs(ms, session_of(scene))
    assert with_extra == F.other_live_bsdfs(ms) and any(b is extra for b in with_extra)
    assert not any(id(b) in own for b in with_extra)
    del extra, with_extra
    gc.collect()
    assert F.other_live_bsdfs(ms, session_of(scene)) == F.other_live_bsdfs(ms)
    mine = sum(1 for b in LIVE_INSTANCES if id(b) in own)
    assert len(F.other_live_bsdfs(ms, session_of(scene))) == len(LIVE_INSTANCES) - mine


def test_a_bare_mitsuba_scene_rendered_again_replays(monkeypatch):
    """render(mi_scene) wraps the Mitsuba scene in the same DraawScene each time, so a
    repeated small render replays its recording (a new wrapper per call recorded anew: 28 ms
    against 6.5 ms a call at 16x16)."""
    calls = []
    real = mi.render
    monkeypatch.setattr(mi, "render", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    monkeypatch.setattr(S, "FREEZE", True)
    mi_scene = draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4)).mi_scene
    assert draaw_mi.load_scene(mi_scene) is draaw_mi.load_scene(mi_scene)
    first = [np.array(draaw_mi.render(mi_scene, version="v4", spp=4, seed=s, post=[])) for s in (1, 2)]
    n = len(calls)
    again = np.array(draaw_mi.render(mi_scene, version="v4", spp=4, seed=1, post=[]))
    assert n >= 1 and len(calls) == n and np.array_equal(again, first[0])


def test_release_wrapped_lets_go_of_bare_mitsuba_scenes():
    """load_scene keeps the wrappers of recent bare mi.Scenes, and with them the scenes (their
    materials then enlarge every later kernel's BSDF calls); release_wrapped lets them go."""
    import gc
    from draaw_mi.materials.draaw_bsdf import LIVE_INSTANCES
    from draaw_mi.scene.loading import release_wrapped
    release_wrapped()
    gc.collect()
    before = len(list(LIVE_INSTANCES))
    mi_scene = draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4)).mi_scene
    wrapper = draaw_mi.load_scene(mi_scene)
    assert draaw_mi.load_scene(mi_scene) is wrapper
    draaw_mi.render(mi_scene, version="v4", spp=1, seed=1, post=[])
    del mi_scene, wrapper
    gc.collect()
    assert len(list(LIVE_INSTANCES)) > before             # kept by the wrapper cache
    release_wrapped()
    gc.collect()
    assert len(list(LIVE_INSTANCES)) == before


def _counting_renders(monkeypatch) -> list:
    """mi.render wrapped to count its calls: one per traced or recorded pass, none per replay."""
    calls = []
    real = mi.render
    monkeypatch.setattr(mi, "render", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    return calls


def _scene_made_and_let_go():
    """A scene loaded and freed (its objects in and out of Dr.Jit's registry)."""
    from conftest import tiny_description
    other = draaw_mi.load_scene(tiny_description(resolution=[8, 8]))
    del other


@pytest.mark.filterwarnings("error::RuntimeWarning")     # (no fallback to tracing for good)
def test_a_recording_made_before_scenes_changed_is_made_anew(scene, monkeypatch, no_collections):
    """A recording replayed after a scene was let go and another loaded can call the freed
    scene's objects (a notebook beside a preview re-running "scene = load_scene(...)"
    segfaulted): once scenes are made or let go, the next pass records anew, then replays."""
    from draaw_mi import guard
    calls = _counting_renders(monkeypatch)
    _record_afresh(scene, monkeypatch)
    session = session_of(scene)
    integ = session.integrator("v4", 3)
    first = [np.array(session.render_pass(integ, 1, s, freeze=True)) for s in range(4)]
    n = len(calls)                         # (one or two recordings, then replays)
    np.array(session.render_pass(integ, 1, 0, freeze=True))
    assert len(calls) == n
    before = guard.registry_changes()
    _scene_made_and_let_go()
    assert guard.registry_changes() == before + 2            # (made, let go)
    again = [np.array(session.render_pass(integ, 1, s, freeze=True)) for s in range(4)]
    assert len(calls) == n + 1                               # recorded anew once
    assert all(np.array_equal(a, b) for a, b in zip(again, first))


def test_a_background_render_records_anew_when_free_and_traces_beside_a_call(scene, monkeypatch, no_collections):
    """A preview's worker (``background``) replays a recording only while no scene was made or
    let go and no other thread began a draaw-mi call since it was made (Dr.Jit 1.5 crashed
    replaying after one); while another thread is inside such a call it traces, and once that
    call is over it records anew and replays again. Same image throughout."""
    import threading

    from draaw_mi import guard
    calls = _counting_renders(monkeypatch)
    _record_afresh(scene, monkeypatch)
    session = session_of(scene)
    integ = session.integrator("v4", 3)
    replayed = [np.array(session.render_pass(integ, 1, 5, freeze=True, background=True)) for _ in range(3)]
    n = len(calls)
    np.array(session.render_pass(integ, 1, 5, freeze=True, background=True))
    assert len(calls) == n                                   # replayed
    _scene_made_and_let_go()
    again = [np.array(session.render_pass(integ, 1, 5, freeze=True, background=True)) for _ in range(2)]
    assert len(calls) == n + 1                               # recorded anew, replayed
    inside, done = threading.Event(), threading.Event()

    def a_call():
        with guard.FOREGROUND:
            inside.set()
            done.wait(10)
    t = threading.Thread(target=a_call)
    t.start()
    inside.wait(10)
    traced = [np.array(session.render_pass(integ, 1, 5, freeze=True, background=True)) for _ in range(2)]
    assert len(calls) == n + 3                               # beside the call: traced
    done.set()
    t.join(10)
    after = [np.array(session.render_pass(integ, 1, 5, freeze=True, background=True)) for _ in range(2)]
    assert len(calls) == n + 4                               # recorded anew, replayed
    assert all(np.allclose(x, replayed[0], rtol=1e-5, atol=1e-6) for x in again + traced + after)


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("refused_in_background", [False, True])
def test_a_replay_refused_for_a_changed_registry_records_anew(scene, monkeypatch, refused_in_background, no_collections):
    """Mitsuba objects made or freed outside draaw-mi (a plain ``mi.load_dict``) change the
    registry without draaw-mi knowing; Dr.Jit then refuses the replay ('The number of registry
    entries ... did not match'), seen beside a preview. That pass records anew, without a
    warning, instead of tracing for good; a preview's worker traces from then on."""
    real = F.dr.freeze
    refusals, replays = [], []

    def refusing_once(fn, **options):
        frozen = real(fn, **options)

        def call(*a, **k):
            if not refusals:
                refusals.append(1)
                raise RuntimeError("assign_with_registry(): The number of registry entries (3) did not "
                                   "match the number of registry entries recorded (6)!")
            replays.append(1)
            return frozen(*a, **k)
        call.clear, call.n_recordings = frozen.clear, 0
        return call
    monkeypatch.setattr(F.dr, "freeze", refusing_once)
    calls = _counting_renders(monkeypatch)
    _record_afresh(scene, monkeypatch)
    session = session_of(scene)
    integ = session.integrator("v4", 3)
    if refused_in_background:
        np.array(session.render_pass(integ, 1, 0, freeze=True, background=True))
        assert refusals == [1] and len(calls) == 1 and not replays      # refused, traced
    images = [np.array(session.render_pass(integ, 1, s, freeze=True)) for s in range(5)]
    n = len(calls)
    np.array(session.render_pass(integ, 1, 0, freeze=True))
    assert refusals == [1] and len(calls) == n               # refused, recorded, replayed
    np.array(session.render_pass(integ, 1, 0, freeze=True, background=True))
    assert len(calls) == n + 1                               # a preview's worker traces
    monkeypatch.setattr(S, "FREEZE", False)
    traced = np.array(session.render_pass(integ, 1, 4, freeze=True))
    assert np.allclose(images[4], traced, rtol=1e-5, atol=1e-6)


THREAD_COUNTS = """
import draaw_mi, drjit as dr, numpy as np
dr.set_thread_count(2)
scene = draaw_mi.load_scene("scenes/fit_sphere.toml", resolution=(16, 16), spp=4)
images = []
for n in (2, 1, 2):
    dr.set_thread_count(n)
    images.append(np.array(draaw_mi.render(scene, version="v1", spp=8, seed=3, post=[])))
print("ok", all(np.array_equal(images[0], i) for i in images))
"""


def test_a_thread_count_changed_between_renders_records_anew(scene, monkeypatch, no_collections):
    """Dr.Jit's recorder records anew after ``dr.set_thread_count`` and, back at the first
    count, replays the first recording: that replay crashed Dr.Jit 1.5 (2 -> 1 -> 2 threads: a
    segmentation fault, 3 runs in 3). A changed count records anew, and the images stay the
    same. The crash in a child process; the recordings counted here."""
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", THREAD_COUNTS], cwd=root, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.split() == ["ok", "True"], out.stderr[-2000:]

    calls = _counting_renders(monkeypatch)
    _record_afresh(scene, monkeypatch)
    session = session_of(scene)
    integ = session.integrator("v4", 3)
    before = dr.thread_count()
    try:
        first = [np.array(session.render_pass(integ, 1, s, freeze=True)) for s in range(3)]
        n = len(calls)
        dr.set_thread_count(before + 1)
        again = np.array(session.render_pass(integ, 1, 0, freeze=True))
        assert len(calls) == n + 1                           # recorded anew
        fn = session.recordings[(id(integ), 1)]
        assert fn.frozen.n_recordings == 1                   # the old recording let go
    finally:
        dr.set_thread_count(before)
    assert np.array_equal(again, first[0])
