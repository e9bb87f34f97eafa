"""Kill-safety: ``draaw-mi batch`` killed with SIGKILL at random moments while it renders, and
resumed each time, leaves no partial or corrupt frame and ends bit-identical to an
uninterrupted run (box filter, 32x24, 8 spp)."""
from __future__ import annotations

import glob
import os
import random
import signal
import subprocess
import sys
import time

import pytest
from batch_helpers import assert_bit_identical, frames_of, manifest, write_manifest

from draaw_mi.batch import runner as batch
from draaw_mi.io import read_exr

CLI = "import sys; from draaw_mi.cli import main; sys.exit(main())"
FRAMES = 80
KILLS = 5


def _finished(folder) -> list[str]:
    return [p for p in glob.glob(os.path.join(str(folder), "*", "*.exr"))
            if not os.path.basename(p).startswith(".")]


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX signals")
def test_sigkill_at_random_moments_then_resume(tmp_path):
    doc = manifest(tmp_path, frames=FRAMES, spp=8)
    doc["output"] = "{job}/{frame:04d}.exr"
    path = write_manifest(tmp_path, doc)
    ref_dir, run_dir = tmp_path / "ref", tmp_path / "killed"
    ref = batch.run(path, out=str(ref_dir), progress=False)            # uninterrupted, in this process
    assert ref.complete and ref.rendered == FRAMES
    _, specs, _ = batch.load(path, out=str(run_dir))
    by_path = {s["output"]: s for s in specs}

    rng = random.Random(20261122)
    kills, temp_seen, progress = 0, set(), []
    for attempt in range(3 * KILLS):
        if kills == KILLS:
            break
        # a random number of frames into the run, then a random moment inside a frame: the
        # kill lands while a frame renders or while its EXR is written, and the batch (fast
        # once its recording replays) cannot finish before the five kills
        target = len(_finished(run_dir)) + rng.randint(1, 8)
        proc = subprocess.Popen([sys.executable, "-c", CLI, "batch", path, "--out", str(run_dir), "--no-progress"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 120
        while len(_finished(run_dir)) < target and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.002)
        time.sleep(rng.uniform(0.0, 0.03))
        if proc.poll() is not None:                                    # it finished first
            assert proc.returncode == 0, proc.stderr.read().decode()
            break
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
        kills += 1
        temp_seen |= set(glob.glob(os.path.join(str(run_dir), "*", ".draaw-*")))
        done = _finished(run_dir)
        progress.append(len(done))
        for p in done:                                                 # 0 partial or corrupt files
            assert batch.frame_status(by_path[p]) == "done", p
            assert read_exr(p).shape == (24, 32, 3)
    assert kills == KILLS, f"only {kills} runs were killed before the batch completed ({progress})"
    assert 0 < progress[0] and progress[-1] < FRAMES and progress == sorted(progress)

    res = batch.run(path, out=str(run_dir), progress=False)           # resume to the end
    assert res.complete and res.skipped == progress[-1] and res.rendered == FRAMES - progress[-1]
    assert not glob.glob(os.path.join(str(run_dir), "*", ".draaw-*")), "temp files left behind"
    assert_bit_identical(frames_of(ref_dir), frames_of(run_dir))
    print(f"kills after {progress} finished frames; temp files seen after kills: {len(temp_seen)}")


WRITER = """
import sys, numpy as np
from draaw_mi.batch.exr import write_frame
img = np.random.default_rng(0).random((1024, 1024, 8), dtype=np.float32)
names = ["R", "G", "B", "depth.Z", "N.X", "N.Y", "N.Z", "albedo.R"]
i = 0
while True:                                   # rewrite the same frame until killed
    write_frame(sys.argv[1], img, names, {"draaw:frame_hash": "h%d" % i})
    i += 1
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX signals")
def test_sigkill_during_exr_writes_never_leaves_a_partial_frame(tmp_path):
    """Kills land inside large EXR writes here (each takes tens of ms): the frame's name holds
    either nothing or a complete file, and the temp file a kill leaves is removed on resume."""
    target = tmp_path / "job" / "0000.exr"
    rng = random.Random(7)
    temps: set = set()
    for _ in range(KILLS):
        ino = target.stat().st_ino if target.exists() else None
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(target)], stderr=subprocess.PIPE)
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline and (
                not target.exists() or target.stat().st_ino == ino):
            time.sleep(0.005)                                 # until this process has written once
        time.sleep(rng.uniform(0.0, 0.3))
        assert proc.poll() is None, proc.stderr.read().decode()
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
        assert read_exr(str(target)).shape == (1024, 1024, 8)      # complete, readable
        temps |= set(glob.glob(str(tmp_path / "job" / ".draaw-*")))
    assert temps, "no kill landed inside a write; the test did not exercise the rename"
    removed = batch.remove_temp_files([{"output": str(target)}])
    assert set(removed) == temps and not glob.glob(str(tmp_path / "job" / ".draaw-*"))


@pytest.mark.skipif(not hasattr(signal, "SIGTERM"), reason="needs POSIX signals")
def test_sigterm_ends_a_batch_as_ctrl_c_does(tmp_path):
    """``kill PID`` (SIGTERM) during a batch: one line, status 143, the log's end record written
    and the output folders' locks released (the default action had ended the process on the
    spot: no end record, lock files left); a resumed run finishes the rest."""
    doc = manifest(tmp_path, frames=40, spp=8)
    doc["output"] = "{job}/{frame:04d}.exr"
    path = write_manifest(tmp_path, doc)
    run_dir = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", CLI, "batch", path, "--out", str(run_dir), "--no-progress"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while len(_finished(run_dir)) < 2 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    assert proc.poll() is None, "the batch ended before the signal"
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 143
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert err.strip().splitlines()[-1] == "draaw-mi: terminated", err
    res = batch.status(path, out=str(run_dir))
    log = batch.read_log(res["log"])
    assert log[-1]["event"] == "end" and 0 < log[-1]["rendered"] < 40
    from draaw_mi.batch.lock import LOCK_NAME
    assert not [d for d, _, files in os.walk(run_dir) if LOCK_NAME in files]   # (a normal end deletes it)
    # the end record's missing count is read from the disk: a frame whose EXR landed as the
    # signal arrived is not missing though its report (and the rendered count) never came
    end = log[-1]
    assert end["rendered"] <= 40 - end["missing"] <= end["rendered"] + 1
    again = batch.run(path, out=str(run_dir), progress=False)
    assert again.complete and again.rendered == end["missing"] and again.skipped == 40 - end["missing"]
