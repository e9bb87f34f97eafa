"""``[[sdf]]`` tables of scene files -> SDF node trees, their hidden proxy shapes and an
:class:`~draaw_mi.sdf.scene.SDFScene`; and fitted values written back into the tables.

``[[sdf]]`` entries use the keys of ``[[shapes]]`` where they overlap, so a sphere moves from
``[[shapes]]`` to ``[[sdf]]`` by renaming the table::

    [[sdf]]                                   # a primitive
    name = "ball"
    type = "sphere"                           # sphere box round_box torus cylinder capsule cone plane
    center = [0, 0.5, 0]
    radius = 0.5
    material = "red"                          # a [materials] name or an inline table
    translate = [1, 0, 0]                     # optional; also rotate = {axis, angle}, scale = s

    [[sdf]]                                   # an operator over named entries
    name = "blob"
    type = "smooth_union"                     # union intersection subtraction smooth_* lse_* ...
    children = ["ball", "block"]              # two or more (folded left); order matters for subtraction
    k = 0.2

    [[sdf]]                                   # GO-Draaw's sphere list (go-draaw-spec.md §5)
    type = "go_draaw_spheres"
    spheres = [{centerX = 0, centerY = 0, centerZ = 0, radius = 16, colorR = 200, ...,
                indexOfOtherSphere = 1, sdfType = 2, amount = 4}]    # or file = "spheres.json"

Entries that no operator names as a child are the *roots*; the scene's SDF is their union
(see :mod:`draaw_mi.sdf.scene` for how the tree reaches the integrators).
"""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from ..errors import DraawError, SceneError, suggest
from ..integrators.features import textured_parameters
from ..sdf.node import FLOAT32_TINY, NAME_PATTERN, SDFNode, is_infinite
from ..sdf.operators import K_DEFAULT, OPERATORS
from ..sdf.primitives import PRIMITIVE_KEYS, PRIMITIVES
from ..sdf.scene import SDFScene
from ..sdf.transforms import Transform, rotation_matrix
from .go_draaw_spheres import go_draaw_entry
from .material_dicts import material_dict
from .meshes import write_ply
from .schema import check_keys, number, rotations, shown, string, vector

COMMON_KEYS = ("type", "name", "material", "translate", "rotate", "scale")
OPERATOR_KEYS = ("children", "k")




def write_back(entries, key: str, value) -> None:
    """Write ``value`` of ``"NODE.PARAM"`` (a key of :meth:`SDFScene.params`) into the
    ``[[sdf]]`` table ``entries`` that made the node, for saving a fitted or tuned scene.
    Raises ``ValueError`` (why) for nodes and parameters that no table key holds: an
    operator's inner node (``NAME_0``: three or more children), a rotation, a
    ``go_draaw_spheres`` file's spheres, and the ``k`` of an operator of three or more
    children (one table key holds the ``k`` of all its inner nodes).

    >>> entries = [{"type": "sphere", "name": "ball", "radius": 0.5}]
    >>> write_back(entries, "ball.radius", 0.6); entries[0]["radius"]
    0.6
    """
    node, _, param = key.partition(".")
    name = node
    if node.endswith("_xf") and param in ("translate", "scale"):
        name = node[:-len("_xf")]                  # the entry's own translate / scale
    for i, entry in enumerate(entries if isinstance(entries, list) else []):
        if not isinstance(entry, dict) or entry.get("name", f"sdf{i}") != name:
            continue
        kind = entry.get("type")
        allowed = (("translate", "scale") if name != node else
                   PRIMITIVE_KEYS.get(kind, ()) if kind in PRIMITIVES else
                   ("k",) if kind in OPERATORS and OPERATORS[kind].smooth else ())
        if param not in allowed:
            raise ValueError(f"[[sdf]] {name!r} ({kind}) has no key {param!r}")
        if param == "k" and len(entry.get("children", [])) > 2:
            raise ValueError(f"[[sdf]] {name!r} has {len(entry['children'])} children; its one 'k' "
                             "is the k of every inner operator")
        entry[param] = value
        return
    raise ValueError(f"no [[sdf]] table makes the node {node!r}")


# --------------------------------------------------------------------------- parsing
def _point(value, where, key: str) -> list[float]:
    """A list of 3 numbers: a point, normal or translation. One number is refused (the Python
    API refuses it too): ``center = 2`` is not (2, 2, 2); only a ``size`` (a cube) broadcasts."""
    if isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and key != "size":
        raise where.error(f"{shown(value)} is one number; expected a list of 3 numbers for {key!r}")
    return vector(value, where)


def _transform_of(entry: dict, where, node: SDFNode) -> SDFNode:
    if not any(k in entry for k in ("translate", "rotate", "scale")):
        return node
    t = _point(entry.get("translate", [0, 0, 0]), where / "translate", "translate")
    R = np.eye(3)
    for axis, angle in rotations(entry, where):
        R = rotation_matrix(axis, angle) @ R
    s = entry.get("scale", 1.0)
    if isinstance(s, list):
        v = vector(s, where / "scale", lo=0.0)
        if max(v) - min(v) > 1e-9 * max(v):
            raise (where / "scale").error(f"{s!r} is not uniform; an SDF keeps exact distances only "
                                          "under uniform scale (give one number)")
        s = v[0]
    s = number(s, where / "scale", lo=0.0, lo_open=True)
    if s < FLOAT32_TINY:                          # (subnormal: 1 / s is inf, the distances NaN)
        raise (where / "scale").error(f"{shown(s)} is below the smallest normal float32; expected a "
                                      f"scale >= {FLOAT32_TINY:.9g}")
    return Transform(node, translate=t, rotation=R, scale=s, name=f"{node.name}_xf")


def _primitive(entry: dict, kind: str, name: str, where) -> SDFNode:
    check_keys(entry, COMMON_KEYS + PRIMITIVE_KEYS[kind], where)
    kw = {}
    for key in PRIMITIVE_KEYS[kind]:
        if key not in entry:
            continue
        v = entry[key]
        if key in ("center", "size", "a", "b", "normal"):
            kw[key] = _point(v, where / key, key)
        else:
            lo = None if key == "offset" else 0.0
            # (a round box's radius may be 0, a sharp box, as RoundBox itself allows)
            closed = key == "offset" or (kind == "round_box" and key == "radius")
            kw[key] = number(v, where / key, lo=lo, lo_open=not closed)
    if "size" in kw and any(x <= 0 for x in kw["size"]):
        raise (where / "size").error(f"{entry['size']!r} has a side <= 0; expected positive edge lengths")
    try:
        return PRIMITIVES[kind](name=name, **kw)
    except DraawError as e:
        raise where.error(str(e)) from None


def build_nodes(entries: list, material_slot, where, resolve=None) -> tuple[list[SDFNode], dict]:
    """Parse ``[[sdf]]`` entries into root nodes. ``material_slot(value, where) -> (id, slot)``
    resolves a ``material`` value (name or inline table) to a material slot; ``resolve(path)``
    a file the entries name (a ``go_draaw_spheres`` file) to where it is, relative to the
    scene file's folder (default: as written)."""
    if not isinstance(entries, list):
        raise where.error("expected a list of SDF tables ([[sdf]])")
    kinds = list(PRIMITIVES) + list(OPERATORS) + ["go_draaw_spheres"]
    tables: dict[str, tuple[dict, object]] = {}
    order: list[str] = []
    extra_roots: list[SDFNode] = []
    for i, entry in enumerate(entries):
        w = where / i
        if not isinstance(entry, dict):
            raise w.error(f"expected an SDF table, got {entry!r}")
        kind = entry.get("type")
        if not isinstance(kind, str):
            raise (w / "type").error(f"{kind!r} is not a string; expected one of {', '.join(kinds)}")
        if kind not in kinds:
            raise (w / "type").error(f"unknown SDF type {kind!r}{suggest(kind, kinds)}")
        if kind == "go_draaw_spheres":
            check_keys(entry, ("type", "spheres", "file", "scale"), w)
            # (the nodes of a second list are named go2_sphere0, ...: names are keys)
            prefix = "go_" if not extra_roots else f"go{len(extra_roots) + 1}_"
            extra_roots.append(go_draaw_entry(entry, material_slot, w, resolve, prefix))
            continue
        name = string(entry.get("name", f"sdf{i}"), w / "name")
        if not NAME_PATTERN.fullmatch(name):
            raise (w / "name").error(f"{name!r}; expected letters, digits, '_' or '-', starting with a "
                                     "letter or '_' (a name is part of the keys sdf.NAME.PARAM)")
        if name in tables:
            raise (w / "name").error(f"duplicate SDF name {name!r}")
        tables[name] = (entry, w)
        order.append(name)

    built: dict[str, SDFNode] = {}
    referenced: set[str] = set()
    visiting: list[str] = []

    def build(name: str) -> SDFNode:
        if name in built:
            return built[name]
        entry, w = tables[name]
        if name in visiting:
            cycle = " -> ".join(visiting[visiting.index(name):] + [name])
            raise (w / "children").error(f"SDF children form a cycle: {cycle}")
        visiting.append(name)
        kind = entry["type"]
        if kind in PRIMITIVES:
            node = _primitive(entry, kind, name, w)
        else:
            check_keys(entry, COMMON_KEYS + OPERATOR_KEYS, w, required=("children",))
            kids = entry["children"]
            if not isinstance(kids, list) or len(kids) < 2 or not all(isinstance(k, str) for k in kids):
                raise (w / "children").error(f"{kids!r}; expected a list of two or more SDF names")
            for k in kids:
                if k not in tables:
                    raise (w / "children").error(f"no SDF named {k!r}{suggest(k, tables)}")
                referenced.add(k)
            cls = OPERATORS[kind]
            k = number(entry.get("k", K_DEFAULT), w / "k", lo=0.0) if cls.smooth else None
            if not cls.smooth and "k" in entry:
                raise (w / "k").error(f"{kind!r} is not a smooth operator and takes no 'k'")
            node = build(kids[0])
            for j, kid in enumerate(kids[1:]):
                nm = name if j == len(kids) - 2 else f"{name}_{j}"
                node = cls(node, build(kid), k, name=nm) if cls.smooth else cls(node, build(kid), name=nm)
        if "material" in entry:
            node.material, node.slot = material_slot(entry["material"], w / "material")
            _assign(node, node.slot)
        node = _transform_of(entry, w, node)
        visiting.pop()
        built[name] = node
        return node

    for name in order:
        build(name)
    roots = [built[n] for n in order if n not in referenced] + extra_roots
    nodes: dict[str, SDFNode] = {}
    for r in roots:
        for n in r.nodes():
            if nodes.setdefault(n.name, n) is not n:     # (a shared child is the same node)
                raise where.error(f"two SDF nodes are named {n.name!r}: names ending in '_xf' or "
                                  "'_0', '_1', ... are given to transforms and to the inner nodes of "
                                  "operators of three or more children, 'go_...' to GO-Draaw spheres; "
                                  "rename the entry")
    return roots, nodes


def _assign(node: SDFNode, slot: int) -> None:
    """Give ``slot`` to every node below ``node`` that has no material of its own."""
    for c in node.children():
        if c.material is None:
            c.slot = slot
            _assign(c, slot)


# --------------------------------------------------------------------------- scene building
def proxy_ply(path: str, bb: mi.ScalarBoundingBox3f) -> str:
    """Write the proxy mesh: one zero-area triangle (a point) at the box centre."""
    c = [0.0, 0.0, 0.0] if is_infinite(bb) else [0.5 * (float(a) + float(b)) for a, b in zip(bb.min, bb.max)]
    write_ply(path, np.array([c, c, c], dtype=np.float32), np.array([[0, 1, 2]], dtype=np.uint32))
    return path


def sdf_dicts(entries, materials: dict, ctx, where):
    """``[[sdf]]`` entries -> ``(proxy shape dicts, SDFScene)``; ``materials`` (the scene's
    material dicts, by id) gains inline and GO-Draaw materials and a default one if needed."""
    slots: list[str] = []

    def material_slot(value, w):
        if isinstance(value, dict):
            mid = ctx.unique("sdf_material")
            materials[mid] = material_dict(mid, value, ctx, w)
        else:
            if not isinstance(value, str):
                raise w.error(f"{value!r} is not a material name or table")
            if value not in materials:
                raise w.error(f"unknown material {value!r}{suggest(value, materials)}")
            mid = value
        if mid not in slots:
            slots.append(mid)
        return mid, slots.index(mid)

    roots, nodes = build_nodes(entries, material_slot, where, resolve=ctx.path)
    if not roots:
        raise where.error("no SDF roots: every entry is a child of another")
    # nodes without any material (no own, no inherited) use a default slot
    default_needed = any(n.material is None and not _has_material_above(r, n)
                         for r in roots for n in r.nodes() if not n.children())
    if default_needed:
        mid = "__sdf_default_material"
        materials[mid] = {"type": "draaw", "two_sided": True}
        slots.append(mid)
        dslot = len(slots) - 1
        for r in roots:
            _default_slots(r, dslot, inherited=False)
    sdf = SDFScene(roots, slots, nodes)
    bb = sdf.bbox()
    shapes = {}
    for pid, mid in zip(sdf.proxy_ids, slots):
        path = proxy_ply(os.path.join(ctx.tmp_dir, ctx.unique("sdf_proxy") + ".ply"), bb)
        shapes[pid] = {"type": "ply", "filename": path, "bsdf": {"type": "ref", "id": mid}}
    return shapes, sdf


def refuse_textured_materials(mi_scene, sdf: SDFScene, source: str) -> None:
    """A :class:`~draaw_mi.errors.SceneError` when an ``[[sdf]]`` object's material has a
    texture or a normal map: an SDF surface has no uv coordinates (its interactions have uv
    (0, 0)), so the texture would render as one colour, the texels at its corner."""
    by_id = {sh.id(): sh for sh in mi_scene.shapes()}
    for slot, (pid, mid) in enumerate(zip(sdf.proxy_ids, sdf.slots)):
        shape = by_id.get(pid)
        textured = textured_parameters(shape.bsdf()) if shape is not None else []
        if textured:
            users = [n.name for n in sdf.nodes.values() if not n.children() and n.slot == slot]
            raise SceneError(f"{source}: [[sdf]] object {', '.join(map(repr, users)) or '?'} uses "
                             f"material {mid!r}, whose {', '.join(textured)} "
                             f"{'is a texture or map' if len(textured) == 1 else 'are textures or maps'}; "
                             "SDF surfaces have no uv coordinates (it would render as one colour, read "
                             "at uv (0, 0)); expected a material of plain values for "
                             "SDF objects (a textured one for [[shapes]] only)")


def _has_material_above(root: SDFNode, target: SDFNode) -> bool:
    def walk(n, inherited):
        has = inherited or n.material is not None
        if n is target:
            return has
        for c in n.children():
            r = walk(c, has)
            if r is not None:
                return r
        return None
    return bool(walk(root, False))


def _default_slots(node: SDFNode, slot: int, inherited: bool) -> None:
    has = inherited or node.material is not None
    if not has:
        node.slot = slot
    for c in node.children():
        _default_slots(c, slot, has)


__all__ = ["build_nodes", "refuse_textured_materials", "sdf_dicts", "write_back"]
