"""Scene loading: TOML/JSON/dict/XML/mesh, names, cameras, and clear errors for bad input."""
from __future__ import annotations

import copy
import json
import math
import os

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi import SceneError
from draaw_mi.scene.camera import go_draaw_look_at, spherical

from conftest import SCENES, bright_column, glowing_ball, go_draaw_patch_point, go_draaw_patch_uv,\
    tiny_description


@pytest.mark.parametrize("name", ["cornell", "material_spheres", "thesis"])
def test_sample_scenes_load_and_render(name):
    scene = draaw_mi.load_scene(os.path.join(SCENES, f"{name}.toml"), resolution=(32, 32), spp=4)
    img = np.array(draaw_mi.render(scene, version="path"))
    assert img.shape == (32, 32, 3)
    assert np.isfinite(img).all() and img.mean() > 0.01


def test_material_keys_are_named_after_materials(tiny_scene):
    keys = tiny_scene.params.keys()
    for k in ("ball.roughness.value", "ball.metallic.value", "ball.base_color.value", "ground.specular.value"):
        assert k in keys
    assert tiny_scene.key("ball.roughness") == "ball.roughness.value"
    with pytest.raises(SceneError, match="did you mean 'ball.roughness(.value)?'"):
        tiny_scene.key("ball.rougness")


def test_toml_json_and_dict_give_the_same_image(tmp_path, tiny_desc):
    import tomllib  # noqa: F401  (stdlib on 3.11)
    js = tmp_path / "s.json"
    js.write_text(json.dumps(tiny_desc))
    toml_text = _to_toml(tiny_desc)
    tm = tmp_path / "s.toml"
    tm.write_text(toml_text)
    imgs = [np.array(draaw_mi.render(draaw_mi.load_scene(src), version="path", seed=3))
            for src in (tiny_desc, str(js), str(tm))]
    assert np.array_equal(imgs[0], imgs[1]) and np.array_equal(imgs[0], imgs[2])


def _to_toml(desc):
    """Minimal TOML writer for the fixture's structure (tables, arrays of tables, inline values)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)
    lines = ["[render]"]
    lines += [f"{k} = {val(v)}" for k, v in desc["render"].items()]
    lines.append("[camera]")
    lines += [f"{k} = {val(v)}" for k, v in desc["camera"].items()]
    for name, mat in desc["materials"].items():
        lines.append(f"[materials.{name}]")
        lines += [f"{k} = {val(v)}" for k, v in mat.items()]
    for sec in ("shapes", "lights"):
        for item in desc[sec]:
            lines.append(f"[[{sec}]]")
            lines += [f"{k} = {val(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def test_go_draaw_camera_looks_through_the_patch_centre():
    theta, phi, fov = 0.335, -1.715, 45.0
    origin, target, up, mirror = go_draaw_look_at([1.0, 2.0, 3.0], theta, phi, fov)
    f = math.radians(fov)
    centre = 0.5 * (spherical(theta + f, phi) + spherical(theta, phi + f))
    d = (target - origin)
    assert np.allclose(d / np.linalg.norm(d), centre / np.linalg.norm(centre))
    assert abs(np.dot(up, d)) < 1e-9                    # orthonormal
    tl_minus_bl = spherical(theta, phi) - spherical(theta, phi + f)
    assert np.dot(up, tl_minus_bl) > 0                  # image-up is decreasing phi
    assert not mirror                                   # (sin phi < 0: image-right is view x up)


@pytest.mark.parametrize("theta, phi", [(0.3, 1.2), (2.0, 0.9), (0.3, -2.08), (-1.0, -1.7)])
def test_go_draaw_camera_shows_go_draaws_view_not_its_mirror_image(theta, phi):
    """A glowing ball a fifth of the way across GO-Draaw's image patch (the spec's formula in
    numpy, conftest.go_draaw_patch_uv) is there in the render, for sin φ > 0 too, where the
    look-at camera alone shows the left-right mirror image (the ball at column ~25 of 32, not
    ~6). Within 3 columns: the pinhole camera is not the patch's bilinear distortion."""
    position, fov = np.array([0.5, -1.0, 2.0]), 45.0
    ball = go_draaw_patch_point(position, theta, phi, fov, 0.2, 0.5, 3.0)
    u, v = go_draaw_patch_uv(position, theta, phi, fov, ball)
    assert (u, v) == pytest.approx((0.2, 0.5))
    scene = draaw_mi.load_scene(glowing_ball({"position": position.tolist(), "angles": [theta, phi], "fov": fov},
                                             ball))
    col = bright_column(draaw_mi.render(scene, version="path"))
    assert col == pytest.approx(u * 32, abs=3.0), (col, u * 32)
    assert scene.info["camera"]["mirror"] == (math.sin(phi) > 0)


def test_snap_light_to_camera(tiny_desc):
    tiny_desc["lights"] = [{"type": "point", "snap_to_camera": True, "intensity": 10.0}]
    scene = draaw_mi.load_scene(tiny_desc)
    pos = np.array(scene.params["point_light0.position"]).ravel()
    assert np.allclose(pos, tiny_desc["camera"]["origin"])


def test_mitsuba_dict_and_xml_pass_through(tmp_path):
    d = mi.cornell_box()
    d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = 16
    scene = draaw_mi.load_scene(d)
    assert scene.resolution == (16, 16)
    xml = tmp_path / "s.xml"
    xml.write_text("""<scene version="3.0.0"><integrator type="path"><integer name="max_depth" value="3"/></integrator>
      <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="20"/>
      <integer name="height" value="10"/></film><sampler type="independent"><integer name="sample_count" value="8"/></sampler></sensor>
      <shape type="sphere"><bsdf type="draaw"><float name="roughness" value="0.3"/></bsdf></shape>
      <emitter type="constant"/></scene>""")
    s = draaw_mi.load_scene(str(xml))
    assert s.resolution == (20, 10) and s.settings["spp"] == 8 and s.settings["max_depth"] == 3
    img = np.array(draaw_mi.render(s, version="path"))
    assert img.shape == (10, 20, 3) and np.isfinite(img).all()
    # the integrator a file names is its render version (it rendered with v4); -1 stays -1
    # (Mitsuba prints it unsigned: 4294967295); a file without one gets draaw-mi's default
    assert s.settings["version"] == "path" and s.summary()["shapes"] == ["unnamed sphere (its own material)"]
    text = xml.read_text()
    xml.write_text(text.replace('<integer name="max_depth" value="3"/>', "").replace('"path"', '"volpath"'))
    s = draaw_mi.load_scene(str(xml))
    assert s.settings["version"] == "volpath" and s.settings["max_depth"] == -1
    _, info = draaw_mi.render(s, spp=1, return_info=True)
    assert info["integrator"] == "volpath"
    start, end = text.index("<integrator"), text.index("</integrator>") + len("</integrator>")
    xml.write_text(text[:start] + text[end:])
    assert draaw_mi.load_scene(str(xml)).settings["version"] == "v4"
    # another of Mitsuba's integrators: the scene's own renders it (tests/scene/test_scene_xml_options.py)
    xml.write_text(text[:start] + '<integrator type="direct"/>' + text[end:])
    assert draaw_mi.load_scene(str(xml)).settings["version"] == "scene"


def test_with_resolution_rebuilds_film(tiny_scene):
    s2 = tiny_scene.with_resolution(16, 8)
    assert s2.resolution == (16, 8)
    assert np.array(draaw_mi.render(s2, version="path")).shape == (8, 16, 3)


def test_with_resolution_keeps_parameter_edits(tiny_scene):
    """A material and a camera edited through ``params`` stay in the resized copy (the reload
    alone gives the file's values): the render equals one of a scene loaded at that size with
    the same edits made."""
    edits = {"ball.base_color.value": mi.Color3f(0.1, 0.7, 0.9), "ball.roughness.value": mi.Float(0.05),
             "sensor.to_world": mi.ScalarTransform4f().look_at(origin=[1.0, 1.5, 4.0], target=[0, 0.6, 0],
                                                                up=[0, 1, 0])}
    p = tiny_scene.params
    for k, v in edits.items():
        p[k] = v
    p.update()
    img = np.array(draaw_mi.render(tiny_scene, version="path", resolution=(16, 12)))
    ref_scene = draaw_mi.load_scene(tiny_description(resolution=[16, 12]))
    q = ref_scene.params
    for k, v in edits.items():
        q[k] = v
    q.update()
    ref = np.array(draaw_mi.render(ref_scene, version="path"))
    plain = np.array(draaw_mi.render(draaw_mi.load_scene(tiny_description(resolution=[16, 12])), version="path"))
    assert np.abs(ref - plain).mean() > 0.02                 # the edits show
    np.testing.assert_allclose(img, ref, atol=1e-6)          # same seed, same scene: the same image


def test_with_resolution_keeps_edits_after_params_keep(tiny_scene):
    """``scene.params.keep([...])`` (Mitsuba's optimisation tutorials narrow the parameters so)
    dropped every other key from what the copy was carried from: a roughness set before it went
    back to the file's 0.9 in a copy at another resolution."""
    tiny_scene.params["ground.roughness.value"] = mi.Float(0.2)
    tiny_scene.params.update()
    tiny_scene.params.keep(["ball.base_color.value"])
    copy_ = tiny_scene.with_resolution(16, 12)
    assert copy_.params["ground.roughness.value"][0] == pytest.approx(0.2)
    np.testing.assert_allclose(np.array(copy_.params["ball.base_color.value"]), np.array(tiny_scene.params["ball.base_color.value"]))


def test_with_resolution_keeps_texture_maps_and_their_edits():
    """A scene whose materials are arrays (texture maps) resizes, twice, with an edited texel
    carried over: the resized render equals that of the scene described at the new size with
    the same edit. (Mitsuba's bitmap moves the tensor out of the dict it loads; reloading the
    kept dict failed with "Bitmap raw tensor has dimension 0", so ``fit()`` with references of
    another size failed on any textured scene.)"""
    desc = tiny_description(resolution=[16, 12])
    rng = np.random.default_rng(3)
    desc["materials"]["ball"] = {"base_color": rng.uniform(0.1, 0.9, (4, 4, 3)).tolist(),
                                 "roughness": rng.uniform(0.2, 0.8, (4, 4)).tolist(), "metallic": 0.2}
    scene = draaw_mi.load_scene(desc)
    edited = np.array(scene.params["ball.roughness.data"])
    edited[1, 2] = 0.05
    scene.params["ball.roughness.data"] = mi.TensorXf(edited)
    scene.params.update()
    resized = scene.with_resolution(12, 8).with_resolution(8, 6)
    assert scene.with_resolution(8, 6).resolution == (8, 6)           # the kept dict loads again
    desc["materials"]["ball"]["roughness"] = edited[..., 0].tolist() if edited.ndim == 3 else edited.tolist()
    desc["render"]["resolution"] = [8, 6]
    ref = np.array(draaw_mi.render(draaw_mi.load_scene(desc), version="path"))
    np.testing.assert_allclose(np.array(resized.params["ball.roughness.data"]).squeeze(), edited.squeeze(), atol=1e-7)
    np.testing.assert_allclose(np.array(draaw_mi.render(resized, version="path")), ref, atol=1e-6)


def test_the_scratch_folder_outlives_the_scene_while_a_derived_scene_holds_it(tmp_path):
    """A described scene's generated files (here a mesh's PLY) go to a scratch folder that
    the scenes derived from it share: it stays while the resized copy lives (and that copy
    reloads from it), then goes once both are collected, without the ``ResourceWarning`` a
    collected ``tempfile.TemporaryDirectory`` gives. A folder per scene removed with its
    scene fails the reload; a ``TemporaryDirectory`` warns."""
    import gc
    import warnings
    obj = tmp_path / "tri.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    desc = tiny_description(resolution=[16, 12])
    desc["shapes"].append({"type": "mesh", "name": "tri", "material": "ground", "file": str(obj)})
    scene = draaw_mi.load_scene(desc)
    folder = scene._tmp.name
    assert os.listdir(folder)                                    # the mesh's PLY
    resized = scene.with_resolution(12, 8)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always", ResourceWarning)
        del scene
        gc.collect()
        assert os.path.isdir(folder)
        assert resized.with_resolution(8, 6).resolution == (8, 6)   # loads its files again
        del resized
        gc.collect()
    assert not os.path.exists(folder)
    assert not [w for w in said if issubclass(w.category, ResourceWarning)], [str(w.message) for w in said]


def test_with_resolution_keeps_edited_vertices_and_only_those():
    """Mesh buffers are written over only where edited (each write rebuilds the BVH): a
    moved box arrives moved, the untouched one as loaded."""
    scene = draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"), resolution=(16, 16))
    p = scene.params
    moved = np.array(p["small_box.vertex_positions"]) + 0.1
    p["small_box.vertex_positions"] = mi.Float(moved.astype(np.float32))
    p.update()
    resized = scene.with_resolution(8, 8)
    np.testing.assert_allclose(np.array(resized.params["small_box.vertex_positions"]), moved, atol=1e-6)
    np.testing.assert_array_equal(np.array(resized.params["tall_box.vertex_positions"]),
                                  np.array(p["tall_box.vertex_positions"]))


@pytest.mark.parametrize("axis", ["y", "diagonal", "smaller"])
def test_with_resolution_keeps_the_fov_axis_angle(axis):
    """On a camera whose fov is along y (or the diagonal, the smaller side) a new aspect ratio
    changes Mitsuba's ``x_fov``: the resized copy has the ``x_fov`` Mitsuba itself derives when
    the file is loaded at that size."""
    desc = tiny_description(resolution=[32, 16])
    desc["camera"]["fov_axis"] = axis
    resized = draaw_mi.load_scene(desc).with_resolution(12, 20)
    desc["render"]["resolution"] = [12, 20]
    ref = draaw_mi.load_scene(desc)
    assert resized.params["sensor.x_fov"][0] == pytest.approx(ref.params["sensor.x_fov"][0], rel=1e-5)
    assert ref.params["sensor.x_fov"][0] != pytest.approx(draaw_mi.load_scene(
        tiny_description(resolution=[32, 16]) | {"camera": desc["camera"]}).params["sensor.x_fov"][0], rel=1e-3)


def test_render_resolution_with_params_is_refused(tiny_scene):
    """``params`` belong to the scene given; a resized render is of a reloaded copy, so its
    gradients would never reach them: refused, naming the way out."""
    with pytest.raises(draaw_mi.RenderError, match="with_resolution"):
        draaw_mi.render(tiny_scene, version="v2", resolution=(16, 12), params=tiny_scene.params)
    # the scene's own size is no resize: allowed
    draaw_mi.render(tiny_scene, version="v2", spp=1, resolution=tiny_scene.resolution, params=tiny_scene.params)


def test_mesh_with_mtl_materials(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\nnewmtl blue\nKd 0.1 0.1 0.8\n")
    (tmp_path / "m.obj").write_text(
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\n"
        "usemtl red\nf 1 2 3 4\nusemtl blue\nf 2 5 6 3\n")
    scene = draaw_mi.load_scene(str(tmp_path / "m.obj"), resolution=(16, 16), spp=4)
    mats = scene.info["materials"]
    assert len(mats) == 2
    colors = sorted(tuple(np.round(np.array(scene.params[f"{m}.base_color.value"]).ravel(), 2)) for m in mats)
    assert colors == [(0.1, 0.1, 0.8), (0.8, 0.1, 0.1)]
    assert np.isfinite(np.array(draaw_mi.render(scene, version="path"))).all()


def test_mtl_colours_are_read_as_written_and_missing_materials_said(tmp_path):
    """trimesh rounds an MTL's Kd to 1/255 (0.020 read 0.0196) and clips it without a word; a
    missing library or an undefined usemtl rendered grey silently (GO-Draaw stops there)."""
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 0.020 0.5 0.3\nnewmtl hot\nKd 2.5 -1 0.3\n")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                    "usemtl red\nf 1 2 3\nusemtl hot\nf 1 2 4\n")
    with pytest.warns(RuntimeWarning, match=r"material 'hot' has Kd 2.5 -1 0.3; expected values in \[0, 1\]"):
        scene = draaw_mi.load_scene(str(tmp_path / "m.obj"), resolution=(8, 8))
    colors = sorted(tuple(np.array(scene.params[f"{m}.base_color.value"]).ravel().tolist()) for m in scene.info["materials"])
    np.testing.assert_allclose(colors, [(0.02, 0.5, 0.3), (1.0, 0.0, 0.3)], atol=1e-7)
    (tmp_path / "n.obj").write_text("mtllib gone.mtl\nusemtl foo\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.warns(RuntimeWarning) as said:
        draaw_mi.load_scene(str(tmp_path / "n.obj"), resolution=(8, 8))
    text = " | ".join(str(w.message) for w in said)
    assert "material library 'gone.mtl' not found" in text and "usemtl 'foo': no material library defines it" in text
    # faces without a material beside faces with one: the grey part's material had the id of
    # the part's shape ("duplicate name 'mesh0_part1' (already used by a material)")
    (tmp_path / "o.obj").write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n"
                                    "usemtl red\nf 1 2 4\n")
    with pytest.warns(RuntimeWarning, match="material 'hot' has Kd"):
        mixed = draaw_mi.load_scene(str(tmp_path / "o.obj"), resolution=(8, 8))
    assert len(mixed.info["materials"]) == 2 and np.isfinite(np.array(draaw_mi.render(mixed, spp=1))).all()


def test_go_draaw_scenes_load_and_render(go_draaw_dir):
    for name in ("monkey.obj", "cubes.obj", "Room.obj", "t90.obj"):
        scene = draaw_mi.load_scene(os.path.join(go_draaw_dir, name), resolution=(24, 16), spp=2)
        img = np.array(draaw_mi.render(scene, version="path"))
        assert img.shape == (16, 24, 3) and np.isfinite(img).all() and img.mean() > 0, name
    room = draaw_mi.load_scene(os.path.join(go_draaw_dir, "Room.obj"), resolution=(8, 8))
    assert len(room.info["materials"]) >= 15      # Room.mtl's materials become draaw materials


def test_go_draaw_camera_positions(go_draaw_dir):
    cams = json.load(open(os.path.join(go_draaw_dir, "camera_positions.json")))
    for c in cams:
        desc = {"render": {"resolution": [20, 15], "spp": 2},
                "camera": {"position": [c["x"], c["y"], c["z"]], "angles": [c["cameraX"], c["cameraY"]], "fov": 45},
                "shapes": [{"type": "mesh", "file": os.path.join(go_draaw_dir, "monkey.obj"), "scale": 75}],
                "lights": [{"type": "point", "snap_to_camera": True, "intensity": 2e6}]}
        img = np.array(draaw_mi.render(draaw_mi.load_scene(desc), version="path"))
        assert np.isfinite(img).all() and img.mean() > 0   # the monkey scene is in view


# ----------------------------------------------------------------------------- bad input
def _mut(path, value):
    d = tiny_description()
    target = d
    for p in path[:-1]:
        target = target[p]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return d


BAD = [
    (("render", "resolution"), [-5, 3], r"render.resolution.width: -5 is out of range"),
    (("render", "resolution"), "axb", r"not a resolution"),
    (("render", "spp"), 0, r"render.spp: 0 is out of range"),
    (("render", "sppp"), 4, r"unknown key 'sppp'; did you mean 'spp'\?"),
    (("render", "filter"), "gauss", r"did you mean 'gaussian'"),
    (("materials", "ball", "roughness"), 1.5, r"materials.ball.roughness: 1.5 is out of range; expected a value in \[0.0, 1.0\]"),
    (("materials", "ball", "metalic"), 0.5, r"unknown key 'metalic'; did you mean 'metallic'\?"),
    (("materials", "ball", "base_color"), [1, -1, 0], r"base_color\[1\]: -1 is out of range"),
    # (float64, but float32 inf: NaN pixels; the tuner saved such a colour)
    (("materials", "ball", "base_color"), [1e40, 0.5, 0.5], r"base_color\[0\]: 1e\+40 is beyond float32"),
    (("materials", "ball", "base_color"), "missing.png", r"texture file 'missing.png' does not exist"),
    (("materials", "ball", "roughness"), [[0.1, 0.9], [0.5]], r"ball.roughness: .* not a rectangular array"),
    (("materials", "ball", "roughness"), [[[0.1, 0.9]]], r"ball.roughness: an array of shape \(1, 1, 2\)"),
    (("shapes", 0, "material"), "bal", r"unknown material 'bal'; did you mean 'ball'\?"),
    (("shapes", 0, "type"), "spehre", r"did you mean 'sphere'"),
    (("shapes", 0, "radius"), -1, r"radius: -1 is out of range"),
    (("shapes", 0, "name"), "floor", r"duplicate name 'floor'"),
    # the scene dict's own keys: a light named "sensor" was deleted by the camera (0 emitters,
    # a black image), a shape named "type" failed with Mitsuba's "std::bad_cast"
    (("lights", 0, "name"), "sensor", r"lights\[0\].name: 'sensor' is reserved \(type, sensor, integrator"),
    (("lights", 0, "name"), "integrator", r"lights\[0\].name: 'integrator' is reserved"),
    (("shapes", 0, "name"), "type", r"shapes\[0\].name: 'type' is reserved"),
    (("shapes", 0, "name"), "sensor", r"shapes\[0\].name: 'sensor' is reserved"),
    (("shapes", 0, "name"), "__sdf_0_0", r"shapes\[0\].name: '__sdf_0_0' is reserved"),
    (("materials", "sensor"), {"base_color": 0.5}, r"materials.sensor: 'sensor' is reserved"),
    (("shapes",), [], r"no shapes"),
    (("camera", "target"), [0.0, 1.0, 5.0], r"camera.target: equals 'origin'"),
    (("camera", "fov"), 180, r"camera.fov: 180 is out of range"),
    (("camera", "angles"), [0.1, 0.2], r"cannot be combined"),
    (("lights", 0, "intensity"), -2, r"lights\[0\].intensity: -2 is out of range"),
    (("lights", 0, "type"), "sun", r"lights\[0\].type: 'sun' is not one of [a-z, ]+$"),
    (("lights", 0, "type"), KeyError, r"lights\[0\]: missing key 'type'; expected one of point"),
    (("shapes", 0, "type"), KeyError, r"shapes\[0\]: missing key 'type'; expected one of mesh, sphere"),
    (("render", "version"), "v9", r"render.version: 'v9' is unknown; expected v1, v2, v3, v4, path"),
    (("lights", 0, "position"), KeyError, r"needs 'position'"),
    (("colour",), {}, r"unknown key 'colour'"),
]


@pytest.mark.parametrize("path,value,message", BAD, ids=[".".join(map(str, b[0])) + "=" + str(b[1]) for b in BAD])
def test_bad_descriptions_raise_one_clear_line(path, value, message):
    with pytest.raises(SceneError, match=message) as info:
        draaw_mi.load_scene(_mut(path, value))
    assert "\n" not in str(info.value)
    assert str(info.value).startswith("<dict>")


def test_bad_files(tmp_path):
    with pytest.raises(SceneError, match="does not exist"):
        draaw_mi.load_scene(str(tmp_path / "nope.toml"))
    bad = tmp_path / "bad.toml"
    bad.write_text("[render\nspp = 3")
    with pytest.raises(SceneError, match="bad.toml: malformed TOML"):
        draaw_mi.load_scene(str(bad))
    badj = tmp_path / "bad.json"
    badj.write_text("{\"render\": {\"spp\": 3,}}")
    with pytest.raises(SceneError, match="bad.json: malformed JSON at line 1"):
        draaw_mi.load_scene(str(badj))
    obj = tmp_path / "bad.obj"
    obj.write_text("this is not an obj file\nf 1 2 3\n")
    with pytest.raises(SceneError, match="bad.obj"):
        draaw_mi.load_scene(str(obj))
    empty = tmp_path / "empty.obj"
    empty.write_text("")
    with pytest.raises(SceneError, match="no triangles|cannot read"):
        draaw_mi.load_scene(str(empty))
    other = tmp_path / "scene.blend"
    other.write_text("x")
    with pytest.raises(SceneError, match="unknown scene format"):
        draaw_mi.load_scene(str(other))
    xml = tmp_path / "bad.xml"
    xml.write_text("<scene version='3.0.0'><shape type='nosuchshape'/></scene>")
    with pytest.raises(SceneError, match="bad.xml"):
        draaw_mi.load_scene(str(xml))
    with pytest.raises(SceneError, match="unknown setting 'sp'"):
        draaw_mi.load_scene(tiny_description(), sp=3)


def test_loading_does_not_mutate_the_description(tiny_desc):
    before = copy.deepcopy(tiny_desc)
    draaw_mi.load_scene(tiny_desc)
    assert tiny_desc == before


def _area_lights_description(n: int) -> dict:
    d = {"render": {"resolution": [16, 16], "spp": 4, "filter": "box"},
         "camera": {"origin": [0.0, 2.0, 8.0], "target": [0.0, 0.6, 0.0]},
         "materials": {"m": {"base_color": [0.5, 0.5, 0.5]}},
         "shapes": [{"name": "floor", "type": "rectangle", "material": "m",
                     "rotate": {"axis": [1, 0, 0], "angle": -90}, "scale": 6.0},
                    {"name": "box", "type": "cube", "material": "m", "scale": 0.5}],
         "lights": [{"name": f"l{i}", "type": "area", "shape": "rectangle",
                     "position": [-3.0 + i, 5.0, 2.0], "target": [0.0, 0.0, 0.0],
                     "size": [0.5, 0.5], "intensity": 5.0 + i} for i in range(n)]}
    return d


def test_area_lights_keep_their_declared_order_and_images_repeat(tmp_path):
    """Mitsuba's mesh merging orders shapes by address, and the emitter order decides which
    light a sample picks: without a fixed order one scene and seed gave different images in
    different loads (and processes, so a resumed batch frame was not bit-identical)."""
    desc = _area_lights_description(6)
    names = [f"l{i}" for i in range(6)]
    images = []
    for _ in range(4):
        s = draaw_mi.load_scene(copy.deepcopy(desc))
        assert [e.get_shape().id() for e in s.mi_scene.emitters()] == names
        images.append(np.array(draaw_mi.render(s, version="v3", spp=4, seed=7, post=[])))
    for img in images[1:]:
        np.testing.assert_array_equal(img, images[0])
    # an XML scene with several area lights loads in its declared order too
    xml = tmp_path / "lights.xml"
    lights = "".join(f'<shape type="rectangle" id="q{i}"><transform name="to_world"><translate x="{i}" y="3" z="0"/>'
                     f'</transform><emitter type="area"><rgb name="radiance" value="{1 + i}"/></emitter></shape>'
                     for i in range(5))
    xml.write_text(f'<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm"><integer name="width" '
                   f'value="8"/><integer name="height" value="8"/></film></sensor>{lights}</scene>')
    for _ in range(3):
        s = draaw_mi.load_scene(str(xml))
        assert [e.get_shape().id() for e in s.mi_scene.emitters()] == [f"q{i}" for i in range(5)]


def test_scenes_with_one_area_light_keep_merged_meshes():
    """Mesh merging (fewer shapes: cheaper frozen renders) stays on where the order of the
    shapes cannot change a render: at most one emitting shape."""
    s = draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"))
    declared = [v for v in s.mi_dict.values() if isinstance(v, dict) and "bsdf" in v]
    assert len(s.mi_scene.shapes()) < len(declared)          # the white walls merged into one


def test_a_texture_written_as_nested_arrays_is_the_numpy_texture(tiny_desc):
    """``roughness = [[0.1, 0.9], [0.5, 0.3]]`` in a scene file (TOML and JSON have no numpy)
    is the texture a numpy array gives in a Python description (it was refused: "not a list of
    3 numbers"); rows of RGB triples are a colour texture."""
    rough = [[0.1, 0.9], [0.5, 0.3]]
    color = [[[0.9, 0.2, 0.1], [0.1, 0.8, 0.2]], [[0.2, 0.2, 0.9], [0.7, 0.7, 0.7]]]
    a, b = copy.deepcopy(tiny_desc), copy.deepcopy(tiny_desc)
    a["materials"]["ball"].update(roughness=rough, base_color=color)
    b["materials"]["ball"].update(roughness=np.array(rough), base_color=np.array(color))
    sa, sb = draaw_mi.load_scene(a), draaw_mi.load_scene(b)
    for k in ("ball.roughness.data", "ball.base_color.data"):
        np.testing.assert_array_equal(np.array(sa.params[k]), np.array(sb.params[k]))
    np.testing.assert_array_equal(np.array(draaw_mi.render(sa, spp=2, seed=1)), np.array(draaw_mi.render(sb, spp=2, seed=1)))


def test_materials_that_start_alike_stay_apart():
    """Two materials with the same values (a scene about to be tuned): Mitsuba's scene
    optimisation made them one BSDF, and the second one's keys were gone. Each keeps its keys,
    and changing one changes only its own object: the image equals a scene built that way."""
    def desc(color_b):
        return {"render": {"resolution": [24, 16], "spp": 4, "filter": "box", "max_depth": 3},
                "camera": {"origin": [0, 0.5, 5], "target": [0, 0.5, 0]},
                "materials": {"a": {"base_color": [0.5, 0.5, 0.5]}, "b": {"base_color": color_b}},
                "shapes": [{"type": "sphere", "material": "a", "center": [-1.1, 0.5, 0]},
                           {"type": "sphere", "material": "b", "center": [1.1, 0.5, 0]}],
                "lights": [{"type": "point", "position": [0, 3, 3], "intensity": 30}]}
    s = draaw_mi.load_scene(desc([0.5, 0.5, 0.5]))
    assert {s.key("a.base_color"), s.key("b.base_color")} == {"a.base_color.value", "b.base_color.value"}
    s.params[s.key("b.base_color")] = mi.Color3f(0.9, 0.1, 0.1)
    s.params.update()
    img = np.array(draaw_mi.render(s, version="path", seed=3, post=[]))
    ref = np.array(draaw_mi.render(draaw_mi.load_scene(desc([0.9, 0.1, 0.1])), version="path", seed=3, post=[]))
    np.testing.assert_allclose(img, ref, atol=1e-6)
    assert np.abs(img[:, 12:, 0] - img[:, 12:, 1]).max() > 0.1          # the right sphere is red


def test_equal_materials_of_a_mitsuba_xml_file_stay_apart(tmp_path):
    """The same for a Mitsuba XML scene: two equal ``<bsdf>`` elements, each referred to by
    a shape, keep their own keys (the file is parsed again without the optimisation)."""
    xml = tmp_path / "s.xml"
    xml.write_text("""<scene version="3.0.0">
      <bsdf type="diffuse" id="a"><rgb name="reflectance" value="0.5"/></bsdf>
      <bsdf type="diffuse" id="b"><rgb name="reflectance" value="0.5"/></bsdf>
      <shape type="sphere"><ref id="a"/></shape>
      <shape type="sphere"><point name="center" x="0" y="0" z="-5"/><ref id="b"/></shape>
      <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>
      <integer name="height" value="8"/></film></sensor></scene>""")
    keys = draaw_mi.load_scene(str(xml)).params.keys()
    assert "a.reflectance.value" in keys and "b.reflectance.value" in keys


def test_a_parameter_name_without_its_material_lists_the_materials_that_have_it():
    """``--param roughness`` listed every Mitsuba key of the scene (sensor.film.crop_offset,
    ...) or suggested an arbitrary one of 16 materials."""
    import draaw_mi
    from draaw_mi.errors import SceneError
    scene = draaw_mi.load_scene(os.path.join(SCENES, "material_spheres.toml"))
    with pytest.raises(SceneError, match=r"no parameter 'roughness'; name the material too: "
                                         r"'ground.roughness', 'r0m0.roughness', .*, \.\.\.$"):
        scene.key("roughness")
    with pytest.raises(SceneError, match=r"did you mean 'r0m0.metallic'\?$"):   # no .value
        scene.key("r0m0.metalic")
    with pytest.raises(SceneError, match=r"`draaw-mi info` lists the scene's materials$"):
        scene.key("zzz")
    # a material's setting, documented beside its parameters, was "missing; did you mean ..."
    with pytest.raises(SceneError, match=r"no parameter 'r0m0.two_sided': two_sided is a setting of "
                                         r"material 'r0m0', read when the scene loads, not a parameter"):
        scene.key("r0m0.two_sided")


def test_a_scene_shows_in_one_line_and_checks_what_it_is_given():
    """A notebook cell showing a scene printed 200 lines (the Mitsuba scene and the
    description); ``with_resolution(0, 32)`` made a scene that failed in its render,
    ``(32.7, 32)`` was cut to 32; ``load_scene(version="v9")`` loaded, the first render refused
    it; a parameter name that is not a string failed with "can only concatenate str"."""
    import numpy as np
    scene = draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"), resolution=np.array([16, 12]))
    assert repr(scene) == ("DraawScene('" + os.path.join(SCENES, "cornell.toml") + "', 16x12, version 'v4', "
                           "spp 64, 6 shapes, 1 emitters, materials white, red, green, metal, plastic)")
    for size, says in (((0, 32), r"resolution.width: 0 is out of range; expected a value in \[1, 16384\]"),
                       ((32.7, 32), r"resolution.width: 32.7 is not an integer"),
                       (("32", 32), r"resolution.width: '32' is not a number")):
        with pytest.raises(draaw_mi.SceneError, match=r"with_resolution: " + says):
            scene.with_resolution(*size)
    assert scene.with_resolution(np.int64(8), 8).resolution == (8, 8)
    with pytest.raises(draaw_mi.SceneError, match=r"override.version: render version 'v9' is unknown"):
        draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"), version="v9")
    with pytest.raises(draaw_mi.ParameterError, match=r"parameter name 123; expected a string"):
        scene.key(123)


def test_a_bare_objs_material_warnings_are_said_once_at_the_callers_line(tmp_path):
    """A mesh file loaded alone is read twice (its bounds place the camera): each MTL warning
    came twice, pointing into the loader."""
    import warnings
    (tmp_path / "b.obj").write_text("usemtl foo\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        draaw_mi.load_scene(str(tmp_path / "b.obj"), resolution=(8, 8))
    ours = [w for w in said if "usemtl 'foo'" in str(w.message)]
    assert len(ours) == 1 and ours[0].filename == __file__, [(w.filename, str(w.message)) for w in said]
