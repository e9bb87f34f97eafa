"""``draaw_mi.sdf.export.to_entries``: a Python-built tree placed into a scene through its
``[[sdf]]`` tables evaluates the same distances as the tree itself (random points), with the
same parameter keys; rotations (including 180 degrees) and nested transforms survive."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import mitsuba as mi
from draaw_mi.sdf import Box, Sphere, Torus, scale, smooth_union, subtraction, translate
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
