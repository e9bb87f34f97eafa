"""CSG operators on SDF nodes, with material blending by the same weight as the distance.

============================  =============================================  ================
operator                      distance                                       kind
============================  =============================================  ================
``union(a, b)``               ``min(a, b)``                                  exact outside
``intersection(a, b)``        ``max(a, b)``                                  bound
``subtraction(a, b)``         ``max(a, -b)``  (a with b cut away)            bound
``smooth_union(a, b, k)``     ``h = clip(1/2 + (b - a)/(2k), 0, 1)``,        bound
                              ``lerp(b, a, h) - k h (1 - h)``
``smooth_intersection``       ``-smooth_union(-a, -b, k)``                   bound
``smooth_subtraction``        ``smooth_intersection(a, -b, k)``              bound
``cubic_smooth_union``        ``h = max(k - |a - b|, 0) / k``,                bound
                              ``min(a, b) - h^3 k / 6`` (GO-Draaw's)
``cubic_smooth_intersection`` ``max(a, b) + h^3 k / 6``                      bound
``cubic_smooth_subtraction``  ``cubic_smooth_intersection(a, -b, k)``        bound
``lse_intersection(a, b)``    ``log(e^a + e^b)`` (GO-Draaw "addition")       bound
``smooth_lse_intersection``   ``k log(e^(a/k) + e^(b/k))`` (GO-Draaw         bound
                              "smoothAddition")
============================  =============================================  ================

*Bound* means ``|f| <=`` the true distance (every operator here is 1-Lipschitz), so sphere
tracing stays safe. The polynomial smooth minimum lies in ``[min(a, b) - k/4, min(a, b)]``
and equals the sharp operator for ``k = 0`` (``k`` is clamped to 1e-12 inside, so ``k = 0``
divides by nothing). The cubic one, GO-Draaw's smoothUnion (used for its sphere lists), lies
in ``[min(a, b) - k/6, min(a, b)]`` and blends over ``|a - b| < k`` (twice the polynomial's
width for the same ``k``). Material weights: the smooth operators blend the operands' material
weights with the same ``h`` (Quilez' colour blend), the sharp ones take the operand that
defines the surface (for ``subtraction``, the cut face belongs to ``b``). The
log-sum-exp pair is GO-Draaw's "addition": since ``log(e^a + e^b) >= max(a, b)`` it is a
soft *intersection* (shrunk by up to ``k log 2``), hence the names; ``addition`` and
``smooth_addition`` are kept as aliases. GO-Draaw's sign bugs (``go-draaw-spec.md`` §5.2) are
not reproduced.

>>> import mitsuba as mi
>>> from draaw_mi.sdf import Sphere, smooth_union
>>> u = smooth_union(Sphere((-0.6, 0, 0), 0.5), Sphere((0.6, 0, 0), 0.5), k=0.3)
>>> float(u.distance(mi.Point3f(0, 0, 0))[0]) < 0.1        # the gap is bridged
True
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..errors import ParameterError
from .node import SDFNode, box, infinite_box, is_infinite, pad, scalar_of

K_MIN = 1e-12
#: the blend radius of every smooth operator given no ``k`` (functions, classes, ``[[sdf]]`` tables)
K_DEFAULT = 0.1


def _union_box(a, b):
    if is_infinite(a) or is_infinite(b):
        return infinite_box()
    return box([min(float(x), float(y)) for x, y in zip(a.min, b.min)],
               [max(float(x), float(y)) for x, y in zip(a.max, b.max)])


def _intersect_box(a, b):
    lo = [max(float(x), float(y)) for x, y in zip(a.min, b.min)]
    hi = [min(float(x), float(y)) for x, y in zip(a.max, b.max)]
    if any(l > h for l, h in zip(lo, hi)):      # empty: a degenerate box at a's centre
        c = [0.5 * (float(x) + float(y)) if abs(float(x)) < 1e30 else 0.0 for x, y in zip(a.min, a.max)]
        return box(c, c)
    return box(lo, hi)


def _lerp_w(wa, wb, h):
    return [dr.lerp(y, x, h) for x, y in zip(wa, wb)]


def _select_w(cond, wa, wb):
    return [dr.select(cond, x, y) for x, y in zip(wa, wb)]


class Operator(SDFNode):
    """A binary operator node (``a`` first operand, ``b`` second)."""
    smooth = False

    def __init__(self, a: SDFNode, b: SDFNode, k=None, *, name=None, material=None):
        if not isinstance(a, SDFNode) or not isinstance(b, SDFNode):
            raise ParameterError(f"sdf.{self.kind}: operands must be SDF nodes, got "
                                 f"{type(a).__name__} and {type(b).__name__}")
        if isinstance(k, SDFNode):
            raise ParameterError(f"sdf.{self.kind}: a third operand ({k.kind} {k.name!r}); an operator "
                                 "takes two: nest them, e.g. union(union(a, b), c)")
        if k is not None and not self.smooth:
            raise ParameterError(f"sdf.{self.kind}: k={k!r}; a sharp operator has no blend radius "
                                 "(smooth_union and the other smooth operators take one)")
        super().__init__(name, material)
        self.a, self.b = a, b
        if self.smooth:
            self.k = self._scalar_param("k", K_DEFAULT if k is None else k, lo=0.0)
            self._lower_bounds = {}

    def children(self):
        return (self.a, self.b)

    def param_range(self, key):
        if key == "k" and self.smooth:
            return (0.0, None)
        return super().param_range(key)

    def _k(self):
        return dr.maximum(self.k, K_MIN)

    def _check(self):
        if self.smooth and scalar_of(self.k) < 0:
            raise ParameterError(f"sdf.{self.kind} {self.name!r}: k={scalar_of(self.k)}; expected >= 0")

    # combine(da, db) -> (d, h) where h is the weight of operand a
    def combine(self, da, db):
        raise NotImplementedError

    def distance(self, p):
        return self.combine(self.a.distance(p), self.b.distance(p))[0]

    def eval(self, p, n_slots):
        da, wa = self.a.eval(p, n_slots)
        db, wb = self.b.eval(p, n_slots)
        d, h = self.combine(da, db)
        if self.material is not None:       # an explicit material overrides the operands'
            return d, [mi.Float(1.0 if i == self.slot else 0.0) for i in range(n_slots)]
        return d, _lerp_w(wa, wb, h)


class Union(Operator):
    kind = "union"

    def combine(self, da, db):
        return dr.minimum(da, db), dr.select(da <= db, 1.0, 0.0)

    def bbox(self):
        return _union_box(self.a.bbox(), self.b.bbox())


class Intersection(Operator):
    kind = "intersection"

    def combine(self, da, db):
        return dr.maximum(da, db), dr.select(da >= db, 1.0, 0.0)

    def bbox(self):
        return _intersect_box(self.a.bbox(), self.b.bbox())


class Subtraction(Operator):
    kind = "subtraction"

    def combine(self, da, db):
        return dr.maximum(da, -db), dr.select(da >= -db, 1.0, 0.0)

    def bbox(self):
        return self.a.bbox()


class SmoothUnion(Operator):
    kind = "smooth_union"
    smooth = True

    def combine(self, da, db):
        k = self._k()
        h = dr.clip(0.5 + 0.5 * (db - da) / k, 0.0, 1.0)
        return dr.lerp(db, da, h) - k * h * (1.0 - h), h

    def bbox(self):
        return pad(_union_box(self.a.bbox(), self.b.bbox()), 0.25 * scalar_of(self.k))


class SmoothIntersection(Operator):
    kind = "smooth_intersection"
    smooth = True

    def combine(self, da, db):
        k = self._k()
        h = dr.clip(0.5 - 0.5 * (db - da) / k, 0.0, 1.0)
        return dr.lerp(db, da, h) + k * h * (1.0 - h), h

    def bbox(self):
        return _intersect_box(self.a.bbox(), self.b.bbox())


class SmoothSubtraction(Operator):
    kind = "smooth_subtraction"
    smooth = True

    def combine(self, da, db):
        k = self._k()
        nb = -db
        h = dr.clip(0.5 - 0.5 * (nb - da) / k, 0.0, 1.0)
        return dr.lerp(nb, da, h) + k * h * (1.0 - h), h

    def bbox(self):
        return self.a.bbox()


class CubicSmoothUnion(Operator):
    """GO-Draaw's smoothUnion; the nearer operand's material weight is ``1 - h^3 / 2``
    (one half where ``a = b``)."""
    kind = "cubic_smooth_union"
    smooth = True
    sign = 1.0                   # -1: the intersection, max(a, b) + h^3 k / 6

    def combine(self, da, db):
        k = self._k()
        h = dr.maximum(k - dr.abs(da - db), 0.0) / k
        w = h * h * h
        a_defines = (da <= db) if self.sign > 0 else (da >= db)
        sharp = dr.select(a_defines, da, db)
        return sharp - self.sign * w * k * (1.0 / 6.0), dr.select(a_defines, 1.0 - 0.5 * w, 0.5 * w)

    def bbox(self):
        return pad(_union_box(self.a.bbox(), self.b.bbox()), scalar_of(self.k) / 6.0)


class CubicSmoothIntersection(CubicSmoothUnion):
    kind = "cubic_smooth_intersection"
    sign = -1.0

    def bbox(self):
        return _intersect_box(self.a.bbox(), self.b.bbox())


class CubicSmoothSubtraction(CubicSmoothIntersection):
    """``a`` with ``b`` cut away: the cubic intersection of ``a`` and ``-b`` (the cut face's
    material is ``b``'s)."""
    kind = "cubic_smooth_subtraction"

    def combine(self, da, db):
        return super().combine(da, -db)

    def bbox(self):
        return self.a.bbox()


class LSEIntersection(Operator):
    """``k log(e^(a/k) + e^(b/k))``, evaluated as ``max + k log1p(e^(-|a-b|/k))``."""
    kind = "lse_intersection"
    smooth = False

    def combine(self, da, db):
        k = 1.0 if not self.smooth else self._k()
        m = dr.maximum(da, db)
        e = dr.exp(-dr.abs(da - db) / k)
        d = m + k * dr.log(1.0 + e)
        wa = dr.select(da >= db, 1.0, e) / (1.0 + e)      # softmax weight of a
        return d, wa

    def bbox(self):
        return _intersect_box(self.a.bbox(), self.b.bbox())


class SmoothLSEIntersection(LSEIntersection):
    kind = "smooth_lse_intersection"
    smooth = True


def union(a, b, *, name=None, material=None):
    """Sharp union ``min(a, b)``."""
    return Union(a, b, name=name, material=material)


def intersection(a, b, *, name=None, material=None):
    """Sharp intersection ``max(a, b)``."""
    return Intersection(a, b, name=name, material=material)


def subtraction(a, b, *, name=None, material=None):
    """``a`` with ``b`` cut away: ``max(a, -b)``."""
    return Subtraction(a, b, name=name, material=material)


def smooth_union(a, b, k=K_DEFAULT, *, name=None, material=None):
    """Polynomial smooth union with blend radius ``k`` >= 0 (k = 0: ``union``)."""
    return SmoothUnion(a, b, k, name=name, material=material)


def smooth_intersection(a, b, k=K_DEFAULT, *, name=None, material=None):
    """Polynomial smooth intersection (k = 0: ``intersection``)."""
    return SmoothIntersection(a, b, k, name=name, material=material)


def smooth_subtraction(a, b, k=K_DEFAULT, *, name=None, material=None):
    """``a`` with ``b`` cut away, smoothed (k = 0: ``subtraction``)."""
    return SmoothSubtraction(a, b, k, name=name, material=material)


def cubic_smooth_union(a, b, k=K_DEFAULT, *, name=None, material=None):
    """GO-Draaw's cubic smooth union, ``min(a, b) - h^3 k / 6`` with ``h = max(k - |a - b|,
    0) / k`` (k = 0: ``union``).

    >>> import mitsuba as mi
    >>> from draaw_mi.sdf import Sphere
    >>> u = cubic_smooth_union(Sphere((-1, 0, 0), 1.0), Sphere((1, 0, 0), 1.0), k=0.6)
    >>> round(float(u.distance(mi.Point3f(0, 0, 0))[0]), 6)     # both spheres touch: -k/6
    -0.1
    """
    return CubicSmoothUnion(a, b, k, name=name, material=material)


def cubic_smooth_intersection(a, b, k=K_DEFAULT, *, name=None, material=None):
    """GO-Draaw's smoothIntersection with its sign fixed, ``max(a, b) + h^3 k / 6``."""
    return CubicSmoothIntersection(a, b, k, name=name, material=material)


def cubic_smooth_subtraction(a, b, k=K_DEFAULT, *, name=None, material=None):
    """``a`` with ``b`` cut away, cubic-smoothed (GO-Draaw's smoothSubtraction, fixed)."""
    return CubicSmoothSubtraction(a, b, k, name=name, material=material)


def lse_intersection(a, b, *, name=None, material=None):
    """GO-Draaw's "addition": ``log(e^a + e^b)``, a soft intersection."""
    return LSEIntersection(a, b, name=name, material=material)


def smooth_lse_intersection(a, b, k=K_DEFAULT, *, name=None, material=None):
    """GO-Draaw's "smoothAddition": ``k log(e^(a/k) + e^(b/k))`` (k -> 0: ``intersection``)."""
    return SmoothLSEIntersection(a, b, k, name=name, material=material)


addition = lse_intersection
smooth_addition = smooth_lse_intersection

OPERATORS = {
    "union": Union, "intersection": Intersection, "subtraction": Subtraction,
    "smooth_union": SmoothUnion, "smooth_intersection": SmoothIntersection,
    "smooth_subtraction": SmoothSubtraction, "cubic_smooth_union": CubicSmoothUnion,
    "cubic_smooth_intersection": CubicSmoothIntersection, "cubic_smooth_subtraction": CubicSmoothSubtraction,
    "lse_intersection": LSEIntersection,
    "smooth_lse_intersection": SmoothLSEIntersection,
    "addition": LSEIntersection, "smooth_addition": SmoothLSEIntersection,
}
