"""The SDF part of `draaw-mi bench`: tracer settings -> time, tracer error, false misses."""
from __future__ import annotations

import json
import os

import draaw_mi
from draaw_mi.sdf.study import run_sdf_study

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


def test_cli_bench_sends_sdf_scenes_to_the_tracer_study(monkeypatch, tmp_path, capsys):
    """`draaw-mi bench` runs the tracer study on [[sdf]] scenes (Mitsuba's path, the main
    study's ground truth, cannot see SDFs) and the main study on the others."""
    import draaw_mi.bench as bench
    import draaw_mi.sdf.study as study
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
