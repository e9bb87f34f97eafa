"""Scene loading, from a review: a mesh without material is GO-Draaw grey (not trimesh's
stand-in texture); a Mitsuba BSDF's own strings pass through; empty texture arrays, negative
reflectances and area lights without an up are refused by name; an XML integrator's
hide_emitters holds; numpy numbers are numbers."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import SceneError

BASE = {"render": {"resolution": [8, 8], "spp": 4}, "camera": {"origin": [0, 0, 4]},
        "shapes": [{"type": "sphere", "material": "m"}], "lights": [{"type": "constant"}]}


def test_a_mesh_with_uvs_and_no_material_is_go_draaw_grey(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    scene = draaw_mi.load_scene(str(obj), resolution=(8, 8))
    keys = [k for k in scene.params.keys() if "base_color" in k]
    assert keys and all(k.endswith(".value") for k in keys), keys        # (a 2x2 '.data' texture)
    np.testing.assert_allclose(np.array(scene.params[keys[0]]).ravel(), 178 / 255, rtol=1e-6)   # (0.127)


def test_a_mitsuba_bsdfs_own_strings_pass_through():
    """Strings other than the plugins' defaults, read back from the loaded BSDFs (they were
    taken for texture files: "no texture file 'Au'")."""
    import mitsuba as mi

    def bsdf(table):
        return draaw_mi.load_scene(dict(BASE, materials={"m": table})).mi_scene.shapes()[0].bsdf()
    gold = mi.traverse(bsdf({"type": "conductor", "material": "Au"}))
    own = mi.traverse(mi.load_dict({"type": "conductor", "material": "Au"}))
    np.testing.assert_allclose(np.array(gold["eta.value"]), np.array(own["eta.value"]))
    assert float(mi.traverse(bsdf({"type": "dielectric", "int_ior": "water"}))["eta"]) ==\
        pytest.approx(1.333 / 1.000277, rel=1e-4)
    assert "distribution = ggx" in str(bsdf({"type": "roughconductor", "distribution": "ggx", "alpha": 0.2}))


@pytest.mark.parametrize("table,match", [
    ({"type": "diffuse", "reflectance": [[]]}, r"materials\.m\.reflectance.*shape \(1, 0\)"),   # (SIGABRT)
    ({"type": "diffuse", "reflectance": -0.5}, r"materials\.m\.reflectance: -0\.5 is out of range"),
    ({"type": "diffuse", "reflectance": [0.5, -0.1, 0.5]}, r"materials\.m\.reflectance"),
    # a transmittance is >= 0 too (a dielectric's -0.5 was let through)
    pytest.param({"type": "dielectric", "specular_transmittance": -0.5},
                 r"materials\.m\.specular_transmittance: -0\.5 is out of range; expected >= 0",
                 id="negative-transmittance"),
])
def test_bad_values_of_a_mitsuba_bsdf_are_refused(table, match):
    with pytest.raises(SceneError, match=match):
        draaw_mi.load_scene(dict(BASE, materials={"m": table}))


@pytest.mark.parametrize("up", [[0, 0, 1], [0, 0, 0]])
def test_an_area_light_needs_an_up_across_its_facing(up):
    desc = dict(BASE, materials={"m": {"type": "diffuse"}},
                lights=[{"type": "area", "position": [0, 0, 2], "target": [0, 0, 0], "up": up}])
    with pytest.raises(SceneError, match=r"lights\[0\]\.up"):          # (a NaN transform: black)
        draaw_mi.load_scene(desc)


def test_an_xml_integrators_hide_emitters_holds(tmp_path):
    xml = tmp_path / "s.xml"
    xml.write_text("""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="4"/><boolean name="hide_emitters" value="true"/></integrator>
  <sensor type="perspective"><float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film>
  </sensor>
  <shape type="sphere"><float name="radius" value="0.5"/><bsdf type="diffuse"/></shape>
  <emitter type="constant"/>
</scene>""")
    scene = draaw_mi.load_scene(str(xml))
    assert scene.settings["hide_emitters"] is True
    img = np.array(draaw_mi.render(scene, spp=4))
    assert img[0, 0].max() == 0.0                                   # the sky it hides (was 1.0)


def test_numpy_numbers_are_numbers():
    scene = draaw_mi.load_scene("scenes/cornell.toml", resolution=(np.int64(8), np.int64(8)), spp=np.int64(4))
    img = draaw_mi.render(scene, spp=np.int64(4), seed=np.uint32(3), max_depth=np.int32(3))
    assert scene.resolution == (8, 8) and np.array(img).shape == (8, 8, 3)
    a = np.array(draaw_mi.render(scene, spp=4, seed=3, max_depth=3))
    assert np.array_equal(np.array(img), a)


def test_a_base_colour_above_one_is_said_at_load():
    """GO-Draaw's 0-255 colours copied into a scene file (base_color = [178, 178, 178]) were
    taken without a word and rendered a sphere 179 times as bright as the sky lighting it."""
    import warnings
    d = {"render": {"resolution": [8, 8], "spp": 1}, "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
         "materials": {"m": {"base_color": [178, 178, 178]}},
         "shapes": [{"type": "sphere", "material": "m"}], "lights": [{"type": "constant", "intensity": 1.0}]}
    with pytest.warns(RuntimeWarning, match=r"materials\.m\.base_color: \[178, 178, 178\] reflects more light "
                                            r"than arrives.*divided by 255"):
        draaw_mi.load_scene(d)
    d["materials"]["m"]["base_color"] = [1.0, 0.7, 0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        draaw_mi.load_scene(d)


def test_a_texture_three_texels_high_and_a_grid_three_deep_load_quietly(capfd):
    """Mitsuba's dict parser tried a tensor of length 3 as a vector and colours first, and
    nanobind printed "implicit conversion from type 'TensorXf' ... failed!" three times for
    each (a 3 x 4 roughness map, a 3 x 3 x 3 smoke grid): they load quietly, with the values
    given, and the map's gradient reaches its texels."""
    import drjit as dr
    from conftest import tiny_description
    rough = np.random.default_rng(3).uniform(0.2, 0.8, (3, 4)).astype(np.float32)
    d = tiny_description(resolution=[12, 8])
    d["materials"]["ball"]["roughness"] = rough
    d["volumes"] = [{"name": "smk", "mode": "smoke", "density": (np.arange(27.0).reshape(3, 3, 3) / 27).tolist(),
                     "bounds": [[-2.5, -1, -2.5], [-1.5, 0, -1.5]]}]
    capfd.readouterr()
    scene = draaw_mi.load_scene(d)
    assert "nanobind" not in capfd.readouterr().err
    key = scene.key("ball.roughness")
    assert np.array_equal(np.array(scene.params[key])[..., 0], rough)
    def given(node):                      # the grid tensors the loader gave Mitsuba
        if isinstance(node, dict):
            if node.get("type") == "gridvolume":
                yield node["data"]
            for v in node.values():
                yield from given(v)
    loaded = sorted(k for k in scene.params.keys() if k.startswith("smk.") and k.endswith(".data"))
    assert loaded == ["smk.interior_medium.albedo.data", "smk.interior_medium.sigma_t.data"]
    sigma_t = [np.array(t) for t in given(scene.mi_dict) if np.array(t).shape == (3, 3, 3, 1)]
    assert len(sigma_t) == 1 and np.array_equal(np.array(scene.params[loaded[1]]), sigma_t[0])
    assert sorted(sigma_t[0].ravel() * 27) == pytest.approx(np.arange(27.0), abs=1e-4)
    # what the plugins' data path refuses (4 channels), or a tensor tracking gradients, stays a
    # tensor: Mitsuba says its own error, and the gradients are kept (not copied away)
    import mitsuba as mi
    from draaw_mi.scene.mitsuba_load import _tensors_shared
    rgba = mi.TensorXf(np.ones((3, 4, 4), np.float32))
    assert "data" in _tensors_shared({"type": "bitmap", "data": rgba})
    tracked = mi.TensorXf(np.ones((3, 4, 3), np.float32))
    dr.enable_grad(tracked)
    assert "data" in _tensors_shared({"type": "bitmap", "data": tracked})
    assert "grid" in _tensors_shared({"type": "gridvolume", "data": mi.TensorXf(np.ones((3, 2, 2, 6), np.float32))})
    p = scene.params
    dr.enable_grad(p[key])
    p.update()
    img = draaw_mi.render(scene, version="v4", spp=2, params=p, post=[])
    dr.backward(dr.mean(img, axis=None))
    assert np.abs(np.array(dr.grad(p[key]))).sum() > 0


@pytest.mark.parametrize("change, match", [
    # a word or a short row in a matrix: a ValueError traceback (exit 1); a numeric string rendered
    ({"shapes": [{"type": "sphere", "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, "a"]]}]},
     r"shapes\[0\]\.matrix: .* is not a 4x4 list of finite numbers"),
    ({"shapes": [{"type": "sphere", "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1]]}]},
     r"shapes\[0\]\.matrix: .* is not a 4x4 list of finite numbers"),
    ({"shapes": [{"type": "sphere", "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, "1"]]}]},
     r"shapes\[0\]\.matrix: .* is not a 4x4 list of finite numbers"),
    ({"shapes": [{"type": "sphere", "matrix": [[True, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]},
     r"shapes\[0\]\.matrix: .* is not a 4x4 list of finite numbers"),
    # a misspelt AOV loaded and failed at the render, naming neither file nor key
    ({"render": {"aovs": ["albdo"]}}, r"render\.aovs: 'albdo' is not an AOV; did you mean 'albedo'\?"),
    # a colour for an emission never given: ignored without a word
    ({"shapes": [{"type": "sphere", "emission_color": [1, 0, 0]}]},
     r"shapes\[0\]\.emission_color: given without 'emission'"),
])
def test_what_a_scene_file_cannot_mean_is_said_at_load(change, match):
    with pytest.raises(SceneError, match=match):
        draaw_mi.load_scene(dict(BASE, **change))
    # the same keys given right load
    good = {"shapes": [{"type": "sphere", "emission": [1, 1, 1], "emission_color": [1, 0, 0],
                        "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}],
            "render": {"aovs": ["albedo", "all"][:1]}}
    draaw_mi.load_scene(dict(BASE, **good))


def test_a_misspelt_mitsuba_plugin_of_a_material_is_named_with_the_closest():
    """A TOML material of another Mitsuba BSDF goes to Mitsuba as is: a misspelt type said only
    '[PluginManager] Plugin "dielectirc" not found!', without a suggestion as draaw materials,
    lights and shapes get."""
    with pytest.raises(SceneError, match=r"'glass': no Mitsuba plugin of type 'dielectirc'; did you mean 'dielectric'\?$"):
        draaw_mi.load_scene(dict(BASE, materials={"glass": {"type": "dielectirc"}},
                                 shapes=[{"type": "sphere", "material": "glass"}]))
    with pytest.raises(SceneError, match=r"'glass': no Mitsuba plugin of type 'xyzzy'$"):
        draaw_mi.load_scene(dict(BASE, materials={"glass": {"type": "xyzzy"}},
                                 shapes=[{"type": "sphere", "material": "glass"}]))
