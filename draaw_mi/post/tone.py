"""Tone curves: GO-Draaw's "Linear" and "Log" colour grades (:func:`linear`, :func:`log`) and
the sRGB transfer function (:func:`srgb`).

GO-Draaw's grades (spec §2.10) work on colours on a 0..255 scale and turn the user's "Gamma"
γ (0..1, default 0.25) into G = 3γ + 1 (an operator-precedence slip). Its per-channel
normalisation by the frame maximum never takes effect, so the *effective* curves are the ones
implemented here, on images where 1.0 = white (``scale`` = 255 converts to GO-Draaw's scale and
back). GO-Draaw saturates the result to 0..255 (``sat8``); here negative inputs map to 0 and
the result is clamped to 1 (``clamp=True``, the default) or left unbounded (``clamp=False``,
HDR; then large values or repeated passes can overflow float32 to inf).
"""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import drjit as dr
import mitsuba as mi

from ._spec import Filter, FilterSpec, Param


def _positive_power(x: mi.Float, e: float) -> mi.Float:
    """x^e for x > 0, 0 otherwise, with finite values and gradients everywhere."""
    pos = x > 0.0
    return dr.select(pos, dr.power(dr.select(pos, x, 1.0), e), 0.0)


# -- linear (GO-Draaw "Linear") ---------------------------------------------------------------
def _linear(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    e = 1.0 / (3.0 * p.gamma)
    # (s·c)^e / s = 2^(e log2 c + (e - 1) log2 s), in one exponent: as a product, s^(e-1)
    # overflows float32 below gamma 0.0196 (0 * inf: NaN on black pixels) and a Python float
    # below 0.0026 (OverflowError), where the result is a finite step
    x = rgb.array
    pos = x > 0.0
    lx = dr.log2(dr.select(pos, x, 1.0))
    out = dr.select(pos, dr.exp2(e * lx + (e - 1.0) * math.log2(float(p.scale))), 0.0)
    return mi.TensorXf(dr.minimum(out, 1.0) if p.clamp else out, rgb.shape)


_GAMMA = Param("gamma", 0.25, lo=0.0, hi=1.0, lo_open=True, aliases=("Gamma",))
# (float32 kernels: 1 / scale and scale * c stay normal numbers; 1e-39 had made black NaN)
_SCALE = Param("scale", 255.0, lo=1e-6, hi=1e6)
_CLAMP = Param("clamp", True, "bool")

LINEAR = FilterSpec("linear", (_GAMMA, _SCALE, _CLAMP), _linear, aliases=("lin", "gamma"), straight=True)


def linear(image: Any, gamma: float = 0.25, *, scale: float = 255.0, clamp: bool = True,
           amount: float = 1.0, multipass: int = 1) -> mi.TensorXf:
    """GO-Draaw's "Linear" grade, a power curve (effective formula of spec §2.10).

    ``f(c) = min((scale · c)^(1 / (3γ)) / scale, 1)`` for c > 0, else 0 (the ``min`` only with
    ``clamp``). γ = 1/3 is the identity; the default γ = 0.25 gives ``6.34 · c^1.333``
    (GO-Draaw's bright look). The result is
    ``lerp(c, f(c), amount)``, repeated ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array, linear radiance, 1.0 = white.
        gamma: GO-Draaw's "Gamma" γ. Default 0.25, range (0, 1] (γ → 0 is a step function).
        scale: white level of GO-Draaw's colour scale. Default 255; 1 applies
            ``c^(1/(3γ))`` directly. Range [1e-6, 1e6].
        clamp: clamp the curve at 1 (GO-Draaw's ``sat8``). Default True.
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape. With ``clamp=False`` small γ or many passes on
        HDR input can overflow float32 to inf.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged (GO-Draaw forces it to opaque).

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.array([[[0.0, 0.25, 1.0]]], np.float32)
        >>> [round(v, 4) for v in post.linear(img, 1 / 3).array]
        [0.0, 0.25, 1.0]
    """
    return LINEAR.apply(image, dict(gamma=gamma, scale=scale, clamp=clamp, amount=amount,
                                    multipass=multipass))


class Linear(Filter):
    """Callable form of :func:`linear`."""
    spec = LINEAR

    def __init__(self, gamma: float = 0.25, *, scale: float = 255.0, clamp: bool = True,
                 amount: float = 1.0, multipass: int = 1) -> None:
        super().__init__(gamma=gamma, scale=scale, clamp=clamp, amount=amount,
                         multipass=multipass)


# -- log (GO-Draaw "Log") ---------------------------------------------------------------------
def _log(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    e = (3.0 * p.gamma + 1.0) / (3.0 * p.gamma)
    x = rgb.array
    pos = x > 0.0
    lg = dr.log2(dr.select(pos, x, 0.0) * p.scale + 1.0)
    out = _positive_power(dr.select(pos, lg, 0.0), e) * (1.0 / p.scale)
    return mi.TensorXf(dr.minimum(out, 1.0) if p.clamp else out, rgb.shape)


LOG = FilterSpec("log", (_GAMMA, _SCALE, _CLAMP), _log, aliases=("logarithmic",), straight=True)


def log(image: Any, gamma: float = 0.25, *, scale: float = 255.0, clamp: bool = True,
        amount: float = 1.0, multipass: int = 1) -> mi.TensorXf:
    """GO-Draaw's "Log" grade (effective formula of spec §2.10).

    ``f(c) = min(log2(scale · c + 1)^((3γ + 1) / (3γ)) / scale, 1)`` for c > 0, else 0 (the
    ``min`` only with ``clamp``). With the
    defaults, white (c = 1) maps to 8^2.333 / 255 = 128 / 255 = 0.502. The result is ``lerp(c, f(c),
    amount)``, repeated ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array, 1.0 = white.
        gamma: GO-Draaw's "Gamma" γ. Default 0.25, range (0, 1].
        scale: white level of GO-Draaw's colour scale. Default 255, range [1e-6, 1e6].
        clamp: clamp the curve at 1 (GO-Draaw's ``sat8``). Default True.
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> round(float(post.log(np.ones((1, 1, 3), np.float32)).array[0]), 4)
        0.502
    """
    return LOG.apply(image, dict(gamma=gamma, scale=scale, clamp=clamp, amount=amount,
                                 multipass=multipass))


class Log(Filter):
    """Callable form of :func:`log`."""
    spec = LOG

    def __init__(self, gamma: float = 0.25, *, scale: float = 255.0, clamp: bool = True,
                 amount: float = 1.0, multipass: int = 1) -> None:
        super().__init__(gamma=gamma, scale=scale, clamp=clamp, amount=amount,
                         multipass=multipass)


# -- sRGB -------------------------------------------------------------------------------------
def _srgb(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    x = rgb.array
    if p.inverse:
        hi = x > 0.04045
        t = (dr.select(hi, x, 1.0) + 0.055) * (1.0 / 1.055)
        curve = dr.square(t) * dr.power(t, 0.4)          # t^2.4, more accurate for t >> 1
        return mi.TensorXf(dr.select(hi, curve, x * (1.0 / 12.92)), rgb.shape)
    hi = x > 0.0031308
    curve = 1.055 * dr.power(dr.select(hi, x, 1.0), 1.0 / 2.4) - 0.055
    return mi.TensorXf(dr.select(hi, curve, x * 12.92), rgb.shape)


SRGB_SPEC = FilterSpec("srgb", (Param("inverse", False, "bool"),), _srgb, straight=True)


def srgb(image: Any, *, inverse: bool = False, amount: float = 1.0,
         multipass: int = 1) -> mi.TensorXf:
    """The sRGB transfer function (IEC 61966-2-1), linear → display-encoded.

    ``f(c) = 12.92 c`` for c ≤ 0.0031308, else ``1.055 c^(1/2.4) - 0.055``; with
    ``inverse=True`` the decoding ``c / 12.92`` for c ≤ 0.04045, else
    ``((c + 0.055) / 1.055)^2.4``. Values above 1 follow the same curve (no clamp); negative
    values take the linear segment. The result is ``lerp(c, f(c), amount)``, repeated
    ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        inverse: decode instead of encode. Default False.
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.array([[[0.0, 0.18, 1.0]]], np.float32)
        >>> [round(v, 4) for v in post.srgb(img).array]
        [0.0, 0.4614, 1.0]
    """
    return SRGB_SPEC.apply(image, dict(inverse=inverse, amount=amount, multipass=multipass))


class SRGB(Filter):
    """Callable form of :func:`srgb`."""
    spec = SRGB_SPEC

    def __init__(self, *, inverse: bool = False, amount: float = 1.0,
                 multipass: int = 1) -> None:
        super().__init__(inverse=inverse, amount=amount, multipass=multipass)
