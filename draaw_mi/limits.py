"""Numeric limits the input checks share.

Mitsuba stores scene values in float32: a number beyond its range (a colour of 1e40, a density
scale of 1e39) becomes Inf there, and NaN pixels at render.

>>> import numpy as np
>>> FLOAT32_MAX == float(np.finfo(np.float32).max), HALF_MAX == float(np.finfo(np.float16).max)
(True, True)
"""
FLOAT32_MAX = 3.4028234663852886e38

#: the largest finite half-float value: an EXR written as half stores anything beyond it as inf
HALF_MAX = 65504.0

#: a camera's field of view in degrees: what scene files take ([camera] fov), the tuner's slider
#: shows and parameter updates (``sensor.x_fov``) are checked against (one range, so a scene saved
#: from the slider's end loads again)
FOV_RANGE = (0.1, 179.0)

#: the largest |g| of a Henyey-Greenstein phase function that scene files, the preview and
#: parameter checks take: nearer +-1 the lobe is all but a delta (at g = 0.9999999, 1 in float32
#: just short, a 16-spp render's dL/dg read -3.4e4 against -0.15 at g = 0.999), and past it the
#: phase function is negative and so are the pixels
HG_G_MAX = 0.999

#: the most cells a voxel grid may have (2^26: 406^3, or 512 x 512 x 256). Voxelising a mesh
#: and rendering the grid peaked at ~67 bytes a cell (256^3: 1.38 GB), so the cap is ~4.5 GB,
#: a fifth of a 24 GiB machine; 1024^3 would have asked for ~72 GB
MAX_GRID_CELLS = 1 << 26
GRID_BYTES_PER_CELL = 67


def grid_size_problem(shape) -> str:
    """What is wrong with a grid of ``shape`` cells for its size, or ``""``.

    >>> grid_size_problem((256, 256, 256)), grid_size_problem((1024,) * 3)[:41]
    ('', '(1024, 1024, 1024) is 1,073,741,824 cells')
    """
    n = 1
    for v in shape:
        n *= int(v)
    if n <= MAX_GRID_CELLS:
        return ""
    return (f"{tuple(int(v) for v in shape)} is {n:,} cells (~{n * GRID_BYTES_PER_CELL / 1e9:.3g} GB to "
            f"build and render, at ~{GRID_BYTES_PER_CELL} bytes a cell); expected at most "
            f"{MAX_GRID_CELLS:,} cells (e.g. 406^3 or 512 x 512 x 256)")
