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
    exr, png = tmp_path / "c.exr", tmp_path / "c.png"
    rc = main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(exr), "--png", str(png),
               "--spp", "4", "--resolution", "24x16", "--version", "path", "--seed", "3"])
    assert rc == 0
    img = draaw_mi.read_exr(str(exr))
    assert img.shape == (16, 24, 3) and np.isfinite(img).all()
    assert png.stat().st_size > 0
    assert "wrote" in capsys.readouterr().out


def test_render_sampler_reaches_the_scene(tmp_path, monkeypatch):
    seen = []
    real = draaw_mi.render

    def spy(scene, *a, **k):
        seen.append(str(scene.mi_scene.sensors()[0].sampler()).split("[")[0].strip())
        return real(scene, *a, **k)

    monkeypatch.setattr(draaw_mi, "render", spy)
    exr = tmp_path / "m.exr"
    assert main(["render", os.path.join(SCENES, "cornell.toml"), "-o", str(exr), "--spp", "4",
                 "--resolution", "16x12", "--version", "path", "--sampler", "multijitter"]) == 0
    assert seen == ["MultijitterSampler"] and exr.exists()


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
    ["render", "{scenes}/cornell.toml", "-o", "{tmp}/x.png"],
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
]


@pytest.mark.parametrize("argv", BAD_ARGS, ids=[" ".join(a)[:60] for a in BAD_ARGS])
def test_bad_input_exits_2_with_one_line(argv, tmp_path, capsys):
    (tmp_path / "bad.toml").write_text("[render]\nspp = -1\n")
    argv = [a.format(tmp=tmp_path, scenes=SCENES) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("draaw-mi: error:") and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "x.exr").exists()


def test_console_script_exit_status(tmp_path):
    exe = os.path.join(os.path.dirname(sys.executable), "draaw-mi")
    if not os.path.exists(exe):
        pytest.skip("console script not installed in this environment")
    r = subprocess.run([exe, "render", str(tmp_path / "none.toml"), "-o", str(tmp_path / "o.exr")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "does not exist" in r.stderr
