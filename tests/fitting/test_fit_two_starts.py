"""fit_two_starts (draaw_mi.fitting.two_starts): the region-by-region merge of two fits' maps,
judged by renders of the captures against Mitsuba ``path`` references (8x8 maps, 32x32
images), and the whole procedure on the captures test's tile."""
from __future__ import annotations

import numpy as np
import pytest
from test_fit_captures import MAPS, N, TRUTH_C, TRUTH_M, TRUTH_R, path_renders, start_scene, tile, tile_captures

import draaw_mi
from draaw_mi.errors import ParameterError
from draaw_mi.fitting.captures import parse_captures
from draaw_mi.fitting.two_starts import _captures_error, fit_two_starts, merge

TRUTH = {"m.base_color": TRUTH_C, "m.roughness": TRUTH_R, "m.metallic": TRUTH_M}


@pytest.fixture(scope="module")
def references():
    return path_renders(draaw_mi.load_scene(tile(TRUTH_C, TRUTH_R, TRUTH_M)), tile_captures())


def test_the_merge_takes_each_region_from_the_maps_the_captures_prefer(references):
    """Two sets of maps, each the truth with one region wrong: ``base`` a false metal patch
    (metallic 1, a pale colour, rough) in the dielectric corner, ``other`` the metal patch's
    lower half dielectric. The merge tests both regions and takes only ``other``'s corner:
    the result is the truth, texel for texel, its error below both inputs'. Catches a merge
    that takes every region (the patch's hole comes in), takes none, swaps the metallic map
    alone (the corner keeps a pale colour), or compares errors of different renders."""
    base = {k: v.copy() for k, v in TRUTH.items()}
    base["m.metallic"][6:8, 0:2] = 1.0
    base["m.base_color"][6:8, 0:2] = 0.9
    base["m.roughness"][6:8, 0:2] = 0.9
    other = {k: v.copy() for k, v in TRUTH.items()}
    other["m.metallic"][4:6, 2:6] = 0.0
    other["m.base_color"][4:6, 2:6] = 0.15
    scene = start_scene()
    caps = parse_captures(tile_captures(), references)
    masks = [None] * len(references)

    def error(values):
        return _captures_error(scene, values, caps, references, masks, "v4", 64, 0)

    e_base, e_other = error(base), error(other)
    merged, e, tested, taken = merge(scene, base, other, e_base, ["m.metallic"], error)
    assert (tested, taken) == (2, 1)
    for k, v in TRUTH.items():
        assert np.array_equal(merged[k], v), k
    assert e < min(e_base, e_other), (e, e_base, e_other)
    assert error(TRUTH) == pytest.approx(e, rel=1e-6)       # the same seeds: the same renders


def test_two_starts_fit_merges_refines_and_reports_its_stages(references):
    """The whole procedure, small (two fits of 40 iterations, a refine of 10): finite maps in
    range, each stage's error reported, the merged maps' error at or below both fits' (the
    greedy merge only accepts improvements), the history and time of all three fits. Catches
    a merge that can raise the error, a refine that does not start from the merged maps (its
    history would not be the third fit's) and a second start that is not metallic 0."""
    res = fit_two_starts(start_scene(), references, MAPS, captures=tile_captures(), spp=8, iterations=40,
                         refine=0.25, batch=2, lr=0.1, progress=False)
    names = [s["stage"] for s in res.stages]
    assert names == ["from the scene's start", "from metallic 0", "merged", "refined"], res.stages
    errors = {s["stage"]: s["error"] for s in res.stages}
    assert errors["merged"] <= min(errors["from the scene's start"], errors["from metallic 0"])
    assert res.iterations == 90 and len(res.history) == 90
    assert res.history[40]["values"]["m.metallic"] is not None
    first_b = np.asarray(res.history[40]["values"]["m.metallic"])
    assert first_b.max() < 0.2, first_b.max()      # the second fit's first step: near 0, not 0.5
    for name in MAPS:
        v = np.asarray(res.values[name])
        assert v.shape[:2] == (N, N) and np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1, name
    assert all(s["seconds"] >= 0 for s in res.stages)


def test_two_starts_refuses_what_it_cannot_merge(references):
    with pytest.raises(ParameterError, match="hold no metallic map"):
        fit_two_starts(start_scene(), references, ["m.base_color"], captures=tile_captures(), iterations=1)
    with pytest.raises(ParameterError, match="refine=2"):
        fit_two_starts(start_scene(), references, MAPS, captures=tile_captures(), iterations=1, refine=2)
    with pytest.raises(ParameterError, match="post chain"):
        fit_two_starts(start_scene(), references, MAPS, captures=tile_captures(), iterations=1,
                       post=[{"type": "tonemap"}])


def test_cli_fits_from_two_starts_and_prints_each_stage(references, tmp_path, capsys):
    """``draaw-mi fit SCENE --captures FILE --two-starts``: each stage's captures error is
    printed, and the maps written; without ``--captures`` it is refused. Catches a flag that
    does not reach fit_two_starts (no stage lines) and one taken without captures to merge by."""
    import json

    from draaw_mi.cli import main
    scene_file = tmp_path / "tile.json"
    scene_file.write_text(json.dumps(tile(np.full((N, N, 3), 0.5), np.full((N, N, 1), 0.5), np.full((N, N, 1), 0.5))))
    caps = []
    for i, c in enumerate(tile_captures()):
        draaw_mi.write_exr(str(tmp_path / f"photo{i}.exr"), references[i])
        caps.append({**c, "camera": {k: np.asarray(v).tolist() for k, v in c["camera"].items()},
                     "reference": f"photo{i}.exr"})
    (tmp_path / "captures.json").write_text(json.dumps(caps))
    rc = main(["fit", str(scene_file), "--captures", str(tmp_path / "captures.json"), "--param", "m.base_color",
               "--param", "m.metallic", "--iterations", "4", "--spp", "4", "--batch", "2", "--two-starts",
               "--maps", str(tmp_path / "maps"), "--no-progress"])
    assert rc == 0
    out = capsys.readouterr().out
    for stage in ("from the scene's start: captures error", "from metallic 0: captures error", "merged: captures error",
                  "refined: captures error"):
        assert stage in out, out
    assert (tmp_path / "maps" / "m.metallic.exr").is_file()
    rc = main(["fit", str(scene_file), "--reference", str(tmp_path / "photo0.exr"), "--param", "m.metallic",
               "--two-starts", "--no-progress"])
    assert rc != 0 and "--two-starts merges fits by each capture's error" in capsys.readouterr().err
