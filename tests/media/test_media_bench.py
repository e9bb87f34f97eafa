"""``draaw-mi bench`` on a scene with media: volpath ground truth, volpath stands in for path,
versions that cannot render media are skipped, V1/V2 refuse media with a clear error."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi
from draaw_mi import bench

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SMOKE = os.path.join(ROOT, "scenes", "smoke.toml")


def test_media_versions_mapping():
    assert bench._media_versions(["v1", "v2", "v3", "v4", "path", "prb"]) == ["v3", "v4", "volpath"]


@pytest.mark.slow
def test_bench_study_on_smoke_scene(tmp_path):
    res = bench.run_study([SMOKE], versions=["v4", "path", "v1"], spps=(2,), adaptive=(None, 8), repeats=2,
                          resolution=(12, 10), gt_spp=64, out_dir=str(tmp_path), progress=False)
    labels = {r["label"] for r in res["rows"]}
    assert labels == {"draaw_v4", "volpath"} or labels == {"v4", "volpath"}, labels
    for r in res["rows"]:
        assert r["finite"] and np.isfinite(r["rmse"])


def test_v1_v2_refuse_media_with_one_line():
    s = draaw_mi.load_scene(SMOKE, resolution=(8, 6))
    for v in ("v1", "v2"):
        with pytest.raises(Exception) as e:
            draaw_mi.render(s, version=v, spp=1)
        err = e.value if isinstance(e.value, draaw_mi.DraawError) else e.value.__cause__
        assert isinstance(err, draaw_mi.RenderError) and "participating media" in str(err)
        assert "\n" not in str(err)
