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


def test_the_merge_takes_each_region_from_the_maps_the_captures_prefer(references, capsys):
    """Two sets of maps, each the truth with one region wrong: ``base`` a false metal patch
    (metallic 1, a pale colour, rough) in the dielectric corner, ``other`` the metal patch's
    lower half dielectric. The merge tests both regions and takes only ``other``'s corner:
    the result is the truth, texel for texel, its error below both inputs'. Catches a merge
    that takes every region (the patch's hole comes in), takes none, swaps the metallic map
    alone (the corner keeps a pale colour), or compares errors of different renders. Its
    progress, as lines, ends at both regions."""
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
    merged, e, tested, taken = merge(scene, base, other, e_base, ["m.metallic"], error, progress="lines")
    assert (tested, taken) == (2, 1)
    assert "two starts: merge: 2/2 region (100 %)" in capsys.readouterr().err
    for k, v in TRUTH.items():
        assert np.array_equal(merged[k], v), k
    assert e < min(e_base, e_other), (e, e_base, e_other)
    assert error(TRUTH) == pytest.approx(e, rel=1e-6)       # the same seeds: the same renders


def test_the_merge_error_leaves_out_the_renders_own_noise(references):
    """The truth's maps against ``path`` references (captures 0-2: the fourth's glint makes
    its reference's own noise dominate): at 4 spp the two-render estimate reads what it reads
    at 256 spp (the references' noise and any bias), where one render's mean squared
    difference reads 8-9x that (its own variance). Catches an error that squares one
    render's difference (metal, whose highlights are noisier, then loses to dielectric maps
    that explain the captures worse: the sphere's hole of ``benchmarks/results/svbrdf_fit.md``),
    or two renders with one seed."""
    from draaw_mi.fitting.captures import render_capture
    scene = start_scene()
    caps = parse_captures(tile_captures(), references)[:3]
    refs = references[:3]

    def estimate(spp):
        return _captures_error(scene, TRUTH, caps, refs, [None] * 3, "v4", spp, 0)

    settled = estimate(256)                  # (the scene now holds the truth's maps)
    single = np.mean([np.mean((render_capture(scene, {k: v for k, v in c.items() if k != "reference"}, spp=4,
                                              version="v4", seed=i).astype(np.float64) - ref[..., :3]) ** 2)
                      for i, (c, ref) in enumerate(zip(caps, refs))])
    assert abs(estimate(4) - settled) < 0.2 * (single - settled), (estimate(4), settled, single)


def test_two_starts_fit_merges_refines_and_reports_its_stages(references, monkeypatch):
    """The whole procedure, small (two fits of 40 iterations, a refine of 10), each fit()
    call's starting maps recorded: the first from the scene's (metallic 0.5), the second with
    metallic 0, the refine from exactly the merged maps; finite maps in range, each stage's
    error, the merged error at or below both fits' (the greedy merge only accepts
    improvements), the three fits' history and iterations, the scene left holding the result.
    Catches a second start that is not metallic 0, a refine that starts elsewhere than the
    merge's maps, a merge that can raise the error."""
    from draaw_mi.fitting import two_starts
    starts, merged = [], {}
    real_fit, real_merge = two_starts.fit, two_starts.merge

    def recording_fit(scene, *args, **kwargs):
        starts.append({n: np.array(scene.all_params[scene.key(n)]).copy() for n in MAPS})
        return real_fit(scene, *args, **kwargs)

    def recording_merge(*args, **kwargs):
        out = real_merge(*args, **kwargs)
        merged.update(out[0])
        return out

    monkeypatch.setattr(two_starts, "fit", recording_fit)
    monkeypatch.setattr(two_starts, "merge", recording_merge)
    scene = start_scene()
    res = fit_two_starts(scene, references, MAPS, captures=tile_captures(), spp=8, iterations=40,
                         refine=0.25, batch=2, lr=0.1, progress=False)
    assert len(starts) == 3
    assert np.all(starts[0]["m.metallic"] == 0.5) and np.all(starts[1]["m.metallic"] == 0.0)
    assert np.array_equal(starts[0]["m.base_color"], starts[1]["m.base_color"])      # the same start otherwise
    for n in MAPS:
        assert np.allclose(starts[2][n], merged[n], atol=1e-6), n
    names = [s["stage"] for s in res.stages]
    assert names == ["from the scene's start", "from metallic 0", "merged", "refined"], res.stages
    errors = {s["stage"]: s["error"] for s in res.stages}
    assert errors["merged"] <= min(errors["from the scene's start"], errors["from metallic 0"])
    assert res.iterations == 90 and len(res.history) == 90
    for name in MAPS:
        v = np.asarray(res.values[name])
        assert v.shape[:2] == (N, N) and np.all(np.isfinite(v)) and v.min() >= 0 and v.max() <= 1, name
        assert np.allclose(np.array(scene.all_params[scene.key(name)]).reshape(v.shape), v, atol=1e-6), name


def test_two_starts_refuses_what_it_cannot_merge(references, monkeypatch):
    """Each refusal comes before any fit runs (a fit fails the test)."""
    def no_fit(*args, **kwargs):
        raise AssertionError("fit_two_starts ran a fit before refusing its arguments")
    monkeypatch.setattr("draaw_mi.fitting.two_starts.fit", no_fit)
    caps = tile_captures()
    cases = [(dict(params=["m.base_color"]), "hold no metallic parameter"),
             (dict(refine=0), "refine=0"), (dict(refine=2), "refine=2"), (dict(eval_spp=0), "eval_spp=0"),
             (dict(post=[{"type": "tonemap"}]), "post= gives a post chain"),
             (dict(exposure="fit"), "exposure='fit'"), (dict(init={"m.metalic": 0.0}), "init names"),
             (dict(polish=-1), "polish=-1"), (dict(polish=2, polish_spp=0), "polish_spp=0")]
    for kwargs, message in cases:
        kwargs = {"params": MAPS, **kwargs}
        with pytest.raises(ParameterError, match=message):
            fit_two_starts(start_scene(), references, captures=caps, iterations=1, **kwargs)


def test_a_metallic_map_at_zero_starts_at_half_and_a_failed_fit_restores_the_scene(references, monkeypatch):
    """A scene whose metallic map is 0 everywhere (the material's default) would run the same
    fit twice: its first start is 0.5. A fit that fails (here: interrupted) leaves the scene
    with its own values, not a start or a candidate. Catches two identical starts and a
    scene left at 0.5 after a failure."""
    from draaw_mi.fitting import two_starts
    seen = []

    def interrupted_fit(scene, *args, **kwargs):
        seen.append(np.array(scene.all_params[scene.key("m.metallic")]).copy())
        raise KeyboardInterrupt

    monkeypatch.setattr(two_starts, "fit", interrupted_fit)
    half = np.full((N, N, 1), 0.5, np.float32)
    scene = draaw_mi.load_scene(tile(np.full((N, N, 3), 0.5, np.float32), half, np.zeros_like(half)))
    with pytest.raises(KeyboardInterrupt):
        fit_two_starts(scene, references, MAPS, captures=tile_captures(), iterations=1)
    assert np.all(seen[0] == 0.5)
    assert np.all(np.array(scene.all_params[scene.key("m.metallic")]) == 0.0)


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
