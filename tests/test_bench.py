"""The benchmark study: metrics, bias, Pareto logic, reports, camera paths, frame times."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import draaw_mi
from draaw_mi import bench
from draaw_mi.bench_report import pareto_check, time_to_error
from draaw_mi.camera_path import GO_DRAAW_BENCHMARK_PATH, interpolate

from conftest import tiny_description


def test_error_metrics_against_independent_formulas():
    rng = np.random.default_rng(1)
    gt = rng.random((8, 9, 3)).astype(np.float32)
    img = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    e = bench.errors(img, gt)
    assert e["rmse"] == pytest.approx(np.sqrt(((img - gt) ** 2).mean()), rel=1e-6)
    assert e["relmse"] == pytest.approx(((img - gt) ** 2 / (gt ** 2 + 0.01)).mean(), rel=1e-6)
    assert bench.errors(gt, gt)["ciede2000"] == pytest.approx(0.0, abs=1e-9)
    # CIEDE2000 of a pure sRGB red vs a slightly darker red, from the published Lab values
    import colour
    a, b = np.full((1, 1, 3), [1.0, 0, 0], np.float32), np.full((1, 1, 3), [0.8, 0, 0], np.float32)
    lab = lambda x: colour.XYZ_to_Lab(colour.sRGB_to_XYZ(draaw_mi.io.srgb_encode(x)))
    assert bench.ciede2000(a, b) == pytest.approx(float(colour.delta_E(lab(a), lab(b), method="CIE 2000")[0, 0]))
    assert lab(a)[0, 0, 0] == pytest.approx(53.24, abs=0.05)      # L* of sRGB red


def test_bias_separates_noise_from_bias():
    rng = np.random.default_rng(0)
    gt = np.zeros((32, 32, 3))
    rows = []
    for label, b in (("unbiased", 0.0), ("biased", 0.1)):
        for spp in (4, 64):
            imgs = [gt + b + rng.normal(0, 0.5 / np.sqrt(spp), gt.shape) for _ in range(4)]
            st = np.stack(imgs)
            rows.append({"scene": "s", "label": label, "max_depth": 3, "spp": spp,
                         "mse": float(((st - gt) ** 2).mean()), "variance": float(st.var(axis=0, ddof=1).mean())})
    est = bench.estimate_bias(rows)
    assert est[("s", "unbiased", 3)] < 0.02
    assert est[("s", "biased", 3)] == pytest.approx(0.1, abs=0.01)


def test_pareto_and_time_to_error():
    assert bench.pareto_front([(1, 5), (2, 3), (3, 4), (4, 1)]) == [0, 1, 3]
    assert time_to_error([(1.0, 0.4), (4.0, 0.1)], 0.2) == pytest.approx(2.0)
    assert time_to_error([(1.0, 0.4)], 0.1) == np.inf
    rows = [{"scene": "s", "max_depth": 3, "adaptive": None, "label": lab, "time_s": t, "rmse": e}
            for lab, pts in {"v4": [(1, 0.4), (4, 0.1)], "v3": [(2, 0.4), (8, 0.1)],
                             "path": [(1.5, 0.4), (6, 0.1)]}.items() for t, e in pts]
    chk = pareto_check(rows, "s", 3)
    assert chk["levels"] == 2 and chk["subject_fastest"] == 2


def test_study_writes_table_summary_and_plots(tmp_path):
    scene_file = tmp_path / "tiny.json"
    scene_file.write_text(json.dumps(tiny_description(resolution=[16, 12])))
    res = bench.run_study([str(scene_file)], versions=("v4", "path"), spps=(1, 4), adaptive=(None, 4),
                          repeats=2, gt_spp=64, out_dir=str(tmp_path / "out"), progress=False)
    out = tmp_path / "out"
    for name in ("results.json", "results.csv", "summary.md", "error_vs_time_tiny_d4.png", "error_images_tiny.png"):
        assert (out / name).stat().st_size > 0, name
    rows = res["rows"]
    assert {r["label"] for r in rows} == {"v4", "path", "v4+adaptive4", "path+adaptive4"}
    for r in rows:
        assert r["time_s"] > 0 and np.isfinite(r["rmse"]) and r["finite"]
    four = {r["label"]: r["rmse"] for r in rows if r["spp"] == 4}
    one = {r["label"]: r["rmse"] for r in rows if r["spp"] == 1 and "adaptive" not in r["label"]}
    assert four["path"] < one["path"]                     # error falls with spp
    cached = list((out / "cache").iterdir())
    assert len(cached) == 1 and cached[0].suffix == ".exr"     # ground truth cached


def test_go_draaw_interpolation_quirks_reproduced():
    keys = [(0, 0, 0, 0, 0), (3, 0, 0, 0, 0), (6, 0, 0, 0, 0), (9, 0, 0, 0, 0)]
    f = interpolate(keys, duration=8 / 60, faithful=True)          # 8 frames, 8 // 3 = 2 per segment
    assert len(f) == 8
    t = 0.5
    assert f[1][0] == pytest.approx(3 * t * t * t * (3 - 2 * t))    # t * smoothstep(t) easing
    assert np.all(f[6] == 0)                                         # the undivided frame stays at 0
    assert f[7][0] == 9
    g = interpolate(keys, duration=8 / 60)
    assert np.all(np.diff(g[:, 0]) >= 0) and g[0][0] == 0 and g[-1][0] == 9


def test_frame_times_along_a_path(go_draaw_dir):
    desc = {"render": {"resolution": [20, 15], "spp": 1, "max_depth": 3},
            "camera": {"position": list(GO_DRAAW_BENCHMARK_PATH[0][:3]), "angles": list(GO_DRAAW_BENCHMARK_PATH[0][3:]),
                       "fov": 45},
            "shapes": [{"type": "mesh", "file": os.path.join(go_draaw_dir, "monkey.obj"), "scale": 75}],
            "lights": [{"type": "point", "position": [0, 1500, 1000], "intensity": 4e6}]}
    scene = draaw_mi.load_scene(desc)
    rows = bench.frame_times(scene, GO_DRAAW_BENCHMARK_PATH, versions=("v1", "v4"), frames=4, error_frames=2,
                             gt_spp=16, progress=False)
    assert [r["version"] for r in rows] == ["v1", "v4"]
    for r in rows:
        assert r["frames"] == 4 and 0 < r["min_s"] <= r["p10_s"] <= r["median_s"] <= r["p90_s"] <= r["max_s"]
        assert np.isfinite(r["rmse"]) and np.isfinite(r["ciede2000"])
