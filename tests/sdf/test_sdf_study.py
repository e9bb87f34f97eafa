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
