"""Mitsuba XML scenes as their users know them (issue 43): ``-D name=value`` /
``load_scene(path, defines=...)`` for a file's ``$name`` defaults, ``--resolution`` /
``resolution=`` and a smaller fit reference applied to the film, the file's own integrator
honoured when no version is given (and said), and ``info`` naming merged meshes.

``data/cbox.xml`` is a Cornell box in the style of Mitsuba's tutorial scene, its film sized by
``$res`` (default 128) and its sampler by ``$spp``."""
from __future__ import annotations

import os

import matplotlib.image
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main

CBOX = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "cbox.xml")


def _png_size(path) -> tuple[int, int]:
    h, w = matplotlib.image.imread(str(path)).shape[:2]
    return w, h


def test_a_define_sets_the_files_res_default_from_python():
    assert draaw_mi.load_scene(CBOX).resolution == (128, 128)
    scene = draaw_mi.load_scene(CBOX, defines={"res": 24, "spp": 2})
    assert scene.resolution == (24, 24) and scene.settings["spp"] == 2
    img = np.array(draaw_mi.render(scene, seed=1))
    assert img.shape == (24, 24, 3) and np.isfinite(img).all() and img.mean() > 0.05


def test_resolution_sizes_an_xml_scenes_film_from_python():
    """``load_scene(xml, resolution=...)``, ``render(..., resolution=...)`` and
    ``with_resolution`` refused an XML scene ("edit its film instead")."""
    scene = draaw_mi.load_scene(CBOX, resolution=(20, 12), spp=1)
    assert scene.resolution == (20, 12)
    # a define that only sized the film is dropped, not refused as unused
    assert draaw_mi.load_scene(CBOX, defines={"res": 64}, resolution=(16, 8)).resolution == (16, 8)
    small = draaw_mi.load_scene(CBOX, defines={"spp": 1}).with_resolution(10, 6)
    assert small.resolution == (10, 6) and small.settings["spp"] == 1       # the define stays
    img = np.array(draaw_mi.render(scene, resolution=(8, 6), seed=0))
    assert img.shape == (6, 8, 3)


def test_parameter_edits_survive_a_resize_of_an_xml_scene():
    scene = draaw_mi.load_scene(CBOX, defines={"res": 16, "spp": 1})
    key = scene.key("red.reflectance")
    scene.params[key] = mi.Color3f(0.1, 0.9, 0.1)
    scene.params.update()
    resized = scene.with_resolution(8, 8)
    assert np.allclose(np.array(resized.params[key]).ravel(), [0.1, 0.9, 0.1])


def test_bad_defines_are_one_line_naming_them():
    with pytest.raises(draaw_mi.SceneError, match=r"define nosuch=3: .*no \$nosuch; its <default>s: spp, res, max_depth"):
        draaw_mi.load_scene(CBOX, defines={"nosuch": 3})
    with pytest.raises(draaw_mi.SceneError, match=r"cornell\.toml: defines=.*Mitsuba XML"):
        draaw_mi.load_scene(os.path.join(os.path.dirname(CBOX), "..", "..", "..", "scenes", "cornell.toml"),
                            defines={"res": 3})
    with pytest.raises(draaw_mi.SceneError, match="define '1x'"):
        draaw_mi.load_scene(CBOX, defines={"1x": 3})


def test_the_cli_renders_the_tutorial_box_at_a_chosen_resolution(tmp_path, capsys):
    out = tmp_path / "a.png"
    assert main(["render", CBOX, "-o", str(out), "-D", "res=32", "-D", "spp=1", "--no-progress"]) == 0
    assert _png_size(out) == (32, 32)
    exr = tmp_path / "b.exr"
    assert main(["render", CBOX, "-o", str(exr), "--resolution", "24x16", "-D", "spp=1", "--no-progress"]) == 0
    assert draaw_mi.read_exr(str(exr)).shape == (16, 24, 3)
    assert main(["info", CBOX, "-D", "res=40"]) == 0
    assert "cbox.xml: 40x40" in capsys.readouterr().out
    for argv, message in ((["-D", "res"], "-D 'res': expected NAME=VALUE"),
                          (["-D", "nosuch=1"], "define nosuch=1:")):
        assert main(["render", CBOX, "-o", str(exr)] + argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("draaw-mi: error: ") and err.count("\n") == 1 and message in err


def test_fit_takes_a_reference_smaller_than_an_xml_scenes_film(tmp_path, capsys):
    ref = tmp_path / "ref.exr"
    draaw_mi.write_exr(str(ref), np.array(draaw_mi.render(draaw_mi.load_scene(CBOX, defines={"res": 12}),
                                                          spp=4, seed=3)))
    out = tmp_path / "values.json"
    assert main(["fit", CBOX, "--reference", str(ref), "--param", "red.reflectance", "--iterations", "2",
                 "--spp", "1", "--no-progress", "-o", str(out)]) == 0
    assert "red.reflectance" in out.read_text()


def _direct_xml(tmp_path) -> str:
    text = open(CBOX).read().replace('<integrator type="path">\n        <integer name="max_depth" value="$max_depth"/>',
                                     '<integrator type="direct">\n        <integer name="emitter_samples" value="2"/>')
    text = text.replace('<default name="max_depth" value="6"/>', "")
    path = tmp_path / "direct.xml"
    path.write_text(text)
    return str(path)


def test_an_xml_scenes_own_integrator_renders_it_when_no_version_is_given(tmp_path):
    """An XML scene whose integrator is ``direct`` rendered with V4 at depth 6 (1.7 % brighter),
    with a warning that said "unless a version is given" whether or not one was."""
    path = _direct_xml(tmp_path)
    scene = draaw_mi.load_scene(path, defines={"res": 16, "spp": 16})
    assert scene.settings["version"] == "scene" and scene.summary()["integrator"] == "direct"
    img, info = draaw_mi.render(scene, seed=2, return_info=True)
    assert info["integrator"] == "direct"
    own = np.array(mi.render(mi.load_file(path, res=16, spp=16), seed=2))
    assert np.allclose(np.array(img), own, atol=1e-5)         # Mitsuba's own render of the file
    # a depth asked of the scene's own integrator is not applied: said, not silent
    with pytest.warns(RuntimeWarning, match=r"max_depth=2 not applied"):
        img2 = draaw_mi.render(scene, seed=2, max_depth=2)
    assert np.allclose(np.array(img2), own, atol=1e-5)
    # another version, given, renders instead; the integrator the file names is in the info
    _, info = draaw_mi.render(scene, version="path", seed=2, return_info=True, spp=1)
    assert info["integrator"] == "path"
    # a scene without an integrator of its own has none to render with
    with pytest.raises(draaw_mi.RenderError, match="declares none"):
        draaw_mi.render(draaw_mi.load_scene(os.path.join(os.path.dirname(CBOX), "..", "..", "..", "scenes",
                                                         "fit_sphere.toml"), resolution=(4, 4)),
                        version="scene", spp=1)


def test_the_cli_says_which_integrator_rendered_an_xml_scene(tmp_path, capsys):
    path = _direct_xml(tmp_path)
    out = str(tmp_path / "d.exr")
    base = ["render", path, "-o", out, "-D", "res=8", "-D", "spp=1", "--no-progress"]
    assert main(base) == 0
    std = capsys.readouterr()
    assert "direct" in std.out and "unless a version is given" not in std.err
    assert "renders with its own integrator 'direct'" in std.err
    assert main(base + ["--version", "path"]) == 0
    std = capsys.readouterr()
    assert ", path," in std.out and "unless a version is given" not in std.err
    assert "declares integrator 'direct'; rendered with --version path" in std.err
    # --version scene asks for the file's own integrator: nothing to note (it said "rendered
    # with --version scene (scene) instead")
    assert main(base + ["--version", "scene"]) == 0
    std = capsys.readouterr()
    assert ", direct," in std.out and "note:" not in std.err
    assert main(["info", path, "-D", "res=8"]) == 0
    assert "integrator: direct (declared by the file; renders with it (version 'scene'))" in capsys.readouterr().out
    assert main(base + ["--max-depth", "3"]) == 2
    assert "--max-depth 3: " in capsys.readouterr().err


def test_info_names_merged_meshes_by_the_shapes_in_them(capsys):
    names = draaw_mi.load_scene(CBOX, defines={"res": 8}).summary()["shapes"]
    assert "unnamed" not in " ".join(names)
    assert "merged mesh of 5 shapes: floor, ceiling, back, cube, cube (material white)" in names
    assert {"light", "left_wall", "right_wall"} <= set(names)
    # the area light by its shape's id (the <emitter> inside <shape id="light"> has none)
    assert draaw_mi.load_scene(CBOX, defines={"res": 8}).summary()["lights"] == ["light (AreaLight)"]
    assert main(["info", CBOX]) == 0
    assert "merged mesh of 5 shapes" in capsys.readouterr().out


def test_version_scene_for_a_file_without_an_integrator_is_one_line(tmp_path, capsys):
    """``--version scene`` asks for the scene's own integrator: a TOML scene has none, said in
    one line (it said "renders with its own integrator '?'" with --max-depth, a RenderError
    traceback-free but late without)."""
    scene = os.path.join(os.path.dirname(CBOX), "..", "..", "..", "scenes", "fit_sphere.toml")
    assert main(["render", scene, "--version", "scene", "-o", str(tmp_path / "x.exr"),
                 "--resolution", "8x8", "--spp", "1", "--max-depth", "3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "declares no integrator of its own" in err[0], err
    assert not (tmp_path / "x.exr").exists()


def test_an_xml_scene_with_double_hyphens_in_a_comment_resizes_as_mitsuba_loads_it():
    """The shipped ``scenes/mitsuba_cbox.xml`` says ``--version v4`` in its first comment:
    Mitsuba (pugixml) loads it, ElementTree refused it, so it could not be resized ("the XML
    does not parse") and a misspelt define listed no ``<default>``s."""
    shipped = os.path.join(os.path.dirname(CBOX), "..", "..", "..", "scenes", "mitsuba_cbox.xml")
    assert "--" in open(shipped).read().split("-->")[0][4:]           # (the case itself)
    assert draaw_mi.load_scene(shipped, resolution=(20, 12), spp=1).resolution == (20, 12)
    with pytest.raises(draaw_mi.SceneError, match=r"no \$rez; its <default>s: spp, res, max_depth"):
        draaw_mi.load_scene(shipped, defines={"rez": 32})


def test_mitsubas_load_error_is_one_line_without_its_source_location(tmp_path, capsys):
    """``-D res=-4`` ended in Mitsuba's "[properties.h:868] Property "height": ..."."""
    assert main(["render", CBOX, "-o", str(tmp_path / "x.exr"), "-D", "res=-4"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'Property "height": value -4 is out of bounds' in err[0], err
    assert ".h:" not in err[0] and "properties.h" not in err[0]



def _include_chain(tmp_path, sky: bool) -> str:
    """main.xml (film sized by $res) includes parts/a.xml, which includes b.xml (beside it, in
    parts/): a point light of intensity $power, the only use of $power, and with ``sky`` a
    constant sky of radiance $res."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "main.xml").write_text(
        '<scene version="3.0.0"><default name="res" value="32"/><default name="power" value="5"/>'
        '<integrator type="path"/>'
        '<sensor type="perspective"><float name="fov" value="40"/><transform name="to_world">'
        '<lookat origin="0, 1.5, 3" target="0, 0.3, 0" up="0, 1, 0"/></transform>'
        '<sampler type="independent"><integer name="sample_count" value="4"/></sampler>'
        '<film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/>'
        '<rfilter type="box"/></film></sensor>'
        '<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/>'
        '</transform></shape><include filename="parts/a.xml"/></scene>')
    (tmp_path / "parts" / "a.xml").write_text('<scene version="3.0.0"><include filename="b.xml"/></scene>')
    (tmp_path / "parts" / "b.xml").write_text(
        '<scene version="3.0.0"><emitter type="point"><point name="position" x="0" y="2" z="0"/>'
        '<float name="intensity" value="$power"/></emitter>'
        + ('<emitter type="constant"><rgb name="radiance" value="$res"/></emitter>' if sky else "")
        + '</scene>')
    return str(tmp_path / "main.xml")


@pytest.mark.parametrize("defines", [{"power": 50}, {"power": 50, "res": 16}])
def test_resolution_keeps_the_defines_of_includes_of_includes(tmp_path, defines):
    """``-D power=50 --resolution 16x16`` of a scene whose $power is used only in an include
    of an include rendered at the file's default power (mean 0.085 for 0.85): the define was
    dropped. A $res that sizes the film and also sets the sky's radiance in that include is
    kept too (it was dropped: the sky at the default 32). Reference: Mitsuba's own
    mi.load_file with the same values at 16 x 16; the same sampler and seed give the same
    image (tolerance: float32 roundings)."""
    path = _include_chain(tmp_path, sky="res" in defines)
    scene = draaw_mi.load_scene(path, defines=defines, resolution=(16, 16))
    ref = mi.load_file(path, **{k: str(v) for k, v in {"res": 16, **defines}.items()})
    mine, theirs = (np.array(mi.render(s, spp=4, seed=0)) for s in (scene.mi_scene, ref))
    assert mine.shape == (16, 16, 3) and theirs.mean() > 0.5
    np.testing.assert_allclose(mine, theirs, rtol=1e-5, atol=1e-6)


def _cropped(tmp_path, crop: str = "16", offset: str = "8") -> str:
    """crop.xml: a 32x32 film whose crop window is ``crop`` pixels square at ``offset``."""
    (tmp_path / "crop.xml").write_text(
        '<scene version="3.0.0"><default name="cw" value="16"/><integrator type="path"/>'
        '<sensor type="perspective"><float name="fov" value="40"/><transform name="to_world">'
        '<lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>'
        '<sampler type="independent"><integer name="sample_count" value="1"/></sampler>'
        '<film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>'
        f'<integer name="crop_width" value="{crop}"/><integer name="crop_height" value="{crop}"/>'
        f'<integer name="crop_offset_x" value="{offset}"/><integer name="crop_offset_y" value="{offset}"/>'
        '<rfilter type="box"/></film></sensor>'
        '<shape type="sphere"><bsdf type="diffuse"/></shape><emitter type="constant"/></scene>')
    return str(tmp_path / "crop.xml")


def _film(scene):
    film = scene.mi_scene.sensors()[0].film()
    return list(film.size()), list(film.crop_size()), list(film.crop_offset())


@pytest.mark.parametrize("crop", ["16", "$cw"])
def test_an_xml_films_crop_window_is_its_resolution_and_resizes_with_it(tmp_path, crop):
    """A 32x32 film cropped to 16x16 at (8, 8) said resolution (32, 32) and rendered 16x16;
    resolution=(24, 24) kept the 16x16 window, and (8, 8) failed (the window outside the film)."""
    path = _cropped(tmp_path, crop)
    scene = draaw_mi.load_scene(path)
    assert scene.resolution == (16, 16) and scene.settings["resolution"] == (16, 16)
    assert np.array(draaw_mi.render(scene, seed=0)).shape == (16, 16, 3)
    for size in (24, 8):
        # the same part of the view: the film and the offset scaled with the window
        for resized in (draaw_mi.load_scene(path, resolution=(size, size)), scene.with_resolution(size, size)):
            assert resized.resolution == (size, size) and resized.settings["resolution"] == (size, size)
            assert _film(resized) == ([2 * size] * 2, [size] * 2, [size // 2] * 2)
            assert np.array(draaw_mi.render(resized, seed=0)).shape == (size, size, 3)


def test_a_load_error_of_a_resized_xml_scene_names_the_users_file(tmp_path):
    """It named the temporary copy the resized film was loaded from (/tmp/draaw-mi-xml-.../)."""
    path = tmp_path / "bad.xml"
    with open(_cropped(tmp_path)) as fh:
        path.write_text(fh.read().replace('value="40"', 'value="forty"'))
    with pytest.raises(draaw_mi.SceneError) as info:
        draaw_mi.load_scene(str(path), resolution=(8, 8))
    assert "draaw-mi-xml-" not in str(info.value) and str(info.value).count(str(path)) >= 2, str(info.value)


_AOV_XML = """<scene version="3.0.0">
  <integrator type="aov">
    <string name="aovs" value="dd.y:depth,nn:sh_normal"/>
    {nested}
  </integrator>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
      <string name="pixel_format" value="{fmt}"/></film>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
  </sensor>
  <shape type="sphere"><bsdf type="diffuse"/></shape>
  <emitter type="constant"/>
</scene>"""


@pytest.mark.parametrize("fmt, nested", [("rgb", '<integrator type="path" name="img"/>'), ("rgba", ""),
                                         ("rgb", "")])
def test_an_xml_scenes_aov_integrator_renders_every_channel_named(tmp_path, fmt, nested):
    """Mitsuba's ``aov`` integrator in an XML file failed in ``render`` and batch frames ("7
    channels with 8 AOV names"): ``mi.render``'s tensor leaves its nested integrator's R, G, B,
    A out (and the colour, where it nests none). Every channel is now rendered, named as
    Mitsuba writes them to an EXR; the depth and normals are Mitsuba's, sample for sample."""
    path = tmp_path / "aov.xml"
    path.write_text(_AOV_XML.format(fmt=fmt, nested=nested))
    img, info = draaw_mi.render(draaw_mi.load_scene(str(path)), seed=3, spp=4, return_info=True)
    img = np.array(img)
    colour = ["R", "G", "B", "A"] if fmt == "rgba" else ["R", "G", "B"]
    inner = ["img.R", "img.G", "img.B", "img.A"] if nested else []
    assert info["channels"] == colour + inner + ["dd.y.T", "nn.X", "nn.Y", "nn.Z"]
    own = np.array(mi.render(mi.load_file(str(path)), seed=3, spp=4))   # (its last 4: depth, normal)
    assert np.allclose(img[..., -4:], own[..., -4:], atol=1e-5)
    depth = img[..., info["channels"].index("dd.y.T")]
    assert 2.9 < depth[3, 4] < 3.1 and depth[0, 0] < 0.1    # (the sphere's front at 3; sky)
    if nested:                                                  # the nested image is the colour
        assert np.allclose(img[..., :3], img[..., 3:6], atol=1e-5) and img[3, 4, 0] > 0.1
    else:
        assert np.all(img[..., :3] == 0)


def test_mitsubas_default_conductor_renders_without_an_out_of_range_warning(tmp_path):
    """A conductor without a material is Mitsuba's 'none', a perfect mirror of eta 0 and k 1:
    every render of it warned that eta=0 was out of (0, inf) and its pixels not to be trusted.
    A conductor's eta may be 0; a negative one, and a dielectric's eta of 0, stay refused."""
    import warnings
    path = tmp_path / "mirror.xml"
    path.write_text('<scene version="3.0.0"><integrator type="path"/><sensor type="perspective">'
                    '<transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>'
                    '<film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>'
                    '</film></sensor><emitter type="constant"/>'
                    '<shape type="sphere" id="ball"><bsdf type="roughconductor"/></shape>'
                    '<shape type="sphere" id="glass"><transform name="to_world"><translate x="3"/></transform>'
                    '<bsdf type="dielectric"/></shape></scene>')
    scene = draaw_mi.load_scene(str(path))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        draaw_mi.render(scene, version="v4", spp=2)
    assert scene.out_of_range() == []
    scene.params.keep(["ball.bsdf.eta.value"])            # (its k out of the user's params)
    assert scene.out_of_range() == []
    eta = scene.params["ball.bsdf.eta.value"]
    scene.params["ball.bsdf.eta.value"] = type(eta)(-0.5)
    scene.params.update()
    found = scene.out_of_range()
    assert any("ball.bsdf.eta.value=-0.5; expected a number in [0, inf)" in m for m in found), found
    scene.check_value("demo", "ball.eta", "ball.bsdf.eta.value", 0.0)        # (taken: a mirror)
    with pytest.raises(draaw_mi.errors.ParameterError, match=r"demo: glass.eta=0.0; expected a number in \(0, inf\)"):
        scene.check_value("demo", "glass.eta", "glass.bsdf.eta", 0.0)


SENSOR_8 = ('<sensor type="perspective"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/>'
            '</transform><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>'
            '</film></sensor>')


def test_lights_and_media_are_named_by_their_own_ids(tmp_path):
    """An XML area light or medium inside a shape without an id has keys Mitsuba names
    ``object_<address>...``, which change from run to run: ``lamp.radiance`` (the name `info`
    shows) was refused. A medium's albedo (``...albedo.value.value``) was not found by its
    short name, and the hint named ``scale``."""
    path = tmp_path / "lamp.xml"
    path.write_text(f'<scene version="3.0.0">{SENSOR_8}'
                    '<shape type="rectangle"><transform name="to_world"><translate z="-1"/></transform>'
                    '<emitter type="area" id="lamp"><rgb name="radiance" value="2"/></emitter></shape>'
                    '<shape type="sphere" id="ball"><bsdf type="diffuse"/></shape>'
                    '<shape type="cube" id="box"><transform name="to_world"><scale value="5"/></transform>'
                    '<bsdf type="null"/><medium name="interior" type="homogeneous" id="fog">'
                    '<rgb name="albedo" value="0.8, 0.5, 0.3"/><float name="sigma_t" value="0.05"/></medium></shape>'
                    '</scene>')
    scene = draaw_mi.load_scene(str(path))
    lamp = scene.key("lamp.radiance")
    assert lamp.startswith("object_") and lamp.endswith(".emitter.radiance.value")
    assert scene.key("fog.albedo") == scene.key("box.interior_medium.albedo") == "box.interior_medium.albedo.value.value"
    res = draaw_mi.fit(scene, np.full((8, 8, 3), 0.5, np.float32), ["lamp.radiance"], version="v4", iterations=2,
                       spp=2, progress=False)
    assert "lamp.radiance" in res.values
    with pytest.raises(draaw_mi.SceneError, match="no parameter 'lamp.radiancee'"):
        scene.key("lamp.radiancee")


def test_a_python_integrator_is_named_by_what_it_prints():
    """A registered Python integrator whose class name lacks 'Integrator' was called 'sampling'
    (its C++ base class) in info, the CLI's note and the EXR header."""
    import mitsuba as mi
    from draaw_mi.scene.mitsuba_xml import integrator_name

    class Tracer(mi.ad.integrators.common.RBIntegrator):
        def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):
            return mi.Spectrum(0.0), mi.Bool(False), [], None
    mi.register_integrator("session75_tracer", lambda props: Tracer(props))
    assert integrator_name(mi.load_dict({"type": "session75_tracer"})) == "tracer"
