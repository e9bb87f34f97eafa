"""render(): passes, seeds, time budget, progress, overrides and clear errors."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.rendering.passes import pass_seeds


def test_same_seed_same_image(tiny_scene):
    a = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, seed=5))
    b = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, seed=5))
    c = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, seed=6))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_single_pass_equals_mitsuba(tiny_scene):
    ours = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, seed=2, max_depth=4))
    ref = np.array(mi.render(tiny_scene.mi_scene, integrator=mi.load_dict({"type": "path", "max_depth": 4}),
                             spp=8, seed=2))
    assert np.array_equal(ours, ref)


def test_passes_are_a_true_mean_of_independent_passes(tiny_scene):
    integ = mi.load_dict({"type": "path", "max_depth": 4})
    seeds = pass_seeds(11, 4)
    assert len(set(seeds)) == 4
    manual = sum(np.array(mi.render(tiny_scene.mi_scene, integrator=integ, spp=4, seed=s)) for s in seeds) / 4
    ours, info = draaw_mi.render(tiny_scene, version="path", spp=16, pass_spp=4, seed=11, return_info=True)
    assert info["spp"] == 16 and info["passes"] == 4
    assert np.allclose(np.array(ours), manual, rtol=1e-6, atol=1e-7)


def test_uneven_passes_are_weighted_by_spp(tiny_scene):
    """10 spp in passes of 4, 4, 2: the image is (4 a + 4 b + 2 c) / 10 of the three passes
    rendered by Mitsuba with the per-pass seeds (an unweighted mean would give c weight 1/3)."""
    img, info = draaw_mi.render(tiny_scene, version="path", spp=10, pass_spp=4, seed=3, return_info=True)
    assert info["spp"] == 10 and info["passes"] == 3
    integ = mi.load_dict({"type": "path", "max_depth": 4})
    seeds = pass_seeds(3, 3)
    passes = [np.array(mi.render(tiny_scene.mi_scene, integrator=integ, spp=n, seed=s))
              for n, s in zip((4, 4, 2), seeds)]
    manual = (4 * passes[0] + 4 * passes[1] + 2 * passes[2]) / 10
    unweighted = sum(passes) / 3
    assert np.abs(manual - unweighted).max() > 1e-3       # the test can tell the two apart
    assert np.allclose(np.array(img), manual, rtol=1e-6, atol=1e-7)


def test_time_budget_stops_early_but_renders_one_pass(tiny_scene):
    img, info = draaw_mi.render(tiny_scene, version="path", spp=4096, pass_spp=4, time_budget=1e-6,
                                return_info=True)
    assert info["spp"] == 4 and np.isfinite(np.array(img)).all()


def test_a_time_budget_of_the_most_samples_lists_its_passes_as_it_goes(tiny_scene, monkeypatch):
    """spp = 2^32 - 1 with a time budget ("as many as fit"): the passes are listed 4096 at a
    time (listed up front in passes of 16, 4e9 spp took 1.4 GB and the whole budget before a
    pass rendered); the image is the mean of the passes done, as with a small spp; one more
    sample is refused by name (Mitsuba counts samples in 32 bits)."""
    from draaw_mi.rendering.session import Session
    asked = []
    real = Session.sample_passes

    def spy(self, spp, pass_spp, sensor=0):
        asked.append(spp)
        assert spp <= 16 * 4096, f"sample_passes asked for {spp} spp at once"
        return real(self, spp, pass_spp, sensor)
    monkeypatch.setattr(Session, "sample_passes", spy)
    img, info = draaw_mi.render(tiny_scene, version="path", spp=2 ** 32 - 1, time_budget=1e-6, seed=3,
                                return_info=True)
    assert asked == [16 * 4096] and info["spp"] == 16 and info["passes"] == 1
    one = draaw_mi.render(tiny_scene, version="path", spp=16, seed=3)
    assert np.array_equal(np.array(img), np.array(one))
    with pytest.raises(draaw_mi.RenderError, match=r"render: spp=4294967296; expected an integer in \[1, 4294967295\]"):
        draaw_mi.render(tiny_scene, version="path", spp=2 ** 32, time_budget=1.0)


def test_progress_bar_does_not_change_the_image(tiny_scene, capsys):
    a = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, pass_spp=4, progress=True))
    b = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, pass_spp=4))
    assert np.array_equal(a, b)


def test_progress_does_not_change_the_pass_layout(tiny_scene, monkeypatch, capsys):
    """With the default pass_spp a bar used to make 16-spp passes and no bar one pass: other
    seeds, another image from the same call, and no adaptive sampling for V4 under a bar
    (``stratify`` off: stratified, V4 renders uniformly)."""
    a = np.array(draaw_mi.render(tiny_scene, version="path", spp=48, progress=True))
    b = np.array(draaw_mi.render(tiny_scene, version="path", spp=48, progress=False))
    assert np.array_equal(a, b)
    from draaw_mi.integrators import adaptive_sampling as ads
    calls, real = [], ads.render_adaptive
    monkeypatch.setattr(ads, "render_adaptive", lambda *a, **k: calls.append(a[4]) or real(*a, **k))
    draaw_mi.render(tiny_scene, version="v4", spp=64, progress="lines", integrator_options={"stratify": False})
    assert calls == [64]


def test_differentiable_render_through_api(tiny_scene):
    params = tiny_scene.params
    key = tiny_scene.key("ball.base_color")
    dr.enable_grad(params[key])
    params.update()
    img = draaw_mi.render(tiny_scene, version="prb", spp=4, params=params)
    dr.backward(dr.mean(img, axis=None))
    g = np.array(dr.grad(params[key]))
    assert np.isfinite(g).all() and (g > 0).all()
    dr.disable_grad(params[key])


@pytest.mark.parametrize("kwargs,msg", [
    ({"spp": 0}, "spp=0"), ({"spp": 2.5}, "spp=2.5"), ({"seed": -1}, "seed=-1"),
    ({"version": "v9"}, "v9"), ({"time_budget": -1}, "time_budget"), ({"max_depth": -2}, "max_depth"),
    ({"resolution": "0x5"}, "out of range"),
    ({"seed": 2 ** 32}, r"seed=4294967296; expected an integer in \[0, 4294967295\]"),   # (a raw Dr.Jit error)
])
def test_bad_render_arguments(tiny_scene, kwargs, msg):
    with pytest.raises(draaw_mi.DraawError, match=msg):
        draaw_mi.render(tiny_scene, **kwargs)
