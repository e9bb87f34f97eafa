"""The SDF part of `draaw-mi bench`: tracer settings -> time, tracer error, false misses."""
from __future__ import annotations

import json
import os

import pytest

import draaw_mi
from draaw_mi.bench.sdf_study import run_sdf_study

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_sdf_study_reports_false_misses_and_error(tmp_path):
    scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "sdf_csg.toml"), resolution=(40, 24))
    settings = [{"sdf_epsilon": 1e-5, "sdf_max_steps": 4, "sdf_relaxation": 1.0},
                {"sdf_epsilon": 1e-6, "sdf_max_steps": 4096, "sdf_relaxation": 1.0},
                {"sdf_epsilon": 1e-5, "sdf_max_steps": 256, "sdf_relaxation": 1.5}]
    r = run_sdf_study(scene, str(tmp_path), settings=settings, spp=2, repeats=1)
    rows = r["rows"]
    assert rows[0]["false_miss_share"] > 0.05 and rows[0]["rmse"] > rows[2]["rmse"]
    assert rows[1]["false_miss_share"] == 0.0 and rows[1]["rmse"] < 1e-6     # = the reference
    assert rows[2]["false_miss_share"] == 0.0
    for ext in (".json", ".csv", ".md"):
        assert os.path.isfile(tmp_path / f"sdf_study_sdf_csg{ext}")
    assert os.path.isfile(tmp_path / "sdf_error_vs_time_sdf_csg.png")
    assert json.loads((tmp_path / "sdf_study_sdf_csg.json").read_text())["sdf_rays"] > 50


def test_sdf_study_bookkeeping_over_repeats(monkeypatch, tmp_path):
    """Three repeats with the renders, the camera march and the clock stubbed (no rendering):
    each repeat is compared with the reference of its own seed (common random numbers: the
    noise cancels, the RMSE is the setting's offset, 0 or 0.1; the first repeat's reference
    left the noise in), the time is the median of the repeats (not the fastest), and the
    false misses are a share of the rays the reference tracer saw hit an SDF (2 of 8, not of
    all 40 camera rays)."""
    import types

    import numpy as np

    import draaw_mi.bench.sdf_study as st
    clock = [0.0]
    # timed renders' durations by (iteration cap, seed): seeds 11, 18, 25 are the repeats
    durations = {(4096, 11): 3.0, (4096, 18): 1.0, (4096, 25): 2.0,
                 (16, 11): 9.0, (16, 18): 5.0, (16, 25): 7.0}

    def fake_render(scene, opts, spp, seed):
        if seed != 1 and opts is not st.REFERENCE:            # warm-ups and references: untimed
            clock[0] += durations[(opts["sdf_max_steps"], seed)]
        noise = np.random.default_rng(seed).random((4, 10, 3))
        return noise + (0.0 if opts["sdf_max_steps"] >= 4096 else 0.1)
    hit_ref = np.zeros(40, bool)
    hit_ref[:8] = True                                         # 8 of the 40 camera rays hit

    def fake_march(scene, opts):
        hit = hit_ref.copy()
        if opts["sdf_max_steps"] < 4096:
            hit[:2] = False                                    # 2 false misses
        return hit, np.full(40, 5.0)
    monkeypatch.setattr(st, "_render", fake_render)
    monkeypatch.setattr(st, "camera_march", fake_march)
    monkeypatch.setattr(st, "time", types.SimpleNamespace(perf_counter=lambda: clock[0]))
    monkeypatch.setattr(st, "plot", lambda result, path: None)     # (the figure is not checked)
    scene = types.SimpleNamespace(source="stub.toml", resolution=(10, 4))
    settings = [dict(st.REFERENCE), {"sdf_epsilon": 1e-5, "sdf_max_steps": 16, "sdf_relaxation": 1.0}]
    rows = run_sdf_study(scene, str(tmp_path), settings=settings, spp=2, repeats=3)["rows"]
    assert [r["rmse"] for r in rows] == [0.0, pytest.approx(0.1, rel=1e-9)]
    assert [r["time_s"] for r in rows] == [2.0, 7.0]           # medians of (3, 1, 2) and (9, 5, 7)
    assert [r["false_miss_share"] for r in rows] == [0.0, 2 / 8]
    assert [r["false_miss_rays"] for r in rows] == [0, 2]


def test_cli_bench_sends_sdf_scenes_to_the_tracer_study(monkeypatch, tmp_path, capsys):
    """`draaw-mi bench` runs the tracer study on [[sdf]] scenes (Mitsuba's path, the main
    study's ground truth, cannot see SDFs) and the main study on the others."""
    import draaw_mi.bench.study as bench
    import draaw_mi.cli.bench as study            # the module that runs the SDF study
    from draaw_mi.cli import main
    calls = {"sdf": [], "main": []}

    def fake_sdf(scene, out, **kw):
        calls["sdf"].append(os.path.basename(scene.source))
        return {"scene": "sdf_csg", "rows": [1, 2]}

    def fake_main(scenes, **kw):
        calls["main"].append([os.path.basename(s) for s in scenes])
        return {"rows": []}
    monkeypatch.setattr(study, "run_sdf_study", fake_sdf)
    monkeypatch.setattr(bench, "run_study", fake_main)
    scenes = [os.path.join(ROOT, "scenes", f) for f in ("sdf_csg.toml", "fit_sphere.toml")]
    assert main(["bench", *scenes, "--quick", "--out", str(tmp_path), "--no-progress"]) == 0
    assert calls == {"sdf": ["sdf_csg.toml"], "main": [["fit_sphere.toml"]]}
    assert "sdf_study_sdf_csg" in capsys.readouterr().out
