"""Session.gradient_pass: one differentiable pass (render, loss, backward), replayed from a
dr.freeze recording or traced, with the same loss and gradients either way."""
from __future__ import annotations

import drjit as dr
import numpy as np
import pytest

import draaw_mi
from draaw_mi.fitting.problem import PassLoss
from draaw_mi.fitting.views import view_sensors
from draaw_mi.rendering.frozen import owned_tensor
from draaw_mi.rendering.session import session_of

#: two cameras that see the softbox's edge, each from its side; the scene's own sees none of it
CAMERAS = [{"origin": [1.2, 0.0, 3.0], "target": [0.3, 0.0, 0.0], "fov": 50},
           {"origin": [-1.2, 0.4, 3.0], "target": [-0.3, 0.2, 0.0], "fov": 50}]


def softbox_tile(rfilter: str) -> dict:
    """A tile with 8x8 maps, a softbox (area light) at the frame's edge, a dim sky: 32x32."""
    rng = np.random.default_rng(5)
    return {"render": {"resolution": [32, 32], "spp": 4, "max_depth": 3, "filter": rfilter},
            "camera": {"origin": [0, -3.0, 0.5], "target": [0, 0, 0], "fov": 20},
            "materials": {"m": {"base_color": rng.uniform(0.2, 0.8, (8, 8, 3)).tolist(),
                                "roughness": rng.uniform(0.2, 0.7, (8, 8)).tolist(), "metallic": 0.3}},
            "shapes": [{"type": "rectangle", "material": "m", "name": "tile"}],
            "lights": [{"type": "area", "name": "box", "shape": "rectangle", "position": [0.0, 1.1, 0.6],
                        "target": [0, 0, 0], "size": [0.8, 0.5], "intensity": 6.0},
                       {"type": "constant", "name": "sky", "intensity": 0.2}]}


@pytest.mark.parametrize("rfilter", ["box", "gaussian"])
def test_a_replayed_gradient_pass_gives_the_traced_loss_and_gradients(rfilter):
    """Passes from two cameras in turn, new texture values each time: the replayed loss and
    base-colour gradient against the traced pass's, same seed: the same random numbers, so equal
    to float rounding. At most two recordings per camera: the camera is an input, not re-traced.
    Catches a replay given the scene camera's emission-splitting edge map instead of its own
    camera's (V4's freeze_state without the sensor), a replay that keeps the first
    recording's texture, a backward pass left out of the recording."""
    scene = draaw_mi.load_scene(softbox_tile(rfilter))
    session = session_of(scene)
    integrator = session.integrator("v4", 3)
    sensors = view_sensors(scene, CAMERAS)
    p = scene.params
    key = scene.key("m.base_color")
    ref = owned_tensor(np.full((32, 32, 3), 0.15, np.float32))
    loss = PassLoss("l2", "fixed", 1.0)
    import warnings
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        _passes_both_ways(session, integrator, sensors, p, key, ref, loss)
    assert not [w for w in said if "could not record" in str(w.message)], [str(w.message) for w in said]
    counts = [r.frozen.n_recordings for k, r in session.recordings.items() if k[0] == "gradient"]
    assert len(counts) == 1 and 1 <= counts[0] <= 2 * len(CAMERAS), counts


def _passes_both_ways(session, integrator, sensors, p, key, ref, loss):
    """Six gradient passes alternating two cameras, each traced and then frozen: the same
    loss and texture gradient."""
    for i, v in enumerate([0, 1, 0, 1, 0, 1]):
        out = {}
        for freeze in (False, True):
            t = owned_tensor(np.full((8, 8, 3), 0.2 + 0.1 * i, np.float32))
            dr.enable_grad(t)
            p[key] = t
            p.update()
            value, _ = session.gradient_pass(integrator, 4, 10 + i, loss, params=p, sensor=sensors[v],
                                             inputs=(ref, None, None, None), freeze=freeze)
            out[freeze] = float(value[0]), np.array(dr.grad(t))
        (traced, g_traced), (frozen, g_frozen) = out[False], out[True]
        assert np.abs(g_traced).max() > 0, "no gradient reached the texture"
        assert frozen == pytest.approx(traced, rel=1e-5), (i, v)
        np.testing.assert_allclose(g_frozen, g_traced, rtol=0, atol=1e-5 * np.abs(g_traced).max())


def test_a_gradient_pass_is_traced_where_the_scene_cannot_be_recorded(monkeypatch):
    """freeze=False (a fit with a post chain) and a scene that cannot be recorded trace the
    pass: no recording is made, and the gradient still arrives."""
    from draaw_mi.rendering import session as S
    monkeypatch.setattr(S, "FREEZE", False)
    scene = draaw_mi.load_scene(softbox_tile("box"))
    session = session_of(scene)
    t = owned_tensor(np.full((8, 8, 3), 0.5, np.float32))
    dr.enable_grad(t)
    scene.params[scene.key("m.base_color")] = t
    scene.params.update()
    value, _ = session.gradient_pass(session.integrator("v4", 3), 4, 1, PassLoss("l2", "fixed", 1.0),
                                     params=scene.params, sensor=scene.mi_scene.sensors()[0],
                                     inputs=(owned_tensor(np.zeros((32, 32, 3), np.float32)), None, None, None))
    assert float(value[0]) > 0 and np.abs(np.array(dr.grad(t))).max() > 0
    assert not any(k[0] == "gradient" for k in session.recordings)


def _one_pass(scene, session, seed=3, spp=4, freeze=True, **options):
    """The base-colour gradient of one pass from the scene's camera (a new texture each call;
    ``options``: V4's)."""
    t = owned_tensor(np.full((8, 8, 3), 0.5, np.float32))
    dr.enable_grad(t)
    scene.params[scene.key("m.base_color")] = t
    scene.params.update()
    value, _ = session.gradient_pass(session.integrator("v4", 3, **options), spp, seed, PassLoss("l2", "fixed", 1.0),
                                     params=scene.params, sensor=scene.mi_scene.sensors()[0],
                                     inputs=(owned_tensor(np.zeros((32, 32, 3), np.float32)), None, None, None),
                                     freeze=freeze)
    return float(value[0]), np.array(dr.grad(t))


def test_a_recording_that_fails_after_its_backward_pass_counts_the_gradient_once(monkeypatch):
    """A recording that fails once its backward pass has begun is traced again (with a
    warning); the gradients it left are put back first. Catches the retry adding the pass's
    gradient a second time (twice the traced gradient)."""
    from draaw_mi.rendering import frozen as F
    scene = draaw_mi.load_scene(softbox_tile("box"))
    session = session_of(scene)
    _, traced = _one_pass(scene, session, freeze=False)

    def failing(fn, **options):
        def frozen(*args, **kwargs):
            fn(*args, **kwargs)                  # the pass, its backward included: then a failure
            raise RuntimeError("record(): stand-in failure after the backward pass")
        return frozen
    monkeypatch.setattr(F.dr, "freeze", failing)
    with pytest.warns(RuntimeWarning, match="traced from now on"):
        _, retried = _one_pass(scene, session)
    assert np.abs(traced).max() > 0
    np.testing.assert_allclose(retried, traced, rtol=0, atol=1e-5 * np.abs(traced).max())


def test_adaptive_passes_are_traced():
    """V4 without ``stratify`` renders a pass of 64 spp or more adaptively (its pilot is read
    back, which a recording cannot hold): such a gradient pass is traced, as the fit traced
    it before recordings, and makes no recording. Catches a recording that would render
    those passes uniformly, a different estimator than the traced fit's. Stratified (V4's
    default on this independent-sampler scene) the 64-spp pass is uniform and recorded."""
    scene = draaw_mi.load_scene(softbox_tile("box"))
    session = session_of(scene)
    _one_pass(scene, session, spp=64, stratify=False)
    assert not any(k[0] == "gradient" for k in session.recordings)
    _one_pass(scene, session, spp=16, stratify=False)
    assert any(k[0] == "gradient" for k in session.recordings)
    stratified = session.integrator("v4", 3)
    _one_pass(scene, session, spp=64)
    assert any(k[0] == "gradient" and k[1] == id(stratified) and k[2] == 64 for k in session.recordings)


def test_an_owned_tensor_holds_the_array_as_it_was_when_the_call_returned():
    """``dr.eval`` only queues a kernel on the CPU backend: behind a long kernel still
    running, ``owned_tensor``'s copy read the numpy array after the caller had changed it
    (every time without the wait for the copy)."""
    import mitsuba as mi
    for i in range(5):
        x = dr.arange(mi.Float, 4_000_000) + i
        busy = dr.sin(x) * dr.cos(0.5 * x) + dr.sqrt(x + 1.0)
        dr.eval(busy)                                   # queued, still running below
        a = np.ones((32, 32, 1), np.float32)
        t = owned_tensor(a)
        a[:] = 7.0
        assert np.array(t).max() == 1.0, i
