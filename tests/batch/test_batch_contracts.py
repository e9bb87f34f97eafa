"""Contracts of the batch pieces that a run's outcome hides: a damaged frame behind an intact
header, stale versus foreign frames, the frame hash, orbit and keyframe cameras, manifest
defaults, probe clean-up and the output-folder lock."""
from __future__ import annotations

import copy
import fcntl as real_fcntl
import os
import time

import numpy as np
import pytest
from batch_helpers import manifest, write_manifest

from draaw_mi.batch import runner as batch
from draaw_mi.batch import lock
from draaw_mi.batch.exr import _scanline_layout, exr_complete
from draaw_mi.errors import BusyError, IOFailure
from draaw_mi.io import read_exr


def _still(tmp_path, frames=1, **job) -> dict:
    """A job (one frame unless told) without parameter ramps."""
    doc = manifest(tmp_path, frames=frames, **job)
    del doc["jobs"][0]["params"]
    return doc


@pytest.mark.parametrize("zeroed", ["table", "pixels"])
def test_an_intact_header_over_zeroed_data_is_damaged(tmp_path, zeroed):
    """A power cut after the rename can leave the header on disk and zeros in place of the
    offset table and pixels. Every offset is then 0, which lies inside the file, and the
    'chunk' read at offset 0 (the magic number and version) passed for a complete one: the
    frame counted as done for ever. With the table intact and the pixels zeroed, the chunks
    read as empty (size 0), which passed too."""
    doc = _still(tmp_path)
    assert batch.run(doc, progress=False).rendered == 1
    _, specs, _ = batch.load(doc)
    path = specs[0]["output"]
    raw = bytearray(open(path, "rb").read())
    table_at, chunks = _scanline_layout(bytes(raw[:1 << 18]))
    assert 0 < table_at < len(raw) and chunks > 0
    start = table_at if zeroed == "table" else table_at + 8 * chunks
    raw[start:] = bytes(len(raw) - start)
    with open(path, "wb") as fh:
        fh.write(raw)
    assert batch.read_header(path)["draaw:frame_hash"] == specs[0]["hash"]   # the header reads
    with pytest.raises(IOFailure):                  # independent: the pixels do not
        read_exr(path)
    assert exr_complete(path) is False
    assert batch.frame_status(specs[0]) == "damaged"


def test_a_preview_is_never_there_without_its_frame(tmp_path, monkeypatch):
    """A frame whose EXR is not written (a kill, a full disk during the write) leaves no PNG:
    the PNG was written first, and a run killed between the two left a preview of a frame
    that does not exist. A kill between the EXR and its PNG leaves a frame without preview,
    which the next run writes from the EXR."""
    from draaw_mi.batch import frame
    doc = _still(tmp_path, frames=1)
    doc["previews"] = True
    _, specs, _ = batch.load(doc)
    png = os.path.splitext(specs[0]["output"])[0] + ".png"

    def disk_full(path, *args, **kwargs):
        raise IOFailure(f"write_exr({path!r}): No space left on device")
    real_frame, real_preview = frame.write_frame, frame.write_preview
    monkeypatch.setattr(frame, "write_frame", disk_full)
    res = batch.run(doc, progress=False)
    assert res.failed and "No space left" in res.failed[0]["error"]
    assert not os.path.exists(specs[0]["output"]) and not os.path.exists(png)
    monkeypatch.setattr(frame, "write_frame", real_frame)

    def killed(spec, *args, **kwargs):
        raise IOFailure("killed between the writes")
    monkeypatch.setattr(frame, "write_preview", killed)
    assert batch.run(doc, progress=False).failed
    assert os.path.exists(specs[0]["output"]) and not os.path.exists(png)
    assert batch.frame_status(specs[0]) == "no-preview"
    monkeypatch.setattr(frame, "write_preview", real_preview)
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 0 and res.previews == 1 and os.path.exists(png)


def test_frames_of_a_dict_manifest_are_stale_not_foreign_to_a_manifest_file(tmp_path):
    """Frames made from a dict manifest carry no draaw:manifest. Run again from a manifest
    file with other settings, they are stale and rendered again; a missing maker is not
    'another manifest' (the run stopped with SceneError as if a second shot owned them)."""
    doc = _still(tmp_path)
    assert batch.run(doc, progress=False).rendered == 1
    _, specs, _ = batch.load(doc)
    assert "draaw:manifest" not in batch.read_header(specs[0]["output"])
    doc["jobs"][0]["spp"] = 8
    path = write_manifest(tmp_path, doc)
    assert batch.status(path)["counts"]["stale"] == 1
    res = batch.run(path, progress=False)
    assert res.rendered == 1 and res.complete
    header = batch.read_header(specs[0]["output"])
    assert header["draaw:spp"] == 8 and header["draaw:manifest"] == os.path.abspath(path)


@pytest.mark.parametrize("key, value", [("max_depth", 2), ("spp", 8), ("seed", 7), ("version", "path")])
def test_each_setting_that_changes_the_pixels_renders_the_frame_again(tmp_path, key, value):
    """The frame hash covers every job setting that changes the pixels: with one missing,
    changing that setting left the old frame 'done' and its header showed the old value."""
    doc = _still(tmp_path)
    assert batch.run(doc, progress=False).rendered == 1
    other = copy.deepcopy(doc)
    other["jobs"][0][key] = value
    _, specs, _ = batch.load(other)
    assert batch.read_header(specs[0]["output"])[f"draaw:{key}"] != specs[0][key]
    res = batch.run(other, progress=False)
    assert res.rendered == 1 and res.skipped == 0
    header = batch.read_header(specs[0]["output"])
    # (the header's seed is the frame's, derived from the job's)
    assert header[f"draaw:{key}"] == specs[0][key]
    if key != "seed":
        assert header[f"draaw:{key}"] == value
    assert batch.run(other, progress=False).rendered == 0


def test_a_partial_orbit_ends_on_its_last_angle(tmp_path):
    """An orbit of 90 degrees over 4 frames shows 0, 30, 60 and 90 degrees from its start:
    only a full turn leaves out its end (which repeats frame 0). Stepping by degrees/frames
    stopped a partial orbit at 67.5 degrees."""
    target = np.array([0.0, 0.5, 0.0])
    doc = _still(tmp_path, frames=4, camera={"orbit": {"target": target.tolist(), "radius": 5.0,
                                                       "height": 0.8, "degrees": 90, "start": 10}})
    _, specs, _ = batch.load(doc)
    d = np.array([s["camera"]["origin"] for s in specs]) - target
    assert np.allclose(d[:, 1], 0.8) and np.allclose(np.hypot(d[:, 0], d[:, 2]), 5.0)
    angles = np.degrees(np.unwrap(np.arctan2(d[:, 0], d[:, 2])))   # in the plane normal to +y
    sweep = angles - angles[0]
    assert np.allclose(np.abs(sweep), [0.0, 30.0, 60.0, 90.0], atol=1e-6), angles
    assert np.all(np.diff(sweep) > 0) or np.all(np.diff(sweep) < 0)
    assert all(np.allclose(s["camera"]["target"], target) for s in specs)


def test_faithful_keyframes_follow_go_draaws_quirky_easing(tmp_path):
    """camera.faithful = true reproduces GO-Draaw's path (go-draaw-spec §2.9): frames/(n-1)
    per segment eased by t * smoothstep(t), the last frame on the last key. The flag was
    dropped on the way to the interpolation, and the frames followed the fixed path."""
    keys = [[0.0, 1.0, 5.0, 0.0, -1.5], [4.0, 1.0, 5.0, 0.0, -1.5], [8.0, 1.0, 5.0, 0.0, -1.5]]
    doc = _still(tmp_path, frames=6, camera={"keyframes": keys, "faithful": True})
    _, specs, _ = batch.load(doc)
    got = np.array([s["camera"]["origin"] for s in specs])
    p = np.array(keys)[:, :3]
    per = 6 // (len(keys) - 1)
    want = []
    for k in range(6):                               # the spec's formula, written out
        seg, t = k // per, (k % per) / per
        want.append(p[seg] + (p[seg + 1] - p[seg]) * t * (t * t * (3 - 2 * t)))
    want[-1] = p[-1]
    # (the origin is the keyframe position up to GO-Draaw's axes: compare the moving x, and
    # that y and z stay put)
    assert np.allclose(got[:, 0], np.array(want)[:, 0], atol=1e-9), got[:, 0]
    assert np.allclose(got[:, 1:], got[0, 1:])
    u = np.linspace(0.0, 2.0, 6) % 1.0                # the fixed path differs here
    u[-1] = 1.0
    fixed = np.array([0, 0, 0, 4, 4, 4]) + 4 * u * u * (3 - 2 * u)
    assert not np.allclose(fixed, np.array(want)[:, 0])


def test_a_job_setting_wins_over_the_defaults(tmp_path):
    """[defaults] fills in what a job does not set: the job's own spp and seed win over the
    defaults' (the defaults overrode them), and max_depth, unset in the job, takes the
    default."""
    doc = manifest(tmp_path, frames=1, spp=4, seed=3)
    doc["defaults"] = {"spp": 16, "seed": 99, "max_depth": 2}
    job = batch.parse_manifest(doc).jobs[0]
    assert (job.spp, job.seed, job.max_depth) == (4, 3, 2)
    del doc["defaults"]["max_depth"]
    assert batch.parse_manifest(doc).jobs[0].max_depth is None


def test_old_folder_probes_are_removed_and_fresh_ones_kept(tmp_path):
    """A folder probe older than the grace period is a killed run's leftover and goes; a
    fresh one may be another run's, in the instant before its lock, and stays."""
    from draaw_mi.batch.runner import PROBE_GRACE_S, remove_temp_files
    out = tmp_path / "out"
    out.mkdir()
    old, fresh = out / ".draaw-probe-old", out / ".draaw-probe-fresh"
    old.write_bytes(b"")
    fresh.write_bytes(b"")
    then = time.time() - 3600
    assert 3600 > PROBE_GRACE_S
    os.utime(old, (then, then))
    removed = remove_temp_files([{"output": str(out / "0000.exr")}])
    assert removed == [str(old)]
    assert sorted(os.listdir(out)) == [".draaw-probe-fresh"]


def _holder_finishing_meanwhile(folder, times):
    """An ``fcntl`` whose ``flock`` first deletes the folder's lock file, as a finishing
    holder does between a run's open and its flock, the first ``times`` times."""
    left = [times]

    class HolderFinishesMeanwhile:
        LOCK_EX, LOCK_NB, LOCK_UN = real_fcntl.LOCK_EX, real_fcntl.LOCK_NB, real_fcntl.LOCK_UN

        @staticmethod
        def flock(fd, op):
            path = os.path.join(folder, lock.LOCK_NAME)
            if left[0] > 0 and os.path.exists(path):
                left[0] -= 1
                os.unlink(path)
            return real_fcntl.flock(fd, op)

    return HolderFinishesMeanwhile


def test_a_lock_on_a_lock_file_its_holder_just_deleted_is_taken_on_the_new_file(tmp_path, monkeypatch):
    """The holder of a folder's lock deletes the lock file as it finishes. A run that opened
    the file just before, and gets the flock just after, holds a lock on a deleted file that
    excludes nobody: the next run creates a new file and locks the folder too (two runs in
    one folder). The run must lock the folder's lock file as it is now: the file there holds
    its pid and a second run is refused."""
    folder = str(tmp_path)
    path = os.path.join(folder, lock.LOCK_NAME)
    monkeypatch.setattr(lock, "fcntl", _holder_finishing_meanwhile(folder, times=2))
    with lock.output_locks([folder], "a.toml"):
        with open(path) as f:
            assert f.read().strip() == str(os.getpid())
        monkeypatch.setattr(lock, "fcntl", real_fcntl)
        fd = os.open(path, os.O_RDONLY)
        try:
            with pytest.raises(BlockingIOError):   # what a second run's flock meets
                real_fcntl.flock(fd, real_fcntl.LOCK_EX | real_fcntl.LOCK_NB)
        finally:
            os.close(fd)
    assert not os.path.exists(path)


def test_a_lock_file_deleted_under_every_attempt_is_refused(tmp_path, monkeypatch):
    """Runs that keep finishing under this one (the file deleted at each attempt): after a
    few attempts the run is told the folder is busy, with nothing locked."""
    folder = str(tmp_path)
    monkeypatch.setattr(lock, "fcntl", _holder_finishing_meanwhile(folder, times=10 ** 6))
    with pytest.raises(BusyError, match="is in use by another draaw-mi batch run"):
        with lock.output_locks([folder], "a.toml"):
            pass
    monkeypatch.setattr(lock, "fcntl", real_fcntl)
    with lock.output_locks([folder], "a.toml"):          # the next try, undisturbed, gets it
        assert os.path.exists(os.path.join(folder, lock.LOCK_NAME))
    assert not os.path.exists(os.path.join(folder, lock.LOCK_NAME))


@pytest.mark.parametrize("was_on", [False, True])
def test_the_in_process_executor_leaves_the_kernel_history_flag_as_it_found_it(was_on, monkeypatch):
    """run_inprocess turns Dr.Jit's kernel history on to count each frame's compiles; it
    left it on afterwards, so every later kernel of the process was kept in the history.
    The flag comes back also when a result's handler raises (the frames are stubbed)."""
    import drjit as dr

    from draaw_mi.batch import executors
    from draaw_mi.batch.executors import run_inprocess
    monkeypatch.setattr(executors, "safe_render_frame", lambda spec, cache, track: spec)
    seen = []

    def stop(result):
        assert dr.flag(dr.JitFlag.KernelHistory)         # on while the frames render
        seen.append(result)
        raise RuntimeError("stop")
    old = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, was_on)
    try:
        run_inprocess([], cache=None, on_result=stop, track_kernels=True)
        assert dr.flag(dr.JitFlag.KernelHistory) == was_on
        with pytest.raises(RuntimeError, match="stop"):
            run_inprocess(["a", "b"], cache=None, on_result=stop, track_kernels=True)
        assert seen == ["a"] and dr.flag(dr.JitFlag.KernelHistory) == was_on
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, old)
