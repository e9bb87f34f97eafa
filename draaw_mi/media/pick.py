"""Exact grid traversal (Amanatides & Woo DDA) of one ray through a regular grid, in numpy.

Used for picking the first occupied voxel along a ray. GO-Draaw marches 64 equal steps
through the box (``go-draaw-spec.md`` §4.4), which skips thin features; the DDA visits every
cell the ray crosses, in order, exactly once.

    >>> import numpy as np
    >>> from draaw_mi.media.pick import traverse
    >>> cells = list(traverse((-1, 0.5, 0.5), (1, 0, 0), (0, 0, 0), (3, 1, 1), (3, 1, 1)))
    >>> [c for c, t0, t1 in cells]
    [(0, 0, 0), (1, 0, 0), (2, 0, 0)]
"""
from __future__ import annotations

from typing import Iterator

import numpy as np


def slab(origin, direction, lo, hi) -> tuple[float, float] | None:
    """Ray-box interval ``(t_enter, t_exit)`` with ``t_exit >= max(t_enter, 0)``, or None."""
    o = np.asarray(origin, float)
    d = np.asarray(direction, float)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    t0, t1 = -np.inf, np.inf
    for a in range(3):
        if d[a] == 0.0:
            if o[a] < lo[a] or o[a] > hi[a]:
                return None
            continue
        ta = (lo[a] - o[a]) / d[a]
        tb = (hi[a] - o[a]) / d[a]
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    if t1 < max(t0, 0.0):
        return None
    return t0, t1


def traverse(origin, direction, lo, hi, shape) -> Iterator[tuple[tuple[int, int, int], float, float]]:
    """Yield ``((ix, iy, iz), t_in, t_out)`` for each cell the ray ``origin + t direction``
    (``t >= 0``) crosses, front to back. Cells may be non-cubic (box ``lo..hi``, ``shape``
    cells per axis). A ray starting inside the box starts in its own cell."""
    o = np.asarray(origin, float)
    d = np.asarray(direction, float)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    n = np.asarray(shape, int)
    hit = slab(o, d, lo, hi)
    if hit is None:
        return
    t_enter, t_exit = hit
    t = max(t_enter, 0.0)
    size = (hi - lo) / n
    p = o + t * d
    cell = np.clip(np.floor((p - lo) / size).astype(int), 0, n - 1)
    step = np.where(d > 0, 1, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(d != 0, 1.0 / np.where(d != 0, d, 1.0), np.inf)
        nxt = lo + (cell + (step > 0)) * size          # next boundary along each axis
        t_max = np.where(d != 0, (nxt - o) * inv, np.inf)
        t_delta = np.where(d != 0, size * np.abs(inv), np.inf)
    while True:
        axis = int(np.argmin(t_max))
        t_out = min(float(t_max[axis]), t_exit)
        yield (int(cell[0]), int(cell[1]), int(cell[2])), t, t_out
        if t_out >= t_exit:
            return
        cell[axis] += step[axis]
        if cell[axis] < 0 or cell[axis] >= n[axis]:
            return
        t = t_out
        t_max[axis] += t_delta[axis]
