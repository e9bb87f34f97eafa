"""Signed distance fields: primitives, transforms, CSG operators, a sphere tracer inside the
draaw integrators, and scene integration (``[[sdf]]`` tables, GO-Draaw sphere lists).

Build a tree in Python::

    >>> from draaw_mi.sdf import Sphere, Box, smooth_union, subtraction
    >>> blob = smooth_union(Sphere((0, 0.5, 0), 0.5), Box((0, 0.2, 0), (1.2, 0.4, 0.6)), k=0.2)
    >>> cut = subtraction(blob, Sphere((0.4, 0.8, 0.3), 0.3))
    >>> cut.bbox().min.y < 0.01
    True

Each node has ``.distance(p)`` (``mi.Point3f`` -> ``mi.Float``), ``.eval(p, n)`` (distance and
material weights), ``.bbox()`` and ``.params()``. In a scene description, ``[[sdf]]`` entries
are read by ``draaw_mi.load_scene`` (:mod:`draaw_mi.scene.sdf_dicts`) and reach the integrators
through :mod:`draaw_mi.sdf.scene`.
"""
from __future__ import annotations

from .node import SDFNode
from .operators import (
                        OPERATORS,
                        addition,
                        cubic_smooth_intersection,
                        cubic_smooth_subtraction,
                        cubic_smooth_union,
                        intersection,
                        lse_intersection,
                        smooth_addition,
                        smooth_intersection,
                        smooth_lse_intersection,
                        smooth_subtraction,
                        smooth_union,
                        subtraction,
                        union,
)
from .params import SDFParameters, parameters
from .primitives import PRIMITIVES, Box, Capsule, Cone, Cylinder, Plane, RoundBox, Sphere, Torus
from .transforms import Transform, rotate, scale, translate

__all__ = [
    "SDFNode", "Sphere", "Box", "RoundBox", "Torus", "Cylinder", "Capsule", "Cone", "Plane",
    "Transform", "translate", "rotate", "scale",
    "union", "intersection", "subtraction", "smooth_union", "smooth_intersection",
    "smooth_subtraction", "cubic_smooth_union", "cubic_smooth_intersection",
    "cubic_smooth_subtraction", "lse_intersection", "smooth_lse_intersection", "addition",
    "smooth_addition", "PRIMITIVES", "OPERATORS", "parameters", "SDFParameters",
]

from .._lazy import on_first_use as _on_first_use  # noqa: E402

# draaw_mi.sdf.export.to_entries(...) and the like after a plain ``import draaw_mi``
__getattr__ = _on_first_use(__name__, ("export", "integration", "scene", "silhouette", "tracer"))
