"""[[sdf]] scene entries, GO-Draaw sphere lists, bad input and `draaw-mi info`."""
from __future__ import annotations

import copy
import json

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.cli import main
from draaw_mi.errors import SceneError
from draaw_mi.scene.go_draaw_spheres import go_draaw_spheres

from sdf_helpers import base_description


def _desc(sdf):
    d = base_description()
    d["sdf"] = sdf
    return d


CSG = [
    {"type": "sphere", "name": "ball", "center": [0, 0.6, 0], "radius": 0.6, "material": "ball"},
    {"type": "box", "name": "block", "center": [0.5, 0.4, 0], "size": [0.6, 0.8, 0.6],
     "material": {"base_color": [0.1, 0.8, 0.1]}},
    {"type": "smooth_union", "name": "blob", "children": ["ball", "block"], "k": 0.25},
    {"type": "torus", "name": "ring", "center": [0, 0, 0], "major": 0.4, "minor": 0.1,
     "translate": [-1.2, 0.1, 0], "rotate": {"axis": [1, 0, 0], "angle": 90}, "scale": 1.5},
]


def test_load_scene_dict_with_sdf_tree():
    s = draaw_mi.load_scene(_desc(CSG))
    assert s.sdf is not None and s.features()["sdf"]
    assert [r.name for r in s.sdf.roots] == ["blob", "ring_xf"]
    assert len(s.sdf.slots) == 3                     # ball, inline block material, default
    keys = s.sdf.params()
    assert {"ball.radius", "block.size", "blob.k", "ring_xf.translate"} <= set(keys)
    # the proxies carry the materials; their parameters are in mi.traverse as usual
    assert "ball.base_color.value" in s.params
    assert not any(k.startswith("__sdf_") for k in s.summary()["shapes"])
    # distance of the scene = union of the roots
    p = mi.Point3f(-0.6, 0.1, 0.0)       # on the centre line of the scaled torus, turned into xy
    assert abs(float(s.sdf.distance(p)[0]) - (0.0 - 0.15)) < 1e-5


def test_a_round_box_of_radius_0_is_the_box():
    """RoundBox allows radius 0 (a sharp box); the scene file refused it ("expected > 0")."""
    box = {"type": "box", "name": "b", "center": [0, 0.4, 0], "size": [0.6, 0.8, 1.0]}
    rb = dict(box, type="round_box", radius=0.0)
    pts = mi.Point3f([0.0, 0.5, 0.2, -1.0], [0.4, 1.1, 0.0, 0.3], [0.0, 0.3, 0.9, 0.0])
    sharp = draaw_mi.load_scene(_desc([box])).sdf.distance(pts)
    round0 = draaw_mi.load_scene(_desc([rb])).sdf.distance(pts)
    np.testing.assert_allclose(np.array(round0), np.array(sharp), atol=1e-6)
    with pytest.raises(SceneError, match="radius"):
        draaw_mi.load_scene(_desc([dict(rb, radius=-0.1)]))


def test_sphere_moves_from_shapes_to_sdf_by_renaming():
    entry = {"type": "sphere", "name": "b", "material": "ball", "center": [0, 0.5, 0], "radius": 0.5,
             "translate": [0.2, 0, 0]}
    d = base_description()
    d["shapes"].append(copy.deepcopy(entry))
    draaw_mi.load_scene(d)
    s = draaw_mi.load_scene(_desc([entry]))
    assert abs(float(s.sdf.distance(mi.Point3f(0.2, 0.5, 0))[0]) + 0.5) < 1e-6


@pytest.mark.parametrize("sdf,match", [
    ([{"type": "sphere", "radius": -1}], r"sdf\[0\]\.radius: -1 is out of range"),
    ([{"type": "box", "size": [1, 0, 1]}], r"size"),
    ([{"type": "spher", "radius": 1}], r"did you mean 'sphere'"),
    ([{"type": "smooth_unoin", "children": ["a", "b"]}], r"did you mean 'smooth_union'"),
    ([{"type": "sphere", "name": "a"}, {"type": "union", "children": ["a", "bb"]}],
     r"no SDF named 'bb'"),
    ([{"type": "union", "name": "u", "children": ["v", "s"]}, {"type": "union", "name": "v",
      "children": ["u", "s"]}, {"type": "sphere", "name": "s"}], r"cycle: u -> v -> u"),
    ([{"type": "sphere", "material": "nope"}], r"unknown material 'nope'"),
    ([{"type": "sphere", "radus": 1}], r"did you mean 'radius'"),
    ([{"type": "union", "children": ["x"]}], r"two or more"),
    ([{"type": "sphere", "scale": [1, 2, 1]}], r"uniform"),
    # names are keys (sdf.NAME.PARAM): a dot or nothing cannot be addressed, and a name the
    # loader gives to a transform or an inner operator node would hide that node
    ([{"type": "sphere", "name": "my.ball"}], r"sdf\[0\]\.name: 'my\.ball'; expected letters, digits"),
    ([{"type": "sphere", "name": ""}], r"sdf\[0\]\.name: ''; expected letters"),
    ([{"type": "sphere", "name": "ball", "translate": [1, 0, 0]}, {"type": "sphere", "name": "ball_xf"}],
     r"two SDF nodes are named 'ball_xf'"),
    ([{"type": "sphere", "name": "a"}, {"type": "sphere", "name": "b"}, {"type": "sphere", "name": "c"},
      {"type": "union", "name": "u", "children": ["a", "b", "c"]}, {"type": "sphere", "name": "u_0"}],
     r"two SDF nodes are named 'u_0'"),
])
def test_bad_input_one_line(sdf, match):
    with pytest.raises(SceneError, match=match) as e:
        draaw_mi.load_scene(_desc(sdf))
    assert "\n" not in str(e.value)


def test_cli_bad_sdf_exits_2(tmp_path, capsys):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(_desc([{"type": "sphere", "radius": -2}])))
    assert main(["info", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("draaw-mi: error:") and "radius" in err[0]


def test_cli_info_lists_sdf_nodes(tmp_path, capsys):
    p = tmp_path / "ok.json"
    p.write_text(json.dumps(_desc(CSG)))
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "sdf: 5 nodes" in out and "blob: smooth_union(k=0.25)" in out and "ball: sphere" in out


GO_SPHERES = [
    {"centerX": 0, "centerY": 0, "centerZ": 0, "radius": 16, "colorR": 255, "colorG": 0, "colorB": 0,
     "colorA": 255, "indexOfOtherSphere": 1, "sdfType": 2, "amount": 8},
    {"centerX": 20, "centerY": 0, "centerZ": 0, "radius": 16, "colorR": 0, "colorG": 0, "colorB": 255,
     "colorA": 255, "indexOfOtherSphere": 0, "sdfType": 0, "amount": 0},
    {"centerX": 0, "centerY": 40, "centerZ": 0, "radius": 10, "colorR": 0, "colorG": 255, "colorB": 0,
     "colorA": 255, "indexOfOtherSphere": 3, "sdfType": 5, "amount": 0},
    {"centerX": 5, "centerY": 40, "centerZ": 0, "radius": 8, "colorR": 9, "colorG": 9, "colorB": 9,
     "colorA": 255, "indexOfOtherSphere": 7, "sdfType": 1, "amount": 0},      # index out of range
]


def _d(node, p):
    return float(node.distance(mi.Point3f(*p))[0])


def test_go_draaw_sphere_list_semantics():
    with pytest.warns(RuntimeWarning, match=r"\[3\]: indexOfOtherSphere 7 names no sphere.*0\.\.3"):
        root = go_draaw_spheres(GO_SPHERES)
    d = lambda c, r, p: float(np.linalg.norm(np.subtract(p, c)) - r)   # noqa: E731
    k = 8.0
    for p in ([10, 0, 0], [0, 17, 0], [30, 5, 0], [0, 40, 0], [3, 40, 0], [-9, 40, 0]):
        d0, d1 = d([0, 0, 0], 16, p), d([20, 0, 0], 16, p)
        h = max(k - abs(d0 - d1), 0) / k                    # go-draaw-spec.md §5.2: cubic
        su = min(d0, d1) - h ** 3 * k / 6                   # sphere 0 smooth-unioned with 1
        sub = max(d([5, 40, 0], 8, p), -d([0, 40, 0], 10, p))   # type 5: other (3) minus this (2)
        ref = min(su, d1, sub)                              # sphere 3's union: skipped (bad index)
        assert _d(root, p) == pytest.approx(ref, abs=1e-4)


def test_go_draaw_smooth_union_leaves_a_gap_open_as_go_draaw_does():
    # two spheres 3 apart with amount 8: GO-Draaw's cubic blend lowers the gap's middle by
    # h^3 k / 6 = 1/6 and leaves it open (+1/6); the polynomial one bridged it (-0.5)
    recs = [{"centerX": -17.5, "radius": 16, "indexOfOtherSphere": 1, "sdfType": 2, "amount": 8},
            {"centerX": 17.5, "radius": 16, "indexOfOtherSphere": 0, "sdfType": 0}]
    assert _d(go_draaw_spheres(recs), [0, 0, 0]) == pytest.approx(1.5 - 8 / 6, abs=1e-5)


@pytest.mark.parametrize("scale", [1.0, 1 / 75, 10.0])
def test_a_scaled_sphere_list_is_go_draaws_shape_scaled(scale):
    """Every operator at ``scale`` gives GO-Draaw's distance (in its units) times ``scale``:
    the "addition" (sdfType 7, ``ln(e^a + e^b)``) kept a temperature of 1 world unit, so a
    list scaled by 1/75 read +0.587 at the lens's centre where -0.097 was due, and rendered
    nothing."""
    d = lambda c, r, p: float(np.linalg.norm(np.subtract(p, c)) - r)   # noqa: E731
    for t in (7, 8, 2):
        # each sphere combined with the other, so that every part of the shape is an operator's
        recs = [{"centerX": -6, "radius": 16, "indexOfOtherSphere": 1, "sdfType": t, "amount": 1},
                {"centerX": 6, "radius": 16, "indexOfOtherSphere": 0, "sdfType": t, "amount": 1}]
        root = go_draaw_spheres(recs, scale=scale)
        for p in ([0, 0, 0], [0, 12, 0], [0, 13.5, 0], [-25, 0, 0]):
            a, b = d([-6, 0, 0], 16, p), d([6, 0, 0], 16, p)
            if t == 2:                                       # go-draaw-spec.md §5.2: cubic
                h = max(1 - abs(a - b), 0)
                go = min(a, b) - h ** 3 / 6
            else:                                            # ln(e^a + e^b) (amount 1)
                go = np.logaddexp(a, b)
            assert _d(root, [float(x) * scale for x in p]) == pytest.approx(go * scale, rel=1e-4, abs=1e-6), (t, p)


def test_go_draaw_entry_in_scene_blends_colours():
    s = draaw_mi.load_scene(_desc([{"type": "go_draaw_spheres", "spheres": GO_SPHERES[:2], "scale": 0.02}]))
    assert len(s.sdf.slots) == 2
    # in the smooth-union neck both materials carry weight
    _, w = s.sdf.eval(mi.Point3f(0.2, 0.0, 0.0))
    w = [float(x[0]) for x in w]
    assert 0.05 < w[0] < 0.95 and abs(sum(w) - 1) < 1e-6


def test_go_draaw_sphere_file_is_found_beside_the_scene_file(tmp_path, monkeypatch):
    """A ``file =`` of a ``go_draaw_spheres`` entry is relative to the scene file, as every
    other file a scene names (it was opened from the working folder), and it is among the
    scene's files (batch jobs hash them); two lists in one scene get their own node names."""
    import tomli_w
    folder = tmp_path / "scenes"
    folder.mkdir()
    (folder / "spheres.json").write_text(json.dumps(GO_SPHERES[:2]))
    d = _desc([{"type": "go_draaw_spheres", "file": "spheres.json", "scale": 0.02},
               {"type": "go_draaw_spheres", "spheres": [dict(GO_SPHERES[0], sdfType=0)], "scale": 0.01}])
    with open(folder / "s.toml", "wb") as fh:
        tomli_w.dump(d, fh)
    monkeypatch.chdir(tmp_path)                         # elsewhere than the scene's folder
    s = draaw_mi.load_scene(str(folder / "s.toml"))
    assert str(folder / "spheres.json") in s.info["files"]
    names = [n for n in s.sdf.params()]
    assert "go_sphere0.radius" in names and "go2_sphere0.radius" in names
    assert len(s.sdf.roots) == 2


def test_a_misspelt_key_of_a_go_draaw_sphere_record_is_refused():
    """``centreX`` was taken without a word, the sphere left at the origin."""
    bad = [{k.replace("centerX", "centreX"): v for k, v in GO_SPHERES[1].items()}]
    with pytest.raises(SceneError, match=r"\[0\]\.centreX.*unknown key.*did you mean 'centerX'"):
        go_draaw_spheres(bad)


def test_go_draaw_bad_operator():
    bad = [dict(GO_SPHERES[0], sdfType="smoothUnoin")]
    with pytest.raises(SceneError, match="did you mean 'smoothUnion'"):
        go_draaw_spheres(bad)


def test_a_list_of_rotations_turns_meshes_and_sdf_objects_alike():
    """rotate = [x 90, y 90] applies its first rotation first, for a mesh's to_world and for an
    SDF object's transform: (0, 0, 1) -> x 90 -> (0, -1, 0) -> y 90 -> (0, -1, 0). Applied in
    the other order it would land on (1, 0, 0)."""
    import numpy as np
    from draaw_mi.scene.description import to_world
    from draaw_mi.scene.schema import Where
    from draaw_mi.scene.sdf_dicts import _transform_of
    from draaw_mi.sdf.primitives import Sphere
    table = {"rotate": [{"axis": [1, 0, 0], "angle": 90}, {"axis": [0, 1, 0], "angle": 90}]}
    m = np.array(to_world(table, Where("t")).matrix, dtype=float).reshape(4, 4)
    assert np.allclose(m[:3, :3] @ [0, 0, 1], [0, -1, 0], atol=1e-6)
    node = _transform_of(table, Where("t"), Sphere(radius=0.5))
    assert np.allclose(node.rotation @ [0, 0, 1], [0, -1, 0], atol=1e-6)


def _bare(kind, entries):
    """No [camera], no floor: only ``entries`` as [[shapes]] or [[sdf]], under a sky."""
    return {"render": {"resolution": [32, 32], "spp": 1, "max_depth": 2, "filter": "box"},
            "materials": {"m": {"base_color": [0.8, 0.3, 0.2]}},
            "lights": [{"type": "constant", "intensity": 1.0}],
            kind: [dict(e, material="m") for e in entries]}


def test_the_automatic_camera_frames_sdf_objects_as_it_frames_shapes():
    """The automatic camera saw the SDF objects only through their proxy (a point at the
    centre of their boxes): it looked at the right place from too close, and two objects 8
    apart both left the picture. Their boxes count now; a Mitsuba sphere with the same centre
    and radius (the same box) is the reference."""
    one = [{"type": "sphere", "name": "obj", "center": [5.0, 0.0, 0.0], "radius": 1.0}]
    cam = draaw_mi.load_scene(_bare("sdf", one)).info["camera"]
    ref = draaw_mi.load_scene(_bare("shapes", one)).info["camera"]
    assert np.allclose(cam["target"], [5.0, 0.0, 0.0]) and np.allclose(cam["target"], ref["target"])
    assert np.allclose(cam["origin"], ref["origin"], atol=1e-5), (cam, ref)
    two = [{"type": "sphere", "name": "a", "center": [4.0, 0.0, 0.0], "radius": 1.5},
           {"type": "sphere", "name": "b", "center": [-4.0, 0.0, 0.0], "radius": 1.5}]
    s = draaw_mi.load_scene(_bare("sdf", two))
    ref2 = draaw_mi.load_scene(_bare("shapes", two)).info["camera"]
    assert np.allclose(s.info["camera"]["origin"], ref2["origin"], atol=1e-5)
    img = np.array(draaw_mi.render(s, version="v2", spp=1, seed=0, post=[]))[..., :3]
    sky = np.all(np.abs(img - 1.0) < 1e-3, axis=2)       # a constant sky of 1 seen directly
    assert sky.mean() > 0.3                               # framed, not filling the picture
    assert (~sky[:, :16]).sum() >= 10 and (~sky[:, 16:]).sum() >= 10, sky.astype(int)


def test_the_automatic_camera_skips_the_sdf_proxy_and_an_unbounded_plane():
    """The SDF objects' proxy shape is placeholder geometry (at the origin when the only SDF
    root is an unbounded plane): counted in the bounds, it stretched the box of a sphere at
    (10, 10, 10) back to the origin and the camera framed mostly empty space. Only the
    sphere's box [9.5, 10.5]^3 counts; the camera is worked out by hand from auto_camera's
    rule (40 degree fov, 1.05 margin, along (0.45, 0.35, 1))."""
    desc = {"render": {"resolution": [8, 8], "spp": 1},
            "shapes": [{"type": "sphere", "center": [10, 10, 10], "radius": 0.5}],
            "sdf": [{"type": "plane", "name": "ground", "normal": [0, 1, 0], "offset": 0.0}],
            "lights": [{"type": "constant"}]}
    cam = draaw_mi.load_scene(desc).info["camera"]
    radius = 0.5 * np.sqrt(3.0)                            # half the box's diagonal
    dist = radius / np.sin(np.radians(20.0)) * 1.05
    direction = np.array([0.45, 0.35, 1.0]) / np.linalg.norm([0.45, 0.35, 1.0])
    np.testing.assert_allclose(cam["target"], [10.0, 10.0, 10.0], atol=1e-4)
    np.testing.assert_allclose(cam["origin"], 10.0 + dist * direction, atol=1e-4)   # (11.04, 10.81, 12.31)


def test_cli_info_shows_the_fixed_shape_values(tmp_path, capsys):
    """A cone's angle, a plane's (unit) normal and a transform's rotation are Python constants,
    not parameters: ``info`` listed neither. The rotation is read back as an angle about an
    axis and checked against the scene's own ``rotate`` (scipy builds the reference)."""
    import re
    from scipy.spatial.transform import Rotation
    sdf = [{"type": "cone", "name": "tip", "center": [0, 0, 0], "angle": 25, "height": 0.5},
           {"type": "plane", "name": "ground", "normal": [0, 2, 0], "offset": -0.1},
           {"type": "box", "name": "tilted", "size": [0.3, 0.3, 0.3], "translate": [1, 0, 0],
            "rotate": {"axis": [1, 2, -2], "angle": 40}}]
    p = tmp_path / "shapes.json"
    p.write_text(json.dumps(_desc(sdf)))
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"tip: cone\(.*angle=25\b", out), out
    assert "ground: plane(offset=-0.1, normal=(0, 1, 0))" in out, out
    m = re.search(r"rotate=([-\d.e]+) deg about \(([^)]*)\)", out)
    assert m, out
    got = Rotation.from_rotvec(np.radians(float(m.group(1))) * np.array([float(v) for v in m.group(2).split(",")]))
    want = Rotation.from_rotvec(np.radians(40) * np.array([1, 2, -2]) / 3.0)
    assert np.allclose(got.as_matrix(), want.as_matrix(), atol=1e-3), (m.group(0), out)


_TEX = [[[0.9, 0.1, 0.1], [0.1, 0.1, 0.9]], [[0.1, 0.1, 0.9], [0.9, 0.1, 0.1]]]


@pytest.mark.parametrize("table, named", [
    ({"base_color": _TEX}, "base_color"),
    ({"roughness": [[0.2, 0.8], [0.8, 0.2]]}, "roughness"),
    ({"normalmap": [[[0.6, 0.5, 0.9], [0.4, 0.5, 0.9]]] * 2}, "normalmap"),
    ({"type": "diffuse", "reflectance": _TEX}, "reflectance"),
])
def test_a_textured_material_on_an_sdf_object_is_refused(table, named):
    """An SDF surface has no uv (its interactions have uv (0, 0)): a textured material
    rendered one colour there, its corner texels', and info said textures were on."""
    d = _desc([{"type": "sphere", "name": "orb", "center": [0, 0.6, 0], "radius": 0.6, "material": "tex"}])
    d["materials"]["tex"] = table
    with pytest.raises(SceneError, match=rf"\[\[sdf\]\] object 'orb' uses material 'tex', whose {named} .*no uv"):
        draaw_mi.load_scene(d)
    # the same material on a mesh loads; plain values on the SDF object load
    d["shapes"].append({"type": "sphere", "name": "mesh_ball", "material": "tex", "center": [2, 0.5, 0],
                        "radius": 0.5})
    d["sdf"][0]["material"] = "ball"
    assert draaw_mi.load_scene(d).features()["sdf"]


def test_a_material_only_an_sdf_object_uses_is_in_the_scene():
    """Materials no shape uses are left out of the Mitsuba scene; an SDF object's are used."""
    s = draaw_mi.load_scene(_desc(CSG))
    assert "ball" in s.info["materials"] and "ball" not in s.info["unused_materials"]
    assert "ball.base_color.value" in s.params.keys()


@pytest.mark.parametrize("table,key", [
    ({"type": "plane", "normal": 1, "offset": 0}, "normal"), ({"type": "capsule", "a": 0, "b": [0, 1, 0]}, "a"),
    ({"type": "capsule", "b": 1}, "b"), ({"type": "sphere", "center": 2}, "center"),
    ({"type": "sphere", "translate": 1}, "translate")])
def test_one_number_for_a_point_normal_or_translation_is_refused(table, key):
    """``center = 2`` was broadcast to (2, 2, 2) (as for a colour) where the Python API says
    "expected 3 numbers"; a ``size`` of one number is a cube."""
    with pytest.raises(SceneError, match=rf"sdf\[0\]\.{key}: \d is one number; expected a list of 3 numbers"):
        draaw_mi.load_scene(_desc([table]))
    sc = draaw_mi.load_scene(_desc([{"type": "box", "name": "cube", "size": 0.5}]))
    assert [float(c[0]) for c in sc.sdf.nodes["cube"].size] == [0.5, 0.5, 0.5]


def test_a_subnormal_scale_is_refused_and_a_table_without_k_has_the_python_default():
    """``scale = 1e-39`` loaded and gave NaN distances (1 / scale is inf in float32)."""
    with pytest.raises(SceneError, match=r"sdf\[0\]\.scale: 1e-39 is below the smallest normal float32"):
        draaw_mi.load_scene(_desc([{"type": "sphere", "scale": 1e-39}]))
    from draaw_mi.sdf import Sphere, smooth_lse_intersection
    sc = draaw_mi.load_scene(_desc([{"type": "sphere", "name": "a"}, {"type": "sphere", "name": "b"},
                                    {"type": "smooth_lse_intersection", "name": "s", "children": ["a", "b"]}]))
    assert float(sc.sdf.nodes["s"].k[0]) == float(smooth_lse_intersection(Sphere(), Sphere()).k[0])
