"""One line, exit status 2, for what a newcomer tries first (issue 43): a truncated EXR, a PNG
as render's output, a batch manifest given to ``render`` and a scene given to ``batch``, a
variant draaw-mi cannot run; and ``fit -o`` keeping the scene file's comments and layout."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import matplotlib.image
import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.errors import IOFailure
from draaw_mi.fitting.reference import load_reference

from conftest import ROOT, SCENES, tiny_description


@pytest.fixture
def truncated_exr(tmp_path):
    """An EXR with 6 channels cut to a twentieth of its length (OpenEXR printed 18 lines of
    its own for it, and the error never said "truncated")."""
    full = tmp_path / "full.exr"
    rng = np.random.default_rng(1)
    draaw_mi.write_exr(str(full), rng.random((256, 256, 6)).astype(np.float32),
                       channels=["R", "G", "B", "A", "depth.Z", "N.X"])
    data = full.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[:len(data) // 20])
    return str(cut)


def _one_error_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("draaw-mi: error: "), err
    return lines[0]


def test_a_truncated_exr_given_to_post_is_one_line_that_says_so(tmp_path, truncated_exr, capfd):
    chain = tmp_path / "chain.json"
    chain.write_text("[]")
    rc = main(["post", truncated_exr, "-o", str(tmp_path / "out.exr"), "--chain", str(chain)])
    out, err = capfd.readouterr()                # (the file descriptors: OpenEXR's C++ output)
    line = _one_error_line(err)
    assert rc == 2 and out == ""
    assert "cut.exr" in line and "truncated or damaged" in line
    assert not os.path.exists(tmp_path / "out.exr")


def test_a_truncated_fit_reference_is_one_error_and_nothing_printed(truncated_exr, capfd):
    with pytest.raises(IOFailure, match=r"cut\.exr.*truncated or damaged"):
        load_reference(truncated_exr)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_a_file_that_is_not_an_exr_is_named_so(tmp_path, capfd):
    fake = tmp_path / "notes.exr"
    fake.write_text("not an image")
    with pytest.raises(IOFailure, match="not an EXR file at all"):
        draaw_mi.read_exr(str(fake))
    assert capfd.readouterr() == ("", "")


@pytest.mark.parametrize("compression", ["ZIP_COMPRESSION", "NO_COMPRESSION", "PIZ_COMPRESSION"])
@pytest.mark.parametrize("keep", ["header", "table", "first chunk", "all but 3 bytes"])
def test_an_exr_cut_anywhere_is_found_before_openexr_prints(tmp_path, capfd, compression, keep):
    """A file cut inside its header, its offset table, its first chunk or 3 bytes short of its
    end: one IOFailure saying so, nothing on the terminal (OpenEXR is not asked: its messages
    went to the process's streams), and the whole file reads back (the check refuses no good
    file). The offset table starts where the header ends: 8 bytes per chunk of 16 / 1 / 32
    lines."""
    import struct

    import OpenEXR
    from draaw_mi.io import exr_cut_short
    full = tmp_path / "full.exr"
    rng = np.random.default_rng(2)
    pixels = rng.random((40, 24, 3)).astype(np.float32)
    comp = getattr(OpenEXR, compression)
    with OpenEXR.File({"compression": comp, "type": OpenEXR.scanlineimage},
                      {"RGB": pixels}) as f:
        f.write(str(full))
    data = full.read_bytes()
    assert exr_cut_short(str(full)) is None
    np.testing.assert_array_equal(draaw_mi.read_exr(str(full)), pixels)
    lines = {"ZIP_COMPRESSION": 16, "NO_COMPRESSION": 1, "PIZ_COMPRESSION": 32}[compression]
    table = 8 * -(-40 // lines)
    # the header ends where a table of increasing offsets starts whose first entry points just
    # past it (found by scanning, independently of the parser under test)
    offsets = header_end = None
    for start in range(8, len(data) - table):
        cand = struct.unpack_from(f"<{table // 8}Q", data, start)
        if cand[0] == start + table and all(a < b for a, b in zip(cand, cand[1:])):
            offsets, header_end = cand, start
            break
    assert offsets is not None
    cut_at = {"header": header_end // 2, "table": header_end + table // 2,
              "first chunk": offsets[0] + 6, "all but 3 bytes": len(data) - 3}[keep]
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[:cut_at])
    capfd.readouterr()
    with pytest.raises(IOFailure, match=r"cut\.exr.*truncated or damaged"):
        draaw_mi.read_exr(str(cut))
    assert capfd.readouterr() == ("", "")


def test_another_threads_output_during_an_exr_read_reaches_the_terminal(tmp_path, truncated_exr, capfd):
    """Nothing is redirected while an EXR is read: a line another thread prints then, Python's
    or C's, is not swallowed (the reads once took the process's descriptors 1 and 2)."""
    import threading
    go = threading.Event()

    def other():
        go.wait()
        print("from another thread", flush=True)
        os.write(2, b"fd2\n")
    t = threading.Thread(target=other)
    t.start()
    for _ in range(50):
        go.set()
        with pytest.raises(IOFailure):
            draaw_mi.read_exr(truncated_exr)
    t.join()
    out, err = capfd.readouterr()
    assert out == "from another thread\n" and err == "fd2\n"


@pytest.fixture
def tiny_file(tmp_path):
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(tiny_description(resolution=[12, 10], spp=1)))
    return str(path)


def test_render_writes_a_png_given_as_its_output(tmp_path, tiny_file, capsys):
    png = tmp_path / "x.png"
    assert main(["render", tiny_file, "-o", str(png), "--no-progress"]) == 0
    img = matplotlib.image.imread(str(png))
    assert img.shape[:2] == (10, 12) and img[..., :3].max() > 0
    assert "wrote " + str(png) in capsys.readouterr().out
    assert not any(p.suffix == ".exr" for p in tmp_path.iterdir())
    # other names are still refused in one line
    assert main(["render", tiny_file, "-o", str(tmp_path / "x.jpg")]) == 2
    assert "must end with .exr or .png" in capsys.readouterr().err
    # --png naming the -o file would write it twice, the second time without the header text
    assert main(["render", tiny_file, "-o", str(png), "--png", str(png), "--no-progress"]) == 2
    assert "the same file as -o" in capsys.readouterr().err


def test_a_batch_manifest_given_to_render_names_the_batch_command(tmp_path, capsys):
    manifest = os.path.join(SCENES, "batch_example.toml")
    for argv in (["render", manifest, "-o", str(tmp_path / "x.exr")], ["info", manifest],
                 ["fit", manifest, "--reference", "r.exr", "--param", "a.b"]):
        assert main(argv) == 2
        line = _one_error_line(capsys.readouterr().err)
        assert f"{manifest} is a batch manifest" in line and f"`draaw-mi batch {manifest}`" in line
        assert "unknown key" not in line
    with pytest.raises(draaw_mi.SceneError, match="is a batch manifest"):
        draaw_mi.load_scene(manifest)


def test_a_scene_given_to_batch_names_the_render_command(tmp_path, capsys):
    for scene in (os.path.join(SCENES, "cornell.toml"),
                  os.path.join(os.path.dirname(__file__), "..", "scene", "data", "cbox.xml")):
        assert main(["batch", scene, "--out", str(tmp_path)]) == 2
        line = _one_error_line(capsys.readouterr().err)
        assert f"{scene} is a scene" in line and f"`draaw-mi render {scene}" in line
        assert "unknown key" not in line and "unknown manifest format" not in line


@pytest.mark.parametrize("variant", ["llvm_ad_spectral_polarized", "llvm_ad_mono", "llvm_ad_spectral"])
def test_a_variant_draaw_mi_cannot_run_is_refused_in_one_line(variant):
    """A spectral, monochrome or polarised variant failed in the first render with a raw
    TypeError (the BSDF computes in Color3f)."""
    env = dict(os.environ, DRAAW_MI_VARIANT=variant)
    exe = os.path.join(os.path.dirname(sys.executable), "draaw-mi")
    cmd = [exe] if os.path.exists(exe) else [sys.executable, "-m", "draaw_mi_cli"]
    r = subprocess.run(cmd + ["info"], capture_output=True, text=True, env=env, timeout=120)
    line = _one_error_line(r.stderr)
    assert r.returncode == 2 and r.stdout == ""
    assert repr(variant) in line and "not supported" in line and "'llvm_ad_rgb'" in line
    r = subprocess.run([sys.executable, "-c", "import draaw_mi"], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 1 and "DraawError" in r.stderr.splitlines()[-1]


# Each command runs in one process where ``import OpenEXR`` fails (as when the package is
# missing or broken); prints {argv: [exit status, stderr]} as JSON.
_WITHOUT_OPENEXR = """
import contextlib, io, json, sys
sys.modules["OpenEXR"] = None
from draaw_mi_cli import main
results = {}
for argv in json.loads(sys.argv[1]):
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            status = main(argv)
        except SystemExit as e:                # --help, --version
            status = e.code
    results[" ".join(argv)] = [status, err.getvalue(), out.getvalue()]
print(json.dumps(results))
"""


def test_without_openexr_help_info_and_png_work_and_exr_is_one_line(tmp_path):
    """Every command crashed with a traceback, --help included, when OpenEXR could not be
    imported (draaw_mi.batch.exr imported it at load); now only EXR files need it."""
    scene, png, exr = os.path.join(SCENES, "cornell.toml"), str(tmp_path / "c.png"), str(tmp_path / "c.exr")
    small = ["--resolution", "8x8", "--spp", "1"]
    whole = str(tmp_path / "whole.exr")
    draaw_mi.write_exr(whole, np.ones((4, 4, 3), np.float32))         # (OpenEXR is here)
    commands = [["--help"], ["--version"], ["info", scene], ["render", scene, "-o", png] + small,
                ["render", scene, "-o", exr] + small, ["post", whole, "-o", str(tmp_path / "p.exr"), "--chain",
                 os.path.join(SCENES, "post_chain.json")]]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-c", _WITHOUT_OPENEXR, json.dumps(commands)], capture_output=True,
                       text=True, env=env, cwd=str(tmp_path), timeout=300)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout.splitlines()[-1])
    for argv in commands[:4]:
        status, err, out = res[" ".join(argv)]
        assert status in (0, None) and "Traceback" not in err, (argv, err)
    assert "usage: draaw-mi" in res["--help"][2] and "draaw-mi" in res["--version"][2]
    assert "materials:" in res[f"info {scene}"][2]
    assert os.path.getsize(png) > 0
    for argv in commands[4:]:
        status, err, _ = res[" ".join(argv)]
        line = _one_error_line(err)
        assert status == 2 and "OpenEXR" in line and "pip install" in line, (argv, line)
    assert not os.path.exists(exr)             # refused before rendering, not after it


COMMENTED = """\
# A sphere to fit: every comment here must survive `draaw-mi fit -o`
[render]
resolution = [16, 12]   # small: a test
spp = 1
max_depth = 3
filter = "box"

# where we look from
[camera]
origin = [0.0, 1.0, 5.0]
target = [0.0, 0.5, 0.0]
fov = 40

[materials.ball]               # the one being fitted
base_color = [0.8, 0.3, 0.2]   # orange
roughness = 0.4                # fitted
metallic = 0.2                 # fitted too

[materials.ground]
base_color = [0.5, 0.5, 0.5]
roughness = 0.9

[[shapes]]
type = "sphere"        # the ball
name = "ball_shape"
material = "ball"
center = [0, 0.8, 0]
radius = 0.8

[[shapes]]
type = "rectangle"
name = "floor"
material = "ground"
scale = 4.0
rotate = { axis = [1, 0, 0], angle = -90 }   # lying down

[[lights]]
type = "point"
position = [2.0, 4.0, 3.0]
intensity = 40.0       # bright
"""


def test_fit_output_keeps_the_scene_files_comments_and_layout(tmp_path, capsys):
    """``fit -o fitted.toml`` rewrote the file from the parsed tables (81 lines with comments
    became 127 without); now only the fitted values' lines differ."""
    scene = tmp_path / "scene.toml"
    scene.write_text(COMMENTED)
    ref = tmp_path / "ref.exr"
    draaw_mi.write_exr(str(ref), np.array(draaw_mi.render(draaw_mi.load_scene(str(scene)), spp=2)))
    out = tmp_path / "fitted.toml"
    assert main(["fit", str(scene), "--reference", str(ref), "--param", "ball.roughness", "--param",
                 "ball.metallic", "--iterations", "2", "--spp", "1", "--no-progress", "-o", str(out)]) == 0
    before, after = COMMENTED.splitlines(), out.read_text().splitlines()
    assert len(after) == len(before)
    changed = [(a, b) for a, b in zip(before, after) if a != b]
    assert [a.split("=")[0].strip() for a, _ in changed] == ["roughness", "metallic"]
    for a, b in changed:                              # the value changes, its comment stays
        assert a.split("#")[1] == b.split("#")[1]
    assert all(line in after for line in before if line.lstrip().startswith("#"))
    fitted = draaw_mi.load_scene(str(out))
    assert fitted.description["materials"]["ball"]["roughness"] != 0.4


@pytest.mark.parametrize("flags, says", [
    (["--resolution", "0x0"], "--resolution: width: 0 is out of range; expected a value in [1, 16384]"),
    (["--sampler", "foo"], "--sampler: 'foo' is not one of independent, multijitter"),
    (["--time-budget", "-1"], "--time-budget -1: expected a finite number of seconds > 0"),
])
def test_a_bad_render_flag_is_named_as_the_flag(tmp_path, tiny_file, capsys, flags, says):
    """They were named as the scene loader's overrides ("override.resolution.width: ...",
    "override.sampler") or as the Python call ("render: time_budget=-1.0")."""
    assert main(["render", tiny_file, "-o", str(tmp_path / "x.exr"), *flags]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert says in line and "override" not in line, line
    assert not (tmp_path / "x.exr").exists()
