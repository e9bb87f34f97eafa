"""Values written into a loaded scene's parameters (``params[key] = ...``), converted to and
checked against the parameter's own type."""
from __future__ import annotations

import drjit as dr
import numpy as np

from ..errors import RenderError, shown


def value_like(current, value, key: str):
    """``value`` for ``params[key] = ...``, in the type of the parameter's ``current`` value: a
    list of as many numbers as a vector parameter holds becomes that vector (a ``Color3f``
    colour, a ``Point3f`` light position or SDF centre), anything else is converted whole.
    Batch frames and preview updates set parameters through it (three numbers are not always a
    colour: an SDF centre would refuse one at the next frame, dropping the change).

    >>> import mitsuba as mi
    >>> type(value_like(mi.Point3f(0.0), [0.1, 0.2, 0.3], "sdf.ball.center")).__name__
    'Point3f'
    """
    check_like(current, value, key)
    if dr.is_tensor_v(current) and np.ndim(value) <= 1 and not dr.is_tensor_v(value):
        # one number, or one per channel: a constant map of the texture's shape
        value = np.broadcast_to(np.asarray(value, np.float32), tuple(current.shape)).copy()
    seq = isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim == 1)
    try:
        if seq and dr.depth_v(current) > 1 and len(value) == len(current):
            return type(current)(*[float(x) for x in value])
        return type(current)(value)
    except Exception as e:  # noqa: BLE001 - Dr.Jit / Mitsuba constructors: many kinds
        raise RenderError(f"params[{key!r}] = {value!r}: cannot convert to {type(current).__name__} "
                          f"({e})") from None


def check_like(current, value, key: str) -> None:
    """The checks of :func:`value_like` that need no conversion (no Dr.Jit value is made, so a
    caller need not wait for a render in another thread): a number or numbers, and for a
    texture one number or one per channel (filling it), or texels of its dimension and channel
    count. A colour of the wrong size written to a textured ``base_color`` would fail at
    ``params.update()`` and stay queued there: every later update would fail with it. An
    integer texture (an 8-bit image Mitsuba loaded itself: an XML scene's) takes no values: a
    float written into it would be truncated (0.9 -> 0, a mirror).

    >>> import mitsuba as mi, numpy as np
    >>> check_like(mi.TensorXf(np.zeros((4, 4, 3))), [1.0, 0.0], "m.base_color.data")
    Traceback (most recent call last):
    ...
    draaw_mi.errors.RenderError: params['m.base_color.data'] = [1.0, 0.0]: m.base_color.data is a texture of shape (4, 4, 3); give one number or 3 (filling it), or texels of shape (H, W, 3)
    """
    if isinstance(value, (str, bytes)) or value is None:       # (TensorXf("0.3") is a tensor)
        raise RenderError(f"params[{key!r}] = {value!r}: expected a number or numbers")
    kind = type(value).__name__
    matrix = (getattr(value, "matrix", None) if "Transform" in kind else value if "Matrix" in kind else None)
    if matrix is not None and not dr.is_tensor_v(value):      # a transform or matrix (a to_world)
        if not np.all(np.isfinite(np.array(matrix, dtype=np.float64))):
            # (rendered a frame of NaN without a word; a zero matrix fails in Mitsuba, said)
            raise RenderError(f"params[{key!r}]: a transform or matrix with NaN or infinite entries; expected "
                              "finite numbers")
    if (dr.is_array_v(current) and not dr.is_tensor_v(current) and dr.depth_v(current) == 1
            and dr.width(current) == 1 and dr.is_float_v(current) and matrix is None):
        try:
            n = np.size(np.array(value, dtype=np.float64))
        except (TypeError, ValueError):
            n = 1                              # (refused by the numbers' own check)
        if n > 1:           # (a uniform value given 3 numbers failed at the next frame, in Mitsuba's words)
            raise RenderError(f"params[{key!r}] = {shown(value)}: {key} holds one number (a uniform value; it "
                              "cannot become a texture here); expected one")
    if dr.is_tensor_v(current):
        if not dr.is_float_v(current):
            raise RenderError(f"params[{key!r}]: an image texture of {type(current).__name__} (8/16-bit "
                              "integers, as Mitsuba stores an XML scene's PNG); it takes no new values "
                              "(floats would be truncated); give the texture as a float image (EXR) or "
                              "load the scene from TOML, which stores its image files as floats")
        shape = tuple(value.shape) if dr.is_tensor_v(value) else np.shape(value)
        channels = current.shape[-1]
        if len(shape) == 0 or (len(shape) == 1 and shape[0] in (1, channels)):
            return
        if len(shape) != current.ndim or shape[-1] != channels:
            given = f"{value!r}" if len(shape) == 1 else f"texels of shape {shape}"
            raise RenderError(f"params[{key!r}] = {given}: {key} is a texture of shape "
                              f"{tuple(current.shape)}; give one number or {channels} (filling it), or "
                              f"texels of shape (H, W, {channels})")
