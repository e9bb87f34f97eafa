"""Bad manifests: one line on stderr, exit 2, and nothing rendered or written."""
from __future__ import annotations

import copy
import os

import pytest
from batch_helpers import manifest, write_manifest

from draaw_mi.batch import runner as batch
from draaw_mi.cli import main
from draaw_mi.errors import ParameterError, SceneError


def _bad(tmp_path, capsys, mutate, expect, *flags):
    doc = manifest(tmp_path, frames=3)
    mutate(doc, tmp_path)
    path = write_manifest(tmp_path, doc)
    assert main(["batch", path, "--no-progress", *flags]) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("draaw-mi: error: "), err
    for e in expect:
        assert e in lines[0], lines[0]
    assert not (tmp_path / "out").exists()                # nothing rendered, no log
    return lines[0]


def test_unknown_job_key_suggests(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(fames=3),
         ["jobs[0].fames", "unknown key 'fames'", "did you mean 'frames'?"])


def test_unknown_top_key_suggests(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d, _: d.update(ouptut="x/{frame}.exr"), ["did you mean 'output'?"])


def test_missing_scene(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d, t: d["jobs"][0].update(scene=str(t / "nope.toml")),
         ["jobs[0].scene", "nope.toml", "does not exist"])


@pytest.mark.parametrize("pattern, expect", [
    ("out/{job}/{frme:04d}.exr", ["unknown field {frme}", "did you mean 'frame'?"]),
    ("out/{job}/still.exr", ["no {frame} field", "3 frames would overwrite"]),
    ("out/{job}/{frame:04d}.png", ["must end with .exr"]),
    ("out/{job}/{frame:04d.exr", ["not a valid pattern"]),
    ("out/{job}/{frame:04q}.exr", ["cannot be formatted"]),
])
def test_bad_pattern(tmp_path, capsys, pattern, expect):
    _bad(tmp_path, capsys, lambda d, t: d.update(output=pattern), expect)


def test_override_of_a_parameter_that_does_not_exist(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(params={"ball.roughnes": 0.3}),
         ["job 'orbit'", "no parameter 'ball.roughnes'", "did you mean 'ball.roughness'?"])


def test_override_with_the_wrong_shape(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(params={"ball.roughness": [0.1, 0.2]}),
         ["ball.roughness", "2 components", "the parameter has 1"])


@pytest.mark.parametrize("params, expect", [
    ({"ball.roughness": {"from": 0.02, "to": 3.0}}, ["frame 1", "ball.roughness=1.51", "[0.0, 1.0]"]),
    ({"ball.base_color": {"values": [[0.1, 0.2, 0.3], [0.1, -1.0, 0.2], [0.1, 0.2, 0.3]]}},
     ["frame 1", "ball.base_color=[0.1, -1.0, 0.2]", ">= 0"]),
    ({"point_light0.intensity": -5.0}, ["frame 0", ">= 0"]),
    ({"point_light0.intensity": {"values": [40.0, 1e39, 40.0]}}, ["1e+39", "beyond float32"]),  # (inf)
])
def test_override_values_outside_the_parameters_range(tmp_path, capsys, params, expect):
    """Values a scene file would refuse are a bad manifest too (roughness 3.0 rendered as 1.0,
    exit status 0, nothing logged)."""
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(params=params), expect)


def test_per_frame_values_must_match_frames(tmp_path, capsys):
    _bad(tmp_path, capsys,
         lambda d, _: d["jobs"][0].update(params={"ball.roughness": {"values": [0.1, 0.2]}}),
         ["has 2 values for 3 frames"])


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root can write anywhere")
def test_unwritable_output_folder_permissions(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        _bad(tmp_path, capsys, lambda d, t: d.update(output="ro/{job}/{frame}.exr"), ["is not writable"])
    finally:
        ro.chmod(0o700)


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc")
def test_unwritable_output_folder_even_for_root(tmp_path, capsys):
    """/proc passes a permission-bit check for root but cannot hold files: the probe write
    catches it before rendering."""
    _bad(tmp_path, capsys, lambda d, t: d.update(output="/proc/draaw-batch-test/{job}/{frame}.exr"),
         ["cannot be written", "/proc/draaw-batch-test"], "--allow-outside-out")


def test_unwritable_output_folder_is_a_file(tmp_path, capsys):
    (tmp_path / "blocker").write_text("a file where a folder should be")
    _bad(tmp_path, capsys, lambda d, t: d.update(output="blocker/{job}/{frame}.exr"),
         ["cannot be created", "blocker"])


def test_bad_version_aov_and_camera(tmp_path, capsys):
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(version="v9"), ["jobs[0].version", "v9"])
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(aovs=["dpeth"]), ["dpeth", "did you mean 'depth'?"])
    # (the frame held it once, silently)
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(aovs=["depth", "normal", "depth"]),
         ["jobs[0].aovs", "names 'depth' twice; expected each AOV once"])
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(camera={"orbit": {"radius": 2}, "look_at": []}),
         ["exactly one of"])
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(camera={"keyframes": [[0, 0, 0, 1]]}),
         ["keyframe 0", "5 finite numbers"])
    # a look_at key with the camera at its target (a flat frame, exit 0, before), and keys
    # fine on their own whose eased frame 1 of 3 puts the camera at the target
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(camera={"look_at": [
        {"origin": [0, 1, 5], "target": [0, 1, 5]}, {"origin": [0, 1, 5], "target": [0, 0, 0]}]}),
        ["look_at[0].target: equals 'origin'"])
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(camera={"look_at": [
        {"origin": [0, 0, 5], "target": [0, 0, 0]}, {"origin": [0, 0, -5], "target": [0, 0, 0]}]}),
        ["look_at frame 1", "equals 'origin'"])


def test_a_version_that_cannot_see_the_scene_is_a_bad_manifest(tmp_path, capsys):
    """Mitsuba's path on a scene with [[sdf]] objects rendered every frame without them."""
    from conftest import SCENES
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0].update(scene=os.path.join(SCENES, "sdf_csg.toml"),
                                                            version="path", resolution=[8, 8]),
         ["job 'orbit'", "[[sdf]] objects"])


def test_same_file_for_two_frames(tmp_path, capsys):
    def two_jobs(d, t):
        d["jobs"].append(dict(d["jobs"][0], name="other"))
        d["output"] = "out/{frame:04d}.exr"
    _bad(tmp_path, capsys, two_jobs, ["same file", "frame 0"])


def test_malformed_toml_and_missing_manifest(tmp_path, capsys):
    p = tmp_path / "broken.toml"
    p.write_text("jobs = [\n")
    assert main(["batch", str(p)]) == 2
    assert "malformed TOML" in capsys.readouterr().err
    assert main(["batch", str(tmp_path / "none.toml")]) == 2
    assert "manifest does not exist" in capsys.readouterr().err


def test_cli_flag_combinations(tmp_path, capsys):
    path = write_manifest(tmp_path, manifest(tmp_path))
    assert main(["batch", path, "--workers", "2"]) == 2
    assert "draaw-mi: error: --workers: needs --executor dask" in capsys.readouterr().err
    assert main(["batch", path, "--executor", "dask", "--scheduler", "localhost:1"]) == 2
    assert "tcp://" in capsys.readouterr().err


def test_worker_counts_beyond_the_cores_or_beside_a_cluster_are_refused(tmp_path, capsys, monkeypatch):
    """More LocalCluster workers than cores oversubscribe them (workers x threads = cores cannot
    hold); workers=0 used to mean the default, and workers beside a scheduler were ignored."""
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    path = write_manifest(tmp_path, manifest(tmp_path))
    assert main(["batch", path, "--executor", "dask", "--workers", "3"]) == 2
    assert "--workers 3: expected an integer from 1 to this machine's 2 cores" in capsys.readouterr().err
    assert main(["batch", path, "--executor", "dask", "--workers", "1", "--scheduler", "tcp://h:1"]) == 2
    assert "has its own workers" in capsys.readouterr().err
    for bad in (0, 3, 1.5, True):
        with pytest.raises(ParameterError, match=f"workers={bad!r}: expected an integer from 1 to"):
            batch.run(path, executor="dask", workers=bad)
    with pytest.raises(ParameterError, match="workers=1 needs executor='dask'"):
        batch.run(path, workers=1)
    with pytest.raises(ParameterError, match="workers=1 sizes a new LocalCluster"):
        batch.run(path, executor="dask", workers=1, scheduler="tcp://h:1")
    with pytest.raises(ParameterError, match="scheduler and client need executor='dask'"):
        batch.run(path, scheduler="tcp://h:1")
    with pytest.raises(ParameterError, match="overwrite='false'; expected True or False"):
        batch.run(path, overwrite="false")          # (a true string: frames would be replaced)
    assert not list(tmp_path.glob("**/*.exr"))                       # refused before rendering


def test_api_raises_scene_error(tmp_path):
    doc = manifest(tmp_path)
    doc["jobs"][0]["params"] = {"nosuch.thing": 1.0}
    with pytest.raises(SceneError, match="no parameter 'nosuch.thing'"):
        batch.run(doc, progress=False)


def test_an_sdf_override_out_of_range_names_the_frame(tmp_path, capsys):
    """Checked for every frame before anything renders (a round box's radius grows past half
    its size at frame 2 of 3)."""
    def mutate(d, t):
        from conftest import tiny_description
        import tomli_w
        desc = tiny_description()
        desc["sdf"] = [{"type": "round_box", "name": "block", "material": "ball", "center": [1, 0.3, 0],
                        "size": [0.6, 0.6, 0.6], "radius": 0.05}]
        path = t / "sdf.toml"
        path.write_bytes(tomli_w.dumps(desc).encode())
        d["jobs"][0].update(scene=str(path), params={"sdf.block.radius": {"from": 0.1, "to": 0.4}})
    _bad(tmp_path, capsys, mutate, ["job 'orbit'", "frame 2", "params.sdf.block.radius",
                                    "radius=0.4", "min(size)/2 = 0.3"])


@pytest.mark.parametrize("pattern, expect", [
    # {job.upper} named a folder after a method's address, new on every run; {job.foo} was a
    # traceback
    ("out/{job.upper}/{frame:04d}.exr", ["{job.upper}", "must be a bare name"]),
    ("out/{job.foo}/{frame:04d}.exr", ["{job.foo}", "must be a bare name"]),
    ("out/{job[0]}/{frame:04d}.exr", ["{job[0]}", "must be a bare name"]),
])
def test_pattern_fields_are_bare_names(tmp_path, capsys, pattern, expect):
    _bad(tmp_path, capsys, lambda d, t: d.update(output=pattern), expect)


def test_a_log_name_with_fields_is_refused(tmp_path, capsys):
    """``log = "{job}.jsonl"`` made a file literally named so: one log serves every job."""
    _bad(tmp_path, capsys, lambda d, t: d.update(log="out/{job}.jsonl"),
         ["log", "must name one file"])


def test_an_override_the_camera_table_would_replace_is_refused(tmp_path, capsys):
    """The orbit's field of view overwrote the job's x_fov override in every frame, silently."""
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0]["params"].update({"sensor.x_fov": {"from": 20, "to": 90}}),
         ["params.sensor.x_fov", "camera table sets the view", "camera.fov"])


def test_two_names_of_one_parameter_are_refused(tmp_path, capsys):
    """``ball.roughness`` and ``ball.roughness.value`` are one parameter: the last one won."""
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0]["params"].update({"ball.roughness.value": 0.5}),
         ["'ball.roughness' and 'ball.roughness.value' are the same parameter", "keep one"])


def test_an_integer_parameter_is_refused_before_rendering(tmp_path, capsys):
    """The film size took floats and failed every frame at render time (exit 1)."""
    _bad(tmp_path, capsys, lambda d, _: d["jobs"][0]["params"].update({"sensor.film.size": [8, 8]}),
         ["params.sensor.film.size", "holds integers", "resolution sets the film size"])


def test_outputs_that_differ_in_case_only_are_refused(tmp_path, capsys):
    """out/a/0000.exr and out/a/0000.EXR shared one preview PNG (and are one file on macOS or
    Windows): the run said "2 rendered ... 1 of 2 frames missing" on every run."""
    def two_jobs(d, t):
        d["previews"] = True
        d["jobs"].append(dict(d["jobs"][0], name="other", output="out/orbit/{frame:04d}.EXR"))
    _bad(tmp_path, capsys, two_jobs, ["same file", "0000.EXR", "job 'orbit' frame 0"])


def test_control_characters_in_names_and_file_names_are_refused(tmp_path):
    """A NUL in a job name made every path function raise (a traceback, exit 1); a
    ``{frame:c}`` pattern names frame 0's file ``f\\x00.exr`` (and frame 1's ``f\\x01.exr``,
    which had been written)."""
    from draaw_mi.batch import runner as batch
    from draaw_mi.errors import SceneError
    doc = manifest(tmp_path, frames=2)
    bad = copy.deepcopy(doc)
    bad["jobs"][0]["name"] = "a\x00b"
    with pytest.raises(SceneError, match=r"jobs\[0\]\.name: 'a\\x00b' holds a control character \(\\x00\)"):
        batch.load(bad)
    bad = copy.deepcopy(doc)
    bad["output"] = "f{frame:c}.exr"
    with pytest.raises(SceneError, match=r"gives '.*f\\x00\.exr' for job 'orbit' frame 0, a name with a control"):
        batch.load(bad, out=str(tmp_path / "o"))


def test_a_contact_sheet_may_not_take_another_jobs_file(tmp_path):
    """Job ``a``'s contact sheet is ``a_contact.png``: a job named ``a_contact`` whose preview
    is that file is refused at planning (it had been overwritten by the sheet, and counted as
    the preview)."""
    from draaw_mi.batch import runner as batch
    from draaw_mi.errors import SceneError
    doc = manifest(tmp_path, frames=1)
    doc.update(output="{job}.exr", previews=True, contact_sheet=True)
    second = copy.deepcopy(doc["jobs"][0])
    doc["jobs"][0]["name"], second["name"] = "a", "a_contact"
    doc["jobs"].append(second)
    with pytest.raises(SceneError, match=r"job 'a'.s contact sheet .*a_contact\.png' is the file of job 'a_contact' frame 0"):
        batch.load(doc, out=str(tmp_path / "o"))
    doc["contact_sheet"] = False
    batch.load(doc, out=str(tmp_path / "o"))                 # (no sheet, no clash)


@pytest.mark.parametrize("kw, match", [
    (dict(out=123), r"batch: out=123; expected an output folder's path"),
    (dict(out=""), r"batch: out=''; expected an output folder's path"),
    (dict(on_result=5), r"batch.run: on_result=5; expected a function"),
    (dict(dry_run="yes"), r"batch.run: dry_run='yes'; expected True or False"),
])
def test_batch_run_refuses_bad_arguments_before_rendering(tmp_path, kw, match):
    from draaw_mi.batch import runner as batch
    from draaw_mi.errors import ParameterError
    doc = manifest(tmp_path, frames=2)
    with pytest.raises(ParameterError, match=match):
        batch.run(doc, **{"out": str(tmp_path / "o"), "progress": False, **kw})
    assert not (tmp_path / "o").exists()
    with pytest.raises(ParameterError, match=r"batch: manifest=None; expected a manifest file's path or a dict"):
        batch.run(None, out=str(tmp_path / "o"), progress=False)


def test_a_folder_is_no_manifest_and_no_scene(tmp_path):
    from draaw_mi.batch import runner as batch
    from draaw_mi.errors import SceneError
    folder = tmp_path / "a.toml"
    folder.mkdir()
    with pytest.raises(SceneError, match=r"a\.toml: is a folder; expected a manifest file"):
        batch.load(str(folder))
    doc = manifest(tmp_path, frames=1)
    doc["jobs"][0]["scene"] = str(tmp_path)
    with pytest.raises(SceneError, match=r"jobs\[0\]\.scene: .* is a folder; expected a scene file"):
        batch.load(doc)
