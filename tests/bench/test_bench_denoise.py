"""Denoised settings in the accuracy-time study: labelled biased, measured like the others."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from draaw_mi.bench import study as bench
from draaw_mi.cli import main

from conftest import tiny_description

pytest.importorskip("pyoidn")


def test_study_has_labelled_denoised_points(tmp_path):
    scene_file = tmp_path / "tiny.json"
    scene_file.write_text(json.dumps(tiny_description(resolution=[24, 16])))
    res = bench.run_study([str(scene_file)], versions=("v4",), spps=(1, 4), adaptive=(None,), repeats=2,
                          gt_spp=64, out_dir=str(tmp_path / "out"), progress=False, denoise_spp=(4,))
    rows = {(r["label"], r["spp"]): r for r in res["rows"]}
    assert set(rows) == {("v4", 1), ("v4", 4), ("v4+oidn (biased)", 4)}
    d, raw = rows[("v4+oidn (biased)", 4)], rows[("v4", 4)]
    assert d["denoise"] is True and raw["denoise"] is False
    assert np.isfinite(d["rmse"]) and d["finite"] and d["time_s"] > 0
    # the denoised row's error, recomputed: render(denoise=True) with the study's seeds (1, 2)
    # against its ground truth (Mitsuba's path at 64 spp, seed 2^31 - 1), mean over repeats
    import draaw_mi
    import mitsuba as mi
    scene = draaw_mi.load_scene(str(scene_file))
    gt = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "path", "max_depth": 4}),
                            spp=64, seed=2 ** 31 - 1))
    imgs = [np.array(draaw_mi.render(scene, version="v4", spp=4, seed=1 + r, denoise=True, post=[]))
            for r in range(2)]
    assert d["rmse"] == pytest.approx(np.mean([np.sqrt(((i - gt) ** 2).mean()) for i in imgs]), rel=1e-4)
    with open(tmp_path / "out" / "results.csv") as fh:
        table = list(csv.DictReader(fh))
    assert {r["label"] for r in table if r["denoise"] == "True"} == {"v4+oidn (biased)"}
    assert "oidn (biased)" in (tmp_path / "out" / "summary.md").read_text()


def test_cli_bench_denoise_option(tmp_path, capsys):
    scene_file = tmp_path / "tiny.json"
    scene_file.write_text(json.dumps(tiny_description(resolution=[16, 12])))
    rc = main(["bench", str(scene_file), "--versions", "v4", "--spp", "1", "--gt-spp", "16", "--repeats", "1",
               "--adaptive", "0", "--denoise", "1", "--out", str(tmp_path / "b"), "--no-progress"])
    assert rc == 0
    rows = json.loads((tmp_path / "b" / "results.json").read_text())["rows"]
    assert sorted(r["label"] for r in rows) == ["v4", "v4+oidn (biased)"]
    assert main(["bench", str(scene_file), "--denoise", "x", "--out", str(tmp_path / "c")]) == 2
    assert "--denoise" in capsys.readouterr().err
