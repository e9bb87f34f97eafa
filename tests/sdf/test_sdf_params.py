"""SDF object parameters as scene parameters (``sdf.NODE.PARAM``): checks that leave nothing
changed, ranges for optimisers, the shared ``all_params`` table, writing values back."""
from __future__ import annotations

import copy

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from sdf_helpers import base_description

import draaw_mi
from draaw_mi.errors import ParameterError, SceneError
from draaw_mi.sdf import RoundBox, Sphere


def _scene(extra=None):
    d = base_description((16, 12))
    d["sdf"] = [{"type": "sphere", "name": "ball", "material": "ball", "center": [0.0, 0.8, 0.0],
                 "radius": 0.5},
                {"type": "round_box", "name": "block", "material": "blocker",
                 "center": [0.9, 0.3, 0.0], "size": [0.6, 0.6, 0.6], "radius": 0.1,
                 "translate": [0.0, 0.0, 0.2]},
                {"type": "smooth_union", "name": "blend", "children": ["ball", "block"], "k": 0.2}]
    d["sdf"] += extra or []
    return draaw_mi.load_scene(d), d


def test_a_refused_value_leaves_the_node_as_it_was():
    """A round box's radius above half its size passes the range check and fails the
    cross-check; the node kept the refused value after the error."""
    b = RoundBox(size=(1.0, 1.0, 1.0), radius=0.1)
    with pytest.raises(ParameterError, match=r"radius=0.8.*min\(size\)/2 = 0.5"):
        b.set_param("radius", 0.8)
    assert b.radius[0] == pytest.approx(0.1) and b.own_params()["radius"][0] == pytest.approx(0.1)
    b.check_param("radius", 0.3)                      # accepted, yet nothing changes
    assert b.radius[0] == pytest.approx(0.1)
    b.set_param("radius", 0.3)
    assert b.radius[0] == pytest.approx(0.3)


def test_a_literal_value_is_made_opaque_and_keeps_its_gradient():
    """``mi.Float(0.6)`` is a literal, which a kernel bakes in: every new value compiled anew."""
    s = Sphere(radius=1.0)
    s.set_param("radius", mi.Float(0.6))
    assert s.radius.state != dr.VarState.Literal
    x = mi.Float(0.5)
    dr.enable_grad(x)
    s.set_param("radius", 2.0 * x)
    dr.backward(s.radius * 3.0)
    assert dr.grad(x)[0] == pytest.approx(6.0)


def test_all_params_resolves_sdf_keys_and_shares_the_scene_table():
    sc, _ = _scene()
    assert sc.key("sdf.ball.radius") == "sdf.ball.radius"
    with pytest.raises(SceneError, match="did you mean 'sdf.ball.radius'"):
        sc.key("sdf.bal.radius")
    p = sc.all_params
    assert p is sc.all_params and p._base is sc.params       # one mi.traverse, not two
    p["ball.roughness.value"] = 0.7                            # a material through all_params
    p["sdf.ball.radius"] = 0.6
    p.update()
    assert sc.params["ball.roughness.value"][0] == pytest.approx(0.7)
    assert sc.sdf.nodes["ball"].radius[0] == pytest.approx(0.6)
    # a scene without SDF objects: all_params is params itself
    plain = draaw_mi.load_scene(base_description((16, 12)))
    assert plain.all_params is plain.params


@pytest.mark.parametrize("key, value, match", [
    ("sdf.ball.radius", -0.1, r"expected a number > 0"),
    ("sdf.block.radius", 0.5, r"min\(size\)/2 = 0.3"),
    ("sdf.blend.k", -1.0, r"k=-1.0; expected >= 0"),
    ("sdf.ball.center", [1.0, 2.0], r"expected 3 finite numbers"),
    ("sdf.ball.radius", float("nan"), r"finite"),
    # Dr.Jit arrays of the stored type: one value, finite (a wide one was taken as it was)
    ("sdf.ball.center", mi.Point3f([0.0, 1.0], [0.0, 0.0], [0.0, 0.0]), r"center is an array of width 2; expected one value"),
    ("sdf.ball.radius", mi.Float([0.3, 0.4]), r"radius is an array of width 2"),
    ("sdf.ball.center", mi.Point3f(0.0, float("nan"), 0.0), r"center=\[0.0, nan, 0.0\]; expected finite values"),
])
def test_check_value_refuses_without_changing_anything(key, value, match):
    sc, _ = _scene()
    before = {k: np.array(v).copy() for k, v in sc.sdf.params().items()}
    with pytest.raises(ParameterError, match=match) as e:
        sc.check_value("demo", key, key, value)
    assert str(e.value).startswith(f"demo: {key}: ")
    after = sc.sdf.params()
    assert all(np.array_equal(before[k], np.array(after[k])) for k in before)
    sc.check_value("demo", key, key, [0.0, 1.0, 0.0] if key.endswith("center") else 0.25)


@pytest.mark.parametrize("make", [mi.Vector3f, mi.Point3f, mi.ScalarVector3f, mi.Normal3f])
def test_a_mitsuba_3_vector_sets_a_centre_as_a_list_does(make):
    """``mi.Vector3f(1, 2, 3)`` was refused with "expected 3 numbers" (only ``mi.Point3f``,
    the type the node stores, and scalar vectors were taken)."""
    sc, _ = _scene()
    target = [0.2, 0.7, 0.1]
    sc.all_params["sdf.ball.center"] = target
    sc.all_params.update()
    ref = np.array(draaw_mi.render(sc, version="v2", spp=2, seed=3, post=[]))
    sc.all_params["sdf.ball.center"] = [0.0, 0.8, 0.0]
    sc.check_value("demo", "sdf.ball.center", "sdf.ball.center", make(*target))
    sc.all_params["sdf.ball.center"] = make(*target)
    sc.all_params.update()
    assert np.allclose([c[0] for c in (sc.sdf.nodes["ball"].center.x, sc.sdf.nodes["ball"].center.y,
                                       sc.sdf.nodes["ball"].center.z)], target)
    img = np.array(draaw_mi.render(sc, version="v2", spp=2, seed=3, post=[]))
    assert np.array_equal(img, ref)
    with pytest.raises(ParameterError, match="expected 3 finite numbers"):     # two vectors
        sc.all_params["sdf.ball.center"] = mi.Vector3f([0, 1], [1, 1], [0, 0])


def test_a_mitsuba_vector_centre_keeps_its_gradient():
    sc, _ = _scene()
    grads = []
    for make in (mi.Point3f, mi.Vector3f):
        v = make(0.0, 0.8, 0.0)
        dr.enable_grad(v)
        sc.all_params["sdf.ball.center"] = v
        sc.all_params.update()
        img = draaw_mi.render(sc, version="v4", spp=2, seed=1, params=sc.all_params, post=[])
        dr.backward(dr.sum(img[..., :3], axis=None))
        grads.append(np.array(dr.grad(v)).ravel())
    assert np.all(np.isfinite(grads[0])) and np.abs(grads[0]).max() > 0, grads
    # (equal up to the order in which two threads sum the lanes' gradients: 1e-4 of the
    # largest component, a 0.5 % change of a small one where the terms cancel)
    assert np.allclose(grads[0], grads[1], rtol=0.0, atol=1e-3 * np.abs(grads[0]).max()), grads


def test_ranges_an_optimiser_projects_onto():
    from draaw_mi.fitting.params import range_for as _range_for
    from draaw_mi.sdf.node import OPEN_MARGIN
    sc, _ = _scene()
    assert _range_for("sdf.ball.radius", sc) == (OPEN_MARGIN, None)
    assert _range_for("sdf.block.radius", sc) == (0.0, pytest.approx(0.3))
    assert _range_for("sdf.blend.k", sc) == (0.0, None)
    assert _range_for("sdf.ball.center", sc) == (None, None)
    assert _range_for("sdf.block_xf.scale", sc) == (OPEN_MARGIN, None)
    assert _range_for("sdf.block.size", sc) == (pytest.approx(0.2 + OPEN_MARGIN), None)  # each side >= 2 r
    with pytest.raises(ParameterError, match="no parameter 'radus'; did you mean 'radius'"):
        sc.sdf.param_range("ball.radus")
    from draaw_mi.fitting.params import space_for as _space_for
    assert _space_for("sdf.alpha.center") == "linear"     # a node named like a BSDF parameter


def test_values_written_back_load_as_they_were_set():
    """A fitted scene saved to TOML: radius, k, centre and a transform's translation go into
    the [[sdf]] tables that made the nodes; the reloaded scene has them."""
    sc, d = _scene()
    values = {"sdf.ball.radius": 0.61, "sdf.blend.k": 0.33, "sdf.ball.center": [0.1, 0.9, -0.1],
              "sdf.block_xf.translate": [0.0, 0.1, 0.3], "ball.roughness": 0.4}
    desc = sc.updated_description(values)
    assert d["sdf"][0]["radius"] == 0.5                      # the scene's own copy untouched
    again = draaw_mi.load_scene(desc)
    got = {k: np.array(v).ravel().tolist() for k, v in again.sdf.params().items()}
    assert got["ball.radius"] == pytest.approx([0.61])
    assert got["blend.k"] == pytest.approx([0.33])
    assert got["ball.center"] == pytest.approx([0.1, 0.9, -0.1])
    assert got["block_xf.translate"] == pytest.approx([0.0, 0.1, 0.3])
    assert desc["materials"]["ball"]["roughness"] == 0.4


@pytest.mark.parametrize("key, match", [
    ("sdf.nope.radius", "no \\[\\[sdf\\]\\] table makes the node 'nope'"),
    ("sdf.trio_0.k", "no \\[\\[sdf\\]\\] table makes the node 'trio_0'"),
    ("sdf.trio.k", "has 3 children"),
    ("sdf.ball.k", "has no key 'k'"),
])
def test_values_no_table_holds_are_refused_by_name(key, match):
    extra = [{"type": "sphere", "name": "s1", "radius": 0.2, "center": [-1, 0.2, 0]},
             {"type": "sphere", "name": "s2", "radius": 0.2, "center": [-1.3, 0.2, 0]},
             {"type": "sphere", "name": "s3", "radius": 0.2, "center": [-1.6, 0.2, 0]},
             {"type": "smooth_union", "name": "trio", "children": ["s1", "s2", "s3"], "k": 0.1,
              "material": "ball"}]
    sc, _ = _scene(copy.deepcopy(extra))
    with pytest.raises(SceneError, match=f"cannot write '{key}' back: .*{match}"):
        sc.updated_description({key: 0.3})


@pytest.mark.parametrize("order", [("size", "radius"), ("radius", "size")])
def test_values_set_together_are_checked_together(order):
    """A round box shrunk from size 0.6 / radius 0.25 to size 0.3 / radius 0.1 is valid, but
    set one key at a time against the other's old value it was refused (size first) or made
    the render fail later; through all_params (batch frames, fit, preview) either order works
    and a refused group leaves every value as it was."""
    sc, _ = _scene()
    p = sc.all_params
    p["sdf.block.radius"] = 0.25
    p.update()
    new = {"size": [0.3, 0.3, 0.3], "radius": 0.1}
    sc.check_values("demo", {f"sdf.block.{k}": (f"sdf.block.{k}", new[k]) for k in order})
    for k in order:
        p[f"sdf.block.{k}"] = new[k]
    p.update()
    node = sc.sdf.nodes["block"]
    assert float(node.radius[0]) == pytest.approx(0.1) and float(node.size.x[0]) == pytest.approx(0.3)
    with pytest.raises(ParameterError, match=r"demo: sdf.block.size, sdf.block.radius: .*radius=0.2"):
        sc.check_values("demo", {"sdf.block.size": ("sdf.block.size", [0.3] * 3),
                                 "sdf.block.radius": ("sdf.block.radius", 0.2)})
    with pytest.raises(ParameterError, match="radius=0.2"):
        sc.sdf.set_many({"block.size": [0.3] * 3, "block.radius": 0.2, "ball.radius": 0.9})
    assert float(node.radius[0]) == pytest.approx(0.1) and float(sc.sdf.nodes["ball"].radius[0]) == 0.5


def test_a_round_boxs_size_and_radius_fit_together_and_from_the_limit():
    """``fit`` of a round box's size and radius together: each was clipped to a range that held
    the other at its start, so the radius stepped past half the new size and the fit stopped
    with an error in an iteration (a review: at 0.3356 against 0.3346); now the object's own
    projection keeps radius <= min(size)/2 at every iterate. And a box whose radius is half its
    size (valid) may have its size fitted (its start had been refused: 0.4 against the
    optimiser's open bound 0.4001)."""
    _, d = _scene()
    d["sdf"][1].update(size=[0.5, 0.5, 0.5], radius=0.24)          # the truth: nearly a ball
    ref = np.array(draaw_mi.render(draaw_mi.load_scene(d), version="v4", spp=16, seed=1))[..., :3]
    d["sdf"][1].update(size=[0.9, 0.9, 0.9], radius=0.1)           # from a big, sharp box
    res = draaw_mi.fit(draaw_mi.load_scene(d), ref, ["sdf.block.size", "sdf.block.radius"], version="v4",
                       spp=2, iterations=40, lr=0.05, progress=False)
    for h in res.history:
        size, radius = h["values"]["sdf.block.size"], h["values"]["sdf.block.radius"]
        assert radius <= 0.5 * min(size) + 1e-6, (size, radius)
    # (where it ends is not asserted: at 16x12 and 2 spp this fit wanders, seeds 0-7 ending at
    # radius 0.0-0.27 for the truth's 0.24, and one seed's end moves with the order in which
    # threads add up the gradient; it did read 0.132 and 0.153 for seed 0)
    assert np.max(np.abs(np.array(res.values["sdf.block.size"]) - 0.9)) > 0.1      # it moved
    d["sdf"][1].update(size=[0.4, 0.4, 0.4], radius=0.2)           # at the limit, valid
    res = draaw_mi.fit(draaw_mi.load_scene(d), ref, ["sdf.block.size"], version="v4", spp=2,
                       iterations=3, progress=False)
    assert min(res.values["sdf.block.size"]) >= 0.4


def test_an_unknown_sdf_key_names_what_exists():
    """``params["sdf.bal.radius"]`` raised a bare ``KeyError: 'sdf.bal.radius'`` (read or
    written, through ``sdf.parameters`` or ``scene.all_params``)."""
    scene, _ = _scene()
    for params in (draaw_mi.sdf.parameters(scene), scene.all_params):
        for key, said in (("sdf.bal.radius", "no node 'bal'; did you mean 'ball'"),
                          ("sdf.ball.radiu", "no parameter 'radiu'; did you mean 'radius'")):
            with pytest.raises(ParameterError, match=said):
                params[key]
            with pytest.raises(ParameterError, match=said):
                params[key] = 0.4
        assert "sdf.bal.radius" not in params and params["sdf.ball.radius"][0] == pytest.approx(0.5)



def test_get_of_an_unknown_sdf_key_gives_the_default():
    """``Mapping.get`` catches KeyError only: the unknown-key error (a ParameterError) escaped
    it; the message names the key as written."""
    scene, _ = _scene()
    params = draaw_mi.sdf.parameters(scene)
    assert params.get("sdf.bal.radius") is None and params.get("sdf.ball.radius")[0] == pytest.approx(0.5)
    with pytest.raises(ParameterError, match=r"parameters\['sdf\.'\]: sdf: no node ''"):
        params["sdf."]


def test_the_node_docstring_names_methods_that_exist():
    """The module docstring said ``node.set(...)``, which no node has."""
    import re
    from draaw_mi.sdf import node as node_mod
    from draaw_mi.sdf.scene import SDFScene
    doc = node_mod.__doc__
    called = re.findall(r"\bnode\.(\w+)\(", doc)
    assert "set_param" in called and all(hasattr(node_mod.SDFNode, m) for m in called), called
    assert all(hasattr(SDFScene, m) for m in re.findall(r"\bSDFScene\.(\w+)\(", doc))
