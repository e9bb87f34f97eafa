"""GO-Draaw's sphere lists (its ``/getSpheres`` records: spheres, each combined with another by
one of ten operators) as SDF trees, for ``type = "go_draaw_spheres"`` entries of ``[[sdf]]``."""
from __future__ import annotations

import json
import warnings

from ..errors import SceneError, suggest
from ..sdf.node import SDFNode
from ..sdf.operators import (
    cubic_smooth_intersection,
    cubic_smooth_subtraction,
    cubic_smooth_union,
    intersection,
    lse_intersection,
    smooth_lse_intersection,
    subtraction,
    union,
)
from ..sdf.primitives import Sphere
from .schema import Where, number, string

GO_DRAAW_TYPES = {0: "distance", 1: "union", 2: "smoothUnion", 3: "intersection",
                  4: "smoothIntersection", 5: "subtraction", 6: "smoothSubtraction", 7: "addition",
                  8: "smoothAddition", 9: "smoothUnionNoColorMix"}
#: the fields of a /getSpheres record
RECORD_KEYS = ("centerX", "centerY", "centerZ", "radius", "colorR", "colorG", "colorB", "colorA",
               "indexOfOtherSphere", "sdfType", "amount")


def go_draaw_entry(entry: dict, material_slot, where, resolve=None, prefix: str = "go_") -> SDFNode:
    if ("spheres" in entry) == ("file" in entry):
        raise where.error("a go_draaw_spheres entry needs exactly one of 'spheres' or 'file'")
    spheres = entry.get("spheres")
    if "file" in entry:
        path = string(entry["file"], where / "file")
        if resolve is not None:
            path = resolve(path)
        try:
            with open(path, encoding="utf-8") as f:
                spheres = json.load(f)
        except OSError as e:
            raise (where / "file").error(f"cannot read {path!r} ({e.strerror})") from None
        except json.JSONDecodeError as e:
            raise (where / "file").error(f"malformed JSON at line {e.lineno}: {e.msg}") from None
    s = number(entry.get("scale", 1.0), where / "scale", lo=0.0, lo_open=True)
    return go_draaw_spheres(spheres, lambda i, col: material_slot(
        {"base_color": col}, where / "spheres" / i), scale=s, where=where / "spheres", prefix=prefix)


def go_draaw_spheres(spheres: list, material_slot=None, scale: float = 1.0, where=None,
                     prefix: str = "go_") -> SDFNode:
    """A GO-Draaw sphere list (``/getSpheres`` records) as one SDF tree.

    Each sphere ``i`` contributes ``op_i(sphere_i, sphere_j)`` with ``j =
    indexOfOtherSphere`` and ``op`` from ``sdfType`` (0 distance, 1 union, 2 smoothUnion,
    3 intersection, 4 smoothIntersection, 5 subtraction, 6 smoothSubtraction, 7 addition,
    8 smoothAddition, 9 smoothUnionNoColorMix; names accepted too), ``k = amount * scale``; the
    result is the union of the contributions, as GO-Draaw's march takes their minimum.
    The smooth ones keep GO-Draaw's cubic blend (``min - h^3 k / 6``,
    :func:`~draaw_mi.sdf.operators.cubic_smooth_union`: the polynomial smooth union would shrink
    touching spheres by k/4 instead of k/6 and bridge a gap GO-Draaw leaves open). GO-Draaw's
    bugs are fixed (go-draaw-spec.md §5.2): smoothUnion blends the two colours
    (type 9 keeps sphere i's), smoothIntersection uses ``k - |a - b|``, both subtractions
    remove sphere ``i`` from sphere ``j`` (GO-Draaw's ``subtraction`` order), addition /
    smoothAddition are the log-sum-exp soft intersections. As in GO-Draaw, a sphere whose
    operator needs another sphere but whose index is out of range is skipped.
    ``material_slot(i, rgb) -> (id, slot)`` assigns materials (colour = colorR..B / 255).
    """
    where = where or Where("go_draaw_spheres")
    if not isinstance(spheres, list) or not spheres:
        raise where.error("expected a non-empty list of GO-Draaw sphere records")
    names = {v: k for k, v in GO_DRAAW_TYPES.items()}
    prims, types, others, ks = [], [], [], []
    for i, rec in enumerate(spheres):
        w = where / i
        if not isinstance(rec, dict):
            raise w.error(f"expected a sphere record, got {rec!r}")
        for key in rec:          # (a misspelt 'centreX' would leave the sphere at the origin)
            if key not in RECORD_KEYS:
                raise (w / str(key)).error(f"unknown key of a GO-Draaw sphere record"
                                           f"{suggest(str(key), RECORD_KEYS)}")
        c = [number(rec.get(f"center{a}", 0.0), w / f"center{a}") * scale for a in "XYZ"]
        r = number(rec.get("radius", 16.0), w / "radius", lo=0.0, lo_open=True) * scale
        col = [number(rec.get(f"color{a}", 255), w / f"color{a}", lo=0, hi=255) / 255.0 for a in "RGB"]
        t = rec.get("sdfType", 0)
        if isinstance(t, str):
            t = names.get(t if t != "smothUnionNoColorMix" else "smoothUnionNoColorMix")
            if t is None:
                raise (w / "sdfType").error(f"unknown GO-Draaw operator {rec['sdfType']!r}"
                                            f"{suggest(str(rec['sdfType']), names)}")
        elif isinstance(t, bool) or not isinstance(t, int) or t not in GO_DRAAW_TYPES:
            raise (w / "sdfType").error(f"{t!r} is not a GO-Draaw operator; expected 0..9 or a name")
        sp = Sphere(c, r, name=f"{prefix}sphere{i}")
        if material_slot is not None:
            sp.material, sp.slot = material_slot(i, col)
        prims.append(sp)
        types.append(t)
        others.append(rec.get("indexOfOtherSphere", -1))
        ks.append(number(rec.get("amount", 0.0), w / "amount", lo=0.0) * scale)
    parts = []
    for i, (sp, t, j, k) in enumerate(zip(prims, types, others, ks)):
        if t == 0:
            parts.append(sp)
            continue
        if isinstance(j, bool) or not isinstance(j, int) or not (0 <= j < len(prims)):
            # GO-Draaw's march skips these (its /updateSphere refuses such an index)
            warnings.warn(f"{where / i}: indexOfOtherSphere {j!r} names no sphere of the list "
                          f"(0..{len(prims) - 1}); as in GO-Draaw, sphere {i} is left out",
                          RuntimeWarning, stacklevel=2)
            continue
        o = prims[j]
        nm = f"{prefix}op{i}"
        node = {1: lambda: union(sp, o, name=nm), 2: lambda: cubic_smooth_union(sp, o, k, name=nm),
                9: lambda: cubic_smooth_union(sp, o, k, name=nm, material=sp.material),
                3: lambda: intersection(sp, o, name=nm),
                4: lambda: cubic_smooth_intersection(sp, o, k, name=nm),
                5: lambda: subtraction(o, sp, name=nm),
                6: lambda: cubic_smooth_subtraction(o, sp, k, name=nm),
                # GO-Draaw's log(e^a + e^b) in its own units: at `scale`, a temperature of
                # `scale` (a fixed 1 shrank a list scaled by 1/75 by up to ln 2 world units)
                7: lambda: (lse_intersection(sp, o, name=nm) if scale == 1.0
                            else smooth_lse_intersection(sp, o, scale, name=nm)),
                8: lambda: smooth_lse_intersection(sp, o, k, name=nm)}[t]()
        if t == 9:
            node.slot = sp.slot
        parts.append(node)
    if not parts:
        raise SceneError(f"{where}: no sphere survives (every operator names a missing other sphere)")
    root = parts[0]
    for n, p in enumerate(parts[1:]):
        root = union(root, p, name=f"{prefix}union{n}")
    return root
