"""``draaw_mi.sdf.export.to_entries``: a Python-built tree placed into a scene through its
``[[sdf]]`` tables evaluates the same distances as the tree itself (random points), with the
same parameter keys; rotations (including 180 degrees) and nested transforms survive."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import mitsuba as mi
from draaw_mi.sdf import Box, Sphere, Torus, scale, smooth_union, subtraction, translate, union
from draaw_mi.sdf.export import to_entries
from draaw_mi.sdf.transforms import axis_angle as _axis_angle
from draaw_mi.sdf.transforms import Transform, rotation_matrix

from sdf_helpers import base_description


def _trees():
    blk = Transform(Box((0, 0.4, 0), (0.8, 0.6, 0.4), name="blk", material="blocker"),
                    translate=(0.3, 0, 0), rotation=rotation_matrix((0.2, 1, 0.3), 130), scale=1.2)
    blob = smooth_union(Sphere((0, 0.8, 0), 0.5, name="ball", material="ball"), blk, k=0.2, name="blob")
    cut = subtraction(blob, Sphere((0.3, 1.0, 0.4), 0.3, name="bite"), name="cut")
    ring = translate(scale(Torus((0, 0.2, 0), 0.4, 0.1, name="ring"), 0.7), (1, 0, 0.5))   # nested
    # the other nesting: the outer scale scales the inner translation (it was dropped: the
    # ball exported at x = 0.6 instead of 1.2)
    pebble = scale(translate(Sphere((0, 0, 0), 0.25, name="pebble"), (0.6, -1.2, 0)), 2.0)
    return cut, ring, pebble


def test_scene_from_entries_has_the_same_distances():
    trees = _trees()
    d = base_description()
    d["sdf"] = to_entries(*trees)
    sc = draaw_mi.load_scene(d)
    P = np.random.default_rng(0).uniform(-2, 2, (2000, 3)).astype(np.float32)
    p = mi.Point3f(*P.T)
    want = np.min([np.array(t.distance(p)) for t in trees], axis=0)
    pebble = np.linalg.norm(P - [1.2, -2.4, 0], axis=1) - 0.5        # numpy: centre 2 x, radius 2 x
    np.testing.assert_allclose(np.array(trees[2].distance(p)), pebble, atol=1e-5)
    np.testing.assert_allclose(np.array(sc.sdf.distance(p)), want, atol=2e-6)
    keys = draaw_mi.sdf.parameters(sc)._sdf_keys()
    assert {"sdf.ball.radius", "sdf.blob.k", "sdf.blk.size", "sdf.ring.major"} <= set(keys)


@pytest.mark.parametrize("axis,angle", [((0, 1, 0), 30.0), ((1, 2, 3), -75.0), ((0, 0, 1), 180.0),
                                        ((1, 1, 0), 179.9)])
def test_axis_angle_round_trip(axis, angle):
    R = rotation_matrix(axis, angle)
    ax, ang = _axis_angle(R)
    np.testing.assert_allclose(rotation_matrix(ax, ang), R, atol=1e-9)


def test_duplicate_names_are_made_unique():
    names = [e["name"] for e in to_entries(smooth_union(Sphere(), Sphere((1, 0, 0)), k=0.1))]
    assert names == ["sphere", "sphere_1", "smooth_union"]


def test_a_named_transform_is_said_to_take_its_childs_name():
    """A transform folds into its child's table, so its own name is not kept: the scene's
    keys are ``NAME_xf.*`` (the docstring said names were kept)."""
    tree = Transform(Sphere(name="ball"), translate=(1, 0, 0), name="mover")
    with pytest.warns(RuntimeWarning, match=r"'mover' becomes .* of 'ball'.*sdf.ball_xf.translate"):
        entries = to_entries(tree)
    d = base_description((8, 8))
    d["sdf"] = entries
    assert "sdf.ball_xf.translate" in draaw_mi.sdf.parameters(draaw_mi.load_scene(d))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        to_entries(Transform(Sphere(name="ball"), translate=(1, 0, 0)))      # NAME_xf: nothing said


def _loads(entries):
    d = base_description((8, 8))
    d["sdf"] = entries
    return draaw_mi.load_scene(d)


def test_a_made_up_name_takes_no_name_of_the_trees():
    """``s, s, s_1`` exported as ``s, s_1, s_1`` (the loader: "duplicate SDF name 's_1'"), and a
    moved ``s`` beside a node named ``s_xf`` gave two nodes ``s_xf``: both now load, and every
    node of the trees keeps its name where no earlier table took it."""
    roots = (Sphere((0, 0, 0), 0.3, name="s"), Sphere((1, 0, 0), 0.3, name="s"), Sphere((2, 0, 0), 0.3, name="s_1"))
    names = [e["name"] for e in to_entries(*roots)]
    assert names == ["s", "s_2", "s_1"]
    p = mi.Point3f([0.0, 1.0, 2.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(np.array(_loads(to_entries(*roots)).sdf.distance(p)), [-0.3] * 3, atol=1e-6)
    names = [e["name"] for e in to_entries(translate(Sphere(name="s"), (1, 0, 0)), Sphere(name="s_xf"))]
    assert names == ["s", "s_xf_1"]
    _loads(to_entries(translate(Sphere(name="s"), (1, 0, 0)), Sphere(name="s_xf")))


def test_a_shared_child_stays_one_node_in_the_scene():
    """A node under two operators was written twice (``sh`` and ``sh_1``), so fitting
    ``sdf.sh.radius`` moved one of them: it is one table that both operators name."""
    sh = Sphere((0, 0, 0), 0.4, name="sh")
    tree = union(smooth_union(sh, Box((1, 0, 0), (0.5, 0.5, 0.5), name="blk"), k=0.1, name="u1"),
                 subtraction(Box(size=(2, 0.3, 2), name="bb"), sh, name="u2"), name="top")
    entries = to_entries(tree)
    assert [e["name"] for e in entries] == ["sh", "blk", "u1", "bb", "u2", "top"]
    assert [e["children"] for e in entries if e["name"] in ("u1", "u2")] == [["sh", "blk"], ["bb", "sh"]]
    sc = _loads(entries)
    assert sc.sdf.nodes["u1"].a is sc.sdf.nodes["u2"].b
    assert sorted(sc.sdf.params()) == ["bb.center", "bb.size", "blk.center", "blk.size", "sh.center",
                                       "sh.radius", "u1.k"]
    params = draaw_mi.sdf.parameters(sc)
    params["sdf.sh.radius"] = 0.6
    params.update()
    sh.set_param("radius", 0.6)                 # the tree: both operators see the new radius
    P = np.random.default_rng(1).uniform(-1.5, 1.5, (500, 3)).astype(np.float32)
    p = mi.Point3f(*P.T)
    np.testing.assert_allclose(np.array(sc.sdf.distance(p)), np.array(tree.distance(p)), atol=2e-6)


def test_a_node_shared_under_two_transforms_is_written_twice_with_a_warning():
    sh = Sphere(radius=0.3, name="sh")
    with pytest.warns(RuntimeWarning, match=r"'sh' is shared under different transforms"):
        entries = to_entries(union(translate(sh, (1, 0, 0)), translate(sh, (-1, 0, 0)), name="u"))
    assert [e["name"] for e in entries] == ["sh", "sh_1", "u"]
    _loads(entries)
