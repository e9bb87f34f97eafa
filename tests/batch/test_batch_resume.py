"""Resuming and reporting: which frames a run renders again (missing, damaged, stale, failed),
``--status`` and its errors, the log, locks on output folders, read-only archives, progress."""
from __future__ import annotations

import copy
import os

import numpy as np
import pytest
import tomli_w
from batch_helpers import assert_bit_identical, frames_of, manifest, write_manifest
from conftest import tiny_description

import draaw_mi
from draaw_mi.batch import runner as batch


def test_resume_renders_only_missing_corrupt_and_stale_frames(tmp_path):
    doc = manifest(tmp_path, frames=5)
    batch.run(doc, progress=False)
    _, specs, _ = batch.load(doc)
    before = frames_of(tmp_path / "out")
    mtimes = {s["frame"]: os.stat(s["output"]).st_mtime_ns for s in specs}
    os.unlink(specs[1]["output"])
    with open(specs[3]["output"], "r+b") as fh:           # a truncated (corrupt) file
        fh.truncate(100)
    # cut short past its header (a copy that ran out of disk): the header still reads, with
    # this job's hash, and the frame counted as done for ever
    with open(specs[4]["output"], "r+b") as fh:
        fh.truncate(int(0.6 * os.path.getsize(specs[4]["output"])))
    assert batch.read_header(specs[4]["output"])["draaw:frame_hash"] == specs[4]["hash"]
    assert [f["status"] for f in batch.status(doc)["frames"]] == ["done", "missing", "done", "damaged",
                                                                 "damaged"]
    mtimes[4] = None
    res = batch.run(doc, progress=False)
    assert sorted(r["frame"] for r in res.results) == [1, 3, 4] and res.skipped == 2 and res.complete
    for f in (0, 2):
        assert os.stat(specs[f]["output"]).st_mtime_ns == mtimes[f]
    assert_bit_identical(before, frames_of(tmp_path / "out"))
    # other settings for the same files: every frame is stale and re-rendered
    for key, value in (("post", [{"type": "srgb"}]), ("seed", 99), ("aovs", ["depth"]), ("half", True)):
        other = copy.deepcopy(doc)                 # (each setting that changes the pixels)
        other["jobs"][0][key] = value
        assert batch.status(other)["counts"]["stale"] == 5, key
    doc2 = copy.deepcopy(doc)
    doc2["jobs"][0]["spp"] = 8
    assert batch.status(doc2)["counts"]["stale"] == 5
    res = batch.run(doc2, progress=False)
    assert res.rendered == 5


def test_failed_frame_is_logged_and_the_rest_go_on(tmp_path, capsys):
    doc = manifest(tmp_path, frames=3)
    # 3.4e38 fits float32, four samples of it seen directly do not: frame 1 renders inf pixels,
    # which the NaN guard refuses (1e39 itself is refused with the manifest, before any frame)
    doc["jobs"][0]["params"] = {"constant_light1.radiance": {"values": [0.2, 3.4e38, 0.2]}}
    _, specs, _ = batch.load(doc)
    assert "radiance" in next(iter(specs[1]["params"]))
    res = batch.run(doc, progress=False)
    assert [r["frame"] for r in res.failed] == [1] and "non-finite" in res.failed[0]["error"]
    assert res.rendered == 2 and not res.complete and res.missing == 1
    assert not os.path.exists(specs[1]["output"])
    log = batch.read_log(res.log)
    assert [r["event"] for r in log] == ["start", "frame", "frame", "frame", "end"]
    assert sum("error" in r for r in log) == 1
    st = batch.status(doc)
    assert st["counts"] == {"done": 2, "missing": 0, "stale": 0, "foreign": 0, "damaged": 0, "no-preview": 0,
                            "failed": 1}
    from draaw_mi.cli import main
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--no-progress"]) == 1        # exit status: not all frames exist
    assert "failed: orbit frame 1" in capsys.readouterr().err


@pytest.mark.parametrize("freeze", [True, False])
def test_the_nan_guard_sees_the_render_before_its_post_chain(tmp_path, freeze):
    """A post chain reads NaN/inf as 0 (draaw_mi.post): the guard must look before it, or a
    frame of inf pixels was written as done, mostly black."""
    doc = manifest(tmp_path, frames=2)
    doc["jobs"][0]["params"] = {"constant_light1.radiance": {"values": [0.2, 3.4e38]}}
    doc["jobs"][0]["post"] = [{"type": "contrast", "amount": 0.0}]
    doc["jobs"][0]["freeze"] = freeze
    _, specs, _ = batch.load(doc)
    res = batch.run(doc, progress=False)
    assert [r["frame"] for r in res.failed] == [1] and "non-finite" in res.failed[0]["error"]
    assert not os.path.exists(specs[1]["output"]) and os.path.exists(specs[0]["output"])


def test_dry_run_and_status_render_nothing(tmp_path, capsys):
    from draaw_mi.cli import main
    path = write_manifest(tmp_path, manifest(tmp_path, frames=3))
    assert main(["batch", path, "--dry-run"]) == 1
    out = capsys.readouterr().out
    assert out.count("missing") >= 3 and "3 frames: 0 done, 3 missing" in out
    assert not (tmp_path / "out").exists()
    assert main(["batch", path, "--no-progress"]) == 0
    assert "3 rendered" in capsys.readouterr().out
    assert main(["batch", path, "--status"]) == 0
    assert "3 frames: 3 done" in capsys.readouterr().out


def test_a_batch_away_from_a_terminal_reports_progress_in_lines(tmp_path, capsys):
    """Standard error captured (a log file, not a terminal): whole progress lines, no bar's
    carriage returns, and the last one counts every frame."""
    from draaw_mi.cli import main
    path = write_manifest(tmp_path, manifest(tmp_path, frames=2))
    assert main(["batch", path]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err
    assert err.splitlines()[-1].startswith("batch: 2/2 frames (100 %), ")
    assert err.splitlines()[-1].endswith("done=2 failed=0")


def test_a_second_run_on_busy_folders_stops_before_touching_them(tmp_path, capsys):
    """A run into folders another run holds would delete that run's temporary files (as a
    killed run's leftovers) and render the same frames: it must stop with one line, exit 2."""
    from draaw_mi.batch.lock import output_locks
    from draaw_mi.cli import main
    from draaw_mi.errors import BusyError
    doc = manifest(tmp_path, frames=2)
    path = write_manifest(tmp_path, doc)
    folder = tmp_path / "out" / "orbit"
    folder.mkdir(parents=True)
    in_flight = folder / ".draaw-0000-in-flight.exr"          # the other run's temporary file
    in_flight.write_bytes(b"partial")
    with output_locks([str(folder)], "other run"):
        with pytest.raises(BusyError, match="is in use by another draaw-mi batch run"):
            batch.run(doc, progress=False)
        assert main(["batch", path, "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "orbit" in err[0] and f"pid {os.getpid()}" in err[0], err
        assert in_flight.exists() and not frames_of(tmp_path / "out")
    res = batch.run(doc, progress=False)                       # the lock went with its holder
    assert res.complete and len(frames_of(tmp_path / "out")) == 2 and not in_flight.exists()


def test_status_says_a_run_holds_the_folders(tmp_path, capsys):
    """--status while a run renders is a snapshot: it says so, naming the run's pid as a second
    run's refusal does; a lock file left by a killed run names no run."""
    import subprocess
    import sys

    from draaw_mi.batch.lock import LOCK_NAME, output_locks
    from draaw_mi.cli import main
    doc = manifest(tmp_path, frames=2)
    path = write_manifest(tmp_path, doc)
    folder = tmp_path / "out" / "orbit"
    folder.mkdir(parents=True)
    with output_locks([str(folder)], "other run"):
        assert batch.status(doc)["running"] == os.getpid()
        assert main(["batch", path, "--status"]) == 1
        out = capsys.readouterr().out.strip().splitlines()
        assert out[-1].endswith(f"(a run is in progress: pid {os.getpid()})"), out
    assert batch.status(doc)["running"] is None
    main(["batch", path, "--status"])
    assert "in progress" not in capsys.readouterr().out
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    (folder / LOCK_NAME).write_text(f"{gone.pid}\n")               # a killed run's lock file
    assert batch.status(doc)["running"] is None
    if os.path.exists("/proc/locks"):          # its pid alive again (reused), the file unlocked
        (folder / LOCK_NAME).write_text(f"{os.getpid()}\n")
        assert batch.status(doc)["running"] is None


def test_the_logs_start_record_names_the_manifest_by_its_absolute_path(tmp_path, monkeypatch):
    """Run from the manifest's folder as ``batch.toml``: the log named it so, where the frames'
    headers have its absolute path."""
    doc = manifest(tmp_path, frames=1)
    write_manifest(tmp_path, doc)
    monkeypatch.chdir(tmp_path)
    res = batch.run("batch.toml", progress=False)
    start = batch.read_log(res.log)[0]
    assert start["event"] == "start" and start["manifest"] == str(tmp_path / "batch.toml")
    assert batch.read_header(res.results[0]["output"])["draaw:manifest"] == start["manifest"]


def test_frames_another_run_finished_before_the_lock_are_not_rendered_again(tmp_path, monkeypatch):
    """Two runs of one manifest: the second plans while the first still renders, then gets the
    lock once the first is done. It must read the frames' state again under the lock and
    render nothing (it rendered every frame a second time)."""
    import contextlib
    from draaw_mi.batch import runner        # the module that takes the locks
    doc = manifest(tmp_path, frames=2)
    real = runner.output_locks

    @contextlib.contextmanager
    def first_run_finishes_meanwhile(folders, where, optional=()):
        monkeypatch.setattr(runner, "output_locks", real)
        assert batch.run(doc, progress=False).rendered == 2     # the other run
        with real(folders, where, optional):
            yield
    monkeypatch.setattr(runner, "output_locks", first_run_finishes_meanwhile)
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 0 and res.skipped == 2


def test_a_frame_is_stale_when_a_file_its_scene_reads_changes(tmp_path, capsys):
    """Frames are keyed by the scene file and by the files it reads: a texture named in the
    scene, an OBJ mesh, its material library and the image that names. Changing any of them
    makes the finished frames stale (they stayed "done" and were never rendered again)."""
    (tmp_path / "quad.obj").write_text(
        "mtllib quad.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl paint\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    (tmp_path / "quad.mtl").write_text("newmtl paint\nKd 0.5 0.5 0.5\nmap_Kd quad.png\n")
    draaw_mi.write_png(str(tmp_path / "quad.png"), np.full((4, 4, 3), 0.3, np.float32))
    draaw_mi.write_png(str(tmp_path / "ball.png"), np.full((4, 4, 3), 0.6, np.float32))
    desc = tiny_description()
    desc["materials"]["ball"]["base_color"] = "ball.png"
    desc["shapes"][1] = {"type": "mesh", "file": "quad.obj", "name": "floor", "scale": 3.0}
    scene = tmp_path / "textured.toml"
    scene.write_bytes(tomli_w.dumps(desc).encode())
    doc = {"output": "out/{frame:04d}.exr",
           "jobs": [{"name": "t", "scene": str(scene), "frames": 1, "spp": 1}]}
    files = sorted(os.path.basename(f) for f in draaw_mi.load_scene(str(scene)).info["files"])
    assert files == ["ball.png", "quad.mtl", "quad.obj", "quad.png"]
    assert batch.run(doc, progress=False).rendered == 1
    header = batch.read_header(str(tmp_path / "out" / "0000.exr"))
    assert len(header["draaw:files_sha256"]) == 64
    for name, edit in (("ball.png", lambda p: draaw_mi.write_png(p, np.full((4, 4, 3), 0.7, np.float32))),
                       ("quad.png", lambda p: draaw_mi.write_png(p, np.full((4, 4, 3), 0.2, np.float32))),
                       ("quad.mtl", lambda p: open(p, "a").write("Ks 0.1 0.1 0.1\n")),
                       ("quad.obj", lambda p: open(p, "a").write("# edited\n"))):
        assert batch.status(doc)["counts"]["done"] == 1
        edit(str(tmp_path / name))
        assert batch.status(doc)["counts"]["stale"] == 1, name
        assert batch.run(doc, progress=False).rendered == 1, name
    # a file edited between planning and rendering (a Dask worker loads the scene late): the
    # frame fails instead of being tagged with the planned files' hash
    from draaw_mi.batch.frame import SceneCache, render_frame
    from draaw_mi.errors import RenderError
    _, specs, _ = batch.load(doc)
    draaw_mi.write_png(str(tmp_path / "ball.png"), np.full((4, 4, 3), 0.1, np.float32))
    with pytest.raises(RenderError, match="a file the scene reads .* changed since the batch was planned"):
        render_frame(specs[0], SceneCache())
    # a long-lived cache (a Dask worker across runs) loads the scene again for the new plan
    worker = SceneCache()
    _, specs, _ = batch.load(doc)
    render_frame(specs[0], worker)
    draaw_mi.write_png(str(tmp_path / "ball.png"), np.full((4, 4, 3), 0.9, np.float32))
    _, specs, _ = batch.load(doc)
    assert render_frame(specs[0], worker)["output"] == specs[0]["output"]


def test_outputs_in_unrelated_trees_log_beside_the_first_job(tmp_path):
    """Jobs writing under two unrelated roots: the log went to their common ancestor, the
    file system's root. It goes to the first job's folder (its pattern's before {job})."""
    import tempfile
    other = tempfile.mkdtemp(dir="/var/tmp" if not str(tmp_path).startswith("/var/tmp") else "/dev/shm")
    try:
        doc = manifest(tmp_path, frames=1)
        second = dict(doc["jobs"][0], name="elsewhere", output=os.path.join(other, "{frame:04d}.exr"))
        doc["jobs"].append(second)
        res = batch.run(doc, dry_run=True, progress=False, allow_outside_out=True)     # (another tree)
        assert os.path.dirname(res.log) == str(tmp_path / "out")
    finally:
        import shutil
        shutil.rmtree(other, ignore_errors=True)


def test_another_users_lock_file_locks_read_only(tmp_path, monkeypatch):
    """A lock file this run may not open for writing (another user's run made it, 0644, in a
    folder both may write): it is locked through a read-only descriptor, so a stale one (its
    run was killed) does not block the folder, and a live holder still does (this was a
    PermissionError traceback)."""
    import errno as errno_mod
    import fcntl
    from draaw_mi.batch import lock as lock_mod
    from draaw_mi.errors import BusyError
    doc = manifest(tmp_path, frames=2)
    folder = tmp_path / "out" / "orbit"
    folder.mkdir(parents=True)
    lock_file = os.path.join(str(folder), lock_mod.LOCK_NAME)
    with open(lock_file, "w") as fh:
        fh.write("999999\n")                                      # the other user's
    real = lock_mod.os.open

    def not_for_writing(path, flags, *args, **kwargs):
        if str(path) == lock_file and flags & (os.O_RDWR | os.O_WRONLY):
            raise PermissionError(errno_mod.EACCES, "Permission denied", str(path))
        return real(path, flags, *args, **kwargs)
    monkeypatch.setattr(lock_mod.os, "open", not_for_writing)
    holder = real(lock_file, os.O_RDONLY)
    fcntl.flock(holder, fcntl.LOCK_EX | fcntl.LOCK_NB)             # a live run of that user
    try:
        with pytest.raises(BusyError, match="in use by another draaw-mi batch run"):
            batch.run(doc, progress=False)
    finally:
        os.close(holder)                                           # ... which ends (or was killed)
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 2 and not os.path.exists(lock_file)


def test_finished_frames_in_read_only_folders_are_complete(tmp_path, monkeypatch, capsys):
    """An archive on a read-only share: ``--status``, ``--dry-run`` and a run with nothing to
    render exited 2 ("output folder ... is not writable"). The folders are made read-only as
    the planner sees them (root writes anywhere, so permission bits cannot do it here)."""
    from draaw_mi.batch import lock as lock_mod
    from draaw_mi.cli import main
    from draaw_mi.errors import SceneError
    doc = manifest(tmp_path, frames=2)
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--no-progress"]) == 0
    capsys.readouterr()
    out = str(tmp_path / "out")

    def read_only(folders, where):
        for f in folders:
            if f.startswith(out):
                raise SceneError(f"{where}: output folder {f!r} is not writable")
    real_lock = lock_mod.output_locks

    def no_lock_files(folders, where, optional=()):
        assert not folders, folders            # only folders it may skip
        return real_lock([], where, ())
    from draaw_mi.batch import runner        # the module that checks, prepares and locks
    monkeypatch.setattr(runner, "check_writable", read_only)
    monkeypatch.setattr(runner, "prepare_outputs", read_only)
    monkeypatch.setattr(runner, "output_locks", no_lock_files)
    assert main(["batch", path, "--status"]) == 0
    assert main(["batch", path, "--dry-run"]) == 0
    assert main(["batch", path, "--no-progress"]) == 0
    assert "all 2 frames present" in capsys.readouterr().out
    os.unlink(os.path.join(out, "orbit", "0001.exr"))          # now there is work: the error
    assert main(["batch", path, "--no-progress"]) == 2
    assert "is not writable" in capsys.readouterr().err


def test_the_log_stays_put_when_a_job_is_added_and_old_errors_are_not_shown(tmp_path, capsys):
    """The default log sat in the folder the frames shared, so adding a job moved it and
    --status lost the failures; and it showed errors of settings edited away since."""
    from draaw_mi.cli import main
    doc = manifest(tmp_path, frames=2)
    doc["jobs"][0]["params"] = {"constant_light1.radiance": {"values": [[1.0, 1.0, 1.0], [3.4e38] * 3]}}
    path = write_manifest(tmp_path, doc)
    res = batch.run(path, progress=False)
    assert [r["frame"] for r in res.failed] == [1]
    assert main(["batch", path, "--status"]) == 1 and "non-finite" in capsys.readouterr().out
    two = copy.deepcopy(doc)
    two["jobs"].append(dict(copy.deepcopy(doc["jobs"][0]), name="second", params={}))
    write_manifest(tmp_path, two)                         # the same file, one job more
    st = batch.status(path)
    assert st["log"] == res.log and st["frames"][1]["status"] == "failed", st
    assert "non-finite" in st["frames"][1]["error"]
    fixed = copy.deepcopy(doc)            # frame 1's radiance edited: its old error is not its
    fixed["jobs"][0]["params"]["constant_light1.radiance"]["values"][1] = [2.0, 2.0, 2.0]
    write_manifest(tmp_path, fixed)
    st = batch.status(path)
    assert st["frames"][1]["status"] == "missing" and st["frames"][1]["error"] is None


def test_another_spelling_of_the_version_keeps_the_frames(tmp_path):
    """``V4`` or ``draaw_v4`` for ``v4`` made every finished frame stale and rendered it again
    with the same integrator."""
    doc = manifest(tmp_path, frames=2, version="v4")
    batch.run(doc, progress=False)
    for name in ("V4", "draaw_v4", "optimised"):
        assert batch.status(dict(doc, jobs=[dict(doc["jobs"][0], version=name)]))["counts"]["done"] == 2
    assert batch.status(dict(doc, jobs=[dict(doc["jobs"][0], version="v3")]))["counts"]["stale"] == 2


def test_the_bar_counts_agree_with_its_position(tmp_path, monkeypatch, capsys):
    """On a terminal the bar drew ``4/6 ... done=5``: the counts were set (and drawn) before the
    step."""
    import re
    from tqdm import tqdm
    monkeypatch.setattr(tqdm, "__init__", _no_rate_limit(tqdm.__init__))
    batch.run(manifest(tmp_path, frames=4), progress="bar")
    err = capsys.readouterr().err
    states = re.findall(r"(\d)/4 \[[^\]]*done=(\d)", err)
    assert len(states) >= 4, err
    assert all(a == b for a, b in states), states


def _no_rate_limit(init):
    def wrapped(self, *a, **k):
        k.update(mininterval=0, miniters=1)
        init(self, *a, **k)
    return wrapped


def test_a_half_frame_beyond_halfs_range_fails_as_a_non_finite_one(tmp_path):
    """``half = true`` stores values past +-65504 as inf: the NaN guard fails the frame before
    it is written (a review's run had written frames with 729 of 768 values inf, counted done)."""
    doc = manifest(tmp_path, frames=2)
    doc["half"] = True
    doc["jobs"][0]["params"] = {"constant_light1.radiance": {"values": [0.2, 1e6]}}
    _, specs, _ = batch.load(doc)
    res = batch.run(doc, progress=False)
    assert [r["frame"] for r in res.failed] == [1]
    assert "beyond half's range" in res.failed[0]["error"] and "half = false" in res.failed[0]["error"]
    assert not os.path.exists(specs[1]["output"]) and os.path.exists(specs[0]["output"])
    assert np.isfinite(draaw_mi.read_exr(specs[0]["output"])).all()
    doc["half"] = False                                    # float32 holds 1e6: done
    assert batch.run(doc, progress=False).complete
