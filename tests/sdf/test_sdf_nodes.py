"""SDF primitives, transforms and operators against independent numpy references.

Exact primitives must equal geometric closed forms (or, where none is simple, the distance to a
densely sampled surface with the sign of an analytic inside test); operators must equal
their formulas; bound operators must be 1-Lipschitz (so |f| never exceeds the distance to
the surface) and reach the sharp operators as k -> 0.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from scipy.spatial import cKDTree

import draaw_mi  # noqa: F401
from draaw_mi.errors import ParameterError
from draaw_mi.sdf import (Box, Capsule, Cone, Cylinder, Plane, RoundBox, Sphere, Torus,
                          cubic_smooth_intersection, cubic_smooth_subtraction, cubic_smooth_union, intersection,
                          lse_intersection, rotate, scale, smooth_intersection, smooth_lse_intersection,
                          smooth_subtraction, smooth_union, subtraction, translate, union)

RNG = np.random.default_rng(14)


def dist(node, pts: np.ndarray) -> np.ndarray:
    p = mi.Point3f(*(pts[:, i].astype(np.float32) for i in range(3)))
    return np.array(node.distance(p), dtype=np.float64)


def rand_points(n=4000, lo=-2.0, hi=2.0):
    return RNG.uniform(lo, hi, size=(n, 3))


def brute(surface: np.ndarray, inside, pts: np.ndarray) -> np.ndarray:
    d, _ = cKDTree(surface).query(pts)
    return np.where(inside(pts), -d, d)


def grid2(n):
    u = (np.arange(n) + 0.5) / n
    return np.meshgrid(u, u, indexing="ij")


# ----------------------------------------------------------------------------- primitives
def test_sphere_exact():
    c, r = np.array([0.3, -0.2, 0.1]), 0.7
    pts = rand_points()
    ref = np.linalg.norm(pts - c, axis=1) - r
    np.testing.assert_allclose(dist(Sphere(center=c, radius=r), pts), ref, atol=2e-6)


def _box_ref(pts, c, size):
    lo, hi = c - size / 2, c + size / 2
    out = np.linalg.norm(pts - np.clip(pts, lo, hi), axis=1)
    inside = np.all((pts > lo) & (pts < hi), axis=1)
    depth = np.min(np.minimum(pts - lo, hi - pts), axis=1)
    return np.where(inside, -depth, out), lo, hi


def test_box_exact():
    c, size = np.array([0.1, 0.2, -0.3]), np.array([1.2, 0.6, 2.0])
    pts = rand_points()
    ref, _, _ = _box_ref(pts, c, size)
    np.testing.assert_allclose(dist(Box(center=c, size=size), pts), ref, atol=2e-6)


def test_round_box_exact():
    c, size, r = np.array([0.0, 0.1, 0.0]), np.array([1.4, 0.8, 1.0]), 0.2
    pts = rand_points()
    inner, lo, hi = _box_ref(pts, c, size - 2 * r)     # Minkowski sum of inner box and ball
    np.testing.assert_allclose(dist(RoundBox(center=c, size=size, radius=r), pts), inner - r, atol=2e-6)


def test_torus_exact():
    c, R, r = np.array([0.2, 0.0, -0.1]), 1.0, 0.3
    pts = rand_points()
    q = pts - c
    ring = np.stack([q[:, 0], np.zeros(len(q)), q[:, 2]], 1)
    ring = R * ring / np.linalg.norm(ring, axis=1, keepdims=True)     # closest point of the circle
    ref = np.linalg.norm(q - ring, axis=1) - r
    np.testing.assert_allclose(dist(Torus(center=c, major=R, minor=r), pts), ref, atol=3e-6)


def test_capsule_exact():
    a, b, r = np.array([-0.5, -0.3, 0.2]), np.array([0.6, 0.5, -0.1]), 0.25
    pts = rand_points()
    ba = b - a
    h = np.clip(((pts - a) @ ba) / (ba @ ba), 0, 1)
    ref = np.linalg.norm(pts - (a + h[:, None] * ba), axis=1) - r
    np.testing.assert_allclose(dist(Capsule(a=a, b=b, radius=r), pts), ref, atol=2e-6)


def test_cylinder_exact_vs_sampled_surface():
    c, r, h = np.array([0.1, -0.1, 0.0]), 0.6, 1.2
    u, v = grid2(500)
    ang = 2 * np.pi * u.ravel()
    side = np.stack([r * np.cos(ang), (v.ravel() - 0.5) * h, r * np.sin(ang)], 1)
    rr = r * np.sqrt(u.ravel())
    caps = [np.stack([rr * np.cos(2 * np.pi * v.ravel()), np.full(rr.shape, s * h / 2),
                      rr * np.sin(2 * np.pi * v.ravel())], 1) for s in (-1, 1)]
    surf = np.concatenate([side] + caps) + c
    pts = rand_points(2000)

    def inside(p):
        q = p - c
        return (np.hypot(q[:, 0], q[:, 2]) < r) & (np.abs(q[:, 1]) < h / 2)
    ref = brute(surf, inside, pts)
    np.testing.assert_allclose(dist(Cylinder(center=c, radius=r, height=h), pts), ref, atol=0.01)


def test_cone_exact_vs_sampled_surface():
    c, ang, h = np.array([0.0, -0.5, 0.1]), 30.0, 1.2
    R = h * math.tan(math.radians(ang))
    u, v = grid2(400)
    s, phi = u.ravel(), 2 * np.pi * v.ravel()
    lateral = np.stack([s * R * np.cos(phi), h * (1 - s), s * R * np.sin(phi)], 1)
    rr = R * np.sqrt(u.ravel())
    base = np.stack([rr * np.cos(phi), np.zeros_like(rr), rr * np.sin(phi)], 1)
    surf = np.concatenate([lateral, base]) + c
    pts = rand_points(2000)

    def inside(p):
        q = p - c
        return (q[:, 1] > 0) & (q[:, 1] < h) & (np.hypot(q[:, 0], q[:, 2]) < R * (1 - q[:, 1] / h))
    ref = brute(surf, inside, pts)
    np.testing.assert_allclose(dist(Cone(center=c, angle=ang, height=h), pts), ref, atol=0.01)


def test_plane_exact():
    n, off = np.array([1.0, 2.0, -0.5]), 0.4
    pts = rand_points()
    ref = pts @ (n / np.linalg.norm(n)) - off
    np.testing.assert_allclose(dist(Plane(normal=n, offset=off), pts), ref, atol=2e-6)


# ----------------------------------------------------------------------------- bounding boxes
@pytest.mark.parametrize("node", [
    Sphere((0.2, 0.1, 0), 0.5), Box((0, 0, 0.3), (0.5, 1.0, 0.2)), RoundBox((0, 0, 0), (1, 1, 1), 0.3),
    Torus((0, 0.2, 0), 0.8, 0.2), Cylinder((0, 0, 0), 0.4, 1.0), Capsule((0, 0, 0), (0.5, 0.5, 0), 0.2),
    Cone((0, 0, 0), 25.0, 1.0),
    rotate(translate(scale(Box((0, 0, 0), (1, 0.4, 0.2)), 1.5), (0.3, 0, 0)), (1, 1, 0), 35.0),
    smooth_union(Sphere((-0.5, 0, 0), 0.4), Sphere((0.5, 0, 0), 0.4), 0.5),
    subtraction(Box((0, 0, 0), (1, 1, 1)), Sphere((0.5, 0.5, 0.5), 0.5)),
    intersection(Sphere((0, 0, 0), 1.0), Box((0.5, 0, 0), (1, 1, 1))),
], ids=lambda n: n.kind)
def test_bbox_contains_every_inside_point(node):
    bb = node.bbox()
    lo, hi = np.array(list(bb.min)), np.array(list(bb.max))
    ext = hi - lo
    pts = np.concatenate([rand_points(20000, -2.5, 2.5),
                          RNG.uniform(lo - 0.5 * ext, hi + 0.5 * ext, size=(20000, 3))])
    d = dist(node, pts)
    inside = pts[d <= 0]
    assert len(inside) > 20
    assert np.all(inside >= lo - 1e-5) and np.all(inside <= hi + 1e-5)
    # and the box is not absurdly loose: some inside point is near each face
    assert np.all(inside.min(axis=0) < lo + 0.2 * (hi - lo))


# ----------------------------------------------------------------------------- transforms
def test_transforms_match_moved_closed_form():
    pts = rand_points()
    node = translate(rotate(scale(Box((0, 0, 0), (1.0, 0.5, 0.25)), 2.0), (0, 0, 1), 90.0), (1, 0, 0))
    # scaled by 2: size (2, 1, 0.5); rotated 90 deg about z: size (1, 2, 0.5); moved to x=1
    ref, _, _ = _box_ref(pts, np.array([1.0, 0, 0]), np.array([1.0, 2.0, 0.5]))
    np.testing.assert_allclose(dist(node, pts), ref, atol=1e-5)


def test_non_uniform_scale_rejected():
    from draaw_mi.sdf import Transform
    with pytest.raises(ParameterError, match="uniform"):
        Transform(Sphere(), scale=[1, 2, 1])


# ----------------------------------------------------------------------------- operators
A = Sphere((-0.3, 0.0, 0.0), 0.6)
B = Box((0.4, 0.1, 0.0), (0.8, 1.0, 0.7))


def _ab(pts):
    return dist(A, pts), dist(B, pts)


def _smin(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0, 1)
    return b + (a - b) * h - k * h * (1 - h)


@pytest.mark.parametrize("op,ref", [
    (lambda: union(A, B), lambda a, b: np.minimum(a, b)),
    (lambda: intersection(A, B), lambda a, b: np.maximum(a, b)),
    (lambda: subtraction(A, B), lambda a, b: np.maximum(a, -b)),
    (lambda: smooth_union(A, B, 0.3), lambda a, b: _smin(a, b, 0.3)),
    (lambda: smooth_intersection(A, B, 0.3), lambda a, b: -_smin(-a, -b, 0.3)),
    (lambda: smooth_subtraction(A, B, 0.3), lambda a, b: -_smin(-a, b, 0.3)),
    (lambda: lse_intersection(A, B), lambda a, b: np.log(np.exp(a) + np.exp(b))),
    (lambda: smooth_lse_intersection(A, B, 0.2), lambda a, b: 0.2 * np.log(np.exp(a / 0.2) + np.exp(b / 0.2))),
], ids=["union", "intersection", "subtraction", "smooth_union", "smooth_intersection",
        "smooth_subtraction", "lse", "smooth_lse"])
def test_operator_formulas(op, ref):
    pts = rand_points()
    a, b = _ab(pts)
    np.testing.assert_allclose(dist(op(), pts), ref(a, b), atol=3e-6, rtol=1e-5)


@pytest.mark.parametrize("make", [
    lambda: smooth_union(A, B, 0.4), lambda: smooth_intersection(A, B, 0.4),
    lambda: smooth_subtraction(A, B, 0.4), lambda: lse_intersection(A, B),
    lambda: smooth_lse_intersection(A, B, 0.3), lambda: subtraction(A, B),
    lambda: rotate(Torus((0.2, 0, 0), 0.7, 0.2), (1, 0, 0), 40.0),
], ids=["smooth_union", "smooth_intersection", "smooth_subtraction", "lse", "smooth_lse",
        "subtraction", "rotated_torus"])
def test_bounds_are_one_lipschitz(make):
    """|f(p) - f(q)| <= |p - q| (with f = 0 on the surface this is |f| <= distance)."""
    node = make()
    p = rand_points(5000)
    q = p + RNG.normal(size=p.shape) * RNG.uniform(1e-3, 0.5, size=(len(p), 1))
    ratio = np.abs(dist(node, p) - dist(node, q)) / np.linalg.norm(p - q, axis=1)
    assert ratio.max() <= 1.0 + 2e-3


def test_bounds_never_overestimate_sampled_surface():
    """|f| <= distance to points sampled on the zero set of a smooth union (found by bisection)."""
    node = smooth_union(A, B, 0.3)
    dirs = RNG.normal(size=(3000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    lo, hi = np.zeros(len(dirs)), np.full(len(dirs), 3.0)     # origin inside, 3 outside
    c = np.array([0.0, 0.0, 0.0])
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        inside = dist(node, c + dirs * mid[:, None]) < 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    surf = c + dirs * lo[:, None]
    pts = rand_points(2000)
    d_true, _ = cKDTree(surf).query(pts)      # >= true distance (finite sampling)
    assert np.all(np.abs(dist(node, pts)) <= d_true + 1e-4)


def test_k_zero_limits_equal_sharp_operators():
    pts = rand_points()
    for smooth, sharp in ((smooth_union, union), (smooth_intersection, intersection),
                          (smooth_subtraction, subtraction)):
        np.testing.assert_array_equal(dist(smooth(A, B, 0.0), pts), dist(sharp(A, B), pts))
        np.testing.assert_allclose(dist(smooth(A, B, 1e-6), pts), dist(sharp(A, B), pts), atol=1e-6)
    d = dist(smooth_lse_intersection(A, B, 0.0), pts)
    assert np.all(np.isfinite(d))
    np.testing.assert_allclose(d, dist(intersection(A, B), pts), atol=1e-6)


def test_smooth_union_blend_weights():
    """Material weights of a smooth union blend with the distance's own h; they sum to 1."""
    a = Sphere((-0.5, 0, 0), 0.5)
    b = Sphere((0.5, 0, 0), 0.5)
    a.slot, b.slot = 0, 1
    node = smooth_union(a, b, 0.4)
    pts = rand_points(500, -1, 1)
    p = mi.Point3f(*(pts[:, i].astype(np.float32) for i in range(3)))
    _, w = node.eval(p, 2)
    w = np.stack([np.array(x) for x in w])
    da, db = dist(a, pts), dist(b, pts)
    h = np.clip(0.5 + 0.5 * (db - da) / 0.4, 0, 1)
    np.testing.assert_allclose(w[0], h, atol=1e-6)
    np.testing.assert_allclose(w.sum(0), 1.0, atol=1e-6)


# ----------------------------------------------------------------------------- parameters
def test_parameter_errors():
    with pytest.raises(ParameterError, match="radius"):
        Sphere(radius=-1.0)
    with pytest.raises(ParameterError, match="size"):
        Box(size=(1, -1, 1))
    with pytest.raises(ParameterError, match="radius"):
        RoundBox(size=(1, 1, 1), radius=0.6)
    with pytest.raises(ParameterError, match="angle"):
        Cone(angle=95.0)
    with pytest.raises(ParameterError, match="normal"):
        Plane(normal=(0, 0, 0))
    with pytest.raises(ParameterError, match="k"):
        smooth_union(A, B, -0.1)
    s = Sphere(radius=1.0, name="ball")
    with pytest.raises(ParameterError, match="did you mean 'radius'"):
        s.set_param("radius_", 2.0)


def test_an_optimisers_out_of_range_value_is_one_clear_error():
    """Dr.Jit values (an optimiser's, with gradients) are range-checked like numbers: a
    negative radius made the sphere vanish with a zero gradient, a zero cone height gave NaN
    distances, a zero scale a distance of 0 everywhere. Values in range pass unchanged."""
    from draaw_mi.sdf import Transform
    s = Sphere(radius=1.0, name="ball")
    r = mi.Float(0.5)
    dr.enable_grad(r)
    s.set_param("radius", r)
    assert s.own_params()["radius"] is r and dr.grad_enabled(s.radius)
    cone = Cone(name="c")
    moved = Transform(Sphere(radius=1.0), scale=2.0, name="t")
    for node, key, bad in ((s, "radius", -0.5), (cone, "height", 0.0), (moved, "scale", 0.0),
                           (s, "radius", float("nan"))):
        value = mi.Float(bad)
        dr.enable_grad(value)
        with pytest.raises(ParameterError, match=rf"{key}=.*expected a number > 0.*clamp"):
            node.set_param(key, value)
    assert float(s.radius[0]) == 0.5                      # the bad value was not kept


def test_params_and_gradient_of_distance():
    s = Sphere((0, 0, 0), 1.0, name="ball")
    u = smooth_union(s, Box((2, 0, 0), (1, 1, 1), name="b"), 0.2, name="u")
    keys = set(u.params())
    assert {"ball.radius", "ball.center", "b.size", "u.k"} <= keys
    r = u.params()["ball.radius"]
    dr.enable_grad(r)
    d = s.distance(mi.Point3f(3, 0, 0))
    dr.backward(d)
    assert dr.grad(r)[0] == pytest.approx(-1.0)


# ----------------------------------------------------------------------------- cubic (GO-Draaw)
def _cubic(a, b, k, sign=1.0):
    """go-draaw-spec.md §5.2: h = max(k - |a - b|, 0) / k; min(a, b) - h^3 k / 6 (and the
    intersection with its sign fixed: max(a, b) + h^3 k / 6)."""
    h = np.maximum(k - np.abs(a - b), 0) / k
    sharp = np.minimum(a, b) if sign > 0 else np.maximum(a, b)
    return sharp - sign * h ** 3 * k / 6


@pytest.mark.parametrize("op,ref", [
    (lambda: cubic_smooth_union(A, B, 0.3), lambda a, b: _cubic(a, b, 0.3)),
    (lambda: cubic_smooth_intersection(A, B, 0.3), lambda a, b: _cubic(a, b, 0.3, -1.0)),
    (lambda: cubic_smooth_subtraction(A, B, 0.3), lambda a, b: _cubic(a, -b, 0.3, -1.0)),
], ids=["union", "intersection", "subtraction"])
def test_cubic_operator_formulas_and_bounds(op, ref):
    pts = rand_points()
    a, b = _ab(pts)
    node = op()
    np.testing.assert_allclose(dist(node, pts), ref(a, b), atol=3e-6, rtol=1e-5)
    q = pts + RNG.normal(size=pts.shape) * RNG.uniform(1e-3, 0.5, size=(len(pts), 1))
    ratio = np.abs(dist(node, pts) - dist(node, q)) / np.linalg.norm(pts - q, axis=1)
    assert ratio.max() <= 1.0 + 2e-3                                    # a bound: 1-Lipschitz
    bb = node.bbox()
    near = rand_points(20000, -1.2, 1.2)
    inside = near[dist(node, near) <= 0]
    assert len(inside) > 20
    assert np.all(inside >= np.array(list(bb.min)) - 1e-5) and np.all(inside <= np.array(list(bb.max)) + 1e-5)


@pytest.mark.parametrize("op, weight_a", [
    (union, lambda da, db: (da <= db).astype(float)),
    (intersection, lambda da, db: (da >= db).astype(float)),
    (subtraction, lambda da, db: (da >= -db).astype(float)),
    (lse_intersection, lambda da, db: 1 / (1 + np.exp(db - da))),
    (lambda a, b: smooth_lse_intersection(a, b, 0.3), lambda da, db: 1 / (1 + np.exp((db - da) / 0.3))),
], ids=["union", "intersection", "subtraction", "lse", "smooth_lse"])
def test_sharp_and_lse_weights_follow_the_operand_that_defines_the_surface(op, weight_a):
    """The material weight of ``a``: 1 where ``a`` defines the distance (the min of a union,
    the max of an intersection, ``a`` against ``-b`` of a subtraction), the softmax weight of
    a log-sum-exp; numpy from the operators' formulas. A flipped comparison gave the outer
    surface of a subtraction, or both sides of an intersection, the other material."""
    a, b = Sphere((0, 0, 0), 0.6), Sphere((0.5, 0, 0), 0.4)
    a.slot, b.slot = 0, 1
    pts = rand_points(500, -1, 1)
    p = mi.Point3f(*(pts[:, i].astype(np.float32) for i in range(3)))
    _, w = op(a, b).eval(p, 2)
    w = np.stack([np.array(x) for x in w])
    da, db = dist(a, pts), dist(b, pts)
    clear = np.abs(np.abs(da) - np.abs(db)) > 1e-4          # (ties: float rounding decides)
    np.testing.assert_allclose(w[0][clear], weight_a(da, db)[clear], atol=1e-5)
    np.testing.assert_allclose(w.sum(0), 1.0, atol=1e-6)
    assert 0.02 < w[0].mean() < 0.98                        # both operands show


def test_cubic_blend_weights_sum_to_one_and_follow_the_nearer_operand():
    a, b = Sphere((-0.5, 0, 0), 0.5), Sphere((0.5, 0, 0), 0.5)
    a.slot, b.slot = 0, 1
    pts = rand_points(500, -1, 1)
    p = mi.Point3f(*(pts[:, i].astype(np.float32) for i in range(3)))
    _, w = cubic_smooth_union(a, b, 0.4).eval(p, 2)
    w = np.stack([np.array(x) for x in w])
    da, db = dist(a, pts), dist(b, pts)
    h3 = (np.maximum(0.4 - np.abs(da - db), 0) / 0.4) ** 3
    np.testing.assert_allclose(w[0], np.where(da <= db, 1 - h3 / 2, h3 / 2), atol=1e-6)
    np.testing.assert_allclose(w.sum(0), 1.0, atol=1e-6)


def test_cubic_union_of_coincident_spheres_grows_by_k_over_6_inside_its_box():
    # a = b everywhere: the surface moves out by k/6, beyond both operands' boxes
    u = cubic_smooth_union(Sphere((0, 0, 0), 0.5), Sphere((0, 0, 0), 0.5), 0.6)
    assert float(u.distance(mi.Point3f(0.59, 0, 0))[0]) == pytest.approx(-0.01, abs=1e-6)
    assert float(u.bbox().max.x) >= 0.6 - 1e-6


def test_polynomial_union_of_coincident_spheres_grows_by_k_over_4_inside_its_box():
    # a = b: h = 1/2, the surface moves out by k/4; the box (which the tracer clips its march
    # to) must reach it, or the shape is cut off
    u = smooth_union(Sphere((0, 0, 0), 0.5), Sphere((0, 0, 0), 0.5), 0.6)
    assert float(u.distance(mi.Point3f(0.64, 0, 0))[0]) == pytest.approx(-0.01, abs=1e-6)
    assert float(u.bbox().max.x) >= 0.65 - 1e-6


def test_cubic_subtraction_gives_the_cut_face_the_cut_materials_weight():
    a, b = Sphere((0, 0, 0), 0.6), Sphere((0.5, 0, 0), 0.4)
    a.slot, b.slot = 0, 1
    pts = rand_points(500, -1, 1)
    p = mi.Point3f(*(pts[:, i].astype(np.float32) for i in range(3)))
    _, w = cubic_smooth_subtraction(a, b, 0.3).eval(p, 2)
    da, nb = dist(a, pts), -dist(b, pts)
    h3 = (np.maximum(0.3 - np.abs(da - nb), 0) / 0.3) ** 3
    np.testing.assert_allclose(np.array(w[0]), np.where(da >= nb, 1 - h3 / 2, h3 / 2), atol=1e-6)


def test_an_operators_third_operand_and_bad_names_are_refused():
    """``union(a, b, c)`` took ``c`` as the node's name (and ``smooth_union(a, b, c)`` as its
    k): ``c`` was silently left out of the tree. A name that cannot be part of a key
    (``sdf.NAME.PARAM``) failed only later, at ``load_scene``."""
    from draaw_mi.sdf import union
    from draaw_mi.sdf.operators import Union
    c = Sphere((2, 0, 0), 0.5, name="c")
    with pytest.raises(TypeError):
        union(A, B, c)
    with pytest.raises(ParameterError, match=r"third operand \(sphere 'c'\).*union\(union\(a, b\), c\)"):
        smooth_union(A, B, c)
    with pytest.raises(ParameterError, match="k=0.3; a sharp operator has no blend radius"):
        Union(A, B, 0.3)
    for bad in ("my ball", "1ball", 3):
        with pytest.raises(ParameterError, match=r"sdf.sphere: name=.*expected letters, digits"):
            Sphere(name=bad)
    with pytest.raises(ParameterError, match="material=1; expected a material's name"):
        Sphere(material=1)
    d = union(union(A, B, name="ab"), c, name="abc")          # nested: three operands
    assert float(d.distance(mi.Point3f(2, 0, 0))[0]) == pytest.approx(-0.5)


def test_two_nodes_of_one_name_are_refused_by_params():
    """``union(Sphere(), Sphere())`` (both named ``sphere``): ``params()`` held the first's
    values only, the second's could be neither set nor fitted through it."""
    from draaw_mi.sdf import union
    with pytest.raises(ParameterError, match=r"two nodes are named 'sphere'.*distinct names"):
        union(Sphere(), Sphere((1, 0, 0))).params()
    keys = union(Sphere(name="s1"), Sphere((1, 0, 0), name="s2")).params()
    assert sorted(keys) == ["s1.center", "s1.radius", "s2.center", "s2.radius"]
    # three operators named 'union': they hold no values, nothing is hidden
    keys = union(union(A, B), union(Sphere(name="c1"), Sphere(name="c2"))).params()
    assert {k.split(".")[0] for k in keys} == {"sphere", "box", "c1", "c2"}



def test_an_operator_of_a_childs_name_hides_none_of_its_values():
    """A sharp operator (no values) named as its child: params() had kept the operator as the
    name's owner and dropped the child's keys (a review of the duplicate check)."""
    from draaw_mi.sdf import union
    keys = union(Sphere(name="ball"), Sphere((1, 0, 0), name="other"), name="ball").params()
    assert sorted(keys) == ["ball.center", "ball.radius", "other.center", "other.radius"]


def test_every_smooth_operator_has_the_same_default_k():
    """``smooth_lse_intersection(a, b)`` took k = 1.0 while its class and an ``[[sdf]]`` table
    without ``k`` took 0.1 (the same tree, two shapes)."""
    import inspect
    from draaw_mi.sdf import operators
    a, b = Sphere((-0.3, 0, 0), 0.6), Sphere((0.3, 0, 0), 0.6)
    assert float(smooth_lse_intersection(a, b).k[0]) == float(operators.SmoothLSEIntersection(a, b).k[0])
    fns = [smooth_union, smooth_intersection, smooth_subtraction, cubic_smooth_union, cubic_smooth_intersection,
           cubic_smooth_subtraction, smooth_lse_intersection]
    assert {inspect.signature(f).parameters["k"].default for f in fns} == {operators.K_DEFAULT}
