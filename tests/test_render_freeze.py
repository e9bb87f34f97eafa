"""Frozen small renders (draaw_mi.render: dr.freeze of mi.render, the seed an opaque value)."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import importlib
R = importlib.import_module("draaw_mi.render")    # the module (draaw_mi.render is the function)
import mitsuba as mi

from draaw_mi.integrators import reference_scenes as rs


@pytest.fixture(scope="module")
def scene():
    return draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))


@pytest.mark.parametrize("version", ["v1", "v4"])
def test_frozen_render_replays_without_tracing(scene, version, monkeypatch):
    calls = []
    real = mi.render

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(mi, "render", counting)
    monkeypatch.setattr(R, "FREEZE", True)
    imgs = [np.array(draaw_mi.render(scene, version=version, spp=4, seed=s, post=[])) for s in (5, 6, 7)]
    n = len(calls)
    again = np.array(draaw_mi.render(scene, version=version, spp=4, seed=5, post=[]))
    other = np.array(draaw_mi.render(scene, version=version, spp=4, seed=8, post=[]))
    assert len(calls) == n                      # replayed: the Python integrator was not traced
    assert np.array_equal(again, imgs[0])       # same seed, same image
    assert not np.allclose(other, imgs[0])      # the opaque seed still changes the samples
    monkeypatch.setattr(R, "FREEZE", False)
    traced = np.array(draaw_mi.render(scene, version=version, spp=4, seed=5, post=[]))
    assert np.allclose(traced, imgs[0], rtol=1e-5, atol=1e-6)


def test_frozen_render_sees_parameter_changes(scene, monkeypatch):
    monkeypatch.setattr(R, "FREEZE", True)
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


def test_large_or_many_spp_renders_are_not_frozen(scene):
    assert R.freeze_eligible(scene.mi_scene, 16)
    assert not R.freeze_eligible(scene.mi_scene, 32)
    big = scene.with_resolution(256, 256)
    assert not R.freeze_eligible(big.mi_scene, 4)


def test_frozen_v4_many_lights_and_constant_sky(monkeypatch):
    """V4's scene-dependent choices work while dr.freeze records: the constant-sky detection
    reads flags only; the power table is not used in frozen renders (uniform selection, which
    has the same expectation: compared with a traced render over seeds)."""
    from draaw_mi import speed_suite as ss
    monkeypatch.setattr(R, "FREEZE", True)
    for name in ("many_lights", "constant_env"):
        scene = draaw_mi.load_scene(ss.build(name, 16, spp=4))
        a = np.mean([np.array(draaw_mi.render(scene, version="v4", spp=16, seed=s, post=[],
                                               max_depth=3)) for s in range(12)], 0)
        monkeypatch.setattr(R, "FREEZE", False)
        b = np.mean([np.array(draaw_mi.render(scene, version="v4", spp=16, seed=100 + s, post=[],
                                               max_depth=3)) for s in range(12)], 0)
        monkeypatch.setattr(R, "FREEZE", True)
        assert np.isfinite(a).all() and a.mean() > 0
        # image means agree within a few standard errors (256 px x 192 spp each)
        assert abs(a.mean() / b.mean() - 1.0) < 0.03, (name, a.mean(), b.mean())
