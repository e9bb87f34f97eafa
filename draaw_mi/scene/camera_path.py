"""Camera paths: GO-Draaw's keyframe interpolation (go-draaw-spec.md §2.9), faithful or fixed.

A keyframe is ``(x, y, z, theta, phi)`` — position and GO-Draaw's two camera angles — or a
dict ``{"x", "y", "z", "cameraX", "cameraY"}`` as in GO-Draaw's ``camera_positions.json``.

GO-Draaw's interpolation renders ``int(60 · duration)`` frames, ``total // (n - 1)`` per
segment, eased with ``t · smoothstep(t)`` (a slip for ``smoothstep``), and leaves the frames
that do not divide evenly at the origin. ``faithful=True`` reproduces that exactly (for
GO-Draaw's benchmark); ``faithful=False`` (default) uses ``smoothstep`` and distributes every
frame over the segments. Both interpolate the angles as the numbers given (as GO-Draaw and
Blender's Euler keys do): theta 0 -> 2 pi is a full orbit, 3.0 -> -3.0 turns 6 rad (write
-3.0 as 3.28 to turn the short way across +-pi).

>>> frames = interpolate([(0, 0, 0, 0, 1), (1, 0, 0, 0, 1)], duration=0.05)
>>> frames.shape, float(frames[0, 0]), float(frames[-1, 0])
((3, 5), 0.0, 1.0)
"""
from __future__ import annotations

import numbers

import numpy as np

from ..errors import ParameterError
from ..limits import FLOAT32_MAX

# GO-Draaw's hard-coded benchmark path (go-draaw-spec.md §7.1), for monkey.obj scaled ×75.
GO_DRAAW_BENCHMARK_PATH = [
    (-424.48, 986.71, 17.54, 0.24, -2.08),
    (54.16, 784.00, 17.54, 1.19, -1.95),
    (669.52, 48.41, 17.54, -0.72, -1.91),
]


def as_keyframes(keys) -> np.ndarray:
    """(n, 5) float array from tuples or GO-Draaw dicts.

    >>> as_keyframes([{"x": 0, "y": 1, "z": 2, "cameraX": 0, "cameraY": "up"}])
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: camera path: keyframe 0 = (0, 1, 2, 0, 'up'); expected 5 finite numbers (x, y, z, theta, phi)
    """
    if isinstance(keys, (dict, str, bytes)) or not hasattr(keys, "__iter__"):
        raise ParameterError(f"camera path: expected a list of keyframes, got {type(keys).__name__}")
    rows = []
    for i, k in enumerate(keys):
        if isinstance(k, dict):
            try:
                k = (k["x"], k["y"], k["z"], k["cameraX"], k["cameraY"])
            except KeyError as e:
                raise ParameterError(f"camera path: keyframe {i} lacks {e.args[0]!r}; expected x, y, z, "
                                     "cameraX, cameraY") from None
        try:
            arr = np.asarray(k, dtype=float)
        except (TypeError, ValueError):
            arr = np.full(0, np.nan)                   # (reported below)
        if arr.shape != (5,) or not np.all(np.isfinite(arr)):
            raise ParameterError(f"camera path: keyframe {i} = {k!r}; expected 5 finite numbers "
                                 "(x, y, z, theta, phi)")
        if np.any(np.abs(arr) > FLOAT32_MAX):          # (Mitsuba's float32: inf, a black frame)
            raise ParameterError(f"camera path: keyframe {i} = {k!r}; expected numbers within "
                                 f"float32 (|x| <= {FLOAT32_MAX:.2g})")
        rows.append(arr)
    if not rows:
        raise ParameterError("camera path: no keyframes")
    return np.stack(rows)


def interpolate(keys, duration: float = 10.0, fps: int = 60, faithful: bool = False) -> np.ndarray:
    """Frames (m, 5) along the keyframes; see the module docstring for the two modes. One
    keyframe is a camera that stays put: its frames are that keyframe, as many as a moving
    camera's (so that ``bench.frame_times(frames=N)`` times N frames, not a single one)."""
    p = as_keyframes(keys)
    n = len(p)
    for name, value, unit in (("duration", duration, "seconds"), ("fps", fps, "frames per second")):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 < value < float("inf"):
            raise ParameterError(f"camera path: {name}={value!r}; expected a positive number of {unit}")
    # GO-Draaw truncates D * 60 (Go's int()); otherwise rounded: 2.05 s at 60 fps is 123
    # frames, and the float product 122.99999999999999 would truncate to 122
    total = int(duration * fps) if faithful else int(round(duration * fps))
    if total < 2:
        raise ParameterError(f"camera path: {duration} s at {fps} fps gives {total} frame(s); need at least 2")
    if n < 2:
        return np.repeat(p, total, axis=0)
    if faithful:
        per = total // (n - 1)
        out = np.zeros((total, 5))
        for i in range(n - 1):
            for f in range(per):
                t = f / per
                s = t * t * (3 - 2 * t)
                out[i * per + f] = p[i] + (p[i + 1] - p[i]) * t * s
        out[total - 1] = p[n - 1]
        return out
    u = np.linspace(0.0, n - 1, total)
    seg = np.minimum(u.astype(int), n - 2)
    t = u - seg
    s = t * t * (3 - 2 * t)
    return p[seg] + (p[seg + 1] - p[seg]) * s[:, None]
