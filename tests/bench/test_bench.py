"""The benchmark study: metrics, bias, Pareto logic, reports, camera paths, frame times."""
from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest

import draaw_mi
from draaw_mi.bench import bias as bench_bias, metrics as image_metrics, study as bench
from draaw_mi.bench.report import pareto_check, time_to_error
from draaw_mi.scene.camera_path import GO_DRAAW_BENCHMARK_PATH, interpolate

from conftest import SCENES, tiny_description


# Sharma, Wu & Dalal (2005), "The CIEDE2000 color-difference formula: implementation notes,
# supplementary test data, and mathematical observations", Color Res. Appl. 30(1), Table 1:
# (L1, a1, b1, L2, a2, b2, dE00) for all 34 pairs (published data, typed in).
SHARMA_2005 = np.array([
    [50.0000, 2.6772, -79.7751, 50.0000, 0.0000, -82.7485, 2.0425],
    [50.0000, 3.1571, -77.2803, 50.0000, 0.0000, -82.7485, 2.8615],
    [50.0000, 2.8361, -74.0200, 50.0000, 0.0000, -82.7485, 3.4412],
    [50.0000, -1.3802, -84.2814, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, -1.1848, -84.8006, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, -0.9009, -85.5211, 50.0000, 0.0000, -82.7485, 1.0000],
    [50.0000, 0.0000, 0.0000, 50.0000, -1.0000, 2.0000, 2.3669],
    [50.0000, -1.0000, 2.0000, 50.0000, 0.0000, 0.0000, 2.3669],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0009, 7.1792],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0010, 7.1792],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0011, 7.2195],
    [50.0000, 2.4900, -0.0010, 50.0000, -2.4900, 0.0012, 7.2195],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0009, -2.4900, 4.8045],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0010, -2.4900, 4.8045],
    [50.0000, -0.0010, 2.4900, 50.0000, 0.0011, -2.4900, 4.7461],
    [50.0000, 2.5000, 0.0000, 50.0000, 0.0000, -2.5000, 4.3065],
    [50.0000, 2.5000, 0.0000, 73.0000, 25.0000, -18.0000, 27.1492],
    [50.0000, 2.5000, 0.0000, 61.0000, -5.0000, 29.0000, 22.8977],
    [50.0000, 2.5000, 0.0000, 56.0000, -27.0000, -3.0000, 31.9030],
    [50.0000, 2.5000, 0.0000, 58.0000, 24.0000, 15.0000, 19.4535],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.1736, 0.5854, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.2972, 0.0000, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 1.8634, 0.5757, 1.0000],
    [50.0000, 2.5000, 0.0000, 50.0000, 3.2592, 0.3350, 1.0000],
    [60.2574, -34.0099, 36.2677, 60.4626, -34.1751, 39.4387, 1.2644],
    [63.0109, -31.0961, -5.8663, 62.8187, -29.7946, -4.0864, 1.2630],
    [61.2901, 3.7196, -5.3901, 61.4292, 2.2480, -4.9620, 1.8731],
    [35.0831, -44.1164, 3.7933, 35.0232, -40.0716, 1.5901, 1.8645],
    [22.7233, 20.0904, -46.6940, 23.0331, 14.9730, -42.5619, 2.0373],
    [36.4612, 47.8580, 18.3852, 36.2715, 50.5065, 21.2231, 1.4146],
    [90.8027, -2.0831, 1.4410, 91.1528, -1.6435, 0.0447, 1.4441],
    [90.9257, -0.5406, -0.9208, 88.6381, -0.8985, -0.7239, 1.5381],
    [6.7747, -0.2908, -2.4247, 5.8714, -0.0985, -2.2286, 0.6377],
    [2.0776, 0.0795, -1.1350, 0.9033, -0.0636, -0.5514, 0.9082],
])


def _lab_to_linear_srgb(lab):
    """CIELAB (D65, xy = 0.3127, 0.3290) -> linear sRGB with the CIE formulas and the
    XYZ -> RGB matrix published in IEC 61966-2-1 (independent of colour-science)."""
    white = np.array([0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290])
    m = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])
    fy = (lab[..., 0] + 16) / 116
    f = np.stack([fy + lab[..., 1] / 500, fy, fy - lab[..., 2] / 200], -1)
    d = 6 / 29
    xyz = np.where(f > d, f ** 3, 3 * d * d * (f - 4 / 29)) * white
    return xyz @ m.T


def test_rmse_and_relmse_against_formulas():
    rng = np.random.default_rng(1)
    gt = rng.random((8, 9, 3)).astype(np.float32)
    img = gt + rng.normal(0, 0.05, gt.shape).astype(np.float32)
    e = image_metrics.errors(img, gt)
    assert e["rmse"] == pytest.approx(np.sqrt(((img - gt) ** 2).mean()), rel=1e-6)
    assert e["relmse"] == pytest.approx(((img - gt) ** 2 / (gt ** 2 + 0.01)).mean(), rel=1e-6)
    assert image_metrics.errors(gt, gt)["ciede2000"] == pytest.approx(0.0, abs=1e-9)


def test_ciede2000_matches_sharma_2005_table():
    """All 34 published pairs, both orders (the formula is symmetric), to the table's 4 decimals."""
    lab1, lab2, de = SHARMA_2005[:, :3], SHARMA_2005[:, 3:6], SHARMA_2005[:, 6]
    got = np.asarray(image_metrics.delta_e2000(lab1, lab2))
    assert got.shape == (34,)
    assert np.abs(got - de).max() < 6e-5, np.round(got - de, 5)
    assert np.abs(np.asarray(image_metrics.delta_e2000(lab2, lab1)) - de).max() < 6e-5


def test_ciede2000_of_images_is_the_mean_over_pixels_of_published_pairs():
    """Pairs inside the sRGB gamut, turned into linear-sRGB pixels by an independent numpy
    conversion: the image metric is the mean of their published differences. (Pairs 9-15 sit
    on the formula's hue discontinuity, where rounding picks the side; they are left out.)"""
    rgb1, rgb2 = _lab_to_linear_srgb(SHARMA_2005[:, :3]), _lab_to_linear_srgb(SHARMA_2005[:, 3:6])
    keep = ((rgb1 >= 0) & (rgb1 <= 1) & (rgb2 >= 0) & (rgb2 <= 1)).all(1)
    keep[8:15] = False
    assert keep.sum() >= 15
    img, gt = rgb1[keep][:, None, :], rgb2[keep][:, None, :]            # an (N, 1, 3) image
    assert image_metrics.ciede2000(img, gt) == pytest.approx(SHARMA_2005[keep, 6].mean(), abs=2e-4)
    # the sRGB primaries and white (IEC 61966-2-1 / CIE published Lab)
    prim = np.array([[[1.0, 0, 0]], [[0, 1.0, 0]], [[0, 0, 1.0]], [[1.0, 1.0, 1.0]]])
    ref = np.array([[53.24, 80.09, 67.20], [87.73, -86.18, 83.18], [32.30, 79.19, -107.86], [100, 0, 0]])
    assert np.abs(image_metrics.srgb_to_lab(prim)[:, 0] - ref).max() < 0.03      # rounding of matrix and table
    # a linear grey g: L* = 116 g^(1/3) - 16 (CIE), i.e. the display encoding is undone exactly
    g = np.array([[[0.05] * 3], [[0.2] * 3], [[0.6] * 3]])
    assert np.allclose(image_metrics.srgb_to_lab(g)[:, 0, 0], 116 * np.cbrt(g[:, 0, 0]) - 16, atol=1e-3)


def _bias_rows(rng, truth, gt, label, bias, spps, repeats=3, sigma=0.5):
    rows = []
    for spp in spps:
        imgs = [truth + bias + rng.normal(0, sigma / np.sqrt(spp), truth.shape) for _ in range(repeats)]
        st = np.stack(imgs)
        sq = [float(((i - gt) ** 2).mean()) for i in imgs]
        rows.append({"scene": "s", "label": label, "max_depth": 3, "spp": spp, "resolution": truth.shape[:2],
                     "repeats": repeats,
                     "mse": float(((st - gt) ** 2).mean()), "variance": float(st.var(axis=0, ddof=1).mean()),
                     "mse_se": float(np.std(sq, ddof=1) / np.sqrt(repeats))})
    return rows


def test_bias_separates_noise_from_bias():
    rng = np.random.default_rng(0)
    gt = np.zeros((32, 32, 3))
    rows = []
    for label, b in (("unbiased", 0.0), ("biased", 0.1)):
        rows += _bias_rows(rng, gt, gt, label, b, (4, 64))
    est = bench.estimate_bias(rows)
    assert est[("s", "unbiased", 3)][0] < 0.02 and not est[("s", "unbiased", 3)][1]
    assert est[("s", "biased", 3)][0] == pytest.approx(0.1, abs=0.01) and est[("s", "biased", 3)][1]


def test_the_ground_truths_own_noise_is_not_a_bias():
    """The ground truth is itself a noisy render (gt_spp samples): every method's MSE holds
    its noise, which the estimate at the highest spp alone reported as a bias of whichever
    method's repeats happened to show it (V4 0.0145 on the Cornell box, path 0).
    Over 20 seeds the one with a bias of 0.03 (below the ground truth's noise of
    0.5 / sqrt(256) = 0.031) is always resolved, the unbiased ones at most once in 40 (the
    3-sigma test flagged 1 % of them over 200 seeds, a bias of 0.01 68 % of the time)."""
    flagged = {"a": 0, "b": 0, "biased": 0, "quiet": 0}
    for seed in range(20):
        rng = np.random.default_rng(seed)
        truth = np.zeros((32, 32, 3))
        gt = truth + rng.normal(0, 0.5 / np.sqrt(256), truth.shape)         # gt_spp = 256
        rows = []
        for label, b in (("a", 0.0), ("b", 0.0), ("biased", 0.03)):
            rows += _bias_rows(rng, truth, gt, label, b, (16, 64, 256, 1024))
        # unbiased with 5x less noise per sample: the floor is the ground truth's ("a" is its
        # integrator), not this method's own variance (which left the whole floor as a bias)
        rows += _bias_rows(rng, truth, gt, "quiet", 0.0, (16, 64, 256, 1024), sigma=0.1)
        est = bench.estimate_bias(rows, gt_spp=256, reference={"s": "a"})
        for k in flagged:
            flagged[k] += est[("s", k, 3)][1]
        assert est[("s", "biased", 3)][0] == pytest.approx(0.03, abs=0.01)
        assert est[("s", "a", 3)][0] < 0.015                 # a bound near 0, not the floor (0.031)
    assert flagged["biased"] == 20 and flagged["a"] + flagged["b"] + flagged["quiet"] <= 1, flagged


def test_pareto_and_time_to_error():
    assert bench_bias.pareto_front([(1, 5), (2, 3), (3, 4), (4, 1)]) == [0, 1, 3]
    assert time_to_error([(1.0, 0.4), (4.0, 0.1)], 0.2) == pytest.approx(2.0)
    assert time_to_error([(1.0, 0.4)], 0.1) == np.inf
    rows = [{"scene": "s", "max_depth": 3, "adaptive": None, "label": lab, "time_s": t, "rmse": e}
            for lab, pts in {"v4": [(1, 0.4), (4, 0.1)], "v3": [(2, 0.4), (8, 0.1)],
                             "path": [(1.5, 0.4), (6, 0.1)]}.items() for t, e in pts]
    chk = pareto_check(rows, "s", 3)
    assert chk["levels"] == 2 and chk["subject_fastest"] == 2
    # the margin to the best other method: path, 1.5x v4's time at the 0.4 level
    first = chk["details"][-1]
    assert first["rmse"] == pytest.approx(0.4) and first["rival"] == "path"
    assert first["subject_s"] / first["rival_s"] == pytest.approx(1 / 1.5)


def test_a_slower_point_at_the_same_error_is_off_the_pareto_front():
    """(2, 5) takes longer than (1, 5) for the same error: dominated, not on the front (it
    was kept when equal errors counted as an improvement)."""
    assert bench_bias.pareto_front([(1, 5), (2, 5), (3, 1)]) == [0, 2]
    assert bench_bias.pareto_front([(2, 5), (1, 5)]) == [1]


def test_time_to_error_extrapolates_only_targets_beyond_the_measured_errors():
    """A target inside the measured range is interpolated in log-log space with or without
    ``extrapolate``: between (1 s, 0.4) and (4 s, 0.1) the error 0.2 is half-way in log
    error, so half-way in log time, sqrt(1 * 4) = 2 s (the Monte Carlo law from the last
    point, 4 * (0.1 / 0.2)^2 = 1 s, was taken instead). Below 0.1 it is that law: 0.05 at 16 s."""
    pts = [(1.0, 0.4), (4.0, 0.1)]
    assert time_to_error(pts, 0.2, extrapolate=True) == pytest.approx(np.sqrt(1.0 * 4.0))
    assert time_to_error(pts, 0.2, extrapolate=False) == pytest.approx(2.0)
    assert time_to_error(pts, 0.05, extrapolate=True) == pytest.approx(4.0 * (0.1 / 0.05) ** 2)


def test_pareto_check_leaves_denoised_rows_out():
    """A denoiser's rows (biased, fast, a low RMSE: 1.2 s at 0.05) are not a method of the
    race: they were named the fastest at every level, and the subject won none. Without them
    v4 is fastest at both of v3's levels, hand computed in log-log: 0.1 at 4 s, and 0.3 at
    4^(ln(0.3/0.4) / ln(0.1/0.4)) = 1 / 0.75 s (v3: 8 s and 2 s)."""
    def row(label, t, e, **extra):
        return {"scene": "s", "max_depth": 5, "adaptive": False, "label": label, "time_s": t,
                "rmse": e, **extra}
    rows = [row("v4", 1.0, 0.4), row("v4", 4.0, 0.1), row("v3", 2.0, 0.3), row("v3", 8.0, 0.1),
            row("v4+oidn (biased)", 1.2, 0.05, denoise=True)]
    chk = pareto_check(rows, "s", 5)
    assert chk["levels"] == 2 and chk["subject_fastest"] == 2, chk
    assert [d["fastest"] for d in chk["details"]] == ["v4", "v4"]
    assert [d["rival"] for d in chk["details"]] == ["v3", "v3"]
    np.testing.assert_allclose([d["fastest_s"] for d in chk["details"]], [4.0, 1 / 0.75], rtol=1e-9)
    np.testing.assert_allclose([d["rival_s"] for d in chk["details"]], [8.0, 2.0], rtol=1e-9)


def test_study_writes_table_summary_and_plots(tmp_path):
    import csv

    import matplotlib.image
    import mitsuba as mi
    scene_file = tmp_path / "tiny.json"
    scene_file.write_text(json.dumps(tiny_description(resolution=[16, 12])))
    res = bench.run_study([str(scene_file)], versions=("v4", "path"), spps=(1, 4), adaptive=(None, 4),
                          repeats=2, gt_spp=64, out_dir=str(tmp_path / "out"), progress=False)
    out = tmp_path / "out"
    rows = res["rows"]
    assert {r["label"] for r in rows} == {"v4", "path", "v4+adaptive4", "path+adaptive4"}
    for r in rows:
        assert r["time_s"] > 0 and np.isfinite(r["rmse"]) and r["finite"]
    # ground truth: cached, and equal to Mitsuba's path at 64 spp with the study's seed
    cached = [f for f in (out / "cache").iterdir() if f.name.startswith("gt-")]
    assert len(cached) == 1 and cached[0].suffix == ".exr"
    # and two converged renders per version (each version's bias; path's is the gt's noise)
    assert len([f for f in (out / "cache").iterdir() if f.name.startswith("conv-")]) == 4
    scene = draaw_mi.load_scene(str(scene_file))
    integ = mi.load_dict({"type": "path", "max_depth": 4})
    gt = np.array(mi.render(scene.mi_scene, integrator=integ, spp=64, seed=2 ** 31 - 1))
    assert np.allclose(draaw_mi.read_exr(str(cached[0])), gt, rtol=1e-6, atol=1e-6)
    # the path rows' errors, recomputed from independent Mitsuba renders (seeds 1, 2; mean of repeats)
    for spp in (1, 4):
        imgs = [np.array(mi.render(scene.mi_scene, integrator=integ, spp=spp, seed=1 + r)) for r in range(2)]
        row = next(r for r in rows if r["label"] == "path" and r["spp"] == spp)
        assert row["rmse"] == pytest.approx(np.mean([np.sqrt(((i - gt) ** 2).mean()) for i in imgs]), rel=1e-5)
        assert row["mse"] == pytest.approx(np.mean((np.stack(imgs) - gt) ** 2), rel=1e-5)
        assert row["variance"] == pytest.approx(np.stack(imgs).var(axis=0, ddof=1).mean(), rel=1e-5)
    four = {r["label"]: r["rmse"] for r in rows if r["spp"] == 4}
    one = {r["label"]: r["rmse"] for r in rows if r["spp"] == 1 and "adaptive" not in r["label"]}
    assert four["path"] < one["path"]                     # error falls with spp
    # the files hold the rows: JSON round trip, one CSV line per row, a table line per row
    assert json.loads((out / "results.json").read_text())["rows"] == json.loads(json.dumps(rows, default=str))
    with open(out / "results.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == len(rows)
    for t, r in zip(table, rows):
        assert t["label"] == r["label"] and int(t["spp"]) == r["spp"]
        assert float(t["rmse"]) == pytest.approx(r["rmse"], rel=1e-9)
    md = (out / "summary.md").read_text()
    for r in rows:
        assert f"| {r['label']} | {r['spp']} | {r['time_s']:.4f} |" in md and f"{r['rmse']:.4f}" in md
    for name in ("error_vs_time_tiny_d4.png", "error_images_tiny.png"):
        png = matplotlib.image.imread(str(out / name))
        assert png.ndim == 3 and min(png.shape[:2]) > 200 and png[..., :3].std() > 0.05, name


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


def test_frame_times_along_a_path(tmp_path, monkeypatch):
    """GO-Draaw's benchmark path over a mesh of the monkey's size (an icosphere written here:
    the test runs without the GO-Draaw data)."""
    import trimesh
    trimesh.creation.icosphere(subdivisions=2).export(tmp_path / "ball.obj")
    desc = {"render": {"resolution": [20, 15], "spp": 1, "max_depth": 3},
            "camera": {"position": list(GO_DRAAW_BENCHMARK_PATH[0][:3]), "angles": list(GO_DRAAW_BENCHMARK_PATH[0][3:]),
                       "fov": 45},
            "shapes": [{"type": "mesh", "file": str(tmp_path / "ball.obj"), "scale": 75}],
            "lights": [{"type": "point", "position": [0, 1500, 1000], "intensity": 4e6}]}
    scene = draaw_mi.load_scene(desc)
    # spy on every render call: which camera position the sensor has at that moment
    render_mod = sys.modules["draaw_mi.bench.study"]      # the module that calls render()
    real_render = render_mod.render
    key = next(k for k in scene.params.keys() if k.endswith("to_world") and "sensor" in k)
    seen = []

    def spy(sc, *a, **kw):
        m = np.array(sc.params[key].matrix).reshape(4, 4)
        seen.append((kw.get("version"), kw.get("seed"), m[:3, 3].copy()))
        return real_render(sc, *a, **kw)
    monkeypatch.setattr(render_mod, "render", spy)
    rows = bench.frame_times(scene, GO_DRAAW_BENCHMARK_PATH, versions=("v1", "v4"), frames=4, error_frames=2,
                             gt_spp=16, progress=False)
    assert [r["version"] for r in rows] == ["v1", "v4"]
    # each timed frame i is rendered from the i-th position of the interpolated path
    path = interpolate(GO_DRAAW_BENCHMARK_PATH, duration=4 / 60)
    assert np.ptp(path[:, :3], axis=0).max() > 1.0                   # the path does move
    for v in ("v1", "v4"):
        timed = [(seed, pos) for ver, seed, pos in seen if ver == v and seed is not None]
        assert [sd for sd, _ in timed] == [0, 1, 2, 3]
        for i, pos in timed:
            assert np.allclose(pos, path[i, :3], rtol=1e-5, atol=1e-3), (v, i, pos, path[i, :3])
    for r in rows:
        assert r["frames"] == 4 and 0 < r["min_s"] <= r["p10_s"] <= r["median_s"] <= r["p90_s"] <= r["max_s"]
        assert np.isfinite(r["rmse"]) and np.isfinite(r["ciede2000"])


def test_frame_times_says_when_the_path_sees_nothing(tmp_path):
    """GO-Draaw's path (x 300..900) over a scene a few units wide: every frame empty, RMSE 0,
    and no word of it. The same path over the scene scaled to GO-Draaw's units does not warn."""
    import warnings
    desc = {"render": {"resolution": [8, 6], "spp": 1, "max_depth": 2},
            "shapes": [{"type": "sphere", "radius": 1.0}],
            "lights": [{"type": "point", "position": [0, 3, 3], "intensity": 10}]}
    scene = draaw_mi.load_scene(desc)
    with pytest.warns(RuntimeWarning, match="black in all 2 frames checked.*sees nothing"):
        rows = bench.frame_times(scene, GO_DRAAW_BENCHMARK_PATH, versions=("v1",), frames=2, error_frames=2,
                                 gt_spp=4, progress=False)
    assert rows[0]["rmse"] == 0.0
    desc["shapes"][0]["radius"] = 150.0
    desc["lights"] = [{"type": "constant", "intensity": 1.0}]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bench.frame_times(draaw_mi.load_scene(desc), GO_DRAAW_BENCHMARK_PATH, versions=("v1",), frames=2,
                          error_frames=2, gt_spp=4, progress=False)


def test_frame_times_keeps_every_frame_and_the_scenes_fov_axis(monkeypatch):
    """123 frames are 123 (123 / 60 s at 60 fps truncated to 122), and a scene whose fov is
    along y keeps its horizontal field of view (the fov went into x_fov as it was)."""
    from draaw_mi.scene.camera import x_fov
    desc = {"render": {"resolution": [8, 4], "spp": 1, "max_depth": 2},
            "camera": {"position": list(GO_DRAAW_BENCHMARK_PATH[0][:3]),
                       "angles": list(GO_DRAAW_BENCHMARK_PATH[0][3:]), "fov": 30, "fov_axis": "y"},
            "shapes": [{"type": "sphere", "radius": 75}],
            "lights": [{"type": "constant", "intensity": 1.0}]}
    scene = draaw_mi.load_scene(desc)
    loaded = float(scene.params["sensor.x_fov"][0])
    assert loaded == pytest.approx(x_fov(30, "y", 8, 4)) and loaded > 50
    render_mod = sys.modules["draaw_mi.bench.study"]      # the module that calls render()
    real_render, fovs = render_mod.render, []

    def spy(sc, *a, **kw):
        fovs.append(float(sc.params["sensor.x_fov"][0]))
        return real_render(sc, *a, **kw)
    monkeypatch.setattr(render_mod, "render", spy)
    rows = bench.frame_times(scene, GO_DRAAW_BENCHMARK_PATH, versions=("v1",), frames=123,
                             error_frames=1, gt_spp=1, progress=False)
    assert rows[0]["frames"] == 123
    assert fovs and all(f == pytest.approx(loaded) for f in fovs)


def test_versions_at_one_spp_are_timed_round_robin(monkeypatch):
    """A drifting machine must not favour whichever version ran first: after one warm-up each,
    the timed renders of the versions at one spp alternate, and every row gets its own
    renders' times, in the plan's (version-major) order."""
    calls = []
    clock = iter(range(1, 1000))

    def fake(scene, s, seed):
        calls.append((s.version, seed))
        return np.full((2, 2, 3), 0.5 if s.version == "v4" else 0.25), float(next(clock))

    monkeypatch.setattr(bench, "_timed_render", fake)
    a, b = bench.Setting("v4", 4, 3), bench.Setting("path", 4, 3)
    out = bench.measure_group(None, [a, b], np.full((2, 2, 3), 0.5), repeats=3, seed=1)
    assert calls == [("v4", 1001), ("path", 1001)] + [(v, 1 + r) for r in range(3) for v in ("v4", "path")]
    (ra, _), (rb, _) = out
    assert ra["time_s"] == 5.0 and rb["time_s"] == 6.0          # medians of (3, 5, 7), (4, 6, 8)
    assert ra["rmse"] == 0.0 and rb["rmse"] > 0.0


def test_an_sdf_scene_is_measured_against_v4_without_mitsubas_integrators(tmp_path):
    """Mitsuba's integrators cannot see [[sdf]] objects: the study leaves them out (with a
    warning) and takes its ground truth from V4 (a path render of the floor alone was the
    reference, and path a measured version, before they were refused)."""
    from draaw_mi.bench.study import reference_version, scene_versions
    scene = draaw_mi.load_scene(os.path.join(SCENES, "sdf_csg.toml"), resolution=(12, 8))
    assert reference_version(scene) == "v4"
    with pytest.warns(RuntimeWarning, match="path cannot see"):
        assert scene_versions(scene, ["v2", "path", "v4"]) == ["v2", "v4"]
    # the study plans no adaptive settings for it (they raised: adaptive cannot see SDFs)
    with pytest.warns(RuntimeWarning, match=r"path cannot see its \[\[sdf\]\] objects; left out"):
        res = bench.run_study([scene], versions=("v4", "path"), spps=(1,), adaptive=(None, 4), repeats=1,
                              gt_spp=8, out_dir=str(tmp_path / "study"), progress=False)
    assert [r["label"] for r in res["rows"]] == ["v4"]
    # a bare Mitsuba scene with SDF proxies is recognised as well (by its shapes)
    with pytest.raises(draaw_mi.RenderError, match=r"\[\[sdf\]\] objects"):
        draaw_mi.render(scene.mi_scene, version="path", spp=1)
    gt = bench.ground_truth(scene, spp=8)
    ref = np.array(draaw_mi.render(scene, version="v4", spp=8, seed=2 ** 31 - 1, post=[]))[..., :3]
    np.testing.assert_array_equal(gt, ref)
    smoke = draaw_mi.load_scene(os.path.join(SCENES, "smoke.toml"), resolution=(12, 8))
    assert reference_version(smoke) == "volpath" and scene_versions(smoke, ["path", "v4"]) == ["volpath", "v4"]
    assert reference_version(draaw_mi.load_scene(tiny_description())) == "path"


def test_finite_is_read_from_the_raw_renders(monkeypatch):
    """A render with a NaN pixel (or one repeat with an inf) is not finite: the column was
    computed from the images after nan_to_num, so it was always True."""
    nan = np.where(np.arange(48).reshape(4, 4, 3) == 0, np.nan, 0.5)
    monkeypatch.setattr(bench, "_timed_render", lambda sc, s, seed: (nan, 0.01))
    row, img = bench.measure(None, bench.Setting("v4", 1, 3), np.full((4, 4, 3), 0.5))
    assert row["finite"] is False and np.isfinite(img).all()
    # an inf in the first repeat only (the last image, the one returned, is finite)
    inf = np.where(np.arange(48).reshape(4, 4, 3) == 5, np.inf, 0.5)
    monkeypatch.setattr(bench, "_timed_render",
                        lambda sc, s, seed: (inf if seed == 1 else np.full((4, 4, 3), 0.5), 0.01))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)     # an inf's error: inf, said quietly
        row, _ = bench.measure(None, bench.Setting("v4", 1, 3), np.full((4, 4, 3), 0.5), repeats=3)
    assert row["finite"] is False and row["mse"] == np.inf
    monkeypatch.setattr(bench, "_timed_render", lambda sc, s, seed: (np.full((4, 4, 3), 0.5), 0.01))
    assert bench.measure(None, bench.Setting("v4", 1, 3), np.full((4, 4, 3), 0.5))[0]["finite"] is True


@pytest.mark.parametrize("depths, expect", [(None, 4), ([2, 12], 12), ([3, -1], -1)])
def test_the_ground_truth_is_rendered_at_the_studys_deepest_max_depth(tmp_path, monkeypatch, depths, expect):
    """With --max-depth 12 the ground truth was rendered at the scene's own depth: the depth
    gap showed as error and bias of every deeper setting."""
    seen = []

    def fake_gt(scene, spp=4096, max_depth=None, cache_dir=None, progress=False):
        seen.append(max_depth)
        return np.zeros((2, 2, 3))
    monkeypatch.setattr(bench, "ground_truth", fake_gt)
    monkeypatch.setattr(bench, "measure_group", lambda scene, settings, gt, repeats, seed: [
        ({"label": s.label, "spp": s.spp, "max_depth": s.max_depth, "mse": 0.0, "variance": float("nan")},
         np.zeros((2, 2, 3))) for s in settings])
    written = {}
    monkeypatch.setattr(bench, "write_report", lambda result, *a: written.update(result))
    scene_file = tmp_path / "tiny.json"
    scene_file.write_text(json.dumps(tiny_description(resolution=[4, 4])))
    bench.run_study([str(scene_file)], versions=("path",), spps=(1,), max_depths=depths, adaptive=(None,),
                    repeats=1, gt_spp=8, out_dir=str(tmp_path / "o"), progress=False, converged=False)
    assert seen == [expect] and written["ground_truth_depth"] == {"tiny": expect}


def test_version_scene_is_left_out_for_a_scene_without_an_integrator_of_its_own():
    """``--versions scene`` asks for the scene's own integrator: a TOML scene has none, so the
    study leaves it out at once, with a warning (it failed after the ground-truth renders);
    an XML scene that declares one keeps it."""
    from draaw_mi.bench.study import scene_versions
    scene = draaw_mi.load_scene(os.path.join(SCENES, "fit_sphere.toml"), resolution=(8, 8))
    with pytest.warns(RuntimeWarning, match="declares no integrator of its own"):
        assert scene_versions(scene, ["scene", "v4"]) == ["v4"]
    xml = os.path.join(os.path.dirname(__file__), "..", "scene", "data", "cbox.xml")
    own = draaw_mi.load_scene(xml, defines={"res": 8})
    assert own.info.get("integrator") and scene_versions(own, ["scene", "v4"]) == ["scene", "v4"]


def test_the_summary_names_only_the_versions_measured():
    """With V4 and `path` alone the summary said "V4 is the fastest to reach 2 of the 2
    error levels that V3 and `path` reach", and "median of 1 renders"."""
    from draaw_mi.bench.report import summary_markdown
    rows = [{"scene": "s", "max_depth": 3, "adaptive": None, "label": lab, "spp": spp, "time_s": t, "rmse": e,
             "compile_s": 0.0, "relmse": e, "ciede2000": 1.0, "bias_rmse": None, "resolution": [8, 8]}
            for lab, pts in {"v4": [(1, 4, 0.4), (4, 16, 0.1)], "path": [(1.5, 4, 0.4), (6, 16, 0.1)]}.items()
            for t, spp, e in pts]
    assert pareto_check(rows, "s", 3)["rivals"] == ["path"]
    md = summary_markdown({"rows": rows, "ground_truth_spp": 64, "repeats": 1, "machine": {}})
    assert "2 of the 2 error levels that `path` reaches" in md and "V3" not in md
    assert "Times: one render after warm-up" in md and "median of 1" not in md
    assert pareto_check([r for r in rows if r["label"] == "v4"], "s", 3) == {}     # no rival measured


def test_the_ground_truth_key_follows_the_files_a_scene_reads(tmp_path):
    """The key of a cached ground truth hashed the scene file alone: an edited mesh it reads
    reused the old ground truth."""
    from draaw_mi.bench.study import _scene_key
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    d = tiny_description()
    d["shapes"].append({"type": "mesh", "file": str(mesh)})
    (tmp_path / "s.json").write_text(json.dumps(d))
    before = _scene_key(draaw_mi.load_scene(str(tmp_path / "s.json")), 16, 3)
    # unchanged files (loaded again, the mesh rewritten with the same bytes) keep the key: the
    # cache is reused (a time stamp or a load's object id in it would never hit)
    assert _scene_key(draaw_mi.load_scene(str(tmp_path / "s.json")), 16, 3) == before
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert _scene_key(draaw_mi.load_scene(str(tmp_path / "s.json")), 16, 3) == before
    mesh.write_text("v 0 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\n")
    assert _scene_key(draaw_mi.load_scene(str(tmp_path / "s.json")), 16, 3) != before


def test_a_report_stopped_midway_leaves_no_summary_of_the_run_before(tmp_path, monkeypatch):
    """A rerun into an existing --out stopped after results.json kept the old plots beside the
    new numbers, and a summary that embedded them: the old summary and results go first, the
    plots are made next, the summary last."""
    from draaw_mi.bench import report
    (tmp_path / "summary.md").write_text("the run before")
    (tmp_path / "results.json").write_text("{}")

    def stopped(*a):
        raise KeyboardInterrupt
    monkeypatch.setattr(report, "_write_plots", stopped)
    with pytest.raises(KeyboardInterrupt):
        report.write_report({"rows": []}, {}, {}, str(tmp_path))
    assert not (tmp_path / "summary.md").exists() and not (tmp_path / "results.json").exists()
