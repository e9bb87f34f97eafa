"""``render(sensor=)`` and ``draaw-mi render --sensor``: a scene's other sensors render (only the
first had, and nothing said so); ``info`` lists them."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main

XML = """<scene version="3.0.0">
  <sensor type="perspective" id="front"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="8"/></film></sensor>
  <sensor type="orthographic" id="top"><transform name="to_world"><lookat origin="0,4,0" target="0,0,0" up="0,0,1"/>
    <scale value="1.5"/></transform>
    <film type="hdrfilm"><integer name="width" value="6"/><integer name="height" value="6"/>
      <string name="pixel_format" value="rgba"/><rfilter type="box"/></film></sensor>
  <emitter type="constant"/><shape type="sphere"><bsdf type="diffuse"/></shape></scene>"""


@pytest.fixture
def two_sensors(tmp_path):
    path = tmp_path / "two.xml"
    path.write_text(XML)
    return str(path)


def test_the_second_sensor_renders_by_index_or_id(two_sensors):
    scene = draaw_mi.load_scene(two_sensors)
    img, info = draaw_mi.render(scene, version="path", spp=4, seed=3, sensor="top", return_info=True)
    assert img.shape == (6, 6, 4) and info["channels"] == ["R", "G", "B", "A"] and info["sensor"] == 1
    # Mitsuba's own render of that sensor, sample for sample
    own = mi.render(scene.mi_scene, sensor=1, integrator=mi.load_dict({"type": "path", "max_depth": 6}),
                    spp=4, seed=3)
    assert np.array_equal(np.array(img), np.array(own))
    assert np.array_equal(np.array(draaw_mi.render(scene, version="path", spp=4, seed=3, sensor=1)), np.array(own))
    assert draaw_mi.render(scene, version="path", spp=4, seed=3).shape == (8, 12, 3)      # (the first)


def test_v4_renders_the_second_sensor_as_path_does(two_sensors):
    """Its mean (from above: the sphere's top, lit by the sky) within 4 standard errors of
    ``path``'s, the errors from the spread over 6 seeds."""
    scene = draaw_mi.load_scene(two_sensors)
    means = {v: np.array([np.array(draaw_mi.render(scene, version=v, spp=32, seed=s, sensor=1))[..., :3].mean()
                          for s in range(6)]) for v in ("path", "v4")}
    se = np.hypot(*(m.std(ddof=1) / np.sqrt(len(m)) for m in means.values()))
    assert abs(means["v4"].mean() - means["path"].mean()) < 4 * se + 1e-6, means
    assert means["path"].mean() > 0.3


@pytest.mark.parametrize("sensor, match", [(2, r"sensor=2; .* has 2 sensor\(s\): expected an index in \[0, 1\] "
                                               r"or an id \('front', 'top'\)"),
                                           ("side", r"sensor='side'"), (True, r"sensor=True"), (-1, r"sensor=-1")])
def test_a_sensor_the_scene_lacks_is_refused_naming_its_sensors(two_sensors, sensor, match):
    with pytest.raises(draaw_mi.RenderError, match=match):
        draaw_mi.render(draaw_mi.load_scene(two_sensors), spp=1, sensor=sensor)


def test_the_cli_renders_and_lists_the_sensors(two_sensors, tmp_path, capsys):
    out = str(tmp_path / "t.exr")
    assert main(["render", two_sensors, "--sensor", "top", "-o", out, "--spp", "2", "--no-progress"]) == 0
    assert draaw_mi.read_exr(out).shape == (6, 6, 4)
    from draaw_mi.batch.exr import read_header
    assert read_header(out).get("draaw:sensor") == "1 top"        # (the header says which)
    assert main(["render", two_sensors, "--sensor", "1", "-o", out, "--spp", "2", "--no-progress"]) == 0
    assert draaw_mi.read_exr(out).shape == (6, 6, 4)
    capsys.readouterr()
    assert main(["info", two_sensors]) == 0
    assert ("sensors: front (PerspectiveCamera, 12x8), top (OrthographicCamera, 6x6) (the first renders; "
            "another with --sensor)") in capsys.readouterr().out
    assert main(["render", two_sensors, "--sensor", "side", "-o", out, "--spp", "2", "--no-progress"]) == 2
    assert "sensor='side'" in capsys.readouterr().err


def test_another_sensor_takes_its_own_samplers_count_and_sizes(tmp_path):
    """Passes were planned with the first sensor's sampler and the default spp was its count:
    a multijitter sensor of 64 spp rendered 4 (the first's), and 32 asked of it rendered 35
    (multijitter rounds 32 up) while the info said 32. A resolution= sized the first film
    and the other rendered at its own size without a word: refused."""
    path = tmp_path / "two.xml"
    path.write_text(XML.replace('<rfilter type="box"/></film></sensor>',
                                '<rfilter type="box"/></film><sampler type="multijitter">'
                                '<integer name="sample_count" value="64"/></sampler></sensor>'))
    scene = draaw_mi.load_scene(str(path))
    _, info = draaw_mi.render(scene, version="path", sensor="top", return_info=True)
    assert info["spp"] == 64 and info["passes"] == 1
    _, info = draaw_mi.render(scene, version="path", sensor="top", spp=32, return_info=True)
    assert info["spp"] == 32 and info["passes"] == 2                 # (30 + 2: counts it takes as they are)
    with pytest.raises(draaw_mi.RenderError, match=r"resolution=\(16, 16\) sizes the scene's first film; "
                                                   r"sensor='top' renders another"):
        draaw_mi.render(scene, sensor="top", resolution=(16, 16), spp=1)
