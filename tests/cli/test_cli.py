"""The draaw-mi command line: renders, info, and one-line errors with exit status 2."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main

from conftest import SCENES


def test_render_writes_exr_and_png(tmp_path, capsys):
    """The EXR is Mitsuba's own ``path`` render of the scene at the resolution, spp, seed and
    depth given on the command line (each flag reaching render() is checked by the pixels),
    and the PNG is its sRGB encoding."""
    import matplotlib.image
    import mitsuba as mi
    exr, png = tmp_path / "c.exr", tmp_path / "c.png"
    rc = main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(exr), "--png", str(png),
               "--spp", "4", "--resolution", "24x16", "--version", "path", "--seed", "3", "--max-depth", "3"])
    assert rc == 0
    said = capsys.readouterr()
    assert said.out.splitlines()[-2:] == [said.out.splitlines()[-2], f"wrote {png}"]    # both files said
    assert said.out.splitlines()[-2].startswith(f"wrote {exr} (24x16, 3 channels, 4 spp, path")
    img = draaw_mi.read_exr(str(exr))
    assert img.shape == (16, 24, 3) and np.isfinite(img).all()
    scene = draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"), resolution=(24, 16))
    assert not scene.settings["post"]
    ref = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "path", "max_depth": 3}),
                             spp=4, seed=3))
    np.testing.assert_allclose(img, ref, rtol=1e-6, atol=1e-7)
    deeper = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "path", "max_depth": 6}),
                                spp=4, seed=3))
    assert not np.allclose(deeper, ref)                # (the depth flag matters here)
    shown = matplotlib.image.imread(str(png))
    from draaw_mi.io import srgb_encode
    assert np.abs(shown - srgb_encode(ref)).max() <= 1.0 / 255 + 1e-6
    # an RGB PNG (matplotlib's imsave added an opaque alpha to every one) with the render's
    # text, as an -o PNG has (the --png one had none: no scene, seed or spp to trace it by)
    from PIL import Image
    with Image.open(str(png)) as im:
        assert im.mode == "RGB" and im.text["draaw:seed"] == "3" and im.text["draaw:spp"] == "4"
    # the header says what rendered it, as batch frames do
    import hashlib
    from draaw_mi.batch.exr import read_header
    header = read_header(str(exr))
    with open(os.path.join(SCENES, "cornell.toml"), "rb") as fh:
        digest = hashlib.sha256(fh.read()).hexdigest()
    assert (header["draaw:version"], header["draaw:spp"], header["draaw:seed"], header["draaw:max_depth"]) ==\
        ("path", 4, 3, 3)
    assert header["draaw:integrator"] == "path"
    assert header["draaw:scene_sha256"] == digest and header["draaw:mitsuba"] == mi.__version__
    assert header["draaw:sampler"] == "independent" and "draaw:post" not in header   # no chain ran


def test_render_records_the_post_chain_it_applied(tmp_path):
    """``render --post`` applied the chain and said nothing of it in the header, unlike
    ``draaw-mi post``."""
    import json
    from draaw_mi.batch.exr import read_header
    chain = tmp_path / "c.json"
    chain.write_text('[{"type": "contrast", "amount": 0.3}]')
    exr = tmp_path / "r.exr"
    assert main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(exr), "--spp", "2",
                 "--resolution", "16x16", "--post", str(chain), "--sampler", "multijitter", "--no-progress",
                 "--version", "V2M"]) == 0
    header = read_header(str(exr))
    # the version as given, as batch frames write it, and the plugin it names (GO-Draaw's V2M
    # is V3 here)
    assert (header["draaw:version"], header["draaw:integrator"]) == ("V2M", "draaw_v3")   # (spec §3)
    assert json.loads(header["draaw:post"])[0]["type"] == "contrast"
    assert json.loads(header["draaw:post"])[0]["amount"] == 0.3
    assert header["draaw:sampler"] == "multijitter"


@pytest.mark.parametrize("argv, expect", [
    (["--spp", "0"], "bench: --spp 0; expected an integer >= 1"),
    (["--gt-spp", "0"], "--gt-spp 0"),
    (["--max-depth", "-5"], "--max-depth -5; expected an integer >= -1"),
    (["--adaptive", "3"], "--adaptive 3; expected a power of two"),
    (["--frames", "0", "--camera-path", "x.json"], "--frames 0"),
    (["--camera-path", "BINARY"], "--camera-path"),
    # (-4 was refused by render() after hours of measuring the other settings)
    (["--denoise", "4,-4"], "bench: --denoise -4; expected an integer >= 1"),
])
def test_bench_refuses_bad_numbers_before_the_ground_truth(tmp_path, capsys, monkeypatch, argv, expect):
    """Checked before any rendering: the ground truth (minutes at the defaults) was rendered
    and cached first, and the camera path read after the whole study."""
    from draaw_mi.bench import study as bench
    monkeypatch.setattr(bench, "run_study", lambda *a, **k: pytest.fail("the study ran"))
    binary = tmp_path / "b.json"
    binary.write_bytes(bytes(range(256)))
    argv = [str(binary) if a == "BINARY" else a for a in argv]
    out = tmp_path / "study"
    assert main(["bench", os.path.join(SCENES, "cornell.toml"), "--quick", "--versions", "v4",
                 "--out", str(out), "--no-progress"] + argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expect in err[0], err
    assert not out.exists()


def test_json_files_that_are_not_text_are_one_line_errors(tmp_path, capsys):
    binary = tmp_path / "b.json"
    binary.write_bytes(bytes(range(256)))
    scene = os.path.join(SCENES, "cornell.toml")
    for argv in (["render", scene, "-o", str(tmp_path / "x.exr"), "--post", str(binary)],
                 ["fit", scene, "--reference", str(binary), "--param", "x.roughness", "--views", str(binary)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "b.json" in err[0] and ("not a" in err[0]), err


def test_render_sampler_reaches_the_scene(tmp_path, monkeypatch):
    seen = []
    real = draaw_mi.render

    def spy(scene, *a, **k):
        seen.append(str(scene.mi_scene.sensors()[0].sampler()).split("[")[0].strip())
        return real(scene, *a, **k)

    from draaw_mi.cli import commands              # the module that calls render()
    monkeypatch.setattr(commands, "render", spy)
    exr = tmp_path / "m.exr"
    assert main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(exr), "--spp", "4",
                 "--resolution", "16x12", "--version", "path", "--sampler", "multijitter"]) == 0
    assert seen == ["MultijitterSampler"] and exr.exists()


def test_info_says_which_extras_are_there(capsys, monkeypatch):
    """One line per set-up: each extra yes, or no with the module missing and the install
    command (pyoidn and distributed hidden here; the others as find_spec finds them)."""
    import importlib.util
    import json
    import tomllib
    monkeypatch.setitem(sys.modules, "pyoidn", None)          # as if not installed
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert main(["info"]) == 0
    line = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith("extras:")]
    assert len(line) == 1, line
    assert "denoise no (no pyoidn: pip install 'draaw-mi[denoise]')" in line[0]
    assert "batch no (no distributed: pip install 'draaw-mi[batch]')" in line[0]
    docs = all(importlib.util.find_spec(m) for m in ("sphinx", "myst_nb", "furo", "sphinxarg"))
    assert ("docs yes" in line[0]) == docs and ("docs no (" in line[0]) == (not docs)
    assert main(["info", "--json"]) == 0
    extras = json.loads(capsys.readouterr().out)["extras"]
    assert extras["denoise"] is False and extras["batch"] is False and extras["docs"] is docs
    assert set(extras) == {"denoise", "batch", "notebooks", "docs"}
    with open(os.path.join(SCENES, "..", "pyproject.toml"), "rb") as fh:    # the extras' real names
        assert set(extras) <= set(tomllib.load(fh)["project"]["optional-dependencies"])


def test_each_extra_info_checks_is_what_pyproject_installs():
    """info's extras (cli.scenes.EXTRAS) name the modules of pyproject.toml's extras, read from
    the file (distribution names to module names by hand): the notebooks extra's pyoidn was
    left out, so info said "notebooks yes" without it. dev and browser are test tooling."""
    import re
    import tomllib

    from draaw_mi.cli.scenes import EXTRAS
    with open(os.path.join(SCENES, "..", "pyproject.toml"), "rb") as fh:
        extras = tomllib.load(fh)["project"]["optional-dependencies"]
    module = {"sphinx_argparse": "sphinxarg"}

    def modules(requirement):
        name, sub = re.match(r"([A-Za-z0-9_.-]+)(?:\[([^\]]*)\])?", requirement).groups()
        names = [name] + (sub.split(",") if sub else [])      # dask[distributed]: both
        return {module.get(n, n) for n in (n.strip().lower().replace("-", "_") for n in names)}

    assert set(EXTRAS) == set(extras) - {"dev", "browser"}
    for extra, mods in EXTRAS.items():
        assert set(mods) == set().union(*map(modules, extras[extra])), extra


def test_info_lists_setup_and_scene(capsys):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "llvm_ad_rgb" in out and "draaw" in out
    assert main(["info", os.path.join(SCENES, "material_spheres.toml")]) == 0
    out = capsys.readouterr().out
    assert "256x256" in out and "features" in out and "sphere_r0m0" in out


BAD_ARGS = [
    ["render", "missing.toml", "-o", "{tmp}/x.exr"],
    ["render", "{scenes}/cornell.toml", "-o", "/proc/nope/x.exr"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.jpg"],      # (.png is an output since issue 43)
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--resolution=-4x4"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--resolution", "abc"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--spp", "0"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--spp", "many"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--version", "v9"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--threads", "0"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--sampler", "sobol"],
    ["render", "{scenes}/cornell.toml"],
    ["frobnicate"],
    ["info", "{tmp}/bad.toml"],
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.exr", "--bogus"],
    ["render", "{scenes}/sdf_csg.toml", "-o", "{tmp}/x.exr", "--version", "path", "--resolution", "8x8"],
    ["render", "{tmp}/s.xml", "-o", "{tmp}/x.exr", "--resolution", "32"],   # (once a TypeError traceback)
    ["render", "{tmp}/s.xml", "-o", "{tmp}/x.exr", "-D", "res=32"],       # (the file has no $res)
]


@pytest.mark.parametrize("argv", BAD_ARGS, ids=[" ".join(a)[:60] for a in BAD_ARGS])
def test_bad_input_exits_2_with_one_line(argv, tmp_path, capsys):
    (tmp_path / "bad.toml").write_text("[render]\nspp = -1\n")
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">'
                                    '<integer name="width" value="16"/><integer name="height" value="8"/>'
                                    '</film></sensor><shape type="sphere"/></scene>')
    argv = [a.format(tmp=tmp_path, scenes=SCENES) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("draaw-mi: error:") and "\n" not in err and "Traceback" not in err
    assert "error: draaw-mi" not in err                # the program named once
    assert not (tmp_path / "x.exr").exists()


def test_console_script_exit_status(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "draaw-mi")
    if not os.path.exists(exe):
        pytest.skip("console script not installed in this environment")
    r = subprocess.run([exe, "render", str(tmp_path / "none.toml"), "-o", str(tmp_path / "o.exr")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "does not exist" in r.stderr


@pytest.mark.parametrize("flag, value, expected", [
    ("--spp", "0", "an integer in [1, 4294967295]"), ("--max-depth", "-2", "an integer >= -1"),
    ("--seed", "-1", "an integer in [0, 4294967295]"),
    ("--spp", "100000000000", "an integer in [1, 4294967295]"), ("--seed", "4294967296", "an integer in [0, 4294967295]"),
    ("--time-budget", "inf", "a finite number of seconds > 0")])
def test_a_bad_render_flag_is_named_as_a_flag(flag, value, expected, tmp_path, capsys):
    """``--spp 0`` was blamed on the scene file ("cornell.toml: override.spp: 0 is out of range"),
    and ``--spp 1e11`` on Mitsuba's sampler ('At dictionary node "sensor.sampler" ... out of
    bounds'); ``--seed 2^32`` and ``--time-budget inf`` were named as the Python call."""
    assert main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(tmp_path / "x.exr"), flag, value]) == 2
    assert capsys.readouterr().err.strip() == f"draaw-mi: error: {flag} {value}: expected {expected}"


def test_no_command_lists_the_commands(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    assert all(c in err for c in ("render", "info", "fit", "bench", "post", "batch")), err


def test_dry_run_and_status_are_one_or_the_other(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "m.toml"), "--dry-run", "--status"]) == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_bench_quick_keeps_an_explicit_gt_spp(tmp_path, monkeypatch):
    """--quick capped the reference at 1024 spp: an explicit --gt-spp 2048 became 1024 (and
    an explicit --repeats 7 became 3)."""
    from draaw_mi.bench import study as bench
    seen = {}

    class Stop(Exception):
        pass

    def study(*a, **k):
        seen.update(k)
        raise Stop
    monkeypatch.setattr(bench, "run_study", study)
    for argv, gt, repeats in (([], 1024, 3), (["--gt-spp", "2048"], 2048, 3), (["--repeats", "7"], 1024, 7)):
        with pytest.raises(Stop):
            main(["bench", os.path.join(SCENES, "cornell.toml"), "--quick", "--versions", "v4",
                  "--out", str(tmp_path / "o"), "--no-progress"] + argv)
        assert seen["gt_spp"] == gt
        assert seen["repeats"] == repeats             # (--quick capped an explicit 7 at 3)
