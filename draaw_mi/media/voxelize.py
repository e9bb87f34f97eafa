"""Mesh voxelisation onto a regular (possibly non-cubic) grid, vectorised per triangle.

* ``surface``: a cell is filled when its centre lies within half a cell of the triangle,
  distances measured in *cell units* (each axis scaled by its cell size). Any plane then
  fills at least one cell in every grid column along its dominant axis, so surfaces have no
  holes. GO-Draaw (``go-draaw-spec.md`` §4.1) uses the distance to the triangle's *plane*
  (<= half the largest cell side) plus a barycentric test of the centre's projection, which
  drops cells along the edges of thin triangles and leaves holes; fixed here.
* ``solid``: ``surface`` plus the interior, found by parity along x: every cell-centre line
  parallel to x counts the triangles it crosses (a scanline fill). The mesh should be closed;
  an open mesh fills by the parity of the crossings it has.

    >>> import numpy as np
    >>> from draaw_mi.media.voxelize import voxelize
    >>> tri = np.array([[[0, 0, 0.5], [1, 0, 0.5], [0, 1, 0.5]]], float)
    >>> occ = voxelize(tri, (4, 4, 4), np.zeros(3), np.ones(3), "surface")
    >>> int(occ[:, :, 1:3].sum()) > 0, int(occ[:, :, 0].sum() + occ[:, :, 3].sum())
    (True, 0)
"""
from __future__ import annotations

import os

import numpy as np

from ..errors import IOFailure, ParameterError


def load_triangles(mesh) -> np.ndarray:
    """Triangles (T, 3, 3) float64 of a mesh file (OBJ/PLY/STL/...) or a trimesh object."""
    import trimesh  # (0.36 s to import: paid by voxelised meshes only)
    if isinstance(mesh, (str, os.PathLike)):
        path = os.fspath(mesh)
        if not os.path.isfile(path):
            raise IOFailure(f"voxelize: mesh file {path!r} does not exist")
        try:
            mesh = trimesh.load(path, force="mesh", process=False)
        except Exception as e:  # noqa: BLE001 - trimesh raises many kinds
            raise IOFailure(f"voxelize: cannot read mesh {path!r}: {e}") from None
    if not hasattr(mesh, "triangles"):
        raise ParameterError(f"voxelize: {type(mesh).__name__} is not a mesh; expected a path or trimesh.Trimesh")
    tris = np.asarray(mesh.triangles, dtype=np.float64)
    if tris.ndim != 3 or tris.shape[0] == 0:
        raise ParameterError("voxelize: the mesh has no triangles")
    return tris


def _closest_sq_dist(p: np.ndarray, a, b, c) -> np.ndarray:
    """Squared distance from points ``p`` (N, 3) to triangle ``abc`` (Ericson, RTCD §5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ap @ ab, ap @ ac
    bp = p - b
    d3, d4 = bp @ ab, bp @ ac
    cp = p - c
    d5, d6 = cp @ ab, cp @ ac
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    eps = 1e-300
    # default: inside the face
    denom = va + vb + vc
    denom = np.where(np.abs(denom) > eps, denom, eps)
    v = vb / denom
    w = vc / denom
    q = a + v[:, None] * ab + w[:, None] * ac
    # edge regions
    bc = c - b
    e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    t_ab = d1 / np.where(d1 - d3 != 0, d1 - d3, 1)
    e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    t_ac = d2 / np.where(d2 - d6 != 0, d2 - d6, 1)
    e_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    t_bc = (d4 - d3) / np.where((d4 - d3) + (d5 - d6) != 0, (d4 - d3) + (d5 - d6), 1)
    q = np.where(e_bc[:, None], b + t_bc[:, None] * bc, q)
    q = np.where(e_ac[:, None], a + t_ac[:, None] * ac, q)
    q = np.where(e_ab[:, None], a + t_ab[:, None] * ab, q)
    # vertex regions
    q = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, q)
    q = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, q)
    q = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, q)
    return np.sum((p - q) ** 2, axis=1)


def voxelize(tris: np.ndarray, shape, bbox_min, bbox_max, fill: str = "surface") -> np.ndarray:
    """Occupancy (nx, ny, nz) bool of triangles (T, 3, 3) in world units; see module doc."""
    if fill not in ("surface", "solid"):
        raise ParameterError(f"voxelize: fill={fill!r}; expected 'surface' or 'solid'")
    shape = np.asarray(shape, int)
    lo = np.asarray(bbox_min, float)
    size = (np.asarray(bbox_max, float) - lo) / shape
    t = (np.asarray(tris, float) - lo) / size          # cell units: centres at i + 0.5
    occ = np.zeros(tuple(shape), bool)
    r = 0.5
    # the cells whose centres (i + 0.5) lie within r of the triangle's box, ties included on
    # both sides as the d2 <= r^2 rule includes them (floor(x) + 1 would leave out a lower cell
    # at exactly r: a plane on a cell boundary would fill one layer, a centred box be lopsided)
    tmin = np.ceil(t.min(axis=1) - r - 0.5).astype(int)
    tmax = np.floor(t.max(axis=1) + r - 0.5).astype(int)
    tmin = np.maximum(tmin, 0)
    tmax = np.minimum(tmax, shape[None, :] - 1)
    for k in range(t.shape[0]):
        a, b = tmin[k], tmax[k]
        if np.any(b < a):
            continue
        ax = [np.arange(a[i], b[i] + 1) for i in range(3)]
        g = np.stack(np.meshgrid(*ax, indexing="ij"), axis=-1).reshape(-1, 3)
        d2 = _closest_sq_dist(g + 0.5, t[k, 0], t[k, 1], t[k, 2])
        hit = g[d2 <= r * r]
        occ[hit[:, 0], hit[:, 1], hit[:, 2]] = True
    if fill == "solid":
        occ |= _parity_fill(t, shape)
    return occ


def _parity_fill(t: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """Cells whose centre has an odd number of triangle crossings on the -x side."""
    nx, ny, nz = (int(s) for s in shape)
    counts = np.zeros((nx + 1, ny, nz), np.int32)
    jitter = np.array([1.3e-7, 2.9e-7])                 # keeps centres off shared edges
    for tri in t:
        y, z = tri[:, 1], tri[:, 2]
        area = (y[1] - y[0]) * (z[2] - z[0]) - (y[2] - y[0]) * (z[1] - z[0])
        if abs(area) < 1e-14:
            continue
        j0, j1 = max(0, int(np.ceil(y.min() - 0.5))), min(ny - 1, int(np.floor(y.max() - 0.5)))
        k0, k1 = max(0, int(np.ceil(z.min() - 0.5))), min(nz - 1, int(np.floor(z.max() - 0.5)))
        if j1 < j0 or k1 < k0:
            continue
        jj, kk = np.meshgrid(np.arange(j0, j1 + 1), np.arange(k0, k1 + 1), indexing="ij")
        py = jj.ravel() + 0.5 + jitter[0]
        pz = kk.ravel() + 0.5 + jitter[1]
        # barycentrics in the yz projection
        w1 = ((py - y[0]) * (z[2] - z[0]) - (y[2] - y[0]) * (pz - z[0])) / area
        w2 = ((y[1] - y[0]) * (pz - z[0]) - (py - y[0]) * (z[1] - z[0])) / area
        w0 = 1.0 - w1 - w2
        inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        if not np.any(inside):
            continue
        x = w0 * tri[0, 0] + w1 * tri[1, 0] + w2 * tri[2, 0]
        ix = np.clip(np.ceil(x[inside] - 0.5).astype(int), 0, nx)
        np.add.at(counts, (ix, jj.ravel()[inside], kk.ravel()[inside]), 1)
    return (np.cumsum(counts, axis=0)[:nx] % 2) == 1
