"""Every file of a batch lies under its output folder (--out, else the current folder): a
climbing, absolute or field-smuggled output pattern, a log outside it and a symbolic link out of
it are refused in one line, exit 2, and nothing is written anywhere; --allow-outside-out lets a
trusted manifest do it (draaw_mi.batch.confine)."""
from __future__ import annotations

import os

import pytest
from batch_helpers import frames_of, manifest, write_manifest

from draaw_mi.batch import runner as batch
from draaw_mi.batch.frame import SceneCache, render_frame
from draaw_mi.cli import main
from draaw_mi.batch.lock import LOCK_NAME
from draaw_mi.errors import BusyError, ParameterError, SceneError


def tree(root) -> set:
    """Every file and folder under ``root`` (links as themselves)."""
    out = set()
    for folder, dirs, files in os.walk(str(root)):
        for name in dirs + files:
            out.add(os.path.relpath(os.path.join(folder, name), str(root)))
    return out


def _refused(tmp_path, capsys, mutate, expect, out="out/a/b"):
    doc = manifest(tmp_path, frames=2)
    mutate(doc)
    path = write_manifest(tmp_path, doc)
    before = tree(tmp_path)
    assert main(["batch", path, "--out", str(tmp_path / out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("draaw-mi: error: "), err
    for e in expect:
        assert e in err, err
    assert tree(tmp_path) == before                    # nothing written anywhere
    return doc, path


def test_a_climbing_pattern_is_refused(tmp_path, capsys):
    _refused(tmp_path, capsys, lambda d: d.update(output="../../escaped/{job}_{frame:04d}.exr"),
             ["jobs[0].output", "'../../escaped/{job}_{frame:04d}.exr' climbs out of the output folder",
              "--allow-outside-out"])


def test_an_absolute_pattern_is_refused(tmp_path, capsys):
    target = str(tmp_path / "elsewhere" / "{job}_{frame:04d}.exr")
    _refused(tmp_path, capsys, lambda d: d.update(output=target), ["is an absolute path", "--allow-outside-out"])


def test_a_field_cannot_smuggle_a_climb(tmp_path, capsys):
    """``{job:.>2.0}`` formats any job name as '..': the pattern has no '..' of its own, its
    frames' files do (checked once the fields are filled in)."""
    _refused(tmp_path, capsys, lambda d: d.update(output="{job:.>2.0}/{frame:04d}.exr"),
             ["job 'orbit' frame 0 would be written to", "outside the output folder"])


@pytest.mark.parametrize("log, why", [("../escaped.jsonl", "'../escaped.jsonl' climbs out of the output folder"),
                                      ("/tmp/draaw-escaped.jsonl", "'/tmp/draaw-escaped.jsonl' is an absolute path")])
def test_a_log_outside_is_refused(tmp_path, capsys, log, why):
    _refused(tmp_path, capsys, lambda d: d.update(log=log), ["log", why, "--allow-outside-out"])


def test_a_log_through_a_symbolic_link_is_refused(tmp_path, capsys):
    """A log name with no '..' whose folder links out: refused once the real path is known."""
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out").mkdir()
    os.symlink(tmp_path / "elsewhere", tmp_path / "out" / "link")
    _refused(tmp_path, capsys, lambda d: d.update(log="link/run.jsonl"),
             ["the log would be written to", "through a symbolic link", "--allow-outside-out"], out="out")


def test_a_log_that_became_a_link_is_not_written_through(tmp_path):
    """The log opens without following a link put in its place after planning."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    os.symlink(victim, tmp_path / "run.jsonl")
    with pytest.raises(SceneError, match="cannot open the log"):
        batch._Log(str(tmp_path / "run.jsonl"))
    assert victim.read_text() == "precious"


def test_a_planted_lock_file_link_is_not_followed(tmp_path):
    """Someone who can write into a shared --out plants the lock file as a link to a file of
    the user's: the run would empty it and write its pid there."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    doc = manifest(tmp_path, frames=1)
    folder = tmp_path / "out" / "out" / "orbit"                # the job's frames' folder
    folder.mkdir(parents=True)
    os.symlink(victim, folder / LOCK_NAME)
    with pytest.raises(BusyError, match="cannot be locked"):
        batch.run(doc, out=str(tmp_path / "out"), progress=False)
    assert victim.read_text() == "precious" and os.path.islink(folder / LOCK_NAME)
    assert frames_of(tmp_path / "out") == {}


@pytest.mark.parametrize("call", [batch.run, batch.status, batch.load])
def test_the_flag_takes_true_or_false_only(tmp_path, call):
    """The string "false" is true: it would have lifted the confinement."""
    doc = manifest(tmp_path, frames=1)
    doc["output"] = "../escaped/{frame:04d}.exr"
    with pytest.raises(ParameterError, match=r"allow_outside_out='false'; expected True or False"):
        call(doc, out=str(tmp_path / "out"), allow_outside_out="false")
    assert not (tmp_path / "escaped").exists()


def test_a_symbolic_link_out_of_the_folder_is_not_written_through(tmp_path, capsys):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out").mkdir()
    os.symlink(tmp_path / "elsewhere", tmp_path / "out" / "link")
    doc, path = _refused(tmp_path, capsys, lambda d: d.update(output="link/{job}/{frame:04d}.exr"),
                         ["through a symbolic link", str(tmp_path / "elsewhere")], out="out")
    # a manifest the user trusts: the flag lets it write there
    assert main(["batch", path, "--out", str(tmp_path / "out"), "--allow-outside-out", "--no-progress"]) == 0
    assert sorted(frames_of(tmp_path / "elsewhere")) == ["orbit/0000.exr", "orbit/0001.exr"]


def test_a_link_made_after_planning_fails_its_frame_and_writes_nothing(tmp_path):
    """The writer checks again: a folder replaced by a link between planning and writing."""
    doc = manifest(tmp_path, frames=1)
    m, specs, cache = batch.load(doc, out=str(tmp_path / "out"))
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out" / "out").mkdir(parents=True)
    os.symlink(tmp_path / "elsewhere", tmp_path / "out" / "out" / "orbit")      # the job's folder
    with pytest.raises(SceneError, match="outside the output folder"):
        render_frame(specs[0], SceneCache())
    assert os.listdir(tmp_path / "elsewhere") == []


def test_the_flag_lets_a_trusted_manifest_climb(tmp_path, capsys):
    doc = manifest(tmp_path, frames=2)
    doc["output"] = "../escaped/{job}_{frame:04d}.exr"
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--out", str(tmp_path / "out"), "--allow-outside-out", "--no-progress"]) == 0
    assert sorted(f for f in os.listdir(tmp_path / "escaped") if f.endswith(".exr")) == ["orbit_0000.exr", "orbit_0001.exr"]
    res = batch.run(doc, out=str(tmp_path / "out"), progress=False, allow_outside_out=True)
    assert res.complete and res.skipped == 2                        # resumable as ever


def test_outputs_inside_are_written_as_before(tmp_path):
    doc = manifest(tmp_path, frames=2)
    res = batch.run(doc, out=str(tmp_path / "o"), progress=False)
    assert res.complete and sorted(frames_of(tmp_path / "o")) == ["out/orbit/0000.exr", "out/orbit/0001.exr"]
    assert all(r["output"].startswith(str(tmp_path / "o")) for r in res.results)
