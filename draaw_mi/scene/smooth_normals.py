"""Vertex normals for ``smooth = true`` meshes: smooth across split vertices, sharp at creases.

Why not Mitsuba's own: a mesh file splits a vertex wherever its corners' texture coordinates
(or file normals) differ, and Mitsuba averages face normals over each split vertex alone. On
GO-Draaw's ``monkey.obj`` (1974 vertices at 513 positions) that leaves ``smooth = true`` almost
as faceted as flat shading. Averaging over every face at a position instead would round off
the edges that the model means to be sharp (its floor meets its wall at 90°) and cancel the
normals of surfaces that only touch. So each corner's normal here is the angle-weighted mean
(Mitsuba's weighting) of the unit normals of the faces at its position that lie within
``crease_deg`` of its own face; the mesh is re-indexed so that each vertex has one normal.
A file's material parts are smoothed together (:func:`smooth_parts`). The normals are made
once, at load: ``params.update()`` after a change of ``vertex_positions`` has Mitsuba
recompute them over each vertex alone.

>>> import numpy as np
>>> v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)   # a corner of a box
>>> f = np.array([[0, 1, 2], [0, 3, 1]])                  # two faces at 90°: +z and +y
>>> _, faces, _, n = smooth_normals(v, f)
>>> n[faces[0]].round(3).tolist() == [[0, 0, 1]] * 3                    # the crease stays sharp
True
>>> _, faces, _, n = smooth_normals(v, f, crease_deg=180)
>>> [round(float(x), 3) for x in n[faces[0][0]]]                       # smoothed across it
[0.0, 0.707, 0.707]
"""
from __future__ import annotations

import numpy as np

#: faces whose normals differ by more than this (degrees) keep their own normals at a shared
#: position; 60° smooths the low-polygon curvature of a mesh like GO-Draaw's monkey and keeps a
#: box's or a room's right angles sharp
CREASE_DEG = 60.0


def smooth_normals(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None,
                   crease_deg: float = CREASE_DEG):
    """``(vertices, faces, uv, normals)``: the mesh re-indexed with one unit normal per vertex
    (float32), smooth across vertices at the same position and sharp where faces meet at more
    than ``crease_deg``. Degenerate faces (zero area) add nothing to their neighbours and take
    the normal of all other faces at their position (+z where there are none)."""
    return reindexed(vertices, faces, uv, corner_normals(vertices, faces, crease_deg))


def smooth_parts(parts, crease_deg: float = CREASE_DEG) -> list:
    """:func:`smooth_normals` of a mesh file's material parts (``MeshPart``) taken together:
    a vertex on the border of two materials gets the same normal on both sides (each part
    alone would leave that seam faceted). One ``(vertices, faces, uv, normals)`` per part."""
    counts = np.cumsum([0] + [len(p.vertices) for p in parts])
    vertices = np.concatenate([p.vertices for p in parts])
    faces = np.concatenate([np.asarray(p.faces, np.int64) + off for p, off in zip(parts, counts)])
    normals = corner_normals(vertices, faces, crease_deg)
    out, first_face = [], 0
    for p in parts:
        rows = slice(first_face, first_face + len(p.faces))
        first_face += len(p.faces)
        out.append(reindexed(p.vertices, p.faces, p.uv, normals[rows]))
    return out


def corner_normals(vertices: np.ndarray, faces: np.ndarray, crease_deg: float = CREASE_DEG) -> np.ndarray:
    """``(faces, 3, 3)`` float64: the unit normal at each face's corners (see the module
    docstring)."""
    if not 0.0 <= crease_deg <= 180.0:
        raise ValueError(f"smooth_normals: crease_deg={crease_deg!r}; expected degrees in [0, 180]")
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cross = np.cross(b - a, c - a)
    length = np.linalg.norm(cross, axis=1, keepdims=True)
    unit = np.divide(cross, length, out=np.zeros_like(cross), where=length > 0)
    angles = np.stack([_angle(a, b, c), _angle(b, c, a), _angle(c, a, b)], axis=1)

    corner_face = np.repeat(np.arange(len(f)), 3)
    _, position = np.unique(v, axis=0, return_inverse=True)
    corner_position = position.ravel()[f.ravel()]
    weighted = unit[corner_face] * angles.ravel()[:, None]       # each corner's contribution
    normals = _gather_within_crease(corner_position, unit[corner_face], weighted,
                                    np.cos(np.radians(crease_deg)))
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
    normals[length[:, 0] == 0] = (0.0, 0.0, 1.0)
    return normals.reshape(-1, 3, 3)


def reindexed(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None, normals: np.ndarray):
    """The mesh with one vertex per distinct (vertex, corner normal): corners that share both
    share a vertex. ``normals``: ``(faces, 3, 3)``, as :func:`corner_normals` gives them."""
    corner_vertex = np.asarray(faces, dtype=np.int64).ravel()
    normals32 = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
    key = np.concatenate([corner_vertex[:, None].astype(np.float64), normals32], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    src = corner_vertex[first]
    out_uv = None if uv is None else np.asarray(uv, dtype=np.float32)[src]
    return (np.asarray(vertices, dtype=np.float32)[src], inverse.ravel().reshape(-1, 3).astype(np.uint32),
            out_uv, normals32[first])


def _angle(p, q, r) -> np.ndarray:
    """The angle at ``p`` of the triangles ``(p, q, r)``; 0 where an edge has no length."""
    e1, e2 = q - p, r - p
    n1, n2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
    den = n1 * n2
    cos = np.divide((e1 * e2).sum(axis=1), den, out=np.ones_like(den), where=den > 0)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _gather_within_crease(group, face_normal, weighted, cos_crease, chunk=1 << 20) -> np.ndarray:
    """For each corner ``i``: the sum of ``weighted[j]`` over the corners ``j`` of its
    ``group`` (position) whose ``face_normal`` is within the crease of its own
    (``dot >= cos_crease``), or over all of them where its own is zero (a degenerate face).
    Pairs are formed group by group, in chunks of at most ``chunk`` pairs, so a vertex shared
    by thousands of faces (a fan) does not need a square matrix of them all."""
    order = np.argsort(group, kind="stable")
    g = group[order]
    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    sizes = np.diff(np.r_[starts, len(g)])
    out = np.zeros_like(weighted)
    # corners of groups of equal size together: one (groups, size, size) block per size
    for size in np.unique(sizes):
        first = starts[sizes == size]
        if size * size > chunk:                  # a fan: each group alone, rows in chunks
            rows = max(1, chunk // int(size))
            for start in first:
                idx = order[start:start + size]
                n, w = face_normal[idx], weighted[idx]
                for r in range(0, size, rows):
                    near = (n[r:r + rows] @ n.T >= cos_crease - 1e-12) | ~n[r:r + rows, None].any(axis=-1)
                    out[idx[r:r + rows]] = near.astype(np.float64) @ w
            continue
        per_block = max(1, chunk // int(size * size))
        for k in range(0, len(first), per_block):
            idx = order[first[k:k + per_block, None] + np.arange(size)]   # (groups, size)
            n = face_normal[idx]
            near = (np.einsum("gik,gjk->gij", n, n) >= cos_crease - 1e-12) | ~n[:, :, None].any(axis=-1)
            out[idx] = np.einsum("gij,gjk->gik", near.astype(np.float64), weighted[idx])
    return out
