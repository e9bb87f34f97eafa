"""Frames whose pixel data does not decode though their size, header and chunk table are
intact (bytes zeroed inside a chunk): ``verify`` finds them, and a run that reads a finished
frame itself (a preview from its EXR, a contact sheet) does not pass one off as done."""
from __future__ import annotations

import os
import shutil
import struct

import pytest
from batch_helpers import assert_bit_identical, frames_of, manifest, write_manifest

from draaw_mi.batch import runner as batch
from draaw_mi.batch.exr import _scanline_layout, exr_complete, exr_decodes
from draaw_mi.errors import IOFailure
from draaw_mi.io import read_exr


def _still(tmp_path, frames=2, **doc) -> dict:
    d = manifest(tmp_path, frames=frames)
    del d["jobs"][0]["params"]
    d.update(doc)
    return d


def _zero_inside_a_chunk(path: str) -> None:
    """Zero bytes in the middle of the first chunk's compressed data: the file keeps its size,
    header, offset table and chunk headers (a bad block, zeros written over a file's middle)."""
    with open(path, "r+b") as fh:
        raw = fh.read()
        table_at, chunks = _scanline_layout(raw[:1 << 18])
        at = struct.unpack_from("<Q", raw, table_at)[0]
        _, length = struct.unpack_from("<ii", raw, at)
        assert length > 16
        fh.seek(at + 8 + length // 4)
        fh.write(bytes(min(200, length // 2)))
    assert os.path.getsize(path) == len(raw)


def _damage(specs, i=1) -> str:
    path = specs[i]["output"]
    _zero_inside_a_chunk(path)
    with pytest.raises(IOFailure):            # independent: reading the pixels fails
        read_exr(path)
    assert exr_complete(path)                 # what is checked without verify passes
    return path


def test_verify_finds_a_frame_whose_pixels_do_not_decode_and_a_run_renders_it_again(tmp_path):
    doc = _still(tmp_path)
    assert batch.run(doc, progress=False).rendered == 2
    ref = tmp_path / "ref"
    shutil.copytree(tmp_path / "out", ref)
    _, specs, _ = batch.load(doc)
    path = _damage(specs)
    assert not exr_decodes(path) and exr_decodes(specs[0]["output"])
    assert batch.status(doc)["counts"]["done"] == 2                      # the cheap check's limit
    st = batch.status(doc, verify=True)
    assert [f["status"] for f in st["frames"]] == ["done", "damaged"]
    assert batch.run(doc, progress=False).rendered == 0                  # not decoded: skipped
    res = batch.run(doc, progress=False, verify=True)
    assert res.rendered == 1 and res.skipped == 1 and res.complete
    assert [r["frame"] for r in res.results] == [1]
    assert batch.status(doc, verify=True)["counts"]["done"] == 2
    assert_bit_identical(frames_of(ref), frames_of(tmp_path / "out"))


def test_status_verify_on_the_command_line_says_damaged_without_openexrs_messages(tmp_path, capfd):
    """OpenEXR's C library prints ``(EXR_ERR_CORRUPT_CHUNK) Unable to decompress`` on standard
    error and its binding a warning on standard output for such a file: the check silences
    both (captured at the file descriptors, where they are written)."""
    from draaw_mi.cli import main
    doc = _still(tmp_path)
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--no-progress"]) == 0
    _, specs, _ = batch.load(doc)
    damaged = _damage(specs)
    capfd.readouterr()
    assert main(["batch", path, "--status"]) == 0
    assert main(["batch", path, "--status", "--verify"]) == 1
    out, err = capfd.readouterr()
    assert f"damaged    {damaged}" in out and "1 damaged (unreadable, cut short or not decoding)" in out
    assert "EXR_ERR" not in out + err and "Exception raised" not in out + err, (out, err)
    assert main(["batch", path, "--no-progress", "--verify"]) == 0
    out, err = capfd.readouterr()
    assert "1 rendered, 1 already done" in out and "EXR_ERR" not in err


def test_a_preview_written_from_an_exr_that_does_not_decode_renders_the_frame_again(tmp_path):
    """Previews turned on for finished frames are written from their EXRs; one EXR does not
    decode: the frame is rendered again (it was a failed frame on every run)."""
    doc = _still(tmp_path)
    assert batch.run(doc, progress=False).rendered == 2
    doc["previews"] = True
    _, specs, _ = batch.load(doc)
    path = _damage(specs)
    assert [f["status"] for f in batch.status(doc)["frames"]] == ["no-preview", "no-preview"]
    res = batch.run(doc, progress=False)
    assert res.complete and not res.failed, res.failed
    assert res.previews == 1 and res.rendered == 1 and [r["frame"] for r in res.results] == [1]
    assert exr_decodes(path) and os.path.isfile(os.path.splitext(path)[0] + ".png")
    assert any(r["event"] == "damaged" and r["output"] == path for r in batch.read_log(res.log))


def test_a_run_with_contact_sheets_verifies_the_frames_it_reads_for_them(tmp_path, capfd):
    doc = _still(tmp_path, contact_sheet=True)
    assert batch.run(doc, progress=False).rendered == 2
    _, specs, _ = batch.load(doc)
    path = _damage(specs)
    capfd.readouterr()
    res = batch.run(doc, progress=False)
    assert res.rendered == 1 and res.complete and not res.sheet_error and not res.damaged, res.summary()
    assert exr_decodes(path)
    out, err = capfd.readouterr()
    assert "EXR_ERR" not in out + err and "Exception raised" not in out + err, (out, err)


def test_a_frame_damaged_while_the_run_renders_makes_it_incomplete(tmp_path):
    """A finished frame that stops decoding after the run checked it (read for the contact
    sheet): the run is not complete, the summary says to run with --verify, the log says which
    (it said 'all frames present', exit 0, contact sheets not written, on every run)."""
    doc = _still(tmp_path, frames=3, contact_sheet=True)
    _, specs, _ = batch.load(doc)
    assert batch.run(doc, progress=False).rendered == 3
    os.unlink(specs[2]["output"])

    def damage_frame_0(r):
        _zero_inside_a_chunk(specs[0]["output"])
    res = batch.run(doc, progress=False, on_result=damage_frame_0)
    assert res.rendered == 1 and not res.complete and res.missing == 1
    assert res.damaged == [specs[0]["output"]] and not res.sheet_error
    assert "counted as done do not decode" in res.summary() and "--verify" in res.summary()
    log = batch.read_log(res.log)
    assert log[-1]["event"] == "end" and log[-1]["missing"] == 1
    assert [r["output"] for r in log if r["event"] == "damaged"] == [specs[0]["output"]]
    again = batch.run(doc, progress=False)
    assert again.rendered == 1 and again.complete


def test_verify_is_a_flag(tmp_path):
    from draaw_mi.errors import ParameterError
    doc = _still(tmp_path, frames=1)
    for fn in (batch.run, batch.status):
        with pytest.raises(ParameterError, match="verify='yes'; expected True or False"):
            fn(doc, verify="yes")
