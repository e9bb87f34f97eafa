"""Procedural density fields for sample scenes (seeded, numpy only).

    >>> from draaw_mi.media.procedural import plume
    >>> d = plume((16, 24, 16), seed=1)
    >>> d.shape, bool(d.min() >= 0), bool(d.max() <= 1)
    ((16, 24, 16), True, True)
"""
from __future__ import annotations

import numbers

import numpy as np

from ..errors import ParameterError
from ..limits import grid_size_problem


def _smooth_noise(shape, cells: int, rng) -> np.ndarray:
    """Value noise: a coarse random lattice upsampled trilinearly to ``shape`` (in [0, 1])."""
    coarse = rng.random((cells + 1,) * 3)
    axes = [np.linspace(0, cells, n) for n in shape]
    out = coarse
    for a, x in enumerate(axes):
        i0 = np.clip(np.floor(x).astype(int), 0, cells - 1)
        f = (x - i0).reshape([-1 if k == a else 1 for k in range(3)])
        out = np.take(out, i0, axis=a) * (1 - f) + np.take(out, i0 + 1, axis=a) * f
    return out


def plume(resolution=(48, 64, 48), seed: int = 0, sharpness: float = 3.0) -> np.ndarray:
    """A rising smoke plume in the unit box, density in [0, 1], indexed ``[ix, iy, iz]``
    (y up): a column that leaves a source near the floor, drifts, widens and breaks up into
    turbulent wisps (two octaves of value noise), fading towards the top."""
    def whole(v):
        return isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))
    # (numpy ints are whole numbers; a float, 8.0 or 8.5, is refused, not cut to 8)
    shape = ()
    if whole(resolution):
        shape = (resolution,) * 3
    elif isinstance(resolution, (tuple, list, np.ndarray)):
        shape = tuple(resolution)
    if len(shape) != 3 or not all(whole(v) for v in shape) or min(shape) < 1:
        raise ParameterError(f"plume: resolution {resolution!r}; expected an integer or "
                             "(nx, ny, nz) integers >= 1")
    shape = tuple(int(v) for v in shape)
    too_large = grid_size_problem(shape)
    if too_large:
        raise ParameterError(f"plume: resolution {too_large}")
    rng = np.random.default_rng(seed)
    x, y, z = np.meshgrid(*[(np.arange(n) + 0.5) / n for n in shape], indexing="ij")
    drift = 0.12 * np.sin(3.0 * y + rng.uniform(0, 6.3)) + 0.15 * y
    cx, cz = 0.45 + drift, 0.5 + 0.08 * np.sin(4.0 * y + rng.uniform(0, 6.3))
    radius = 0.06 + 0.22 * y
    r2 = ((x - cx) ** 2 + (z - cz) ** 2) / radius ** 2
    column = np.exp(-r2) * np.clip(y / 0.08, 0, 1) * np.clip((1.0 - y) / 0.35, 0, 1)
    noise = 0.65 * _smooth_noise(shape, 5, rng) + 0.35 * _smooth_noise(shape, 13, rng)
    d = column * np.clip(1.6 * noise - 0.3, 0, None) ** (sharpness / 3.0)
    return np.clip(d / max(float(d.max()), 1e-12), 0.0, 1.0).astype(np.float32)
