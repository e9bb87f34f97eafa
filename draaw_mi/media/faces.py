"""Solid voxels as triangle meshes: only the *exterior* faces (a face between two occupied
cells is never emitted), merged into one Mitsuba mesh per material / colour group.

Each exposed cell face becomes a quad (two triangles, outward winding) with its own four
vertices, so per-face colours stay sharp. By default one mesh holds every face and the
voxel colours ride along as the face attribute ``face_color``, read by the ``draaw``
material through a ``mesh_attribute`` texture (differentiable through ``mi.traverse`` as
``<id>.face_color``); ``group_by="color"`` instead makes one mesh per distinct colour with
a constant ``base_color`` (for BSDFs that cannot read attributes). Hard shadows and every
integrator come for free: they are ordinary triangles.

    >>> import numpy as np
    >>> from draaw_mi.media.faces import exterior_faces
    >>> occ = np.zeros((3, 3, 3), bool); occ[1, 1, 1] = occ[1, 1, 2] = True
    >>> v, f, cell = exterior_faces(occ, (0, 0, 0), (1, 1, 1))
    >>> f.shape[0] // 2                               # 2 cubes sharing a face: 10 quads
    10
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

from ..errors import ParameterError

# For each of the 6 directions (axis, sign): the quad's corners as offsets in the cell,
# ordered counter-clockwise seen from outside (outward normal by the right-hand rule).
_QUADS = {
    (0, -1): [(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)],
    (0, +1): [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)],
    (1, -1): [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)],
    (1, +1): [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)],
    (2, -1): [(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)],
    (2, +1): [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],
}


def exposed_mask(occ: np.ndarray, axis: int, sign: int) -> np.ndarray:
    """Occupied cells whose neighbour in direction ``sign`` along ``axis`` is empty
    (outside the grid counts as empty)."""
    pad = [(0, 0)] * 3
    pad[axis] = (1, 1)
    p = np.pad(occ, pad)
    sl = [slice(None)] * 3
    sl[axis] = slice(2, None) if sign > 0 else slice(0, -2)
    return occ & ~p[tuple(sl)]


def exterior_faces(occ, bbox_min, bbox_max):
    """``(vertices (4F, 3) float32, triangles (2F, 3) uint32, cells (F, 3) int)`` of the F
    exposed faces of the occupied cells ``occ`` in the box ``bbox_min .. bbox_max``."""
    occ = np.asarray(occ, bool)
    lo = np.asarray(bbox_min, np.float64)
    size = (np.asarray(bbox_max, np.float64) - lo) / np.asarray(occ.shape)
    verts, cells = [], []
    for (axis, sign), corners in _QUADS.items():
        idx = np.argwhere(exposed_mask(occ, axis, sign))
        if idx.size == 0:
            continue
        c = np.asarray(corners, np.float64)                       # (4, 3)
        verts.append(lo + (idx[:, None, :] + c[None]) * size)     # (n, 4, 3)
        cells.append(idx)
    if not verts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32), np.zeros((0, 3), int)
    v = np.concatenate(verts).reshape(-1, 3).astype(np.float32)
    cells = np.concatenate(cells)
    base = (np.arange(cells.shape[0], dtype=np.uint32) * 4)[:, None]
    tris = np.concatenate([base + np.array([0, 1, 2], np.uint32), base + np.array([0, 2, 3], np.uint32)], axis=1)
    return v, tris.reshape(-1, 3), cells


def _mesh(name: str, v: np.ndarray, f: np.ndarray, bsdf, face_color: np.ndarray | None):
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = bsdf
    mesh = mi.Mesh(name, v.shape[0], f.shape[0], props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(v.ravel())
    params["faces"] = mi.UInt32(f.ravel())
    params.update()
    if face_color is not None:
        mesh.add_attribute("face_color", 3, mi.Float(np.repeat(face_color, 2, axis=0).astype(np.float32).ravel()))
    return mesh


#: the colour parameter of the BSDFs solid voxels can be coloured with (group_by="color")
_COLOUR_KEYS = {"draaw": "base_color", "principled": "base_color", "diffuse": "reflectance",
                "plastic": "diffuse_reflectance", "roughplastic": "diffuse_reflectance",
                "conductor": "specular_reflectance", "roughconductor": "specular_reflectance"}


def solid_meshes(grid, material: dict | None = None, name: str = "voxels", group_by: str | None = None) -> dict:
    """Mitsuba meshes (``{id: mi.Mesh}``) of ``grid``'s solid voxels (exterior faces only).

    ``material``: parameters of the ``draaw`` BSDF (``roughness``, ``metallic``, ...; any
    ``base_color`` is replaced by the voxel colours) or a full Mitsuba BSDF dict with a
    ``type`` (then ``group_by="color"`` is needed for colours). Empty grids give ``{}``.
    """
    if group_by not in (None, "color"):
        raise ParameterError(f"solid_meshes: group_by={group_by!r}; expected None or 'color'")
    v, f, cells = exterior_faces(grid.occupied, grid.bbox_min, grid.bbox_max)
    if cells.shape[0] == 0:
        return {}
    mat = dict(material or {})
    mat.setdefault("type", "draaw")
    mat.pop("base_color", None) if mat["type"] == "draaw" else None
    colors = grid.color[cells[:, 0], cells[:, 1], cells[:, 2]]
    if group_by is None:
        if mat["type"] != "draaw":
            raise ParameterError("solid_meshes: per-face colours need the 'draaw' material; "
                                 "use group_by='color' for other BSDFs")
        bsdf = mi.load_dict(dict(mat, base_color={"type": "mesh_attribute", "name": "face_color"}))
        return {name: _mesh(name, v, f, bsdf, colors)}
    key = _COLOUR_KEYS.get(mat["type"])
    if key is None:             # (else Mitsuba's 'unreferenced property "base_color"')
        raise ParameterError(f"solid_meshes: material type {mat['type']!r} has no colour parameter "
                             f"draaw-mi knows; expected one of {', '.join(sorted(_COLOUR_KEYS))}")
    out = {}
    uniq, inv = np.unique(colors, axis=0, return_inverse=True)
    inv = inv.ravel()
    for k, col in enumerate(uniq):
        sel = np.nonzero(inv == k)[0]
        vk = v.reshape(-1, 4, 3)[sel].reshape(-1, 3)
        fk = f[: 2 * sel.size]                                 # local indices restart at 0
        bsdf = mi.load_dict(dict(mat, **{key: {"type": "rgb", "value": col.tolist()}}))
        out[f"{name}_{k}"] = _mesh(f"{name}_{k}", vk, fk, bsdf, None)
    return out
