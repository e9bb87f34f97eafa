"""Building blocks shared by the ``draaw_mi.post`` filters (all differentiable Dr.Jit code).

* image checks and conversion (numpy → ``mi.TensorXf``), alpha split/join;
* per-channel constants, per-pixel views (``mi.Color3f``) of an (H, W, 3) tensor;
* :func:`dense_kernel`: taps at *fractional* pixel offsets (linear interpolation) as integer
  taps; :func:`gather_taps` / :func:`separable_taps`: fused per-pixel filters built on
  ``dr.gather`` (one kernel per pass, faster than chained ``dr.convolve`` calls here);
* :func:`remap`: out-of-image indices → in-image indices for every boundary mode, valid for
  arbitrarily large offsets, and :func:`bilinear_rgb`, a bilinear RGB fetch built on it.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError

Taps = Sequence[tuple[float, float]]


# -- images ----------------------------------------------------------------------------------
def as_image(image: Any, where: str) -> mi.TensorXf:
    """Return ``image`` as an (H, W, 3|4) ``mi.TensorXf``; numpy/lists are converted (float32)."""
    if isinstance(image, mi.TensorXf):
        t = image
    elif image is not None and dr.is_tensor_v(image):
        try:
            t = mi.TensorXf(image)
        except Exception as exc:  # noqa: BLE001 - report any conversion failure the same way
            raise ParameterError(f"{where}: cannot convert image of type "
                                 f"{type(image).__name__} to mi.TensorXf ({exc})") from None
    else:
        # (the dtype is read before any conversion: an 8-bit mi.Bitmap or PIL image had been
        # taken as values up to 255)
        try:
            a = np.asarray(image) if image is not None else None
        except (TypeError, ValueError):
            a = None
        if a is None or a.dtype == object:
            raise ParameterError(f"{where}: image must be an mi.TensorXf or a float numpy "
                                 f"array, got {type(image).__name__}") from None
        if a.dtype.kind not in "fiu" or (a.dtype.kind in "iu" and not isinstance(image, (list, tuple))):
            raise ParameterError(
                f"{where}: image must be a float array (linear RGB, 1.0 = white), got dtype "
                f"{a.dtype}; convert 8-bit images with img.astype(np.float32) / 255 (and "
                "draaw_mi.io.srgb_decode if they are sRGB-encoded)")
        t = mi.TensorXf(np.ascontiguousarray(a, dtype=np.float32))
    shape = tuple(t.shape)
    if len(shape) != 3 or shape[2] not in (3, 4) or shape[0] < 1 or shape[1] < 1:
        raise ParameterError(f"{where}: image must have shape (H, W, 3) or (H, W, 4) with "
                             f"H, W >= 1, got {shape}")
    return t


def finite_rgb(rgb: mi.TensorXf) -> mi.TensorXf:
    """``rgb`` with its non-finite values (NaN, ±inf) read as 0, as :func:`draaw_mi.denoise`
    does: one bad pixel of a user's image would otherwise spread through every blur (a NaN
    pixel would become a 13 × 13 NaN square under the default bloom). Finite values pass bit-identical
    with gradient 1; the replaced ones get gradient 0.

    >>> import mitsuba as mi
    >>> t = mi.TensorXf([float("nan"), float("inf"), -2.0], (1, 1, 3))
    >>> [float(v) for v in finite_rgb(t).array]
    [0.0, 0.0, -2.0]
    """
    return mi.TensorXf(dr.select(dr.isfinite(rgb.array), rgb.array, 0.0), rgb.shape)


def split_alpha(t: mi.TensorXf) -> tuple[mi.TensorXf, mi.TensorXf | None]:
    """(H, W, 4) → RGB (H, W, 3) and alpha (H, W, 1); (H, W, 3) → (t, None)."""
    if t.shape[2] == 3:
        return t, None
    return t[:, :, 0:3], t[:, :, 3:4]


def join_alpha(rgb: mi.TensorXf, alpha: mi.TensorXf | None) -> mi.TensorXf:
    """Inverse of :func:`split_alpha`; the alpha values come back bit-identical."""
    if alpha is None:
        return rgb
    return dr.concat([rgb, alpha], axis=2)


def channel_index(rgb: mi.TensorXf) -> mi.UInt32:
    """Channel (0, 1, 2) of every element of the flat array of an (H, W, 3) tensor."""
    return dr.arange(mi.UInt32, dr.width(rgb.array)) % 3


def per_channel(rgb: mi.TensorXf, values: Sequence[float]) -> Any:
    """A flat per-element array holding ``values[c]`` for channel c (a float if all equal)."""
    r, g, b = (float(v) for v in values)
    if r == g == b:
        return r
    c = channel_index(rgb)
    return dr.select(c == 0, r, dr.select(c == 1, g, b))


def pixels(rgb: mi.TensorXf) -> mi.Color3f:
    """Per-pixel view of an (H, W, 3) tensor (a strided gather, differentiable).

    Not ``dr.unravel``: in Dr.Jit 1.5 its adjoint *overwrites* the source gradient instead of
    adding to it, so ``unravel(x) + unravel(2·x)`` gets the gradient 1 instead of 3.
    """
    return dr.gather(mi.Color3f, rgb.array, dr.arange(mi.UInt32, dr.width(rgb.array) // 3))


def from_pixels(c: mi.Color3f, shape: Sequence[int]) -> mi.TensorXf:
    """Inverse of :func:`pixels`."""
    return mi.TensorXf(dr.ravel(c), (shape[0], shape[1], 3))


def luminance(c: mi.Color3f) -> mi.Float:
    """Rec. 709 luminance Y = 0.2126 r + 0.7152 g + 0.0722 b (GO-Draaw's weights)."""
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def safe_norm2(gx: Any, gy: Any) -> Any:
    """sqrt(gx² + gy²) with a zero (not NaN/inf) gradient where both are 0, and no overflow:
    the squares are of the components divided by the larger one (hypot's scaling; plain
    squares would make edges of 1e19-bright pixels infinite).

    >>> import mitsuba as mi
    >>> round(float(safe_norm2(mi.Float(3e30), mi.Float(4e30))[0]) / 1e30, 5)
    5.0
    """
    # m detached: the value is m's either way, and the derivative through rcp(m) (-1/m^2)
    # underflows past 1e19 (NaN gradients of bright edges); d/dgx = gx / |g| as it should
    m = dr.detach(dr.maximum(dr.abs(gx), dr.abs(gy)))
    pos = m > 0
    inv = dr.select(pos, dr.rcp(dr.select(pos, m, 1.0)), 0.0)
    return dr.select(pos, m * dr.sqrt(dr.square(gx * inv) + dr.square(gy * inv)), 0.0)


# -- correlation with fractional taps ---------------------------------------------------------
def dense_kernel(taps: Taps) -> list[float]:
    """Correlation weights K[-R..R] equivalent to sampling at each (offset, weight) tap with
    linear interpolation between the two nearest pixels (exact for integer offsets)."""
    acc: dict[int, float] = {}
    for off, w in taps:
        n = math.floor(off)
        f = off - n
        acc[n] = acc.get(n, 0.0) + w * (1.0 - f)
        if f > 0.0:
            acc[n + 1] = acc.get(n + 1, 0.0) + w * f
    radius = max(abs(k) for k in acc)
    return [acc.get(k, 0.0) for k in range(-radius, radius + 1)]


def outer_taps(taps_x: Taps, taps_y: Taps, weight: float = 1.0) -> dict[tuple[int, int], float]:
    """Integer 2-D taps {(dy, dx): w} of the separable kernel ``taps_y ⊗ taps_x``."""
    kx, ky = dense_kernel(taps_x), dense_kernel(taps_y)
    rx, ry = len(kx) // 2, len(ky) // 2
    return {(j - ry, i - rx): weight * wy * wx
            for j, wy in enumerate(ky) if wy for i, wx in enumerate(kx) if wx}


def pixel_coords(H: int, W: int) -> tuple[mi.Int32, mi.Int32, mi.Int32]:
    """(pixel index, x, y) of every pixel of an H × W image, row-major."""
    pix = dr.arange(mi.Int32, H * W)
    x = pix % W
    return pix, x, pix // W


def _axis_index(i: mi.Int32, off: int, n: int, boundary: str, reach: float
                ) -> tuple[mi.Int32, mi.Bool | None]:
    return (i, None) if off == 0 else remap(i + off, n, boundary, reach)


def gather_taps(src: Any, dtype: type, H: int, W: int, taps: dict[tuple[int, int], float],
                boundary: str) -> Any:
    """``Σ w · src[y + dy, x + dx]`` per pixel for integer taps ``{(dy, dx): w}``.

    ``src`` is a flat per-pixel array of ``dtype`` elements (``mi.Float`` for one channel,
    ``mi.Color3f`` for the interleaved RGB array of an (H, W, 3) tensor). One kernel, one
    gather per tap; differentiable (the adjoint is a scatter-add).
    """
    _, x, y = pixel_coords(H, W)
    reach = max(max(abs(dy), abs(dx)) for dy, dx in taps) + 1.0
    xs = {dx: _axis_index(x, dx, W, boundary, reach) for dx in {dx for _, dx in taps}}
    ys = {dy: _axis_index(y, dy, H, boundary, reach) for dy in {dy for dy, _ in taps}}
    out = None
    for (dy, dx), w in taps.items():
        (xi, vx), (yi, vy) = xs[dx], ys[dy]
        valid = vx if vy is None else (vy if vx is None else vx & vy)
        v = dr.gather(dtype, src, mi.UInt32(yi * W + xi), True if valid is None else valid)
        out = v * w if out is None else dr.fma(v, w, out)
    return out


def separable_taps(src: Any, dtype: type, H: int, W: int,
                   kernels: Sequence[tuple[Taps, Taps]], boundary: str) -> Any:
    """``Σ_k (taps_y_k ⊗ taps_x_k) ∗ src`` per pixel, in two kernels: all horizontal passes
    share one gather per column offset, then the vertical passes are summed."""
    dense = [(dense_kernel(tx), dense_kernel(ty)) for tx, ty in kernels]
    rows = [gather_taps(src, dtype, H, W, {(0, i - len(kx) // 2): w
                                          for i, w in enumerate(kx) if w}, boundary)
            for kx, _ in dense]
    dr.eval(rows)                       # one kernel for every horizontal pass
    out = None
    for row, (_, ky) in zip(rows, dense):
        v = gather_taps(row, dtype, H, W, {(j - len(ky) // 2, 0): w
                                           for j, w in enumerate(ky) if w}, boundary)
        out = v if out is None else out + v
    return out


# -- index remapping and bilinear fetches ----------------------------------------------------
def remap(i: mi.Int32, n: int, boundary: str, reach: float = math.inf
          ) -> tuple[mi.Int32, mi.Bool | None]:
    """Map any integer pixel index to [0, n) as ``boundary`` says (scipy.ndimage semantics).

    Returns ``(index, valid)``; ``valid`` is a mask only for ``'zero'`` (out-of-image pixels read
    0). ``reach`` bounds how far outside the image ``i`` can be; a reach below ``n`` allows the
    cheaper single-reflection formulas.
    """
    if boundary == "nearest":
        return dr.clip(i, 0, n - 1), None
    if boundary == "zero":
        return dr.clip(i, 0, n - 1), (i >= 0) & (i < n)
    if boundary == "wrap":
        if reach < n:
            return dr.select(i < 0, i + n, dr.select(i >= n, i - n, i)), None
        m = i % n
        return dr.select(m < 0, m + n, m), None
    if boundary == "reflect":       # d c b a | a b c d | d c b a   (period 2n)
        if reach < n:
            j = dr.select(i < 0, -i - 1, i)
            return dr.select(j >= n, 2 * n - 1 - j, j), None
        p = 2 * n
        m = i % p
        m = dr.select(m < 0, m + p, m)
        return dr.select(m < n, m, p - 1 - m), None
    if boundary == "mirror":        # d c b | a b c d | c b a       (period 2n - 2)
        if n == 1:
            return dr.zeros(mi.Int32, dr.width(i)), None
        if reach < n - 1:
            j = dr.select(i < 0, -i, i)
            return dr.select(j >= n, 2 * n - 2 - j, j), None
        p = 2 * n - 2
        m = i % p
        m = dr.select(m < 0, m + p, m)
        return dr.select(m < n, m, p - m), None
    raise AssertionError(boundary)  # pragma: no cover - validated before


def bilinear_rgb(src: mi.Float, x0: mi.Int32, y0: mi.Int32, fx: Any, fy: Any, W: int, H: int,
                 boundary: str, reach: float = math.inf) -> mi.Color3f:
    """RGB at (x0 + fx, y0 + fy) (pixel-centre units) of the flat (H, W, 3) array ``src``."""
    xa, va = remap(x0, W, boundary, reach)
    xb, vb = remap(x0 + 1, W, boundary, reach)
    ya, wa = remap(y0, H, boundary, reach)
    yb, wb = remap(y0 + 1, H, boundary, reach)

    def fetch(xx: mi.Int32, yy: mi.Int32, vx: Any, vy: Any) -> mi.Color3f:
        idx = mi.UInt32(yy * W + xx)
        if vx is None:
            return dr.gather(mi.Color3f, src, idx)
        return dr.gather(mi.Color3f, src, idx, vx & vy)

    top = dr.lerp(fetch(xa, ya, va, wa), fetch(xb, ya, vb, wa), fx)
    bottom = dr.lerp(fetch(xa, yb, va, wb), fetch(xb, yb, vb, wb), fx)
    return dr.lerp(top, bottom, fy)
