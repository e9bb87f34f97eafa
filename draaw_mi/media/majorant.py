"""Local majorant grids for Mitsuba media (built once per scene preparation, in numpy).

Mitsuba 3.9.1's ``heterogeneous`` medium has *one* majorant, ``scale * max(sigma_t)``, so
delta tracking through sparse smoke takes steps sized by the densest voxel everywhere
(anchors-volumes §1). Following pbrt-v4 (``MajorantGrid``, 16^3 cells over the medium's box),
:func:`build_majorant` max-pools the medium's own ``sigma_t`` grid data to a coarse grid; the
integrators walk it with a DDA and track within each coarse cell against its own bound.

* Conservative for both ``nearest`` and ``trilinear`` lookups: each coarse cell takes the
  maximum over the voxels it overlaps *dilated by one voxel* (a trilinear lookup blends the
  neighbouring voxel centres).
* The grid's placement is not exposed by ``gridvolume``; it is recovered from the medium's
  ``intersect_aabb`` and then *verified* by evaluating ``sigma_t`` at sampled voxel centres
  against ``scale * data``. If that check fails (a rotated or mirrored ``to_world``, a
  Python medium, spectral data) the medium falls back to one global majorant (Mitsuba's own
  bound: always correct, only slower).
* Values are plain numbers: the majorant is *detached* from any gradient (guide §3.4).

    >>> import numpy as np, mitsuba as mi, draaw_mi
    >>> from draaw_mi.media.majorant import build_majorant
    >>> d = np.zeros((32, 32, 32, 1), np.float32); d[3, 4, 5] = 10.0
    >>> m = mi.load_dict({'type': 'heterogeneous', 'sigma_t': {'type': 'gridvolume',
    ...                   'data': mi.TensorXf(d)}, 'scale': 2.0})
    >>> maj = build_majorant(m, resolution=16)
    >>> maj.kind, maj.values.shape, float(maj.values.max()), int((maj.values > 0).sum())
    ('grid', (16, 16, 16), 20.0, 8)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GLOBAL_BOX = 1e6        # half-size of the box of a global (1x1x1) majorant
UNIFORM_GAIN = 1.3      # local grid kept only if max > 1.3 x mean of the local bounds


@dataclass
class Majorant:
    """``kind``: ``'homogeneous'`` (closed-form tracking, ``sigma_t`` constant), ``'grid'``
    (a local majorant grid) or ``'global'`` (one bound everywhere). ``values`` is indexed
    ``[ix, iy, iz]`` over ``bbox_min .. bbox_max``; ``note`` says why a fallback was used."""
    kind: str
    values: np.ndarray
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    note: str = ""


def _probe_box(medium, inside) -> tuple[np.ndarray, np.ndarray] | None:
    """The medium's box from ``intersect_aabb`` rays through a point ``inside`` it."""
    import mitsuba as mi
    lo, hi = np.zeros(3), np.zeros(3)
    for a in range(3):
        d = [0.0, 0.0, 0.0]
        d[a] = 1.0
        ray = mi.Ray3f(mi.Point3f(*[float(v) for v in inside]), mi.Vector3f(*d))
        ok, mint, maxt = medium.intersect_aabb(ray)
        if not bool(ok[0]) or not np.isfinite(mint[0]) or not np.isfinite(maxt[0]):
            return None
        lo[a], hi[a] = inside[a] + float(mint[0]), inside[a] + float(maxt[0])
    if np.any(hi <= lo):
        return None
    return lo, hi


def _pool(data: np.ndarray, res) -> np.ndarray:
    """Max over the voxels each coarse cell overlaps, dilated by one voxel; data [ix, iy, iz]."""
    n = np.asarray(data.shape)
    out = data
    for a in range(3):
        edges = np.linspace(0, n[a], res[a] + 1)
        i0 = np.maximum(np.floor(edges[:-1]).astype(int) - 1, 0)
        i1 = np.minimum(np.ceil(edges[1:]).astype(int) + 1, n[a])
        # running maximum over [i0, i1) along axis a
        slabs = [np.max(np.take(out, np.arange(s, e), axis=a), axis=a, keepdims=True)
                 for s, e in zip(i0, i1)]
        out = np.concatenate(slabs, axis=a)
    return out


def build_majorant(medium, resolution: int = 16, inside=None) -> Majorant:
    """Majorant of a Mitsuba medium (see module doc). ``inside``: a point inside the medium's
    box used to locate it (default: its centre as reported for a probe from the origin)."""
    import drjit as dr
    import mitsuba as mi
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p = mi.Point3f(*[float(v) for v in (inside if inside is not None else (0.0, 0.0, 0.0))])
    if medium.is_homogeneous():
        return Majorant("homogeneous", np.zeros((1, 1, 1)), np.full(3, -GLOBAL_BOX), np.full(3, GLOBAL_BOX))
    glob = float(np.max(np.array(medium.get_majorant(mei))))
    fallback = Majorant("global", np.full((1, 1, 1), glob), np.full(3, -GLOBAL_BOX), np.full(3, GLOBAL_BOX))
    params = mi.traverse(medium)
    if "sigma_t.data" not in params.keys() or "scale" not in params.keys():
        fallback.note = "no sigma_t grid data"
        return fallback
    raw = np.array(params["sigma_t.data"], dtype=np.float64)
    scale = float(params["scale"])
    if raw.ndim != 4 or raw.shape[3] != 1:
        fallback.note = f"sigma_t grid of shape {raw.shape} (spectral data)"
        return fallback
    data = scale * raw[..., 0].transpose(2, 1, 0)                 # -> [ix, iy, iz]
    box = None
    for p in ([inside] if inside is not None else []) + [np.zeros(3)]:
        box = _probe_box(medium, np.asarray(p, float))
        if box is not None:
            break
    if box is None:
        fallback.note = "could not locate the grid's box"
        return fallback
    lo, hi = box
    # verify the placement: sigma_t at sampled voxel centres equals scale * data
    n = np.asarray(data.shape)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, n, size=(min(2048, int(n.prod())), 3))
    idx = np.concatenate([idx, np.argwhere(data == data.max())[:64]])
    centres = lo + (idx + 0.5) * (hi - lo) / n
    m = dr.zeros(mi.MediumInteraction3f, len(idx))
    m.p = mi.Point3f(*[mi.Float(centres[:, k].astype(np.float32)) for k in range(3)])
    m.medium = mi.MediumPtr(medium)
    _, _, sigma_t = medium.get_scattering_coefficients(m)
    got = np.array(sigma_t)[0]
    want = data[idx[:, 0], idx[:, 1], idx[:, 2]]
    if not np.allclose(got, want, rtol=1e-4, atol=1e-6 * max(1.0, float(data.max()))):
        fallback.note = "grid placement not axis-aligned (rotated or mirrored to_world)"
        return fallback
    res = tuple(int(min(resolution, s)) for s in n)
    local = _pool(data, res)
    # A nearly uniform grid gains nothing from local bounds but pays a DDA step per coarse
    # cell crossed: bound it with a single cell over its box instead.
    if float(local.max()) <= UNIFORM_GAIN * float(local.mean()):
        return Majorant("grid", np.full((1, 1, 1), float(local.max())), lo, hi, "nearly uniform: one cell")
    return Majorant("grid", local, lo, hi)
