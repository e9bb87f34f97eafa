"""Rigid transforms and uniform scale of SDF nodes (distance-preserving, so exactness and
bounds carry over).

``Transform(child, translate, rotate, scale)`` applies scale, then rotation, then translation
(the order of ``[[shapes]]`` tables): ``f(p) = s * child(R^T (p - t) / s)``. ``translate`` and
``scale`` are differentiable parameters; the rotation is a constant (degrees, about an axis).
Non-uniform scale does not preserve distances and is rejected.

>>> import mitsuba as mi
>>> from draaw_mi.sdf import Sphere, translate, scale
>>> s = translate(scale(Sphere(radius=1.0), 2.0), (5, 0, 0))
>>> s.distance(mi.Point3f(0, 0, 0))
[3]
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from .node import SDFNode, _scalar, _vec3, box, infinite_box, is_infinite, scalar_of, vec_of


def axis_angle(R: np.ndarray) -> tuple[list[float], float]:
    """Rotation matrix -> (unit axis, degrees): the axis is the eigenvector of eigenvalue 1,
    the angle's sign comes from the skew part (robust at 0 and 180 degrees)."""
    w, v = np.linalg.eig(R)
    axis = np.real(v[:, np.argmin(np.abs(w - 1.0))])
    axis = axis / max(np.linalg.norm(axis), 1e-30)
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    angle = math.degrees(math.atan2(0.5 * float(axis @ skew), 0.5 * (np.trace(R) - 1.0)))
    return axis.tolist(), angle


def _rotation(value, name: str) -> np.ndarray:
    """``value`` as a 3x3 rotation matrix: orthonormal with determinant +1 (to float32
    rounding). Anything else changes distances (``diag(2, 1, 1)`` doubles a sphere's, so the
    march would step through it) and has no angle and axis for ``describe`` or export."""
    try:
        R = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        R = None
    if R is None or R.shape != (3, 3) or not np.all(np.isfinite(R)):
        shown = value.tolist() if isinstance(value, np.ndarray) else value
        raise ParameterError(f"sdf {name!r}: rotation={shown!r}; expected a 3x3 rotation matrix")
    if not (np.allclose(R @ R.T, np.eye(3), atol=1e-5) and np.linalg.det(R) > 0):
        raise ParameterError(f"sdf {name!r}: rotation={R.tolist()!r} is not a rotation (R R^T = I, "
                             "det R = +1); scale with scale=, mirror by other means")
    return R


def rotation_matrix(axis, angle_deg: float) -> np.ndarray:
    """3x3 rotation by ``angle_deg`` degrees about ``axis`` (Rodrigues)."""
    try:
        a = np.asarray(axis, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError(f"sdf rotate: axis={axis!r}; expected 3 numbers") from None
    n = np.linalg.norm(a)
    if a.shape != (3,) or n == 0 or not np.all(np.isfinite(a)):
        raise ParameterError(f"sdf rotate: axis={axis!r}; expected a non-zero finite 3-vector")
    x, y, z = a / n
    t = math.radians(angle_deg)
    c, s = math.cos(t), math.sin(t)
    C = 1 - c
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


class Transform(SDFNode):
    """``child`` scaled by ``scale`` (> 0, uniform), rotated by ``rotation`` (3x3 matrix) and
    translated by ``translate``."""

    kind = "transform"

    def __init__(self, child: SDFNode, translate=(0.0, 0.0, 0.0), rotation=None, scale=1.0,
                 name=None, material=None):
        if not isinstance(child, SDFNode):      # (else: 'str' object has no attribute 'name')
            raise ParameterError(f"sdf.transform: child={child!r}; expected an SDF node "
                                 "(Sphere, Box, union(...), ...)")
        super().__init__(name or f"{child.name}_xf", material)
        self.child = child
        self.translate = self._vec_param("translate", translate)
        s = float(scale) if isinstance(scale, np.ndarray) and scale.size == 1 else scale
        if isinstance(scale, (list, tuple)) or (isinstance(scale, np.ndarray) and scale.size == 3):
            given = [float(x) for x in np.ravel(scale)] if isinstance(scale, np.ndarray) else scale
            v = _vec3(given, f"sdf {self.name!r}", "scale")
            if max(v) - min(v) > 1e-9 * max(abs(x) for x in v):
                raise ParameterError(f"sdf {self.name!r}: scale={list(given)!r}; only uniform scale "
                                     "keeps distances exact (give one number)")
            s = v[0]
        self.scale = self._scalar_param("scale", s, lo=0.0, lo_open=True)
        self._lower_bounds = {"scale": 0.0}
        R = np.eye(3) if rotation is None else _rotation(rotation, self.name)
        self.rotation = R
        self._identity_rot = bool(np.allclose(R, np.eye(3)))

    def children(self):
        return (self.child,)

    def fixed_values(self) -> dict:
        if self._identity_rot:
            return {}
        axis, angle = axis_angle(self.rotation)
        axis = np.asarray(axis)
        if angle < 0:
            axis, angle = -axis, -angle
        axis = np.where(np.abs(axis) < 1e-9, 0.0, axis)     # (no -6.1e-17 in the listing)
        return {"rotate": f"{angle:g} deg about ({', '.join(f'{c:.4g}' for c in axis)})"}

    def to_local(self, p):
        q = mi.Vector3f(p - self.translate)
        if not self._identity_rot:
            R = self.rotation.tolist()     # q_local = R^T q (Python floats: numpy scalars
            R = [[float(v) for v in row] for row in R]   # would try to read the JIT arrays)
            q = mi.Vector3f(R[0][0] * q.x + R[1][0] * q.y + R[2][0] * q.z,
                            R[0][1] * q.x + R[1][1] * q.y + R[2][1] * q.z,
                            R[0][2] * q.x + R[1][2] * q.y + R[2][2] * q.z)
        return mi.Point3f(q / self.scale)

    def distance(self, p):
        return self.child.distance(self.to_local(p)) * self.scale

    def eval(self, p, n_slots):
        d, w = self.child.eval(self.to_local(p), n_slots)
        return d * self.scale, w

    def bbox(self):
        bb = self.child.bbox()
        if is_infinite(bb):
            return infinite_box()
        s, t = scalar_of(self.scale), np.array(vec_of(self.translate))
        lo, hi = np.array(list(bb.min), float), np.array(list(bb.max), float)
        corners = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
        world = (corners * s) @ self.rotation.T + t
        return box(world.min(axis=0), world.max(axis=0))


def translate(node: SDFNode, offset) -> Transform:
    """``node`` moved by ``offset``."""
    return Transform(node, translate=offset)


def rotate(node: SDFNode, axis, angle: float) -> Transform:
    """``node`` rotated by ``angle`` degrees about ``axis`` through the origin."""
    ang = _scalar(angle, "sdf rotate", "angle")
    return Transform(node, rotation=rotation_matrix(axis, ang))


def scale(node: SDFNode, factor: float) -> Transform:
    """``node`` scaled uniformly by ``factor`` > 0 about the origin."""
    return Transform(node, scale=factor)


__all__ = ["Transform", "translate", "rotate", "scale", "rotation_matrix"]
# keep dr imported for doctest users who copy the example
_ = dr
