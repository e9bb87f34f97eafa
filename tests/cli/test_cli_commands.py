"""The CLI sub-commands users script: ``post``, ``render --post``, ``info --json``, ``bench``
(with ``--camera-path``) and ``fit`` (``--views``, ``--post``, ``--loss``, PNG references).

Outputs are checked against independent computations: the numpy post-filter reference of
tests/post, the library called directly, Mitsuba renders and the sRGB formulas.
"""
from __future__ import annotations

import json
import os

import matplotlib.image
import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.cli.parser import build_parser

from conftest import SCENES, tiny_description

CHAIN = [{"type": "contrast", "contrast": 1.3, "pivot": 0.4}]


def _contrast(c):                                 # the chain above, in numpy
    return (c - 0.4) * 1.3 + 0.4


@pytest.fixture
def tiny_file(tmp_path):
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(tiny_description(resolution=[12, 10])))
    return str(path)


@pytest.fixture
def chain_file(tmp_path):
    path = tmp_path / "chain.json"
    path.write_text(json.dumps(CHAIN))
    return str(path)


def test_post_applies_the_chain_to_colour_and_keeps_other_channels(tmp_path, chain_file, capsys):
    rng = np.random.default_rng(2)
    img = rng.random((7, 9, 5)).astype(np.float32)
    src = str(tmp_path / "in.exr")
    draaw_mi.write_exr(src, img, channels=["R", "G", "B", "depth", "normal.X"],
                       metadata={"draaw:version": "draaw_v4", "draaw:spp": 16, "other": "x"})
    assert main(["post", src, "-o", str(tmp_path / "out.exr"), "--chain", chain_file]) == 0
    from draaw_mi.batch.exr import read_header
    header = read_header(str(tmp_path / "out.exr"))
    # what rendered the input goes along, with the chain applied; other attributes do not
    assert header["draaw:version"] == "draaw_v4" and header["draaw:spp"] == 16 and "other" not in header
    assert json.loads(header["draaw:post"]) == json.loads(open(chain_file).read())
    # a second post run: the header lists both chains, in the order they ran (the first one
    # was overwritten, though the image had been through it)
    assert main(["post", str(tmp_path / "out.exr"), "-o", str(tmp_path / "twice.exr"), "--chain", chain_file]) == 0
    assert json.loads(read_header(str(tmp_path / "twice.exr"))["draaw:post"]) == 2 * CHAIN
    out, names = draaw_mi.read_exr(str(tmp_path / "out.exr"), with_names=True)
    assert names == ["R", "G", "B", "depth", "normal.X"]
    assert np.allclose(out[..., :3], _contrast(img[..., :3]), atol=1e-6)
    assert np.array_equal(out[..., 3:], img[..., 3:])                # AOVs untouched
    # PNG output: the sRGB encoding of the same result, 8 bits
    assert main(["post", src, "-o", str(tmp_path / "out.png"), "--chain", chain_file]) == 0
    png = matplotlib.image.imread(str(tmp_path / "out.png"))[..., :3]
    c = np.clip(_contrast(img[..., :3]), 0, 1)
    enc = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    assert np.abs(png - enc).max() <= 0.5 / 255 + 1e-6
    assert "wrote" in capsys.readouterr().out


def test_post_reads_non_finite_colour_as_zero_and_says_so(tmp_path, chain_file, capsys):
    img = np.random.default_rng(3).random((6, 8, 4)).astype(np.float32)
    img[1, 2, 0] = img[4, 4, 1] = np.nan
    img[5, 7, 2] = np.inf
    img[0, 0, 3] = np.nan                                  # an AOV's NaN is its own business
    src = str(tmp_path / "in.exr")
    draaw_mi.write_exr(src, img, channels=["R", "G", "B", "depth"])
    assert main(["post", src, "-o", str(tmp_path / "out.exr"), "--chain", chain_file]) == 0
    err = capsys.readouterr().err
    assert "3 non-finite colour values" in err and "in.exr" in err
    out = draaw_mi.read_exr(str(tmp_path / "out.exr"))
    clean = np.nan_to_num(img[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    assert np.allclose(out[..., :3], _contrast(clean), atol=1e-6)
    assert np.isnan(out[0, 0, 3]) and np.array_equal(out[1:, :, 3], img[1:, :, 3])
    # a finite image: no warning
    assert main(["post", str(tmp_path / "out.exr"), "-o", str(tmp_path / "b.exr"), "--chain", chain_file]) == 0
    assert "non-finite" not in capsys.readouterr().err


@pytest.mark.parametrize("extra", [["--post", "CHAIN"], []])
def test_render_warns_of_non_finite_pixels_even_behind_a_post_chain(tmp_path, chain_file, capsys, extra):
    """The post chain reads NaN/inf as 0: the warning comes from the render's own count."""
    desc = tiny_description(resolution=[8, 6])
    desc["lights"][1]["intensity"] = 3.4e38              # fits float32; four samples do not
    path = tmp_path / "inf.json"
    path.write_text(json.dumps(desc))
    argv = ["render", str(path), "-o", str(tmp_path / "o.exr"), "--no-progress"]
    assert main(argv + [chain_file if a == "CHAIN" else a for a in extra]) == 0
    assert "WARNING: non-finite pixels" in capsys.readouterr().out
    desc["lights"][1]["intensity"] = 0.2
    path.write_text(json.dumps(desc))
    assert main(argv + [chain_file if a == "CHAIN" else a for a in extra]) == 0
    assert "non-finite" not in capsys.readouterr().out


def test_render_gives_one_image_with_a_bar_or_without(tmp_path, monkeypatch):
    """One pass layout either way: a bar made 16-spp passes, a pipe one of 48, and
    their seeds other samples (the same command gave two images)."""
    import draaw_mi.cli.commands as cli
    desc = tiny_description(resolution=[8, 6], spp=48)
    path = tmp_path / "s.json"
    path.write_text(json.dumps(desc))
    images = []
    for mode in ("bar", False):
        monkeypatch.setattr(cli, "progress_mode", lambda no_progress, m=mode: m)
        out = str(tmp_path / f"{mode}.exr")
        assert main(["render", str(path), "-o", out]) == 0
        images.append(draaw_mi.read_exr(out))
    assert np.array_equal(images[0], images[1])


def test_render_records_the_scenes_own_chain(tmp_path):
    """Without --post the scene's chain is applied: the header says so (render's info["post"])."""
    from draaw_mi.batch.exr import read_header
    desc = dict(tiny_description(resolution=[8, 6]), post=CHAIN)
    path = tmp_path / "s.json"
    path.write_text(json.dumps(desc))
    assert main(["render", str(path), "-o", str(tmp_path / "o.exr"), "--no-progress"]) == 0
    (entry,) = json.loads(read_header(str(tmp_path / "o.exr"))["draaw:post"])
    assert {k: entry[k] for k in CHAIN[0]} == CHAIN[0]            # (with its defaults spelled out)


def test_render_post_is_the_chain_applied_to_the_plain_render(tmp_path, tiny_file, chain_file):
    base = ["render", tiny_file, "--spp", "4", "--seed", "7", "--version", "path"]
    assert main(base + ["-o", str(tmp_path / "plain.exr")]) == 0
    assert main(base + ["-o", str(tmp_path / "post.exr"), "--post", chain_file]) == 0
    plain, post = draaw_mi.read_exr(str(tmp_path / "plain.exr")), draaw_mi.read_exr(str(tmp_path / "post.exr"))
    assert np.abs(post - plain).max() > 0.01
    assert np.allclose(post, _contrast(plain), atol=1e-5)


def test_info_json_describes_the_setup_and_the_scene(tiny_file, capsys):
    assert main(["info", "--json", tiny_file]) == 0
    out = json.loads(capsys.readouterr().out)
    import mitsuba as mi
    assert out["variant"] == mi.variant() and out["mitsuba"] == mi.__version__
    assert "draaw" in out["plugins"]["bsdf"]
    assert {"draaw_v1", "draaw_v2", "draaw_v3", "draaw_v4"} <= set(out["plugins"]["integrators"])
    assert out["versions"]["v4"] == "draaw_v4"
    s = out["scene"]
    assert list(s["resolution"]) == [12, 10]
    assert set(s["shapes"]) >= {"ball_shape", "floor"} and set(s["materials"]) == {"ball", "ground"}
    assert isinstance(s["features"], dict) and s["features"]


def test_a_reader_that_leaves_ends_the_command_quietly(tiny_file, monkeypatch, capsys):
    """``draaw-mi info --json SCENE | head -3`` (or a batch --dry-run's listing) ended in a
    BrokenPipeError traceback: the command now ends as a shell tool does on SIGPIPE."""
    import signal
    import sys

    class Gone:                                  # a pipe whose reader has left
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            pass
    monkeypatch.setattr(sys, "stdout", Gone())
    assert main(["info", "--json", tiny_file]) == 128 + signal.SIGPIPE
    assert "Traceback" not in capsys.readouterr().err


def test_bench_quick_with_a_camera_path(tmp_path, tiny_file, capsys):
    keys = [[0.0, 1.0, 5.0, 0.0, 0.0], [1.0, 1.2, 4.0, 0.2, 0.1]]
    (tmp_path / "keys.json").write_text(json.dumps(keys))
    out = tmp_path / "bench"
    rc = main(["bench", tiny_file, "--quick", "--versions", "v4,path", "--spp", "1,2", "--adaptive", "0",
               "--repeats", "2", "--resolution", "8x6", "--gt-spp", "16", "--out", str(out),
               "--camera-path", str(tmp_path / "keys.json"), "--frames", "3", "--no-progress"])
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    rows = res["rows"]
    assert sorted((r["label"], r["spp"]) for r in rows) == [("path", 1), ("path", 2), ("v4", 1), ("v4", 2)]
    assert all(r["resolution"] == [8, 6] and r["repeats"] == 2 for r in rows)
    assert res["ground_truth_spp"] == 16
    frames = json.loads((out / "frame_times.json").read_text())
    assert [f["version"] for f in frames] == ["v4", "path"]
    assert all(f["frames"] == 3 and f["min_s"] <= f["median_s"] <= f["max_s"] for f in frames)
    printed = capsys.readouterr().out
    assert "frame_times.json" in printed and "4 settings" in printed


@pytest.mark.parametrize("keys, frames, message", [
    ([{"x": 0, "y": 1, "z": 5, "cameraX": 0}], "3", "keyframe 0 lacks 'cameraY'"),
    ({"x": 0}, "3", "expected a list of keyframes"),
    ([[0.0, 1.0, 5.0, 0.0, 0.0], [1.0, 1.2, 4.0, 0.2, 0.1]], "1", "--frames 1; a camera path needs at least 2"),
])
def test_bench_checks_its_camera_path_before_the_study(tmp_path, tiny_file, capsys, monkeypatch,
                                                       keys, frames, message):
    """Bad keyframes or --frames failed after the whole accuracy study (minutes at the
    defaults), or with a traceback."""
    from draaw_mi.bench import study as bench
    monkeypatch.setattr(bench, "run_study", lambda *a, **k: pytest.fail("the study ran"))
    (tmp_path / "keys.json").write_text(json.dumps(keys))
    rc = main(["bench", tiny_file, "--quick", "--out", str(tmp_path / "b"), "--frames", frames,
               "--camera-path", str(tmp_path / "keys.json"), "--no-progress"])
    assert rc == 2 and message in capsys.readouterr().err


@pytest.mark.parametrize("flags, message", [
    (["--resolution", "abc"], "--resolution 'abc'"),
    (["--resolution", "0"], "--resolution '0'"),
    (["--spp", "0"], "--spp '0'; expected one integer >= 1"),
    (["--spp", "abc"], "--spp 'abc': expected comma-separated integers"),
    (["--repeats", "0"], "--repeats 0"),
    # (the reference rendered, then Mitsuba refused the suite's scene dict for 'scene')
    (["--versions", "scene"], "--versions 'scene': the suite's scenes are built in Python"),
    (["--versions", "v4,,path"], "bench --suite speed: --versions 'v4,,path': render version ''"),
    (["--spp", ""], "--spp '': empty"),                 # (was the default, silently)
])
def test_bench_suite_speed_checks_its_flags(tmp_path, capsys, flags, message):
    rc = main(["bench", "--suite", "speed", "metal_018", "--out", str(tmp_path / "s")] + flags)
    err = capsys.readouterr().err
    assert rc == 2 and message in err and "Traceback" not in err, err


def test_bench_suite_speed_passes_gt_spp_and_refuses_the_options_it_does_not_use(tmp_path, capsys, monkeypatch):
    """An explicit --gt-spp 4096 became 1024 (taken for the study's default), and --max-depth,
    --adaptive, --quick and --denoise were dropped silently."""
    from draaw_mi.bench import speed as speed_bench
    seen = []
    monkeypatch.setattr(speed_bench, "main", lambda argv, command=None: seen.append(argv) or 0)
    base = ["bench", "--suite", "speed", "metal_018", "--out", str(tmp_path / "s")]
    for gt, ref in (["--gt-spp", "4096"], "4096"), ([], "1024"), (["--gt-spp", "256"], "256"):
        assert main(base + gt) == 0
        assert seen[-1][seen[-1].index("--ref-spp") + 1] == ref
    for flags, named in ((["--max-depth", "12"], "--max-depth does"), (["--adaptive", "0"], "--adaptive does"),
                         (["--quick"], "--quick does"), (["--denoise", "4"], "--denoise does"),
                         (["--max-depth", "3", "--quick", "--frames", "9"], "--max-depth, --quick, --frames do"),
                         (["--gt-spp", "100"], "--gt-spp 100 (the reference's spp); expected a multiple of 64")):
        capsys.readouterr()
        assert main(base + flags) == 2
        err = capsys.readouterr().err
        assert named in err and "Traceback" not in err, err
    assert len(seen) == 3


def test_bench_refuses_study_options_for_sdf_scenes_it_would_ignore(tmp_path, capsys, monkeypatch):
    """Scenes with [[sdf]] objects run the SDF tracer study, which uses none of --spp,
    --versions, --gt-spp, --max-depth, --camera-path: they were ignored with exit 0."""
    from draaw_mi.bench import study as bench
    from draaw_mi.cli import bench as study          # the module that runs the SDF study
    ran = []
    monkeypatch.setattr(study, "run_sdf_study", lambda scene, out, **kw: ran.append("sdf") or
                        {"scene": "sdf_csg", "rows": []})
    monkeypatch.setattr(bench, "run_study", lambda scenes, **kw: ran.append(len(scenes)) or {"rows": []})
    sdf = os.path.join(SCENES, "sdf_csg.toml")
    out = str(tmp_path / "b")
    assert main(["bench", sdf, "--spp", "1,2", "--versions", "v4", "--max-depth", "3", "--out", out]) == 2
    err = capsys.readouterr().err
    assert ("sdf_csg.toml has [[sdf]] objects" in err and "does not use --spp, --versions, --max-depth" in err
            and "leave them out" in err), err
    assert main(["bench", sdf, "--gt-spp", "64", "--out", out]) == 2
    assert "does not use --gt-spp" in capsys.readouterr().err and ran == []
    # its own options are fine; beside another scene the study options apply to that one (said)
    assert main(["bench", sdf, "--quick", "--repeats", "1", "--out", out, "--no-progress"]) == 0
    assert ran == ["sdf"]
    assert main(["bench", sdf, os.path.join(SCENES, "cornell.toml"), "--spp", "1", "--out", out,
                 "--no-progress"]) == 0
    assert ran == ["sdf", "sdf", 1]
    assert "does not use --spp (it applies to the other scenes only)" in capsys.readouterr().err


def test_fit_passes_views_post_and_loss_through(tmp_path, chain_file, monkeypatch, capsys):
    """--views (one camera table per --reference), --post and --loss reach fit() unchanged,
    and the run completes with a scene written."""
    views = [{"origin": [0.0, 0.7, 3.2], "target": [0.0, 0.5, 0.0], "fov": 30.0},
             {"origin": [2.4, 1.9, 1.8], "target": [0.0, 0.3, 0.0], "fov": 34.0}]
    (tmp_path / "views.json").write_text(json.dumps(views))
    scene_file = _small_fit_scene(tmp_path)
    refs = []
    for i in range(2):
        refs.append(str(tmp_path / f"ref{i}.exr"))
        draaw_mi.write_exr(refs[-1], np.full((16, 16, 3), 0.2 + 0.1 * i, np.float32))
    seen = {}
    real_fit = draaw_mi.fit

    def spy(scene, references, **kw):
        seen.update(kw, references=references)
        seen["result"] = real_fit(scene, references, **kw)
        return seen["result"]
    from draaw_mi.cli import commands              # the module that calls fit()
    monkeypatch.setattr(commands, "fit", spy)
    rc = main(["fit", scene_file, "--reference", refs[0], "--reference", refs[1], "--param", "target.roughness",
               "--views", str(tmp_path / "views.json"), "--post", chain_file, "--loss", "l1",
               "--iterations", "2", "--spp", "2", "-o", str(tmp_path / "out.json"), "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    assert seen["references"] == refs and seen["views"] == views and seen["loss"] == "l1"
    x = np.random.default_rng(0).random((4, 5, 3)).astype(np.float32)
    assert np.allclose(np.array(draaw_mi.post.apply(x, seen["post"])), _contrast(x), atol=1e-6)
    assert seen["params"] == ["target.roughness"]
    written = draaw_mi.load_scene(str(tmp_path / "out.json")).params["target.roughness.value"]
    assert float(np.array(written).ravel()[0]) == pytest.approx(seen["result"].values["target.roughness"], abs=1e-6)


def _small_fit_scene(tmp_path):
    import tomllib
    import tomli_w
    with open(os.path.join(SCENES, "fit_sphere.toml"), "rb") as f:
        desc = tomllib.load(f)
    desc["render"]["resolution"] = [16, 16]
    path = tmp_path / "fit_small.toml"
    path.write_text(tomli_w.dumps(desc))
    return str(path)


def test_a_chain_that_ends_in_srgb_is_not_encoded_twice_in_pngs(tmp_path):
    """A chain ending in ``srgb`` leaves display-encoded values: ``post -o x.png`` and
    ``render --png`` store them as they are (both encoded them again: mean 108 against 53)."""
    import matplotlib.image
    chain = tmp_path / "srgb.json"
    chain.write_text(json.dumps([{"type": "contrast", "contrast": 1.2}, {"type": "srgb"}]))
    img = np.random.default_rng(3).random((6, 5, 3)).astype(np.float32) * 0.5
    src = str(tmp_path / "in.exr")
    draaw_mi.write_exr(src, img)
    assert main(["post", src, "-o", str(tmp_path / "p.exr"), "--chain", str(chain)]) == 0
    assert main(["post", src, "-o", str(tmp_path / "p.png"), "--chain", str(chain)]) == 0
    encoded = draaw_mi.read_exr(str(tmp_path / "p.exr"))
    png = matplotlib.image.imread(str(tmp_path / "p.png"))[..., :3]
    assert np.abs(png - np.clip(encoded, 0, 1)).max() <= 0.5 / 255 + 1e-6
    exr, png_path = tmp_path / "c.exr", tmp_path / "c.png"
    assert main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(exr), "--png", str(png_path),
                 "--spp", "2", "--resolution", "16x12", "--version", "path", "--post", str(chain)]) == 0
    png = matplotlib.image.imread(str(png_path))[..., :3]
    assert np.abs(png - np.clip(draaw_mi.read_exr(str(exr)), 0, 1)).max() <= 0.5 / 255 + 1e-6


def test_png_reference_is_srgb_decoded(tmp_path):
    """A PNG reference is display-encoded sRGB: fit() works on its linear values."""
    from draaw_mi.fitting.fitter import load_reference
    rng = np.random.default_rng(4)
    linear = rng.random((6, 8, 3)).astype(np.float32) ** 2
    draaw_mi.write_png(str(tmp_path / "r.png"), linear)
    back = load_reference(str(tmp_path / "r.png"))
    enc = lambda c: np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.clip(c, 0, 1) ** (1 / 2.4) - 0.055)  # noqa: E731
    assert back.shape == (6, 8, 3) and np.abs(enc(back) - enc(linear)).max() <= 0.5 / 255 + 1e-5
    grey = np.full((2, 2, 3), 128, np.uint8)                     # sRGB 128/255 -> 0.2158605 linear
    matplotlib.image.imsave(str(tmp_path / "g.png"), grey)
    assert np.allclose(load_reference(str(tmp_path / "g.png")), ((128 / 255 + 0.055) / 1.055) ** 2.4, atol=1e-5)


def test_cli_fit_accepts_a_png_reference(tmp_path, monkeypatch):
    scene_file = _small_fit_scene(tmp_path)
    draaw_mi.write_png(str(tmp_path / "ref.png"), np.full((16, 16, 3), 0.2158605, np.float32))
    seen = {}
    import sys
    fit_mod = sys.modules["draaw_mi.fitting.fitter"]
    real = fit_mod.load_reference

    def spy(ref, encoded=False, who="fit"):
        seen.setdefault("arrays", []).append(real(ref, encoded, who))
        return seen["arrays"][-1]
    monkeypatch.setattr(fit_mod, "load_reference", spy)
    assert main(["fit", scene_file, "--reference", str(tmp_path / "ref.png"), "--param", "target.metallic",
                 "--iterations", "1", "--spp", "1", "--no-progress"]) == 0
    assert len(seen["arrays"]) == 1 and np.allclose(seen["arrays"][0], 0.2158605, atol=2e-3)


def test_bench_suite_speed(tmp_path, capsys, monkeypatch):
    """`draaw-mi bench --suite speed`: the speed suite on one small scene; each cell is the time
    ratio times the MSE ratio, one column per version, the reference cached under --out."""
    import re
    out = tmp_path / "suite"
    argv = ["bench", "--suite", "speed", "metal_018", "--versions", "v4,v2", "--resolution", "16",
            "--repeats", "2", "--spp", "8", "--gt-spp", "128", "--out", str(out)]
    assert main(argv) == 0
    text = (out / "speed_suite.md").read_text()
    assert "`draaw_v4` | `draaw_v2`" in text
    # the report's command is the one typed, runnable as pasted (it was the script's flags,
    # with an unquoted ';')
    import shlex
    command = re.search(r"Command: `([^`]*)`", text).group(1)
    assert shlex.split(command) == ["draaw-mi"] + argv
    row = next(line for line in text.splitlines() if line.startswith("| metal_018 |"))
    cells = re.findall(r"\*\*([\d.]+)\*\* \(([\d.]+), ([\d.]+)\)", row)
    assert len(cells) == 2
    for ratio, t, mse in cells:
        assert float(t) > 0 and float(mse) > 0
        assert abs(float(ratio) - float(t) * float(mse)) <= 0.01 + 0.01 * float(ratio)
    import doctest
    import draaw_mi.bench.speed as sb
    assert doctest.testmod(sb).failed == 0            # the cells' number format
    (ref,) = (out / "refs").glob("metal_018_16_d5_128_*.exr")       # (+ the scene's content hash)
    stamp = ref.stat().st_mtime_ns
    assert main(argv) == 0 and ref.stat().st_mtime_ns == stamp          # reused, not re-rendered
    assert main(["bench", "--suite", "speed", "metal018", "--out", str(out)]) == 2
    assert "did you mean 'metal_018'" in capsys.readouterr().err
    # the GO-Draaw mesh absent: the scene is skipped saying where it was looked for, and a run
    # that measured nothing fails (it wrote an empty table and exited 0)
    from draaw_mi.bench import suite as speed_suite
    monkeypatch.setattr(speed_suite, "GO_DRAAW", str(tmp_path / "nowhere"))
    assert main(["bench", "--suite", "speed", "monkey", "--out", str(out / "m")]) == 2
    err = capsys.readouterr().err
    assert f"looked for {tmp_path / 'nowhere'}/monkey.obj" in err and "every requested scene was skipped" in err
    assert not (out / "m").exists()


def test_post_png_of_an_image_rendered_with_srgb_is_not_encoded_twice(tmp_path, capsys):
    """(defect: the PNG's encoding looked at the new chain only, not the input's draaw:post
    header: an image rendered with a chain ending in srgb came out washed out, 188 for 223)"""
    desc = dict(tiny_description(resolution=[12, 10]), post=[{"type": "srgb"}])
    (tmp_path / "s.json").write_text(json.dumps(desc))
    (tmp_path / "noop.json").write_text(json.dumps([{"type": "contrast", "amount": 0.0}]))
    assert main(["render", str(tmp_path / "s.json"), "-o", str(tmp_path / "s.exr"),
                 "--png", str(tmp_path / "a.png"), "--no-progress"]) == 0
    assert main(["post", str(tmp_path / "s.exr"), "-o", str(tmp_path / "b.png"),
                 "--chain", str(tmp_path / "noop.json")]) == 0
    a, b = (matplotlib.image.imread(str(tmp_path / n)) for n in ("a.png", "b.png"))
    assert a[..., :3].mean() > 0.2 and np.array_equal(a, b)
    # a recorded chain that does not load (another version's filter): read as linear, and said
    img = np.full((4, 5, 3), 0.25, np.float32)
    draaw_mi.write_exr(str(tmp_path / "old.exr"), img, metadata={"draaw:post": '[{"type": "nosuch"}]'})
    capsys.readouterr()
    assert main(["post", str(tmp_path / "old.exr"), "-o", str(tmp_path / "old.png"),
                 "--chain", str(tmp_path / "noop.json")]) == 0
    assert "draaw:post chain does not load" in capsys.readouterr().err
    enc = 1.055 * 0.25 ** (1 / 2.4) - 0.055
    assert np.abs(matplotlib.image.imread(str(tmp_path / "old.png"))[..., :3] - enc).max() <= 0.5 / 255 + 1e-6


def test_a_library_warning_is_one_draaw_mi_line(tmp_path, capsys):
    """A warning from the library reaches the terminal as ``draaw-mi: warning: ...`` (it came
    as ``.../cli.py:189: RuntimeWarning: ...`` with the source line under it)."""
    path = tmp_path / "s.json"
    path.write_text(json.dumps(tiny_description(resolution=[8, 6], spp=1)))
    assert main(["render", str(path), "-o", str(tmp_path / "o.exr"), "--no-progress", "--version", "V4-Log"]) == 0
    err = capsys.readouterr().err
    assert "draaw-mi: warning: render: version 'V4-Log' renders linear light" in err
    assert "RuntimeWarning" not in err and "cli.py" not in err


@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_the_tool_says_its_version(flag, capsys):
    """``draaw-mi --version`` said "the following arguments are required: command"; a
    command's ``--version`` stays the render version it takes."""
    with pytest.raises(SystemExit) as stop:
        main([flag])
    assert stop.value.code == 0 and capsys.readouterr().out == f"draaw-mi {draaw_mi.__version__}\n"
    args = build_parser().parse_args(["render", "s.toml", "-o", "x.exr", "--version", "v4"])
    assert args.version == "v4"


def test_bench_refuses_what_it_would_measure_wrongly_before_anything_runs(tmp_path, tiny_file, capsys, monkeypatch):
    """Two scenes of one file name were measured against one ground truth (the study keys
    them by name: 2.26 for a scene whose own run reads 0.289); --out naming a file raised a
    FileExistsError traceback; a missing scene left an empty out folder; --frames without a
    --camera-path was ignored; an unknown --versions entry did not name the option."""
    from draaw_mi.bench import study as bench
    monkeypatch.setattr(bench, "run_study", lambda *a, **k: pytest.fail("the study ran"))
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "s.json").write_text(open(tiny_file).read())
    (tmp_path / "afile").write_text("")
    for argv, said in (([str(tmp_path / "a" / "s.json"), str(tmp_path / "b" / "s.json")], "two scenes named 's'"),
                       ([tiny_file, "--out", str(tmp_path / "afile")], "--out '" + str(tmp_path / "afile") + "': exists and is not a folder"),
                       ([str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")], "does not exist"),
                       ([tiny_file, "--frames", "5"], "--frames 5 times the frames of a --camera-path"),
                       ([tiny_file, "--versions", "v4,v9"], "bench --versions: render version 'v9' is unknown"),
                       # (a NotADirectoryError traceback; an empty value ran the whole grid)
                       ([tiny_file, "--out", str(tmp_path / "afile" / "sub")], "afile' is a file, not a folder"),
                       ([tiny_file, "--versions", ""], "--versions '': empty"),
                       ([tiny_file, "--spp", " "], "--spp ' ': empty")):
        rc = main(["bench", *argv, "--quick", "--no-progress"] + ([] if "--out" in argv else ["--out", str(tmp_path / "o")]))
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and said in err, err
    assert not (tmp_path / "o").exists()


def test_render_records_an_xml_scenes_defines(tmp_path):
    """Two renders of one XML file with other -D values gave other images under the same
    draaw:* header."""
    from draaw_mi.batch.exr import read_header
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><default name="res" value="8"/><default name="r" value="0.5"/>'
                   '<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="$res"/>'
                   '<integer name="height" value="$res"/></film></sensor>'
                   '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="$r, 0.5, 0.5"/>'
                   '</bsdf></shape><emitter type="constant"/></scene>')
    out = str(tmp_path / "a.exr")
    assert main(["render", str(xml), "-o", out, "--spp", "1", "-D", "r=0.9", "--no-progress"]) == 0
    assert json.loads(read_header(out)["draaw:defines"]) == {"r": "0.9"}
    plain = str(tmp_path / "b.exr")
    assert main(["render", str(xml), "-o", plain, "--spp", "1", "--no-progress"]) == 0
    assert "draaw:defines" not in read_header(plain)


def test_info_names_an_emitting_shape_and_the_default_material(tmp_path, capsys):
    """info said 'lights: emitter' (the dict key of the shape's emitter) and 'materials: (from
    the file)' for a TOML scene whose shapes take the default draaw material."""
    import tomli_w
    desc = {"render": {"resolution": [8, 8]}, "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
            "shapes": [{"type": "rectangle", "name": "lamp", "emission": 5.0, "translate": [0, 2, 0]},
                       {"type": "sphere", "name": "ball"}]}
    path = tmp_path / "e.toml"
    path.write_text(tomli_w.dumps(desc))
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "lights: lamp (AreaLight)" in out and "materials: (the default draaw material)" in out
