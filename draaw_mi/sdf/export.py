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
``RuntimeWarning`` says so where it was named otherwise). A node whose name (or, moved, whose
``NAME_xf``) an earlier table took gets the first ``_1``, ``_2``... suffix that no table and no
node of the trees has; a node shared by two operators is one table named by both.
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

    A node that two operators share (the same object, under the same transforms) is one
    table that both name as a child, so it stays one node (one ``sdf.NAME.radius``) in the
    scene; under different transforms it is written once per transform (a
    ``RuntimeWarning`` says that the copies become independent).
    """
    entries: list[dict] = []
    # every name the trees give their nodes, so that a made-up NAME_N takes none of them
    # (s, s, s_1: the second s becomes s_2, not a second s_1)
    wanted = {n.name for r in roots if isinstance(r, SDFNode) for n in r.nodes()
              if not isinstance(n, Transform)}
    taken: set[str] = set()                      # the tables' names and their NAME_xf
    done: dict[tuple, str] = {}                  # (id(node), transform, material) -> its table
    first: dict[int, tuple] = {}                 # id(node) -> the key of its first table
    split: list[str] = []                        # shared nodes written twice (other transforms)
    renamed: list[tuple[str, str]] = []          # (a transform's own name, the node it folds into)

    def unique(name: str, moved: bool) -> str:
        """``name`` if no table took it, else the first ``name_N`` that neither a table nor a
        node of the trees has; a moved node's ``NAME_xf`` (the loader's transform node) the same."""
        def free(cand: str, own: bool) -> bool:
            return cand not in taken and (own or cand not in wanted)
        n = 0
        while True:
            cand = name if n == 0 else f"{name}_{n}"
            if free(cand, n == 0) and not (moved and not free(f"{cand}_xf", n == 0)):
                taken.update((cand, f"{cand}_xf") if moved else (cand,))
                return cand
            n += 1

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
        key = (id(node), s, tuple(R.ravel()), tuple(t), node.material or material)
        if key in done:                            # a shared child: one table, named twice
            return done[key]
        if first.setdefault(id(node), key) != key:
            split.append(node.name)
        if isinstance(node, Operator):
            kids = [emit(node.a), emit(node.b)]
            e = {"type": node.kind, "children": kids}
            if node.smooth:
                e["k"] = _f(scalar_of(node.k))
        elif node.kind in PRIMITIVE_KEYS:
            e = {"type": node.kind}
            for k in PRIMITIVE_KEYS[node.kind]:
                e[k] = _value(getattr(node, k))
        else:
            raise ParameterError(f"sdf.export: node {node.name!r} of kind {node.kind!r} has no table form")
        moves = bool(np.any(t != 0)) or not np.allclose(R, np.eye(3)) or s != 1.0
        e["name"] = unique(node.name, moves)
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
        done[key] = e["name"]
        return e["name"]

    for r in roots:
        emit(r)
    if renamed:
        (own, name), more = renamed[0], f" (and {len(renamed) - 1} more)" if len(renamed) > 1 else ""
        warnings.warn(f"to_entries: the transform {own!r} becomes the translate/rotate/scale of {name!r}{more}; "
                      f"its keys in the scene are sdf.{name}_xf.translate and sdf.{name}_xf.scale",
                      RuntimeWarning, stacklevel=2)
    if split:
        warnings.warn(f"to_entries: node {split[0]!r} is shared under different transforms or materials; "
                      "a table holds one transform, so it is written once per transform and the copies' "
                      "parameters are independent in the scene", RuntimeWarning, stacklevel=2)
    return entries
