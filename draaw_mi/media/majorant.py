"""Local majorant grids for Mitsuba media (built once per scene preparation, in numpy).

Mitsuba 3.9.1's ``heterogeneous`` medium has *one* majorant, ``scale * max(sigma_t)``, so
delta tracking through sparse smoke takes steps sized by the densest voxel everywhere
(anchors-volumes §1). Following pbrt-v4 (``MajorantGrid``, 16^3 cells over the medium's box),
:func:`build_majorant` max-pools the medium's own ``sigma_t`` grid data to a coarse grid; the
integrators walk it with a DDA and track within each coarse cell against its own bound.

* **Cells between voxel centres.** The cells' faces lie on voxel *centres*, so a cell of
  ``k`` voxels per axis spans ``k + 1`` voxel centres and takes their maximum: a trilinear
  lookup inside it blends only those centres (a tight bound), a ``nearest`` lookup reads one
  of them (conservative too). Cells with faces on voxel faces would need a one-voxel
  dilation (``k + 2`` voxels): with one dense voxel in a 4^3 grid that spreads its bound over
  27 of 64 cells, and flights through empty space run out of steps (too dark a render).
* **Cell size chosen per medium.** ``k`` starts at ``resolution`` cells per axis and halves
  down to one voxel, keeping the level of least expected work per ray -- ``chord * (sum_a
  1 / (2 k h_a) + mean(majorant))``: DDA steps plus tentative collisions over a box's mean
  chord -- among the levels whose densest cell is at most ``MAX_CELL_DEPTH`` optical depths
  across (in differentiated renders, whose bounds are scaled, after the scaling), else the
  finest level. A flight through a thin part of such a cell takes up to that many null
  steps; the trackers' ``MAX_TRACKING_STEPS`` (65536), past which a flight counts as
  absorbed, is far above what a few such cells need.
* The grid's placement is not exposed by ``gridvolume``; it is recovered from the medium's
  ``intersect_aabb`` and then *verified* by evaluating ``sigma_t`` at sampled voxel centres,
  and a quarter voxel inside each face, against ``scale * data``. If that check fails (a
  rotated or mirrored ``to_world``, a wrap mode other than ``clamp``, a Python medium,
  spectral data) the medium falls back to one global majorant (Mitsuba's own
  bound, ``scale * max(sigma_t)`` everywhere in its box). That bound is correct but costs
  ``bound * chord`` null steps per crossing: where a hot voxel in thin smoke makes ``bound *
  diagonal`` (``Majorant.diagonal``, the located box's) reach the trackers' step budget,
  flights run out of steps and count as absorbed (a dark image), which the integrators say in a
  ``RuntimeWarning`` (:class:`draaw_mi.integrators.volume.MediaTable`). A medium dense
  throughout (``Majorant.median``) ends its flights in a few steps and is not warned of.
* Values are plain numbers: the majorant is *detached* from any gradient (guide §3.4).

    >>> import numpy as np, mitsuba as mi, draaw_mi
    >>> from draaw_mi.media.majorant import build_majorant
    >>> d = np.zeros((32, 32, 32, 1), np.float32); d[3, 4, 5] = 10.0
    >>> m = mi.load_dict({'type': 'heterogeneous', 'sigma_t': {'type': 'gridvolume',
    ...                   'data': mi.TensorXf(d)}, 'scale': 2.0})
    >>> maj = build_majorant(m, resolution=16)
    >>> maj.kind, maj.values.shape, float(maj.values.max()), int((maj.values > 0).sum())
    ('grid', (17, 17, 17), 20.0, 2)
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError

GLOBAL_BOX = 1e6        # half-size of the box of a global (1x1x1) majorant
UNIFORM_GAIN = 1.3      # local grid kept only if max > 1.3 x mean of the local bounds
MAX_CELL_DEPTH = 2048.0  # densest cell's majorant x diagonal, where a level can keep it
MAX_CELLS = 1 << 21     # finest level allowed (~128^3 cells, 8 MB of float32)


@dataclass
class Majorant:
    """``kind``: ``'homogeneous'`` (closed-form tracking, ``sigma_t`` constant), ``'grid'``
    (a local majorant grid) or ``'global'`` (one bound everywhere). ``values`` is indexed
    ``[ix, iy, iz]`` over ``bbox_min .. bbox_max``; ``note`` says why a fallback was used, or the
    voxels per cell of a local grid. ``diagonal``: the diagonal of the medium's box where it
    was located (a global bound's cost per crossing is ``bound * diagonal`` null steps at
    most), else 0."""
    kind: str
    values: np.ndarray
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    note: str = ""
    diagonal: float = 0.0
    median: float = 0.0        # the grid's median sigma_t (a typical flight's density), else 0


def _probe_box(medium, inside) -> tuple[np.ndarray, np.ndarray] | None:
    """The medium's box from ``intersect_aabb`` rays through a point ``inside`` it."""
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


def pool_between_centres(data: np.ndarray, k) -> np.ndarray:
    """Max-pool ``data`` [ix, iy, iz] into cells whose faces lie on voxel centres, ``k[a]``
    voxels per cell along axis ``a``: cell ``j`` spans the centres of voxels ``(j-1) k .. j k``
    (clipped to the grid), so ``ceil(n / k) + 1`` cells per axis, the first starting at the
    voxel coordinate ``0.5 - k`` (voxel ``i`` spans ``[i, i + 1)``, its centre ``i + 0.5``).

        >>> import numpy as np
        >>> pool_between_centres(np.array([0., 0., 5., 0.])[:, None, None], (1, 1, 1))[:, 0, 0].tolist()
        [0.0, 0.0, 5.0, 5.0, 0.0]
        >>> pool_between_centres(np.array([0., 0., 5., 0.])[:, None, None], (2, 1, 1))[:, 0, 0].tolist()
        [0.0, 5.0, 5.0]
    """
    out = data
    for a in range(3):
        n, ka = out.shape[a], int(k[a])
        starts = np.arange(0, n, ka)
        block = np.maximum.reduceat(out, starts, axis=a)         # voxels [b k, (b+1) k)
        first = out[(slice(None),) * a + (slice(0, None, ka),)]   # voxel b k (a view)
        lo_pad = [(0, 0)] * 3
        lo_pad[a] = (1, 0)
        hi_pad = [(0, 0)] * 3
        hi_pad[a] = (0, 1)
        # cell j = block j-1 and the first voxel of block j
        out = np.maximum(np.pad(block, lo_pad, constant_values=0.0),
                         np.pad(first, hi_pad, constant_values=0.0))
    return out


def coarsen(values: np.ndarray, n, k_fine, k_coarse) -> np.ndarray:
    """The :func:`pool_between_centres` level of ``k_coarse`` voxels per cell from the level of
    ``k_fine`` (``k_coarse[a]`` is ``k_fine[a]`` or twice it): coarse cell ``j`` spans fine cells
    ``2j - 1`` and ``2j`` (their shared face is a voxel centre), without reading the voxels.

        >>> import numpy as np
        >>> d = np.array([0., 0., 5., 0., 0., 0., 0.])[:, None, None]
        >>> coarsen(pool_between_centres(d, (1, 1, 1)), (7, 1, 1), (1, 1, 1), (2, 1, 1))[:, 0, 0].tolist()
        [0.0, 5.0, 5.0, 0.0, 0.0]
        >>> pool_between_centres(d, (2, 1, 1))[:, 0, 0].tolist()
        [0.0, 5.0, 5.0, 0.0, 0.0]
    """
    out = values
    for a in range(3):
        if int(k_coarse[a]) == int(k_fine[a]):
            continue
        cells = -(-int(n[a]) // int(k_coarse[a])) + 1
        pad = [(0, 0)] * 3
        pad[a] = (1, max(0, 2 * cells - 1 - out.shape[a]))         # fine cell -1 and beyond: none
        paired = np.pad(out, pad)[(slice(None),) * a + (slice(0, 2 * cells),)]
        shape = list(paired.shape)
        shape[a:a + 1] = [cells, 2]
        out = paired.reshape(shape).max(axis=a + 1)
    return out


def choose_level(data: np.ndarray, lo, hi, resolution: int = 16, factor: float = 1.0):
    """``(values, grid_lo, grid_hi, k)``: the pooled level :func:`build_majorant` uses (see the
    module doc); ``data`` is ``scale * sigma_t`` [ix, iy, iz] on the box ``lo .. hi``; the
    tracker will use ``factor * values`` (differentiated renders scale their bounds)."""
    n = np.asarray(data.shape)
    h = (np.asarray(hi, float) - np.asarray(lo, float)) / n
    ext = n * h
    area = 2.0 * float(ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2])
    chord = 4.0 * float(np.prod(ext)) / area                     # a convex body's mean chord
    ks = [np.maximum(1, 2 ** np.ceil(np.log2(np.maximum(n / resolution, 1.0)))).astype(int)]
    while not np.all(ks[-1] == 1):
        k = np.maximum(ks[-1] // 2, 1)
        if np.prod(-(-n // k) + 1) > MAX_CELLS:
            break
        ks.append(k)
    # pool the voxels once, at the finest level; each coarser level from the one below it
    levels = []
    values = pool_between_centres(data, ks[-1])
    for i in range(len(ks) - 1, -1, -1):
        k = ks[i]
        if i < len(ks) - 1:
            values = coarsen(values, n, ks[i + 1], k)
        cost = chord * (float(np.sum(1.0 / (2.0 * k * h))) + factor * float(values.mean()))
        depth = factor * float(values.max()) * float(np.linalg.norm(k * h))
        levels.append((cost, depth, values, k))                   # finest first
    within = [lv for lv in levels if lv[1] <= MAX_CELL_DEPTH]
    _, _, values, k = min(within, key=lambda lv: lv[0]) if within else levels[0]
    grid_lo = np.asarray(lo, float) + (0.5 - k) * h
    return values, grid_lo, grid_lo + np.asarray(values.shape) * k * h, k


def _around(data: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Per voxel index ``idx`` (N, 3): the largest value of ``data`` over its 3^3 neighbourhood
    (clipped to the grid)."""
    n = np.asarray(data.shape)
    out = np.zeros(len(idx))
    for off in np.stack(np.meshgrid(*[(-1, 0, 1)] * 3, indexing="ij"), -1).reshape(-1, 3):
        j = np.clip(idx + off, 0, n - 1)
        out = np.maximum(out, data[j[:, 0], j[:, 1], j[:, 2]])
    return out


def _check_values(medium, raw: np.ndarray, scale: float, name: str | None) -> None:
    """Refuse what no render can use, set through ``mi.traverse`` where nothing checks it: a
    non-finite density or a scale below 0 or non-finite (every sigma_t then reads as 0 here,
    no smoke, while volpath renders the raw product). A density below 0 is kept, as no medium.
    ``name``: the medium's parameter prefix (``plume.interior_medium``), else its id."""
    key = f"{name}." if name else f"medium {medium.id() or medium.class_name()!r}: "
    if not (np.isfinite(scale) and scale >= 0):
        raise ParameterError(f"draaw_v3/draaw_v4: {key}scale = {scale!r}; expected a finite density "
                             "scale >= 0")
    bad = ~np.isfinite(raw)
    if bad.any():
        first = [int(i) for i in np.argwhere(bad)[0]]
        raise ParameterError(f"draaw_v3/draaw_v4: {key}sigma_t.data{first} = {float(raw[tuple(first)])!r} "
                             f"({int(bad.sum())} non-finite value(s), [z, y, x, channel]); expected finite "
                             "densities")


def build_majorant(medium, resolution: int = 16, inside=None, factor: float = 1.0,
                   name: str | None = None) -> Majorant:
    """Majorant of a Mitsuba medium (see module doc). ``inside``: a point inside the medium's
    box used to locate it (default: its centre as reported for a probe from the origin);
    ``factor``: the tracker multiplies the bounds by it (the level is chosen for that);
    ``name``: the medium's parameter prefix, naming it in the :class:`ParameterError` for a
    non-finite density or a scale below 0 or non-finite."""
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p = mi.Point3f(*[float(v) for v in (inside if inside is not None else (0.0, 0.0, 0.0))])
    if medium.is_homogeneous():
        return Majorant("homogeneous", np.zeros((1, 1, 1)), np.full(3, -GLOBAL_BOX), np.full(3, GLOBAL_BOX))
    glob = max(float(np.max(np.array(medium.get_majorant(mei)))), 0.0)
    fallback = Majorant("global", np.full((1, 1, 1), glob), np.full(3, -GLOBAL_BOX), np.full(3, GLOBAL_BOX))
    located = _probe_box(medium, np.asarray(inside if inside is not None else np.zeros(3), float))
    if located is not None:
        fallback.diagonal = float(np.linalg.norm(located[1] - located[0]))
    params = mi.traverse(medium)
    if "sigma_t.data" not in params.keys() or "scale" not in params.keys():
        fallback.note = "no sigma_t grid data"
        return fallback
    raw = np.array(params["sigma_t.data"], dtype=np.float64)
    scale = float(params["scale"])
    _check_values(medium, raw, scale, name)
    if raw.ndim != 4 or raw.shape[3] != 1:
        fallback.note = f"sigma_t grid of shape {raw.shape} (spectral data)"
        return fallback
    # at least 0, as the trackers read sigma_t (volume_tracking.coefficients): a density an
    # optimiser step set below 0 through the parameters is no medium there
    data = scale * np.maximum(raw[..., 0], 0.0).transpose(2, 1, 0)   # -> [ix, iy, iz]
    fallback.median = float(np.median(data))
    box = None
    for p in ([inside] if inside is not None else []) + [np.zeros(3)]:
        box = _probe_box(medium, np.asarray(p, float))
        if box is not None:
            break
    if box is None:
        fallback.note = "could not locate the grid's box"
        return fallback
    lo, hi = box
    fallback.diagonal = float(np.linalg.norm(hi - lo))
    # verify the placement: sigma_t at sampled voxel centres equals scale * data, and a
    # quarter voxel inside each face equals the face's voxels (clamped lookups; a 'repeat'
    # wrap blends the opposite face's voxels in there, which no cell bounds)
    n = np.asarray(data.shape)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, n, size=(min(2048, int(n.prod())), 3))
    idx = np.concatenate([idx, np.argwhere(data == data.max())[:64]])
    u = idx + 0.5
    face_idx, face_u = [], []
    for a in range(3):
        others = [b for b in range(3) if b != a]
        for face, opposite, ua in ((0, n[a] - 1, 0.25), (n[a] - 1, 0, n[a] - 0.25)):
            slab = np.take(data, opposite, axis=a)            # the opposite face's voxels
            top = np.argpartition(slab, -min(16, slab.size), axis=None)[-16:]
            jk = np.concatenate([np.stack(np.unravel_index(top, slab.shape), 1),
                                 rng.integers(0, n[others], size=(32, 2))])
            f = np.empty((len(jk), 3), int)
            f[:, a], f[:, others[0]], f[:, others[1]] = face, jk[:, 0], jk[:, 1]
            fu = f + 0.5
            fu[:, a] = ua
            face_idx.append(f)
            face_u.append(fu)
    idx = np.concatenate([idx] + face_idx)
    u = np.concatenate([u] + face_u)
    centres = lo + u * (hi - lo) / n
    m = dr.zeros(mi.MediumInteraction3f, len(idx))
    m.p = mi.Point3f(*[mi.Float(centres[:, k].astype(np.float32)) for k in range(3)])
    m.medium = mi.MediumPtr(medium)
    _, _, sigma_t = medium.get_scattering_coefficients(m)
    got = np.maximum(np.array(sigma_t)[0], 0.0)
    want = data[idx[:, 0], idx[:, 1], idx[:, 2]]
    # Mitsuba's float32 lookup puts a centre off by ~1.5 n 2^-23 voxels (n voxels per axis:
    # measured 1.4e-7 n to 1.8e-7 n for n = 64..512), so a trilinear lookup there blends that
    # much of a neighbour's value; a box far from the origin adds its float32 position error
    # (|x| 2^-23 over a voxel); a misplaced grid is off by whole voxel values
    h = (hi - lo) / n
    far = float(np.max(np.abs(np.concatenate([lo, hi]))))
    leak = max(1e-5, 8.0 * float(n.max()) * 2.0 ** -24 + 8.0 * far * 2.0 ** -24 / float(h.min()))
    # (each probe's tolerance scales with the voxels around it, the values a lookup there can
    # blend in: a global max(data) let a mirrored grid with a large dynamic range pass)
    if not np.allclose(got, want, rtol=1e-4, atol=leak * np.maximum(1.0, _around(data, idx))):
        fallback.note = ("sigma_t at voxel centres or box faces does not match the grid data (a rotated "
                         "or mirrored to_world, or a wrap mode other than clamp)")
        return fallback
    local, grid_lo, grid_hi, k = choose_level(data, lo, hi, resolution, factor)
    # A nearly uniform grid gains nothing from local bounds but pays a DDA step per coarse
    # cell crossed: bound it with a single cell over its box instead.
    if float(local.max()) <= UNIFORM_GAIN * float(local.mean()):
        return Majorant("grid", np.full((1, 1, 1), float(local.max())), lo, hi, "nearly uniform: one cell")
    return Majorant("grid", local, grid_lo, grid_hi, f"{k.tolist()} voxels per cell")
