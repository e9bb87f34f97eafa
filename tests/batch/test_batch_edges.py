"""Batch edge cases from a review: two manifests on one output folder, braces in folder names,
a log that names an output or a folder, an orbit without an axis, camera tables on Mitsuba XML
scenes whose sensor is not called "sensor", a full disk under the log, damaged logs, and EXR
headers longer than the bytes the completeness check reads."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest
from batch_helpers import frames_of, manifest, write_manifest

from draaw_mi.batch import runner as batch
from draaw_mi.errors import SceneError


def _one_frame(tmp_path, **job):
    """A one-frame job without a name (``job0``: the default name two manifests share)."""
    doc = manifest(tmp_path, frames=1, **job)
    del doc["jobs"][0]["name"]
    doc["output"] = "{job}/{frame:04d}.exr"          # relative: under --out
    return doc


def test_another_manifest_does_not_replace_finished_frames(tmp_path, capsys):
    out = str(tmp_path / "shared")
    a = write_manifest(tmp_path, _one_frame(tmp_path), "shot_a.toml")
    b = write_manifest(tmp_path, _one_frame(tmp_path, spp=8), "shot_b.toml")
    assert batch.run(a, out=out, progress=False).rendered == 1
    before = frames_of(out)
    header = batch.read_header(os.path.join(out, "job0", "0000.exr"))
    assert header["draaw:manifest"] == os.path.abspath(a)
    st = batch.status(b, out=out)
    assert st["counts"]["foreign"] == 1 and st["frames"][0]["status"] == "foreign"
    with pytest.raises(SceneError, match="shot_a.toml") as e:        # (b overwrote a's frame, exit 0)
        batch.run(b, out=out, progress=False)
    assert "overwrite" in str(e.value)
    after = frames_of(out)
    assert np.array_equal(before["job0/0000.exr"], after["job0/0000.exr"])
    from draaw_mi.cli import main
    assert main(["batch", b, "--out", out, "--no-progress"]) == 2
    assert "overwrite" in capsys.readouterr().err
    assert main(["batch", b, "--out", out, "--no-progress", "--overwrite"]) == 0
    assert batch.read_header(os.path.join(out, "job0", "0000.exr"))["draaw:manifest"] == os.path.abspath(b)
    # the same manifest moved elsewhere: its frames are its own (the path is not in the hash)
    moved = write_manifest(tmp_path / "shared", _one_frame(tmp_path, spp=8), "moved_b.toml")
    st = batch.status(moved, out=out)
    assert st["counts"]["done"] == 1, st["counts"]
    # the same manifest with other settings: stale, rendered again without a word
    write_manifest(tmp_path, _one_frame(tmp_path, spp=2), "shot_b.toml")
    assert batch.run(b, out=out, progress=False).rendered == 1


def test_braces_in_the_output_folder_are_text(tmp_path):
    doc = _one_frame(tmp_path)
    out = str(tmp_path / "out{x}")
    res = batch.run(doc, out=out, progress=False)          # (KeyError: 'x')
    assert res.complete and os.path.isfile(os.path.join(out, "job0", "0000.exr"))
    assert os.path.dirname(res.log) == out
    out = str(tmp_path / "{job}dir")             # (the frames went to 'job0dir/job0/...')
    doc["output"] = "{job}/frames/{frame:04d}.exr"
    res = batch.run(doc, out=out, progress=False)
    assert os.path.isfile(os.path.join(out, "job0", "frames", "0000.exr")), os.listdir(tmp_path)
    assert os.path.dirname(res.log) == out          # (the log went to the folder of the first field)


def test_the_log_is_a_file_of_its_own(tmp_path):
    doc = _one_frame(tmp_path)
    out = str(tmp_path / "o")
    batch.run(doc, out=out, progress=False)
    done = os.path.join(out, "job0", "0000.exr")
    size = os.path.getsize(done)
    with pytest.raises(SceneError, match="is an output of job 'job0' frame 0"):
        batch.run(dict(doc, log="job0/0000.exr"), out=out, progress=False)
    assert os.path.getsize(done) == size                    # (JSON was appended to the frame)
    os.makedirs(os.path.join(out, "logs"))
    with pytest.raises(SceneError, match="is a folder"):
        batch.run(dict(doc, log="logs"), out=out, progress=False)


def test_orbit_without_an_axis_is_refused(tmp_path):
    doc = _one_frame(tmp_path)
    doc["jobs"][0]["camera"]["orbit"]["up"] = [0, 0, 0]    # (black frames, exit 0)
    with pytest.raises(SceneError, match=r"orbit\.up.*no direction"):
        batch.load(doc)


XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective"{sid}>
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0.5,4" target="0,0.3,0" up="0,1,0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="cube" id="box"><transform name="to_world"><scale value="0.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7,0.3,0.2"/></bsdf></shape>
  <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
</scene>
"""


@pytest.mark.parametrize("sid", [' id="Camera"', ""])
def test_camera_tables_on_xml_scenes_find_the_sensor(tmp_path, sid):
    path = tmp_path / "s.xml"
    path.write_text(XML.format(sid=sid))
    doc = {"output": "o/{frame}.exr",
           "jobs": [{"name": "x", "scene": str(path), "frames": 2, "version": "path", "spp": 4,
                     "camera": {"orbit": {"target": [0, 0, 0], "radius": 4, "degrees": 90}, "fov": 30}}]}
    res = batch.run(doc, progress=False)      # ("the scene's sensor has no to_world parameter")
    assert res.complete, res.failed
    f0, f1 = (frames_of(tmp_path / "o")[f"{i}.exr"] for i in (0, 1))
    assert np.abs(f0 - f1).max() > 0.05                   # the camera moved
    doc["jobs"][0]["camera"]["fov"] = 40                   # the table's fov reaches the sensor
    doc["output"] = "o40/{frame}.exr"
    assert batch.run(doc, progress=False).complete
    assert np.abs(frames_of(tmp_path / "o40")["0.exr"] - f0).max() > 0.05


def test_a_full_disk_under_the_log_leaves_the_summary(tmp_path, monkeypatch):
    doc = _one_frame(tmp_path)
    doc["jobs"][0]["frames"] = 2
    calls = []
    real = os.fsync

    def fsync(fd):                    # the log's third record (the first frame) meets a full disk
        calls.append(fd)
        if len(calls) >= 2:
            raise OSError(28, "No space left on device")
        real(fd)
    monkeypatch.setattr(os, "fsync", fsync)
    res = batch.run(doc, out=str(tmp_path / "o"), progress=False)   # (a traceback, no summary)
    assert res.rendered == 2 and res.complete
    assert "No space left on device" in res.log_error and "WARNING" in res.summary()


def test_damaged_log_lines_are_skipped(tmp_path):
    doc = _one_frame(tmp_path)
    out = str(tmp_path / "o")
    res = batch.run(doc, out=out, progress=False)
    with open(res.log, "ab") as fh:
        fh.write(b"\xff\xfe\x00garbage\n[1, 2]\n\"text\"\n")
    records = batch.read_log(res.log)
    assert [r["event"] for r in records] == ["start", "frame", "end"]
    assert batch.status(doc, out=out)["counts"]["done"] == 1        # (UnicodeDecodeError)
    assert batch.run(doc, out=out, progress=False).skipped == 1


def test_a_header_longer_than_the_bytes_read_is_read_in_full(tmp_path):
    from draaw_mi.batch.exr import _HEADER_READ, exr_complete, frame_status, write_frame
    img = np.ones((8, 8, 3), np.float32)
    for pad in range(0, 1200, 40):          # headers ending just before and past the bytes read
        p = str(tmp_path / f"f{pad}.exr")
        write_frame(p, img, ["R", "G", "B"], {"draaw:frame_hash": "h1", "draaw:params": "x" * (_HEADER_READ - 1000 + pad)})
        assert exr_complete(p), pad                             # (False: 'damaged' for ever)
        assert frame_status({"output": p, "hash": "h1"}) == "done", pad
        with open(p, "r+b") as fh:                              # still: a cut frame is not complete
            fh.truncate(os.path.getsize(p) - 1)
        assert not exr_complete(p), pad



def test_a_frame_post_processed_in_place_is_no_longer_done(tmp_path):
    """``draaw-mi post`` on a batch frame, in place: the frame holds a chain its manifest never
    named, so the batch must not count it as done (it kept the frame's hash, "1 done"); it is
    foreign, and left alone without --overwrite."""
    from draaw_mi.cli import main
    out = str(tmp_path / "out")
    a = write_manifest(tmp_path, _one_frame(tmp_path), "shot.toml")
    assert batch.run(a, out=out, progress=False).rendered == 1
    frame = os.path.join(out, "job0", "0000.exr")
    chain = tmp_path / "chain.json"
    chain.write_text(json.dumps([{"type": "contrast", "contrast": 1.5}]))
    assert main(["post", frame, "-o", frame, "--chain", str(chain)]) == 0
    header = batch.read_header(frame)
    assert "contrast" in header["draaw:post"] and header["draaw:job"] == "job0"
    assert batch.status(a, out=out)["frames"][0]["status"] == "foreign"
    with pytest.raises(SceneError, match="made by draaw-mi post"):
        batch.run(a, out=out, progress=False)


def test_the_log_may_name_no_file_the_run_reads_or_writes(tmp_path):
    """A ``log`` naming the job's scene or the manifest had JSON lines appended to it (every
    later load: "malformed TOML"); one naming a contact sheet was renamed over (the log's
    records lost). Each is refused before anything is written."""
    import tomli_w
    doc = _one_frame(tmp_path)
    scene = doc["jobs"][0]["scene"]
    path = os.path.join(str(tmp_path), "m.toml")
    with open(scene, "rb") as fh:
        scene_bytes = fh.read()
    for log, what in ((scene, "the scene file of job 'job0'"), (path, "the manifest")):
        with open(path, "wb") as fh:
            tomli_w.dump(dict(doc, log=os.path.basename(log)), fh)
        with open(path, "rb") as fh:
            manifest_bytes = fh.read()
        with pytest.raises(SceneError, match=f"log .* is {what}; give it a name of its own"):
            batch.run(path, out=str(tmp_path), progress=False)
        for file, before in ((scene, scene_bytes), (path, manifest_bytes)):
            with open(file, "rb") as fh:
                assert fh.read() == before
    out = str(tmp_path / "o")
    with pytest.raises(SceneError, match="is an output of job 'job0' frame 0"):
        batch.run(dict(doc, log="job0/job0_contact.png", contact_sheet=True), out=out, progress=False)
    assert not os.path.exists(os.path.join(out, "job0"))


def test_a_frame_may_not_be_written_over_a_file_its_scene_reads(tmp_path):
    """An output pattern naming the scene's environment map replaced it with the frame, and
    every later run rendered the frame again from its previous output (its input files' hash
    changed each time): refused at planning, the map untouched."""
    from batch_helpers import tiny_description
    from draaw_mi.io import write_exr
    import tomli_w
    env = str(tmp_path / "env.exr")
    write_exr(env, np.full((8, 16, 3), 0.5, np.float32))
    d = tiny_description()
    d["lights"] = [{"type": "envmap", "file": "env.exr"}]
    scene = str(tmp_path / "lit.toml")
    with open(scene, "wb") as fh:
        tomli_w.dump(d, fh)
    with open(env, "rb") as fh:
        before = fh.read()
    doc = {"output": "env.exr", "jobs": [{"name": "j", "scene": scene, "frames": 1, "spp": 2}]}
    for dry in (True, False):
        with pytest.raises(SceneError, match=r"output pattern gives '.*env.exr' for job 'j' frame 0, which is "
                                             r"a file the scene of job 'j' reads"):
            batch.run(doc, out=str(tmp_path), progress=False, dry_run=dry)
    with open(env, "rb") as fh:
        assert fh.read() == before
    # another file whose name differs only in case is not the map where the file system tells
    # them apart (it was refused as "a file the scene reads")
    other = str(tmp_path / "ENV.exr")
    if not os.path.exists(other):                  # (a case-sensitive file system)
        doc["output"] = "ENV.exr"
        assert batch.run(doc, out=str(tmp_path), progress=False).complete
        with open(env, "rb") as fh:
            assert fh.read() == before


def test_a_file_name_longer_than_the_file_system_takes_is_refused_before_rendering(tmp_path):
    """A 300-byte name passed planning and --dry-run; each frame then rendered and failed as it
    was written ("File name too long")."""
    doc = _one_frame(tmp_path)
    doc["output"] = "x" * 300 + "_{frame}.exr"
    out = str(tmp_path / "o")
    with pytest.raises(SceneError, match=r"a name of 306 bytes \(xxxx.*\.\.\.\); expected at most 255"):
        batch.run(doc, out=out, progress=False, dry_run=True)
    doc["output"] = "{frame:>300}.exr"
    with pytest.raises(SceneError, match=r"a name of 304 bytes"):
        batch.run(doc, out=out, progress=False)
    assert not os.path.exists(out) or not os.listdir(out)
    # a contact sheet's name (the job's name + _contact.png) too: its frames had rendered first
    doc = _one_frame(tmp_path)
    doc["jobs"][0]["name"] = "j" * 250
    doc["contact_sheet"] = True
    with pytest.raises(SceneError, match=r"gives the contact sheet of job 'j+' a name of 262 bytes"):
        batch.run(doc, out=out, progress=False)
    assert not os.path.exists(out) or not os.listdir(out)
