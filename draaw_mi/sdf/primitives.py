"""SDF primitives (Inigo Quilez's distance functions, re-derived; exact, except inside a
spindle torus).

=============================================  ==================================================
``Sphere(center, radius)``                     ``|p - c| - r``
``Box(center, size)``                          axis-aligned box, ``size`` = full edge lengths
``RoundBox(center, size, radius)``             box of outer size ``size`` with edges rounded by
                                               ``radius <= min(size) / 2``
``Torus(center, major, minor)``                ring in the xz-plane (axis y)
``Cylinder(center, radius, height)``           capped, axis y, ``height`` = full length
``Capsule(a, b, radius)``                      segment ``a``-``b`` swept by a ball
``Cone(center, angle, height)``                capped cone, axis y: base disk centred at
                                               ``center``, apex at ``center + (0, height, 0)``,
                                               half-angle ``angle`` in degrees (0 < angle < 90)
``Plane(normal, offset)``                      ``dot(p, n / |n|) - offset`` (the plane through
                                               ``offset * n / |n|``; infinite bounding box)
=============================================  ==================================================

Orient and move them with :mod:`draaw_mi.sdf.transforms`. Example::

    >>> import mitsuba as mi
    >>> from draaw_mi.sdf import Sphere
    >>> Sphere(center=(0, 0, 0), radius=1.0).distance(mi.Point3f(3, 0, 0))
    [2]
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from .node import OPEN_MARGIN, SDFNode, _scalar, _vec3, box, infinite_box, safe_norm, scalar_of, vec_of


def _len2(x, y):
    return dr.sqrt(dr.maximum(dr.square(x) + dr.square(y), 1e-30))


class Sphere(SDFNode):
    """Sphere of ``radius`` > 0 around ``center`` (exact)."""
    kind = "sphere"
    _lower_bounds = {"radius": 0.0}

    def __init__(self, center=(0.0, 0.0, 0.0), radius=1.0, name=None, material=None):
        super().__init__(name, material)
        self.center = self._vec_param("center", center)
        self.radius = self._scalar_param("radius", radius, lo=0.0, lo_open=True)

    def distance(self, p):
        return safe_norm(p - self.center) - self.radius

    def bbox(self):
        c, r = vec_of(self.center), scalar_of(self.radius)
        return box([x - r for x in c], [x + r for x in c])


class Box(SDFNode):
    """Axis-aligned box with full edge lengths ``size`` (each > 0) centred at ``center``."""
    kind = "box"

    def __init__(self, center=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0), name=None, material=None):
        super().__init__(name, material)
        self.center = self._vec_param("center", center)
        self.size = self._vec_param("size", size)
        self._check()

    def _check(self):
        if any(s <= 0 for s in vec_of(self.size)):
            raise ParameterError(f"sdf.{self.kind} {self.name!r}: size={vec_of(self.size)}; "
                                 "expected 3 numbers > 0 (full edge lengths)")

    def _rounded(self, p, r):
        q = dr.abs(p - self.center) - (0.5 * self.size - r)
        outside = safe_norm(dr.maximum(q, 0.0))
        inside = dr.minimum(dr.maximum(dr.maximum(q.x, q.y), q.z), 0.0)
        # outside term: its safe-norm floor (1e-15) only matters exactly on/inside the box
        return dr.select(dr.max(q) > 0, outside, 0.0) + inside - r

    def distance(self, p):
        return self._rounded(p, 0.0)

    def param_range(self, key):
        if key == "size":              # every side > 0 (an optimiser's step can make one negative)
            return (OPEN_MARGIN, None)
        return super().param_range(key)

    def bbox(self):
        c, s = vec_of(self.center), vec_of(self.size)
        return box([a - 0.5 * b for a, b in zip(c, s)], [a + 0.5 * b for a, b in zip(c, s)])


class RoundBox(Box):
    """Box of outer size ``size`` whose edges and corners are rounded by ``radius``
    (0 <= radius <= min(size) / 2; exact)."""

    kind = "round_box"
    _lower_bounds = {}

    def __init__(self, center=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0), radius=0.1, name=None,
                 material=None):
        SDFNode.__init__(self, name, material)
        self.center = self._vec_param("center", center)
        self.size = self._vec_param("size", size)
        self.radius = self._scalar_param("radius", radius, lo=0.0)
        self._check()

    def _check(self):
        super()._check()
        r = scalar_of(self.radius)
        if r < 0 or r > 0.5 * min(vec_of(self.size)) + 1e-12:
            raise ParameterError(f"sdf.round_box {self.name!r}: radius={r:g}; expected a value "
                                 f"in [0, min(size)/2 = {0.5 * min(vec_of(self.size)):g}]")

    def param_range(self, key):
        """The radius up to half the smallest side; every side at least twice the radius (so
        a fit of ``size`` alone does not step below it and stop with an error at the update).
        Each bound holds the other parameter at its present value."""
        if key == "radius":
            return (0.0, 0.5 * min(vec_of(self.size)))
        if key == "size":
            return (2.0 * scalar_of(self.radius) + OPEN_MARGIN, None)
        return super().param_range(key)

    def project(self, values):
        """Radius and size moved together: the radius at most half the new smallest side, then
        every side at least twice the new radius (each bound of :meth:`param_range` held the
        other at its present value: a fit moving both stepped out of range and stopped).

        >>> box = RoundBox(size=(0.9, 0.9, 0.9), radius=0.1)
        >>> out = box.project({"size": [0.5, 0.6, 0.7], "radius": 0.34})
        >>> round(float(out["radius"]), 6), [round(float(x), 6) for x in out["size"]]
        (0.25, [0.5001, 0.6, 0.7])
        """
        out = super().project({k: v for k, v in values.items() if k not in ("size", "radius")})
        size = np.maximum(np.asarray(values.get("size", vec_of(self.size)), dtype=np.float64), OPEN_MARGIN)
        radius = float(np.clip(np.asarray(values.get("radius", scalar_of(self.radius)),
                                          dtype=np.float64).ravel()[0], 0.0, 0.5 * size.min()))
        if "radius" in values:
            out["radius"] = np.asarray(radius)
        if "size" in values:
            out["size"] = np.maximum(size, 2.0 * radius + OPEN_MARGIN)
        return out

    def distance(self, p):
        return self._rounded(p, self.radius)


class Torus(SDFNode):
    """Torus around the y axis through ``center``: ring radius ``major`` > 0, tube radius
    ``minor`` > 0 (exact, except inside a spindle torus, ``minor > major``, where it is a
    bound: in the self-intersecting core it underestimates the distance)."""

    kind = "torus"
    _lower_bounds = {"major": 0.0, "minor": 0.0}

    def __init__(self, center=(0.0, 0.0, 0.0), major=1.0, minor=0.25, name=None, material=None):
        super().__init__(name, material)
        self.center = self._vec_param("center", center)
        self.major = self._scalar_param("major", major, lo=0.0, lo_open=True)
        self.minor = self._scalar_param("minor", minor, lo=0.0, lo_open=True)

    def distance(self, p):
        q = p - self.center
        return _len2(_len2(q.x, q.z) - self.major, q.y) - self.minor

    def bbox(self):
        c, R, r = vec_of(self.center), scalar_of(self.major), scalar_of(self.minor)
        e = (R + r, r, R + r)
        return box([a - b for a, b in zip(c, e)], [a + b for a, b in zip(c, e)])


class Cylinder(SDFNode):
    """Capped cylinder along y centred at ``center``: ``radius`` > 0, full ``height`` > 0."""
    kind = "cylinder"
    _lower_bounds = {"radius": 0.0, "height": 0.0}

    def __init__(self, center=(0.0, 0.0, 0.0), radius=0.5, height=1.0, name=None, material=None):
        super().__init__(name, material)
        self.center = self._vec_param("center", center)
        self.radius = self._scalar_param("radius", radius, lo=0.0, lo_open=True)
        self.height = self._scalar_param("height", height, lo=0.0, lo_open=True)

    def distance(self, p):
        q = p - self.center
        dx = _len2(q.x, q.z) - self.radius
        dy = dr.abs(q.y) - 0.5 * self.height
        out = _len2(dr.maximum(dx, 0.0), dr.maximum(dy, 0.0))
        out = dr.select((dx > 0) | (dy > 0), out, 0.0)
        return dr.minimum(dr.maximum(dx, dy), 0.0) + out

    def bbox(self):
        c, r, h = vec_of(self.center), scalar_of(self.radius), scalar_of(self.height)
        e = (r, 0.5 * h, r)
        return box([a - b for a, b in zip(c, e)], [a + b for a, b in zip(c, e)])


class Capsule(SDFNode):
    """Segment from ``a`` to ``b`` swept by a ball of ``radius`` > 0 (exact; a == b is a
    sphere)."""

    kind = "capsule"
    _lower_bounds = {"radius": 0.0}

    def __init__(self, a=(0.0, -0.5, 0.0), b=(0.0, 0.5, 0.0), radius=0.25, name=None,
                 material=None):
        super().__init__(name, material)
        self.a = self._vec_param("a", a)
        self.b = self._vec_param("b", b)
        self.radius = self._scalar_param("radius", radius, lo=0.0, lo_open=True)

    def distance(self, p):
        pa = p - self.a
        ba = self.b - self.a
        bb = dr.squared_norm(ba)
        h = dr.clip(dr.dot(pa, ba) / dr.maximum(bb, 1e-30), 0.0, 1.0)
        return safe_norm(pa - ba * h) - self.radius

    def bbox(self):
        a, b, r = vec_of(self.a), vec_of(self.b), scalar_of(self.radius)
        return box([min(x, y) - r for x, y in zip(a, b)], [max(x, y) + r for x, y in zip(a, b)])


class Cone(SDFNode):
    """Capped cone along +y: base disk centred at ``center``, apex ``height`` above it,
    half-angle ``angle`` degrees in (0, 90) (exact)."""

    kind = "cone"
    _lower_bounds = {"height": 0.0}

    def __init__(self, center=(0.0, 0.0, 0.0), angle=30.0, height=1.0, name=None, material=None):
        super().__init__(name, material)
        self.center = self._vec_param("center", center)
        ang = _scalar(angle, f"sdf.cone {self.name!r}", "angle")
        if not (0.0 < ang < 90.0):
            raise ParameterError(f"sdf.cone {self.name!r}: angle={ang!r}; expected degrees in (0, 90)")
        self.angle = ang                    # not differentiable (a Python constant)
        self.height = self._scalar_param("height", height, lo=0.0, lo_open=True)

    def distance(self, p):
        # apex at the origin, the cone extends to y = -h; q = (h tan(angle), -h)
        h = self.height
        rel = p - self.center
        wx = _len2(rel.x, rel.z)
        wy = rel.y - h
        qx = h * math.tan(math.radians(self.angle))
        qy = -h
        qq = dr.square(qx) + dr.square(qy)
        s = dr.clip((wx * qx + wy * qy) / qq, 0.0, 1.0)
        ax, ay = wx - qx * s, wy - qy * s
        bx, by = wx - qx * dr.clip(wx / qx, 0.0, 1.0), wy - qy
        d2 = dr.minimum(dr.square(ax) + dr.square(ay), dr.square(bx) + dr.square(by))
        # k = sign(qy) = -1
        sgn = dr.maximum(-(wx * qy - wy * qx), -(wy - qy))
        return dr.sqrt(dr.maximum(d2, 1e-30)) * dr.select(sgn < 0, -1.0, 1.0)

    def fixed_values(self) -> dict:
        return {"angle": f"{self.angle:g}"}

    def bbox(self):
        c, h = vec_of(self.center), scalar_of(self.height)
        r = h * math.tan(math.radians(self.angle))
        return box([c[0] - r, c[1], c[2] - r], [c[0] + r, c[1] + h, c[2] + r])


class Plane(SDFNode):
    """The plane ``dot(p, n) = offset`` with unit ``n = normal / |normal|`` (exact, signed:
    positive on the side ``normal`` points to; infinite bounding box)."""

    kind = "plane"

    def __init__(self, normal=(0.0, 1.0, 0.0), offset=0.0, name=None, material=None):
        super().__init__(name, material)
        n = _vec3(normal, f"sdf.plane {self.name!r}", "normal")
        ln = math.sqrt(sum(x * x for x in n))
        if ln == 0:
            raise ParameterError(f"sdf.plane {self.name!r}: normal={normal!r}; expected a non-zero vector")
        self.normal = mi.ScalarVector3f(*(x / ln for x in n))     # not differentiable
        self.offset = self._scalar_param("offset", offset)

    def distance(self, p):
        return dr.dot(mi.Vector3f(p), mi.Vector3f(self.normal)) - self.offset

    def fixed_values(self) -> dict:
        return {"normal": f"({', '.join(f'{c:g}' for c in self.normal)})"}

    def bbox(self):
        return infinite_box()


PRIMITIVES = {cls.kind: cls for cls in (Sphere, Box, RoundBox, Torus, Cylinder, Capsule, Cone, Plane)}


#: the ``[[sdf]]`` table keys of each primitive (its constructor's parameters)
PRIMITIVE_KEYS = {
    "sphere": ("center", "radius"),
    "box": ("center", "size"),
    "round_box": ("center", "size", "radius"),
    "torus": ("center", "major", "minor"),
    "cylinder": ("center", "radius", "height"),
    "capsule": ("a", "b", "radius"),
    "cone": ("center", "angle", "height"),
    "plane": ("normal", "offset"),
}
