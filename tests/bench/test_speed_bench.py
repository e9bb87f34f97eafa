"""The speed suite's measurement (draaw_mi.bench.speed): its reference passes and cache names,
its option checks and its report's default file. Renders are stubbed: nothing here times."""
from __future__ import annotations

import argparse
import os

import numpy as np
import pytest
from conftest import ROOT

from draaw_mi.bench import speed as sb
from draaw_mi.bench import suite as ss


def _fake_render(calls):
    """speed_bench.render stub: a 2x2 image that depends on the seed, 0.01 s."""
    def render(scene, integ, spp, seed):
        calls.append((spp, seed))
        return np.full((2, 2, 3), 0.5 + 0.01 * (seed % 7)), 0.01
    return render


@pytest.mark.parametrize("spp", [0, 64, 100, 1000, -128])
def test_reference_refuses_spp_that_are_not_whole_passes(monkeypatch, spp, tmp_path):
    """--ref-spp 100 rendered one 64-spp pass (no noise estimate: variance 0), 1000 rendered
    960 and 0 raised ZeroDivisionError."""
    calls = []
    monkeypatch.setattr(sb, "render", _fake_render(calls))
    with pytest.raises(ValueError, match=rf"draaw_mi.bench.speed.reference: spp {spp}; expected a multiple of 64 "
                                         r"that is at least 128"):
        sb.reference("x", 2, None, 3, spp, str(tmp_path))
    assert calls == [] and list(tmp_path.iterdir()) == []


def test_reference_renders_every_sample_in_64_spp_passes(monkeypatch):
    calls = []
    monkeypatch.setattr(sb, "render", _fake_render(calls))
    mean, var, _ = sb.reference("x", 2, None, 3, 256, "")
    assert [c[0] for c in calls] == [64] * 4 and len({c[1] for c in calls}) == 4
    passes = np.array([0.5 + 0.01 * (seed % 7) for _, seed in calls])
    assert np.allclose(mean, passes.mean()) and np.allclose(var, passes.var(ddof=1) / 4)


def _args(tmp_path, **kw):
    a = dict(sampler="independent", ref_spp=128, cache=str(tmp_path / "refs"), integrators="path;path",
             spp=4, repeats=2)
    a.update(kw)
    return argparse.Namespace(**a)


def test_an_edited_scene_gets_its_own_cached_reference(monkeypatch, tmp_path):
    """The cache name was {name}_{res}_d{depth}_{spp}.exr: an edited builder (or thesis.toml)
    reused the stale reference of the scene before the edit."""
    calls = []
    monkeypatch.setattr(sb, "render", _fake_render(calls))
    kind, builder, depth, rfilter = ss.SCENES["metal_018"]

    def brighter(res):
        d = builder(res)
        d["light"]["emitter"]["radiance"]["value"] = [18.0, 17.0, 16.0]
        return d
    args = _args(tmp_path)
    sb.bench("metal_018", 4, args)
    monkeypatch.setitem(ss.SCENES, "metal_018", (kind, brighter, depth, rfilter))
    sb.bench("metal_018", 4, args)
    files = sorted(os.listdir(tmp_path / "refs"))
    assert len(files) == 2 and all(f.startswith("metal_018_4_d5_128_") for f in files), files
    # the unchanged scene, built again, finds its own reference (no reference passes rendered)
    before = len(calls)
    sb.bench("metal_018", 4, args)
    assert len(calls) - before == 2 + 2 * 2             # warm-ups and timed renders only
    assert sorted(os.listdir(tmp_path / "refs")) == files


@pytest.mark.parametrize("flags, message", [
    (["--spp", "0"], "--spp 0; expected an integer >= 1"),
    (["--repeats", "0"], "--repeats 0; expected an integer >= 1"),
    (["--ref-spp", "100"], "--ref-spp 100; expected a multiple of 64 that is at least 128"),
    (["--ref-spp", "0"], "--ref-spp 0; expected a multiple of 64"),
    (["--res", "0"], "--res '0'; expected comma-separated integers >= 1"),
    (["--res", "x"], "--res 'x'; expected comma-separated integers >= 1"),
])
def test_main_checks_its_numbers_before_rendering(monkeypatch, tmp_path, capsys, flags, message):
    """--spp 0 rendered at the sampler's 64 spp and reported 0; --repeats 0 raised
    StatisticsError after the references were rendered."""
    monkeypatch.setattr(sb, "bench", lambda *a: pytest.fail("measured"))
    with pytest.raises(SystemExit) as e:
        sb.main(["--scenes", "metal_018", "--res", "4", "--cache", str(tmp_path), "--out", ""] + flags)
    assert e.value.code == 2 and message in capsys.readouterr().err


def test_main_does_not_overwrite_the_curated_results_by_default(monkeypatch, tmp_path):
    """The default --out was benchmarks/results/speed_suite.md, the hand-curated record (several
    runs and the "Samplers" section the README cites)."""
    row = dict(spec="path", time=0.1, mse=1.0, mse_se=0.0, t_ratio=1.0, mse_ratio=1.0, ratio=1.0)
    monkeypatch.setattr(sb, "bench", lambda name, res, args: dict(
        name=name, res=res, depth=5, rows=[row, dict(row, spec="draaw_v4")], noise=0.0, t_ref=0.0,
        ref_mean=0.5, kind="k"))
    written = []
    monkeypatch.setattr(sb, "print_report", lambda text, path: written.append(path))
    assert sb.main(["--scenes", "metal_018", "--res", "4", "--cache", str(tmp_path)]) == 0
    results = os.path.join(ROOT, "benchmarks", "results")           # the repository's, found by the test
    assert len(written) == 1 and os.path.abspath(written[0]) != os.path.join(results, "speed_suite.md")
    assert os.path.abspath(written[0]) == os.path.join(results, "speed_suite_latest.md")


def test_learning_time_trains_from_the_pilots_records_and_counts_their_cost(monkeypatch):
    """Where adaptive sampling's pilot decides (here forced at 32x32, 64 spp, the training
    taking 2,048 paths), the benchmark's learning time is the training from the pilot's
    records plus what recording them costs the pilot, as a first render pays it: no camera
    pass of its own runs, and the recording's cost is measured. Timing the decision with no
    records (the training's own camera pass) fails. (As in the suite, a warm-up render has
    read the share.)"""
    import mitsuba as mi

    from draaw_mi.integrators import guiding
    monkeypatch.setattr(guiding, "PILOTED_MIN_SAMPLES", 1)
    monkeypatch.setattr(guiding, "MIN_TRAIN_PATHS", 1)
    scene = ss.load("glossy_diffuse", 32)
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 5})
    mi.render(scene, integrator=integ, spp=64)      # the warm-up: its pilot reads the share
    traced, costs = [], []
    trace = guiding._trace
    monkeypatch.setattr(guiding, "_trace", lambda *a, **k: traced.append(a[2]) or trace(*a, **k))
    cost = sb.recording_cost
    monkeypatch.setattr(sb, "recording_cost", lambda *a, **k: costs.append(cost(*a, **k)) or costs[-1])
    seconds = sb.learning_time(integ, scene, 64)
    assert traced == [] and len(costs) == 1 and costs[0] >= 0.0
    assert seconds >= costs[0] and np.isfinite(seconds)
    assert integ.guides.guide(integ, scene, integ.selection_key(scene)) is not None


def test_each_scene_is_measured_with_the_earlier_ones_let_go(monkeypatch, tmp_path):
    """The suite releases the bare scenes ``draaw_mi.render`` keeps (``release_wrapped``)
    after every scene, before the next is measured: live scenes' BSDFs are traced into every
    later loop (six kept alive took the glossy panel's guide learning from 11 to 41 ms)."""
    events = []
    monkeypatch.setattr(sb, "bench", lambda name, res, args: events.append(name))
    monkeypatch.setattr(sb, "release_wrapped", lambda: events.append("release"))
    with pytest.raises(SystemExit):          # (every scene "skipped": nothing to report)
        sb.main(["--scenes", "metal_018,metals", "--res", "4", "--cache", str(tmp_path), "--out", ""])
    assert events == ["metal_018", "release", "metals", "release"]


def test_the_glass_scene_keeps_its_files_and_lets_its_scene_go():
    """``suite.glass`` loads the thesis scene to take its dict, whose meshes are files in the
    scene's scratch folder: the folder is kept, the scene is not (keeping the scene kept its
    five Python BSDFs alive, traced into every later scene's loops)."""
    import gc

    import mitsuba as mi

    def live_bsdfs():
        gc.collect()
        return sum(1 for o in gc.get_objects() if isinstance(o, mi.BSDF))
    before = live_bsdfs()
    d = ss.build("glass", 16)
    assert live_bsdfs() == before
    scene = ss.load_built(d)                 # its files are still there
    assert len(scene.shapes()) > 3 and live_bsdfs() > before
