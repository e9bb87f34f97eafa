"""Jobs of Mitsuba XML scenes: ``defines``, the ``$name`` parameters, as ``draaw-mi render -D``
sets them (a batch of an XML scene had rendered every frame with the file's ``<default>``s), and
``sensor``, another of a scene's sensors."""
from __future__ import annotations

import pytest
import numpy as np
from batch_helpers import write_scene

import draaw_mi
from draaw_mi.batch import runner as batch
from draaw_mi.batch.planner import frame_seed
from draaw_mi.errors import DraawError

XML = """<scene version="3.0.0">
  <default name="albedo" value="0.2"/>
  <default name="res" value="8"/>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="$albedo"/></bsdf></shape>
  <emitter type="constant"/>
</scene>"""


def _xml(tmp_path) -> str:
    path = tmp_path / "ball.xml"
    path.write_text(XML)
    return str(path)


def _doc(scene, **defines_by_job):
    return {"output": "out/{job}/{frame:04d}.exr",
            "jobs": [{"name": name, "scene": scene, "frames": 1, "spp": 4, "version": "v4",
                      **({"defines": d} if d is not None else {})} for name, d in defines_by_job.items()]}


def test_a_jobs_defines_set_the_xml_scenes_parameters(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = _xml(tmp_path)
    res = batch.run(_doc(scene, plain=None, bright={"albedo": 0.8, "res": 12}), progress=False)
    assert res.complete and res.rendered == 2
    plain = draaw_mi.read_exr("out/plain/0000.exr")
    bright = draaw_mi.read_exr("out/bright/0000.exr")
    assert plain.shape[:2] == (8, 8) and bright.shape[:2] == (12, 12)
    for got, defines in ((plain, None), (bright, {"albedo": 0.8, "res": 12})):
        ref = np.array(draaw_mi.render(draaw_mi.load_scene(scene, defines=defines), version="v4",
                                       seed=frame_seed(0, 0), spp=4))
        assert np.array_equal(got, ref)          # (the same render as the file loaded with them)
    assert bright[6, 6, 0] > 2.5 * plain[4, 4, 0]            # (albedo 0.8 against 0.2)


def test_frames_are_rendered_again_when_their_defines_change(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = _xml(tmp_path)
    assert batch.run(_doc(scene, a={"albedo": 0.5}), progress=False).rendered == 1
    assert batch.run(_doc(scene, a={"albedo": 0.5}), progress=False).rendered == 0      # done
    assert batch.run(_doc(scene, a={"albedo": 0.6}), progress=False).rendered == 1      # changed
    _, with_none, _ = batch.load(_doc(scene, a=None))
    _, with_empty, _ = batch.load(_doc(scene, a={}))
    assert with_none[0]["hash"] == with_empty[0]["hash"]   # (jobs without defines keep their hash)


@pytest.mark.parametrize("defines, match", [
    ({"albedo": [0.1]}, r"jobs\[0\]\.defines: define albedo=\[0.1\]: expected a string or number"),
    ({"bad name": 1}, r"jobs\[0\]\.defines: define 'bad name': expected a parameter name"),
    ("albedo=0.3", r"jobs\[0\]\.defines: 'albedo=0.3'; expected a table of \$name values"),
    ({"albedo": 0.3}, None)])
def test_bad_defines_are_refused_naming_the_field(tmp_path, defines, match):
    scene = _xml(tmp_path) if match else write_scene(tmp_path)
    if match is None:
        match = r"jobs\[0\]\.defines: sets \$name parameters of a Mitsuba XML scene; 'tiny.toml' is not one"
    with pytest.raises(DraawError, match=match):
        batch.load(_doc(scene, a=defines))


TWO = """<scene version="3.0.0">
  <sensor type="perspective" id="front"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="8"/><rfilter type="box"/></film></sensor>
  <sensor type="orthographic" id="top"><transform name="to_world"><lookat origin="0,4,0" target="0,0,0" up="0,0,1"/>
    <scale value="1.5"/></transform>
    <film type="hdrfilm"><integer name="width" value="6"/><integer name="height" value="6"/><rfilter type="box"/></film></sensor>
  <emitter type="constant"/><shape type="sphere"><bsdf type="diffuse"/></shape></scene>"""


def test_a_jobs_sensor_renders_another_of_the_scenes_sensors(tmp_path, monkeypatch):
    """As render(sensor=) does: a job's frames of an XML scene's second sensor (the first had
    rendered whatever the job said); frames of the first keep their hash."""
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "two.xml"
    scene.write_text(TWO)
    doc = {"output": "out/{job}/{frame:04d}.exr",
           "jobs": [{"name": n, "scene": str(scene), "frames": 1, "spp": 4, "version": "v4", **extra}
                    for n, extra in (("front", {}), ("top", {"sensor": "top"}), ("one", {"sensor": 1}))]}
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 3
    top = draaw_mi.read_exr("out/top/0000.exr")
    ref = np.array(draaw_mi.render(draaw_mi.load_scene(str(scene)), version="v4", seed=frame_seed(0, 0), spp=4,
                                   sensor="top"))
    assert top.shape == (6, 6, 3) and np.array_equal(top, ref)
    assert np.array_equal(draaw_mi.read_exr("out/one/0000.exr"), top)
    assert draaw_mi.read_exr("out/front/0000.exr").shape == (8, 12, 3)
    _, specs, _ = batch.load(doc)
    _, plain, _ = batch.load({**doc, "jobs": [{**doc["jobs"][0], "sensor": 0}]})
    assert specs[0]["hash"] == plain[0]["hash"] and specs[1]["hash"] != specs[0]["hash"]
    for bad, match in (({"sensor": "side"}, r"job 'front': sensor='side'; .* has 2 sensor\(s\)"),
                       ({"sensor": -1}, r"jobs\[0\]\.sensor: -1; expected a sensor's index"),
                       ({"sensor": 1, "camera": {"orbit": {"radius": 4.0}}}, r"a camera table moves the scene's first"),
                       ({"sensor": 1, "resolution": [16, 16]}, r"resolution sizes the scene's first film; sensor = 1")):
        with pytest.raises(DraawError, match=match):
            batch.load({**doc, "jobs": [{**doc["jobs"][0], **bad}]})
