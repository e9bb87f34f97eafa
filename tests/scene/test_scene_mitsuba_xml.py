"""Mitsuba XML scenes: the files they read (batch frames go stale with them) and an integrator
declared in an included file (draaw_mi.scene.mitsuba_xml)."""
import os

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.batch import runner as batch
from draaw_mi.scene.mitsuba_xml import xml_references

SENSOR = ('<sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 4" '
          'target="0, 0, 0" up="0, 1, 0"/></transform><film type="hdrfilm"><integer name="width" '
          'value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>'
          '<sampler type="independent"><integer name="sample_count" value="1"/></sampler></sensor>')


def _scene(tmp_path):
    """scene.xml: a texture named through a <default>, an OBJ mesh in a sub-folder, an
    <include> of parts/light.xml (which names its own integrator and a file beside it), a
    commented-out integrator and a file that exists nowhere Mitsuba looks."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "quad.obj").write_text(
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    draaw_mi.write_png(str(tmp_path / "wood.png"), np.full((4, 4, 3), 0.4, np.float32))
    (tmp_path / "parts" / "light.xml").write_text(
        '<scene version="3.0.0"><integrator type="path"><integer name="max_depth" value="3"/>'
        '</integrator><emitter type="constant"><rgb name="radiance" value="1"/></emitter></scene>')
    (tmp_path / "scene.xml").write_text(
        f'<scene version="3.0.0"><default name="tex" value="wood.png"/>'
        f'<!-- <integrator type="direct"/> --><include filename="parts/light.xml"/>{SENSOR}'
        '<shape type="obj"><string name="filename" value="meshes/quad.obj"/>'
        '<bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        '<string name="filename" value="$tex"/></texture></bsdf></shape></scene>')
    return tmp_path / "scene.xml"


def test_the_files_an_xml_scene_reads_are_listed(tmp_path):
    path = _scene(tmp_path)
    files, named = xml_references(str(path))
    assert sorted(os.path.relpath(f, tmp_path) for f in files) ==\
        ["meshes/quad.obj", "parts/light.xml", "wood.png"]
    assert named                                  # declared in the included file only
    s = draaw_mi.load_scene(str(path))
    assert sorted(s.info["files"]) == sorted(files)
    assert s.settings["version"] == "path" and s.settings["max_depth"] == 3
    # the same scene without the include: the commented-out integrator does not count
    text = path.read_text().replace('<include filename="parts/light.xml"/>', "")
    path.write_text(text)
    files, named = xml_references(str(path))
    assert not named and sorted(os.path.relpath(f, tmp_path) for f in files) == ["meshes/quad.obj", "wood.png"]
    assert draaw_mi.load_scene(str(path)).settings["version"] != "path"


def test_a_name_given_only_at_load_time_or_missing_is_left_out(tmp_path):
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><shape type="ply"><string name="filename" value="$mesh"/></shape>'
        '<shape type="obj"><string name="filename" value="gone.obj"/></shape>'
        '<include filename="$part"/></scene>')
    assert xml_references(str(tmp_path / "s.xml")) == ([], False)


def test_an_unparsable_file_falls_back_to_the_text_test(tmp_path):
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><integrator type="path"/>&undefined;</scene>')
    assert xml_references(str(tmp_path / "s.xml")) == ([], True)


def test_batch_frames_of_an_xml_scene_go_stale_when_a_file_it_reads_changes(tmp_path, monkeypatch):
    """A texture, a mesh or an included file of an XML scene edited: its finished frames are
    stale (they stayed "done": XML scenes listed no files)."""
    path = _scene(tmp_path)
    monkeypatch.chdir(tmp_path)                  # the batch's output folder
    doc = {"output": "out/{frame:04d}.exr",
           "jobs": [{"name": "x", "scene": str(path), "frames": 1, "spp": 1}]}
    assert batch.run(doc, progress=False).rendered == 1
    assert len(batch.read_header(str(tmp_path / "out" / "0000.exr"))["draaw:files_sha256"]) == 64
    for name, edit in (("wood.png", lambda p: draaw_mi.write_png(p, np.full((4, 4, 3), 0.8, np.float32))),
                       ("meshes/quad.obj", lambda p: open(p, "a").write("# edited\n")),
                       ("parts/light.xml", lambda p: open(p, "a").write("<!-- edited -->\n"))):
        assert batch.status(doc)["counts"]["done"] == 1, name
        edit(str(tmp_path / name))
        assert batch.status(doc)["counts"]["stale"] == 1, name
        assert batch.run(doc, progress=False).rendered == 1, name


def test_a_name_found_in_two_folders_lists_both(tmp_path):
    """Mitsuba looks in the <path> folders before the scene's; a name in both could be either:
    both are listed (the one it reads, sub/t.png here, was left out and its edits went unseen)."""
    (tmp_path / "sub").mkdir()
    for folder in (tmp_path, tmp_path / "sub"):
        draaw_mi.write_png(str(folder / "t.png"), np.full((2, 2, 3), 0.5, np.float32))
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><path value="sub"/><bsdf type="diffuse"><texture type="bitmap" '
        'name="reflectance"><string name="filename" value="t.png"/></texture></bsdf></scene>')
    files, _ = xml_references(str(tmp_path / "s.xml"))
    assert sorted(os.path.relpath(f, tmp_path) for f in files) == ["sub/t.png", "t.png"]


@pytest.mark.parametrize("rfilter, name", [("", "gaussian"), ('<rfilter type="box"/>', "box"),
                                           ('<rfilter type="lanczos"/>', "lanczos")])
def test_an_xml_scenes_filter_is_its_films(tmp_path, rfilter, name):
    """The settings said 'box' for any XML scene ('info' showed it; fit's extra views were
    made with a box filter while the scene's film had Mitsuba's default gaussian)."""
    xml = tmp_path / "s.xml"
    xml.write_text(f"""<scene version="3.0.0"><shape type="sphere"/><emitter type="constant"/>
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
    <integer name="height" value="8"/>{rfilter}</film></sensor></scene>""")
    scene = draaw_mi.load_scene(str(xml))
    assert scene.settings["filter"] == name
    assert draaw_mi.load_scene(str(xml), filter=name).settings["filter"] == name
    other = "tent"
    with pytest.raises(draaw_mi.DraawError, match=f"filter='tent' cannot override the filter of a Mitsuba "
                                                  f"scene \\('{name}'\\)"):
        draaw_mi.load_scene(str(xml), filter=other)
    from draaw_mi.fitting.views import view_sensors as _views
    (view,) = _views(scene, [{"origin": [0, 0, 4], "target": [0, 0, 0]}])
    assert str(view.film().rfilter()).split("[")[0] == str(scene.mi_scene.sensors()[0].film().rfilter()).split("[")[0]


@pytest.mark.parametrize("rfilter", ['<rfilter type="gaussian"><float name="stddev" value="0.25"/></rfilter>',
                                     '<rfilter type="lanczos"><integer name="lobes" value="2"/></rfilter>',
                                     '<rfilter type="tent"><float name="radius" value="1.5"/></rfilter>'])
def test_fit_views_keep_the_films_filter_parameters(tmp_path, rfilter):
    """fit's extra views had the film's filter by name only: an XML film's gaussian of stddev
    0.25 became one of 0.5 (radius 2, not 1), and a view equal to the scene's camera rendered
    another image than the scene's."""
    xml = tmp_path / "s.xml"
    xml.write_text(f"""<scene version="3.0.0"><shape type="sphere"/><emitter type="constant"/>
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="12"/>
    {rfilter}</film></sensor></scene>""")
    import mitsuba as mi
    scene = draaw_mi.load_scene(str(xml))
    from draaw_mi.fitting.views import view_sensors as _views
    (view,) = _views(scene, [{"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 40.0}])
    own = scene.mi_scene.sensors()[0]
    assert view.film().rfilter().radius() == own.film().rfilter().radius()
    integ = mi.load_dict({"type": "path", "max_depth": 2})
    a, b = (np.array(mi.render(scene.mi_scene, sensor=s, integrator=integ, spp=4, seed=3)) for s in (own, view))
    np.testing.assert_allclose(b, a, atol=1e-5)


def _film_scene(tmp_path, pixel_format):
    """A 16x16 diffuse sphere under a constant sky whose film stores ``pixel_format``."""
    path = tmp_path / f"{pixel_format}.xml"
    path.write_text(
        '<scene version="3.0.0"><shape type="sphere"><bsdf type="diffuse"/></shape>'
        '<emitter type="constant"><rgb name="radiance" value="1"/></emitter>'
        + SENSOR.replace('<rfilter type="box"/>', f'<string name="pixel_format" value="{pixel_format}"/>'
                         '<rfilter type="box"/>') + '</scene>')
    return str(path)


@pytest.mark.parametrize("pixel_format, colour", [("rgba", ["R", "G", "B", "A"]), ("luminance", ["Y"]),
                                                  ("luminance_alpha", ["Y", "A"]), ("rgb", ["R", "G", "B"]),
                                                  ("xyz", ["X", "Y", "Z"]), ("xyza", ["X", "Y", "Z", "A"])])
def test_an_xml_films_pixel_format_names_the_colour_channels(tmp_path, pixel_format, colour):
    """(defect: info["channels"] was R, G, B then the AOVs whatever the film stored, and
    `draaw-mi render x.xml` of an rgba or luminance film rendered, then failed in write_exr:
    "3 channel names for an image with 4 channels")"""
    from draaw_mi.cli import main
    path = _film_scene(tmp_path, pixel_format)
    scene = draaw_mi.load_scene(path)
    for aovs, extra in (([], []), (["depth"], ["depth.Z"])):
        img, info = draaw_mi.render(scene, version="v4", spp=4, aovs=aovs, return_info=True)
        assert info["channels"] == colour + extra and img.shape == (16, 16, len(colour) + len(extra))
    assert main(["render", path, "-o", str(tmp_path / "o.exr"), "--png", str(tmp_path / "o.png"),
                 "--no-progress"]) == 0
    arr, names = draaw_mi.read_exr(str(tmp_path / "o.exr"), with_names=True)
    assert names == colour and arr.shape == (16, 16, len(colour))
    if "A" in colour:                                     # the sphere and the sky: all covered
        assert np.allclose(arr[..., -1], 1.0)
    # a white sphere under a white sky is grey in the PNG: an xyz film's X, Y, Z (ratios
    # 0.9505 : 1 : 1.089 for D65 white) were shown as R, G, B, a pink-grey
    import matplotlib.image
    png = matplotlib.image.imread(str(tmp_path / "o.png"))
    if len(colour) >= 3:
        assert np.abs(png[..., 0] - png[..., 2]).max() <= 1 / 255 and png[..., 1].std() > 0.01


def test_a_luminance_film_is_refused_by_a_post_chain_before_the_render(tmp_path):
    """A post chain and the denoiser read R, G, B: a luminance film is named before rendering
    (the chain failed after it with a shape error, the denoiser read AOVs as colour)."""
    scene = draaw_mi.load_scene(_film_scene(tmp_path, "luminance"))
    with pytest.raises(draaw_mi.DraawError, match="stores Y colour.*'luminance'.*a post chain needs rgb"):
        draaw_mi.render(scene, spp=1, post=[{"type": "srgb"}])
    with pytest.raises(draaw_mi.DraawError, match="denoising needs rgb or rgba"):
        draaw_mi.render(scene, spp=1, denoise=True)
    xyz = draaw_mi.load_scene(_film_scene(tmp_path, "xyz"))       # (read as R, G, B before)
    with pytest.raises(draaw_mi.DraawError, match="stores X, Y, Z colour.*'xyz'.*a post chain needs rgb"):
        draaw_mi.render(xyz, spp=1, post=[{"type": "srgb"}])
    img = np.array(draaw_mi.render(_film_scene(tmp_path, "rgba"), spp=4, post=[{"type": "srgb"}]))
    assert img.shape == (16, 16, 4) and np.allclose(img[..., 3], 1.0)     # alpha passes through


def test_adaptive_subsampling_refuses_a_film_that_is_not_rgb(tmp_path):
    """Adaptive subsampling renders R, G, B: an rgba film's alpha was dropped without a word
    (the plain render gave 4 channels, the adaptive one 3, named R, G, B)."""
    for fmt, stored in (("rgba", "R, G, B, A"), ("luminance", "Y")):
        scene = draaw_mi.load_scene(_film_scene(tmp_path, fmt))
        with pytest.raises(draaw_mi.RenderError, match=f"adaptive subsampling renders R, G, B; the film .* stores {stored}:"):
            draaw_mi.render(scene, version="path", spp=4, adaptive=8)
    img = draaw_mi.render(draaw_mi.load_scene(_film_scene(tmp_path, "rgb")), version="path", spp=4, adaptive=8)
    assert np.array(img).shape == (16, 16, 3)


@pytest.mark.parametrize("pixel_format, colour", [("xyz", ["X", "Y", "Z"]), ("rgba", ["R", "G", "B", "A"])])
def test_batch_frames_name_the_films_colour_as_render_does(tmp_path, pixel_format, colour, monkeypatch):
    """The batch's frozen one-pass path named every frame's colour R, G, B: an xyz film's
    frames were labelled R, G, B, an rgba film's failed after rendering ("3 channel names
    for an image of shape (16, 16, 4)"); a post chain on an xyz film ran on X, Y, Z."""
    path = _film_scene(tmp_path, pixel_format)
    monkeypatch.chdir(tmp_path)                  # the batch's output folder
    doc = {"output": "out/{frame:04d}.exr",
           "jobs": [{"name": "x", "scene": path, "frames": 1, "spp": 2, "previews": True}]}
    assert batch.run(doc, progress=False).rendered == 1
    arr, names = draaw_mi.read_exr(str(tmp_path / "out" / "0000.exr"), with_names=True)
    assert names == colour
    # the preview by name too: a white sphere under a white sky is grey (X, Y, Z shown as
    # R, G, B were pink-grey)
    import matplotlib.image
    png = matplotlib.image.imread(str(tmp_path / "out" / "0000.png"))
    assert np.abs(png[..., 0] - png[..., 2]).max() <= 1 / 255
    ref = np.array(draaw_mi.render(path, spp=2, seed=batch.load(doc)[1][0]["seed"]))
    assert np.array_equal(arr, ref)                               # render()'s image, bit for bit
    if pixel_format == "xyz":
        doc["jobs"][0]["post"] = [{"type": "srgb"}]
        doc["output"] = "post/{frame:04d}.exr"
        res = batch.run(doc, progress=False)
        assert res.rendered == 0 and "stores X, Y, Z colour" in res.failed[0]["error"]


@pytest.mark.parametrize("bsdf, match", [
    ('<bsdf type="dielectric"><float name="int_iro" value="1.5"/></bsdf>',
     r"line \d+, col \d+: 'int_iro' is not a parameter of Mitsuba's 'dielectric' bsdf; did you mean 'int_ior'\?$"),
    ('<bsdf type="roughconductor"><float name="alph" value="0.1"/></bsdf>',
     r"'alph' is not a parameter of Mitsuba's 'roughconductor' bsdf; did you mean 'alpha'\?$"),
    ('<bsdf type="dielectric"><float name="zzz" value="1.5"/></bsdf>',
     r"'zzz' is not a parameter of Mitsuba's 'dielectric' bsdf$"),
    ('<bsdf type="draaw"><float name="roughnes" value="0.3"/></bsdf>',
     r"'roughnes' is not a parameter of the 'draaw' BSDF; did you mean 'roughness'\?"),
])
def test_a_misspelt_bsdf_parameter_is_named_with_its_plugin(tmp_path, bsdf, match):
    """Mitsuba lists unknown parameters on lines of their own; only the last line was kept
    (``- float "int_iro": 1.5``), naming neither the material nor the problem. A close name
    among a common Mitsuba BSDF's parameters is suggested, as the draaw BSDF's is."""
    path = tmp_path / "s.xml"
    path.write_text(f'<scene version="3.0.0"><shape type="sphere">{bsdf}</shape>{SENSOR}</scene>')
    with pytest.raises(draaw_mi.SceneError, match=match):
        draaw_mi.load_scene(str(path))


def test_a_misspelt_parameter_of_a_mitsuba_material_in_a_description_names_the_material():
    with pytest.raises(draaw_mi.SceneError, match=r"'glass': 'int_iro', 'ext_iro' are not parameters "
                                                  r"of Mitsuba's 'dielectric' bsdf"):
        draaw_mi.load_scene({"materials": {"glass": {"type": "dielectric", "int_iro": 1.5, "ext_iro": 1.0}},
                             "shapes": [{"type": "sphere", "material": "glass"}]})


def test_an_xml_scenes_own_draaw_v4_renders_it_with_its_properties(tmp_path, capsys):
    """An XML file declaring ``draaw_v4`` with ``stratify = false`` and a uniform light
    selection was rendered by a new default V4 (stratified, auto), and ``draaw-mi info`` named
    it 'draawv4' and described the default's sampling."""
    from draaw_mi.cli import main
    from draaw_mi.rendering.session import session_of
    path = tmp_path / "v4.xml"
    path.write_text(
        '<scene version="3.0.0"><integrator type="draaw_v4"><boolean name="stratify" value="false"/>'
        '<string name="light_selection" value="uniform"/><integer name="max_depth" value="4"/></integrator>'
        '<shape type="sphere"><bsdf type="diffuse"/></shape>'
        '<emitter type="constant"><rgb name="radiance" value="1"/></emitter>'
        + SENSOR.replace('value="1"/></sampler>', 'value="16"/></sampler>') + '</scene>')
    scene = draaw_mi.load_scene(str(path))
    st = scene.settings
    used = session_of(scene).integrator(st["version"], st["max_depth"], st["hide_emitters"], [])
    assert used is scene.mi_scene.integrator() and not used.stratify and used.light_selection == "uniform"
    other = session_of(scene).integrator("v4", 2, False, [])        # another depth: a plugin of its own
    assert other is not used and other.stratify
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "integrator: draaw_v4 (declared by the file" in out and "v4 samples: independent (stratify=false)" in out
    # a scene that declares path: info still says how --version v4 would sample it
    path.write_text(path.read_text().replace('<integrator type="draaw_v4"><boolean name="stratify" value="false"/>'
                                             '<string name="light_selection" value="uniform"/>', '<integrator type="path">'))
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "integrator: path (declared" in out and "v4 samples: stratified" in out and "v4 lights:" in out


def test_the_suggested_mitsuba_bsdf_parameters_are_ones_mitsuba_takes():
    """Each name of the suggestion table loads in its plugin (a wrong entry would suggest a
    parameter that Mitsuba refuses in turn)."""
    from draaw_mi.scene.mitsuba_load import _BSDF_PARAMETERS
    values = {"distribution": "ggx", "material": "Au", "sample_visible": True, "nonlinear": True, "int_ior": 1.5,
              "ext_ior": 1.0, "k": 1.0, "eta": 1.5}
    nested = {"blendbsdf": {"a": {"type": "diffuse"}, "b": {"type": "diffuse"}}, "mask": {"b": {"type": "diffuse"}},
              "bumpmap": {"b": {"type": "diffuse"}, "t": {"type": "checkerboard"}},
              "normalmap": {"b": {"type": "diffuse"}}}
    flat = {"type": "bitmap", "raw": True, "bitmap": mi.Bitmap(np.full((2, 2, 3), 0.5, np.float32))}
    for plugin, names in _BSDF_PARAMETERS.items():
        for name in names.split():
            d = {"type": plugin, **nested.get(plugin, {})}
            d.update({"alpha_u": 0.1, "alpha_v": 0.2} if name in ("alpha_u", "alpha_v") else
                     {name: flat} if plugin == "normalmap" else {name: values.get(name, 0.5)})
            mi.load_dict(d)                       # (raises on a parameter the plugin does not take)
