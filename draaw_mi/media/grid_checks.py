"""Value checks of :class:`~draaw_mi.media.voxel_grid.VoxelGrid` inputs (split from
``voxel_grid.py``): a grid resolution, and densities checked in float64 *before* the grid
stores them as float32 (where 1e39 would become inf, with only numpy's overflow warning).

    >>> import numpy as np
    >>> from draaw_mi.media.grid_checks import check_density
    >>> check_density(np.array([[[1e39]]]), "demo")
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: demo: density[0, 0, 0] = 1e+39; expected finite values >= 0 up to the float32 limit 3.4028234663852886e+38 (the grid stores float32)
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..limits import FLOAT32_MAX, grid_size_problem


def check_density(d, where: str) -> None:
    """Refuse a density array with a value that is not finite, below 0 or past float32's
    largest value; the message names the first such voxel ``[ix, iy, iz]`` and its value."""
    d = np.asarray(d, np.float64)
    for bad, expected in ((~np.isfinite(d), "finite values >= 0"), (d < 0, "values >= 0"),
                          (d > FLOAT32_MAX, f"finite values >= 0 up to the float32 limit {FLOAT32_MAX!r} "
                                            "(the grid stores float32)")):
        if bad.any():
            first = np.argwhere(bad)[0]
            raise ParameterError(f"{where}: density[{', '.join(map(str, first))}] = {float(d[tuple(first)])!r}; "
                                 f"expected {expected}")


def resolution(value, where: str) -> tuple[int, int, int]:
    """``value`` (an int or ``(nx, ny, nz)`` of ints >= 1, within the size limits) as a tuple."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (int(value),) * 3
    try:
        t = tuple(int(v) for v in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{where}: resolution {value!r}; expected an int or (nx, ny, nz)") from None
    if len(t) != 3 or min(t) < 1 or any(v != w for v, w in zip(t, value)):
        raise ParameterError(f"{where}: resolution {value!r}; expected an int or (nx, ny, nz) of ints >= 1")
    too_large = grid_size_problem(t)
    if too_large:
        raise ParameterError(f"{where}: resolution {too_large}")
    return t
