"""A Python-built SDF tree -> ``[[sdf]]`` tables, so it can be placed in a scene description.

>>> from draaw_mi.sdf import Sphere, Box, smooth_union
>>> from draaw_mi.sdf.export import to_entries
>>> tree = smooth_union(Sphere((0, 0.5, 0), 0.5, name="ball"), Box(name="block"), k=0.2, name="blob")
>>> [e["type"] for e in to_entries(tree)]
['sphere', 'box', 'smooth_union']
>>> # draaw_mi.load_scene({..., "sdf": to_entries(tree)})

The scene loader builds its own nodes from the tables (with the same names, so the keys of
:func:`draaw_mi.sdf.parameters` are ``"sdf.ball.radius"`` etc.); the tree passed in is not
modified. Transforms fold into the ``translate`` / ``rotate`` / ``scale`` keys of the node they
wrap (nested transforms are composed), so a transform's own name is not kept: in the scene its
keys are ``"sdf.NAME_xf.translate"`` and ``"sdf.NAME_xf.scale"`` after the node it wraps (a
``RuntimeWarning`` says so where it was named otherwise). Nodes with the same name get ``_1``,
``_2``... suffixes.
"""
from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from .node import SDFNode, scalar_of, vec_of
from .operators import Operator
from .primitives import PRIMITIVE_KEYS
from .transforms import Transform, axis_angle


def _f(x) -> float:
    """The shortest decimal that reads back as the same float32 (0.8, not 0.800000011920929)."""
    return float(str(np.float32(x)))


def _value(v):
    if isinstance(v, mi.Point3f):
        return [_f(c) for c in vec_of(v)]
    if isinstance(v, (mi.ScalarVector3f, mi.ScalarPoint3f)):
        return [_f(c) for c in v]
    if dr.is_array_v(v):
        return _f(scalar_of(v))
    return _f(v)


def to_entries(*roots: SDFNode) -> list[dict]:
    """``[[sdf]]`` tables (dicts) describing ``roots`` (their union, as in a scene file).

    ======== =====================================================================
    roots    one or more :class:`~draaw_mi.sdf.SDFNode` trees
    returns  a list of dicts, children before their operators
    ======== =====================================================================
    """
    entries: list[dict] = []
    used: dict[str, int] = {}
    renamed: list[tuple[str, str]] = []          # (a transform's own name, the node it folds into)

    def unique(name: str) -> str:
        n = used.get(name, 0)
        used[name] = n + 1
        return name if n == 0 else f"{name}_{n}"

    def emit(node: SDFNode) -> str:
        s, R, t = 1.0, np.eye(3), np.zeros(3)
        material = None
        names = []                                 # transforms named otherwise than NAME_xf
        while isinstance(node, Transform):         # compose: outer(s1,R1,t1) o inner(s2,R2,t2)
            material = material or node.material
            s2, R2, t2 = scalar_of(node.scale), node.rotation, np.array(vec_of(node.translate))
            t = t + s * (R @ t2)
            R = R @ R2
            s = s * s2
            if isinstance(node.child, SDFNode) and node.name != f"{node.child.name}_xf":
                names.append(node.name)
            node = node.child
        if not isinstance(node, SDFNode):
            raise ParameterError(f"sdf.export: {node!r} is not an SDF node")
        if isinstance(node, Operator):
            kids = [emit(node.a), emit(node.b)]
            e = {"type": node.kind, "children": kids}
            if node.smooth:
                e["k"] = _f(scalar_of(node.k))
        elif node.kind in PRIMITIVE_KEYS:
            e = {"type": node.kind}
            for key in PRIMITIVE_KEYS[node.kind]:
                e[key] = _value(getattr(node, key))
        else:
            raise ParameterError(f"sdf.export: node {node.name!r} of kind {node.kind!r} has no table form")
        e["name"] = unique(node.name)
        moves = np.any(t != 0) or not np.allclose(R, np.eye(3)) or s != 1.0
        if names and moves:                        # (an identity transform makes no keys at all)
            renamed.append((names[0], e["name"]))
        if node.material or material:
            e["material"] = node.material or material
        if np.any(t != 0):
            e["translate"] = t.tolist()
        if not np.allclose(R, np.eye(3)):
            axis, angle = axis_angle(R)
            e["rotate"] = {"axis": axis, "angle": angle}
        if s != 1.0:
            e["scale"] = s
        entries.append(e)
        return e["name"]

    for r in roots:
        emit(r)
    if renamed:
        (own, name), more = renamed[0], f" (and {len(renamed) - 1} more)" if len(renamed) > 1 else ""
        warnings.warn(f"to_entries: the transform {own!r} becomes the translate/rotate/scale of {name!r}{more}; "
                      f"its keys in the scene are sdf.{name}_xf.translate and sdf.{name}_xf.scale",
                      RuntimeWarning, stacklevel=2)
    return entries
