"""fit(polish=N): a second run from the first's values at more samples per pixel
(:mod:`draaw_mi.fitting.polish`). Its accuracy gain is measured at 128x128 by
benchmarks/fit_accuracy.py (``--polish``); these 32x32 tests check what it does."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.errors import ParameterError
from draaw_mi.fitting.polish import POLISH_LR, joined
from draaw_mi.fitting.result import FitResult

from conftest import SCENES

RES = 32
P = ["target.roughness", "target.metallic"]
START = {"target.roughness": 0.5, "target.metallic": 0.5}


@pytest.fixture(scope="module")
def scene_and_ref():
    scene = draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(RES, RES))
    p = scene.params
    p["target.roughness.value"], p["target.metallic.value"] = 0.25, 0.8
    p.update()
    ref = np.array(draaw_mi.render(scene, version="path", spp=1024, seed=1234))
    return scene, ref


def test_the_polish_continues_from_the_fit_at_more_spp_and_a_constant_smaller_rate(scene_and_ref):
    """30 iterations at 4 spp, then 12 at 32 spp. Each check names what it catches:
    * the polish's rate is ``POLISH_LR * lr`` in every iteration (``lr_final`` left at 0.1, or
      the full ``lr``, fails);
    * its first iterate is one Adam step (at most its rate, in log roughness and in metallic)
      from the first run's averaged values (a polish restarted from ``init`` = 0.5 fails:
      0.25 / 0.8 is 0.69 in log roughness and 0.3 in metallic away);
    * its losses are below half of the first run's last ones: near the optimum the l2 loss is
      mostly the render's variance, spp 4 -> 32 divides it by 8 (the polish at the fit's spp
      fails: measured ratio about 1);
    * the scene holds the polish's averaged values (the first run's left in it fails)."""
    scene, ref = scene_and_ref
    lr, its, n = 0.05, 30, 12
    res = draaw_mi.fit(scene, ref, P, spp=4, iterations=its, lr=lr, init=START, polish=n, polish_spp=32,
                       progress=False, seed=5)
    assert res.iterations == its + n and len(res.history) == its + n
    assert [(st["stage"], st["iterations"], st["spp"]) for st in res.stages] == [("fit", its, 4), ("polish", n, 32)]
    assert [h["lr"] for h in res.history[its:]] == pytest.approx([POLISH_LR * lr] * n)
    last = res.history[its - max(1, round(0.25 * its)):its]        # the first run's averaged iterates
    first_r = np.mean([h["values"]["target.roughness"] for h in last])
    first_m = np.mean([h["values"]["target.metallic"] for h in last])
    r0, m0 = res.history[its]["values"]["target.roughness"], res.history[its]["values"]["target.metallic"]
    step = POLISH_LR * lr * 1.05
    assert abs(np.log(r0 / first_r)) <= step and abs(m0 - first_m) <= step, (r0, first_r, m0, first_m)
    assert np.mean(res.losses[its:]) < 0.5 * np.mean(res.losses[its - 10:its])
    polished = res.history[-max(1, round(0.25 * n)):]
    assert res.values["target.roughness"] == pytest.approx(np.mean([h["values"]["target.roughness"] for h in polished]))
    assert float(np.array(scene.params["target.roughness.value"]).ravel()[0]) == pytest.approx(
        res.values["target.roughness"], rel=1e-6)
    assert abs(res.values["target.roughness"] - 0.25) < 0.03 and abs(res.values["target.metallic"] - 0.8) < 0.06


@pytest.mark.parametrize("kw,expected", [({"polish": -1}, "polish=-1; expected an integer >= 0"),
                                         ({"polish": 2.5}, "polish=2.5; expected an integer >= 0"),
                                         ({"polish": 3, "polish_spp": 0}, "polish_spp=0; expected an integer >= 1")])
def test_bad_polish_arguments_are_refused_before_any_render(scene_and_ref, kw, expected, monkeypatch):
    """Refused by the settings' check, before the fit is set up (a set-up fails the test); with
    the check gone, ``polish=-1`` would reach a polish of -1 iterations and fail there, named
    ``iterations``, after a whole fit."""
    def no_set_up(*args, **kwargs):
        raise AssertionError("fit set up (and would render) before refusing its arguments")
    monkeypatch.setattr("draaw_mi.fitting.fitter._set_up", no_set_up)
    scene, ref = scene_and_ref
    with pytest.raises(ParameterError, match=expected):
        draaw_mi.fit(scene, ref, P, iterations=1, progress=False, **kw)


def test_cli_polish_prints_both_stages(tmp_path, scene_and_ref, capsys):
    """``--polish N`` reaches fit(): the stage lines name the polish's iterations and spp
    (8x --spp); the flag dropped, no polish line is printed."""
    _, ref = scene_and_ref
    path = str(tmp_path / "ref.exr")
    draaw_mi.write_exr(path, ref)
    assert main(["fit", os.path.join(SCENES, "fit_sphere.toml"), "--reference", path, "--param", "target.metallic",
                 "--iterations", "3", "--spp", "2", "--polish", "2", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "fit: 3 iterations at 2 spp" in out and "polish: 2 iterations at 16 spp" in out, out
    assert "in 5 iterations" in out


def _run(n, value, lr, iterations=None):
    return FitResult(values={"m": value}, iterations=iterations or n, seconds=1.0, converged=False,
                     history=[{"loss": 1.0, "lr": lr, "values": {"m": value}, "latent": {"m": value}}] * n)


def test_joined_runs_judge_convergence_on_the_whole_history_and_name_each_runs_samples():
    """A settled 40-iteration fit and a 6-iteration polish (too short alone to judge: settled
    needs 16 iterations) converge together: ``joined`` keeping the polish's own verdict
    (False) fails. Each stage carries its run's spp, and spp_grad only where one was given."""
    out = joined(_run(40, 0.3, 0.05), _run(6, 0.3, 0.02), (16, None), (128, 64), 0.0, 5e-3)
    assert out.converged and out.iterations == 46 and len(out.history) == 46
    assert out.stages == [{"stage": "fit", "iterations": 40, "spp": 16, "seconds": 1.0},
                          {"stage": "polish", "iterations": 6, "spp": 128, "seconds": 1.0, "spp_grad": 64}]
    assert not joined(_run(40, 0.3, 0.05), _run(6, 0.4, 0.02), (16, None), (128, None), 0.0, 5e-3).converged


def test_a_polished_map_fit_renders_every_capture_in_each_polish_iteration():
    """With ``batch=1`` of 4 captures the fit renders one capture an iteration; its polish
    renders all four (a batched polish could miss a capture, and its fill of the texels it did
    not see would overwrite what the fit fitted there): ``batch`` passed on to the polish fails."""
    from test_fit_captures import MAPS, path_renders, start_scene, tile, tile_captures, TRUTH_C, TRUTH_M, TRUTH_R
    caps = tile_captures()
    refs = path_renders(draaw_mi.load_scene(tile(TRUTH_C, TRUTH_R, TRUTH_M)), caps, spp=64)
    res = draaw_mi.fit(start_scene(), refs, MAPS, captures=caps, batch=1, iterations=4, polish=2, spp=2,
                       progress=False, seed=1)
    assert [len(h["views"]) for h in res.history] == [1] * 4 + [4] * 2
    assert [st["spp"] for st in res.stages] == [2, 16]
    assert all(np.isfinite(np.asarray(v)).all() for v in res.values.values())
