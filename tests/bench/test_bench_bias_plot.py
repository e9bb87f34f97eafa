"""Issue 43: the quick study's plot. V1's and V2's errors on the material spheres jump and rise
with spp (0.48 -> 0.95 -> 1.09 at 1/4/16 spp) because their noise is a few fireflies
(near-mirror Phong lobes lit by emitter sampling alone); their bias (0.07 against `path`) was
reported as "< 0.91" (the highest three spp levels of a quick study cannot tell it from that
noise); and the legend covered the data."""
from __future__ import annotations

import json

import numpy as np
import pytest

from draaw_mi.bench import bias as bench_bias, study as bench
from draaw_mi.bench.report import error_vs_time_figure, summary_markdown

from conftest import tiny_description


def _firefly_render(rng, truth, spp, bias=0.0, p=2e-3, value=100.0):
    """A render of ``spp`` samples per value: unit Gaussian noise per sample plus rare samples
    worth ``value`` (probability ``p``), their mean taken out: unbiased around truth + bias."""
    gauss = rng.normal(0, 1 / np.sqrt(spp), truth.shape)
    hits = rng.binomial(spp, p, truth.shape)
    return truth + bias + gauss + (hits * value - spp * p * value) / spp


def test_tail_share_tells_fireflies_from_gaussian_noise():
    """Gaussian noise keeps about 5 % of its squared error in the largest 0.5 % of values
    (the expectation: 2 (z phi(z) + 1 - Phi(z)) at z = 2.807, 0.047); a firefly render
    holds nearly all of it there (a plain study row would not say so)."""
    rng = np.random.default_rng(3)
    truth = np.zeros((64, 64, 3))
    shares = [bench_bias.tail_share(truth + rng.normal(0, 0.1, truth.shape), truth) for _ in range(5)]
    assert np.mean(shares) == pytest.approx(0.047, abs=0.01)
    ff = bench_bias.tail_share(_firefly_render(rng, truth, 4), truth)
    assert ff > bench_bias.FIREFLY_SHARE


def test_converged_bias_resolves_what_the_spp_levels_of_a_quick_study_cannot():
    """A biased firefly method at 1, 4, 16 spp (3 repeats): the estimate from those levels is
    an unresolved bound far above the bias; two converged renders of it (1024 spp each, the
    ground truth's spp) against a ground truth at 2048 spp resolve it within 20 %."""
    rng = np.random.default_rng(7)
    truth = np.full((32, 32, 3), 0.5)
    gt = truth + rng.normal(0, 0.1 / np.sqrt(2048), truth.shape)
    rows = []
    for spp in (1, 4, 16):
        imgs = np.stack([_firefly_render(rng, truth, spp, bias=0.07) for _ in range(3)])
        sq = ((imgs - gt) ** 2).mean(axis=(1, 2, 3))
        rows.append({"scene": "s", "label": "v1", "max_depth": 6, "spp": spp, "resolution": [32, 32],
                     "mse": float(sq.mean()), "variance": float(imgs.var(axis=0, ddof=1).mean()),
                     "mse_se": float(sq.std(ddof=1) / np.sqrt(3)), "repeats": 3})
    old, old_resolved = bench_bias.estimate_bias(rows)[("s", "v1", 6)]
    assert not old_resolved and old > 0.3
    halves = [_firefly_render(rng, truth, 1024, bias=0.07) for _ in range(2)]
    gt_halves = [truth + rng.normal(0, 0.1 / np.sqrt(1024), truth.shape) for _ in range(2)]
    new, resolved = bench_bias.converged_bias(halves, gt, gt_halves)
    assert resolved and new == pytest.approx(0.07, rel=0.2)
    # an unbiased firefly method: not resolved, a bound well below the biased one's estimate
    halves = [_firefly_render(rng, truth, 1024) for _ in range(2)]
    b, resolved = bench_bias.converged_bias(halves, gt, gt_halves)
    assert not resolved and b < 0.05


def _row(label, spp, t, e, **extra):
    return {"scene": "s", "max_depth": 6, "label": label, "spp": spp, "time_s": t, "rmse": e,
            "rmse_min": e * 0.8, "rmse_max": e * 1.3, "adaptive": None, "denoise": False, **extra}


def test_the_legend_is_outside_the_axes_and_the_bias_and_fireflies_are_drawn():
    rows = []
    for lab, errs, b in (("v1", (0.48, 0.95, 1.09), 0.07), ("v4", (0.13, 0.09, 0.046), 0.001),
                         ("path", (0.17, 0.1, 0.05), 0.002)):
        for spp, e in zip((1, 4, 16), errs):
            rows.append(_row(lab, spp, 0.003 * spp, e, fireflies=lab == "v1", bias_rmse=b,
                             bias_resolved=lab == "v1", bias_method="converged"))
    fig = error_vs_time_figure(rows, "s", 6)
    fig.canvas.draw()
    ax = fig.axes[0]
    leg = ax.get_legend()
    a, lg = ax.get_window_extent(), leg.get_window_extent()
    assert lg.x0 >= a.x1, (lg, a)                      # right of the axes: covers no data
    assert lg.x1 <= fig.bbox.x1 + 1                    # and inside the figure
    texts = [t.get_text() for t in leg.get_texts()]
    assert "v1 bias 0.07" in texts and "v4 bias ≤ 0.001" in texts
    assert any("firefly" in t.get_text() for t in fig.texts)
    # v1's dashed bias line at 0.07
    lines = [ln for ln in ax.get_lines() if ln.get_label() == "v1 bias 0.07"]
    assert lines and lines[0].get_linestyle() == "--" and lines[0].get_ydata()[0] == pytest.approx(0.07)


def test_summary_marks_firefly_rows_and_says_what_the_bias_is():
    rows = [dict(_row("v1", 4, 0.01, 0.95, fireflies=True, bias_rmse=0.07, bias_resolved=True),
                 relmse=1.0, ciede2000=9.0, compile_s=0.1, resolution=[64, 64])]
    md = summary_markdown({"rows": rows, "ground_truth_spp": 1024, "repeats": 3, "machine": {},
                           "bias_from": "converged renders"})
    assert "| v1 | 4 | 0.0100 | 0.100 | 0.9500 † | 0.7600–1.2350 |" in md
    assert "two more renders of it at 512 spp each" in md and "*Fireflies* (†)" in md


def test_a_biased_version_shows_its_bias_from_converged_renders(tmp_path):
    """The study end to end on a tiny scene: V1 (truncated transport: darker) resolves a bias
    against path's ground truth from the converged renders; path's own bias is not resolved;
    every plain row says where its bias comes from and carries its repeats' spread."""
    scene_file = tmp_path / "tiny.json"
    scene_file.write_text(json.dumps(tiny_description(resolution=[16, 12])))
    res = bench.run_study([str(scene_file)], versions=("v1", "path"), spps=(1, 4), adaptive=(None,),
                          repeats=2, gt_spp=256, out_dir=str(tmp_path / "out"), progress=False)
    rows = {(r["label"], r["spp"]): r for r in res["rows"]}
    assert res["bias_from"] == "converged renders"
    for r in rows.values():
        assert r["bias_method"] == "converged" and r["rmse_min"] <= r["rmse"] <= r["rmse_max"]
        assert 0 <= r["tail_share"] <= 1
    assert not any(r["fireflies"] for r in rows.values())        # smooth noise: a tiny diffuse scene
    v1, path = rows[("v1", 4)], rows[("path", 4)]
    assert v1["bias_resolved"] and not path["bias_resolved"]
    assert v1["bias_rmse"] > 2 * path["bias_rmse"]
    # the bias is what the converged renders say: their mean against the ground truth
    gt = next(p for p in (tmp_path / "out" / "cache").iterdir() if p.name.startswith("gt-"))
    from draaw_mi.io import read_exr
    conv = [read_exr(str(p))[..., :3] for p in sorted((tmp_path / "out" / "cache").iterdir())
            if p.name.startswith("conv-tiny-v1-")]
    direct = float(np.sqrt(np.mean(((conv[0] + conv[1]) / 2 - read_exr(str(gt))[..., :3]) ** 2)))
    assert v1["bias_rmse"] == pytest.approx(direct, rel=0.25)


def test_a_setting_whose_repeats_differ_by_fireflies_is_flagged(monkeypatch):
    """measure_group flags a setting whose repeats' RMSEs differ 2x or more (one repeat with a
    firefly of 50 in one pixel value, the others smooth noise), not one with smooth noise."""
    truth = np.zeros((16, 16, 3))
    rng = np.random.default_rng(5)

    def fake(scene, s, seed):
        img = truth + rng.normal(0, 0.05, truth.shape)
        if s.version == "v1" and seed == 2:
            img[3, 3, 0] = 50.0
        return img, 0.01
    monkeypatch.setattr(bench, "_timed_render", fake)
    out = bench.measure_group(None, [bench.Setting("v1", 4, 6), bench.Setting("v4", 4, 6)], truth, repeats=3)
    (v1, _), (v4, _) = out
    assert v1["fireflies"] and v1["rmse_max"] > 10 * v1["rmse_min"]
    assert not v4["fireflies"] and v4["rmse_min"] <= v4["rmse"] <= v4["rmse_max"]
