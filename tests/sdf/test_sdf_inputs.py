"""What SDF nodes accept (from a review): every value an optimiser may project onto is one
``set_param`` takes; numpy scalars are numbers and strings are not; a Transform's rotation is a
rotation and its child a node; the helpers name the bad value."""
from __future__ import annotations

import numpy as np
import pytest

import mitsuba as mi
from draaw_mi.errors import ParameterError
from draaw_mi.sdf import (Box, Capsule, Cone, Cylinder, RoundBox, Sphere, Torus, rotate, scale, smooth_union,
                          translate)
from draaw_mi.sdf.node import OPEN_MARGIN, scalar_of
from draaw_mi.sdf.transforms import Transform, rotation_matrix

NODES = [Sphere(radius=0.5), Box(size=(1, 2, 3)), RoundBox(size=(1, 1.2, 1.4), radius=0.3),
         Torus(major=1.0, minor=0.3), Cylinder(radius=0.4, height=1.0), Capsule(radius=0.2),
         Cone(height=1.0), smooth_union(Sphere(), Box(), k=0.2), scale(Sphere(), 2.0)]


def _value(node, key, x):
    return (x, x, x) if dr_vector(node, key) else x


def dr_vector(node, key):
    return isinstance(node._params[key], mi.Point3f)


@pytest.mark.parametrize("node", NODES, ids=lambda n: n.kind)
def test_every_value_in_a_parameters_range_is_accepted(node):
    """fit() projects a parameter onto ``param_range`` and then sets it: a bound that
    ``set_param`` refuses stopped a fit with an error (a round box's size at 1e-4 beside its
    radius 0.3), and one it accepts beyond is a bound that is not the node's."""
    checked = 0
    for key in node._params:
        lo, hi = node.param_range(key)
        for bound, outside in ((lo, None if lo is None else lo - 2 * OPEN_MARGIN),
                               (hi, None if hi is None else hi + 2 * OPEN_MARGIN)):
            if bound is None:
                continue
            node.check_param(key, _value(node, key, bound))
            with pytest.raises(ParameterError):
                node.check_param(key, _value(node, key, outside))
            checked += 1
    assert checked >= 1


def test_numpy_scalars_are_numbers_and_strings_are_not():
    assert scalar_of(Sphere(radius=np.float32(0.5)).radius) == 0.5      # (refused: "expected a finite number")
    assert scalar_of(Sphere(radius=np.int64(2)).radius) == 2.0
    assert scalar_of(smooth_union(Sphere(), Box(), k=np.float64(0.25)).k) == 0.25
    assert scalar_of(scale(Sphere(), np.float32(2.0)).scale) == 2.0
    s = Sphere()
    s.set_param("radius", np.float32(0.75))
    assert scalar_of(s.radius) == 0.75
    for bad in ("5", np.bool_(True), True):
        with pytest.raises(ParameterError, match="radius="):
            Sphere(radius=bad)
    with pytest.raises(ParameterError, match=r"center='123'; expected 3 numbers"):   # (was (1, 2, 3))
        Sphere(center="123")


def test_a_transform_takes_only_rotations():
    sph = Sphere(radius=0.5)
    for bad in (np.diag([2.0, 1.0, 1.0]), np.diag([1.0, 1.0, -1.0]), np.eye(2), np.full((3, 3), np.nan), "x"):
        with pytest.raises(ParameterError, match="rotation="):
            Transform(sph, rotation=bad)
    R = rotation_matrix((1, 2, 3), 40.0) @ rotation_matrix((0, 1, 0), -75.0)
    x = Transform(sph, rotation=R, translate=(1, 0, 0))
    p = np.array([0.3, -0.2, 0.9])
    q = R.T @ (p - [1, 0, 0])                                   # a rotation keeps the distance
    assert float(x.distance(mi.Point3f(*p.tolist()))[0]) == pytest.approx(np.linalg.norm(q) - 0.5, abs=1e-6)


def test_transform_helpers_name_the_bad_value():
    with pytest.raises(ParameterError, match="child='ball'; expected an SDF node"):
        translate("ball", (1, 0, 0))
    with pytest.raises(ParameterError, match="child=None"):
        scale(None, 2.0)
    with pytest.raises(ParameterError, match="axis='y'"):
        rotate(Sphere(), "y", 30)
    with pytest.raises(ParameterError, match="axis=3"):
        rotate(Sphere(), 3, 30)


def test_values_beyond_float32_or_subnormal_are_refused():
    """Sphere(radius=1e39) gave -inf distances and scale(Sphere(), 1e-39) NaN ones (the object
    vanished) where the scene loader refuses |x| > 3.4e38."""
    import drjit as dr
    cases = [(lambda: Sphere(radius=1e39), r"radius=1e\+39; expected a number within float32"),
             (lambda: Sphere(center=(1e39, 0, 0)), r"center=\(1e\+39, 0, 0\); expected 3 numbers within float32"),
             (lambda: smooth_union(Sphere(), Box(), k=-1e39), r"k=-1e\+39; expected a number within float32"),
             (lambda: scale(Sphere(), 1e-39), r"scale=1e-39; expected a number >= 1\.17549435e-38"),
             (lambda: Sphere(radius=1e-40), r"radius=1e-40; expected a number >= 1\.17549435e-38")]
    for make, match in cases:
        with pytest.raises(ParameterError, match=match):
            make()
    s = Sphere()
    with pytest.raises(ParameterError, match=r"radius=1\.0\d*e-39; expected a number >= 1\.17549435e-38"):
        s.set_param("radius", dr.opaque(mi.Float, 1e-39))              # an optimiser's array
    assert scalar_of(s.radius) == 1.0
    assert scalar_of(scale(Sphere(), 1.2e-38).scale) > 0               # the smallest normal is taken


def test_a_numpy_array_of_one_number_is_a_number_whatever_its_shape():
    """np.array(0.5) (0-d) was "not a finite number" where np.array([0.5]) was taken."""
    for v in (np.array(0.5), np.array([0.5]), np.array([[0.5]]), np.array(0.5, dtype=np.float32)):
        assert scalar_of(Sphere(radius=v).radius) == 0.5
    assert scalar_of(smooth_union(Sphere(), Box(), k=np.array(0.25)).k) == 0.25
    s = Sphere()
    s.set_param("radius", np.array(0.75))
    assert scalar_of(s.radius) == 0.75
    for bad in (np.array(True), np.array([0.5, 0.6]), np.array([])):
        with pytest.raises(ParameterError, match="radius="):
            Sphere(radius=bad)
