"""Numeric limits the input checks share.

Mitsuba stores scene values in float32: a number beyond its range (a colour of 1e40, a density
scale of 1e39) becomes Inf there, and NaN pixels at render.

>>> import numpy as np
>>> FLOAT32_MAX == float(np.finfo(np.float32).max)
True
"""
FLOAT32_MAX = 3.4028234663852886e38
