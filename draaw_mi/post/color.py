"""Per-pixel colour filters: :func:`contrast`, :func:`tint`, :func:`lighten`, :func:`color_mapping`.

GO-Draaw's Kage shaders ``contrast``, ``tint``, ``Lighten`` and ``colorMapping`` (spec §6) on
float (HDR) images. Every filter returns ``lerp(c, f(c), amount)`` with ``f`` its full effect,
applied ``multipass`` times; ``amount = 0`` returns the input unchanged. The alpha channel of an
(H, W, 4) image passes through untouched.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any, Sequence

import drjit as dr
import mitsuba as mi

from ._spec import Filter, FilterSpec, Param
from ._util import per_channel


# -- contrast ---------------------------------------------------------------------------------
def _contrast(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    return (rgb - p.pivot) * p.contrast + p.pivot


CONTRAST = FilterSpec("contrast", (
    Param("contrast", 1.0, lo=0.0, hi=10.0),
    Param("pivot", 0.5, lo=0.0),
), _contrast)


def contrast(image: Any, contrast: float = 1.0, pivot: float = 0.5, *,
             amount: float = 1.0, multipass: int = 1) -> mi.TensorXf:
    """Scale the distance of every channel from a pivot grey (GO-Draaw ``contrast``).

    ``f(c) = (c - pivot) · contrast + pivot``, per channel; the result is
    ``lerp(c, f(c), amount)``, repeated ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) ``mi.TensorXf`` or float numpy array, linear, HDR allowed.
        contrast: GO-Draaw ``Contrast``; 1 is the identity, 0 gives flat ``pivot`` grey.
            Default 1.0, range [0, 10].
        pivot: grey level that stays fixed. Default 0.5 (GO-Draaw's fixed value), range [0, inf).
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape. Not clamped: GO-Draaw clamps to [0, 1] because its
        passes write 8-bit textures; here values may leave [0, 1] (dark pixels go negative for
        contrast > 1).

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.full((2, 3, 3), 0.75, dtype=np.float32)
        >>> out = post.contrast(img, 2.0)
        >>> out.shape, float(out[0, 0, 0].array[0])
        ((2, 3, 3), 1.0)
    """
    return CONTRAST.apply(image, dict(contrast=contrast, pivot=pivot, amount=amount,
                                      multipass=multipass))


class Contrast(Filter):
    """Callable form of :func:`contrast`: ``Contrast(2.0)(image)``."""
    spec = CONTRAST

    def __init__(self, contrast: float = 1.0, pivot: float = 0.5, *, amount: float = 1.0,
                 multipass: int = 1) -> None:
        super().__init__(contrast=contrast, pivot=pivot, amount=amount, multipass=multipass)


# -- tint -------------------------------------------------------------------------------------
def _tint(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    t = per_channel(rgb, p.color)
    if isinstance(t, float):
        return rgb + (t - rgb) * p.strength
    return mi.TensorXf(rgb.array + (t - rgb.array) * p.strength, rgb.shape)


TINT = FilterSpec("tint", (
    Param("color", (1.0, 1.0, 1.0), "color", lo=0.0, aliases=("TintColor", "colour")),
    Param("strength", 0.1, lo=0.0, hi=1.0, aliases=("TintStrength",)),
), _tint)


def tint(image: Any, color: Sequence[float] | str | float = (1.0, 1.0, 1.0),
         strength: float = 0.1, *, amount: float = 1.0, multipass: int = 1) -> mi.TensorXf:
    """Mix every pixel towards a colour (GO-Draaw ``tint``).

    ``f(c) = c + strength · (color - c)`` (``mix(c, color, strength)``); the result is
    ``lerp(c, f(c), amount)``, repeated ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        color: GO-Draaw ``TintColor``: 3 numbers, one number (grey), ``'#rrggbb'`` or
            ``{'r':, 'g':, 'b':}``. Default (1, 1, 1), each component in [0, inf) (HDR colours
            allowed).
        strength: GO-Draaw ``TintStrength``. Default 0.1, range [0, 1].
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape, not clamped (GO-Draaw's [0, 1] clamp is 8-bit
        storage, dropped for HDR).

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged (GO-Draaw also mixes alpha to 1).

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> out = post.tint(np.zeros((1, 1, 3), np.float32), "#ff0000", 0.5)
        >>> [round(v, 3) for v in out.array]
        [0.5, 0.0, 0.0]
    """
    return TINT.apply(image, dict(color=color, strength=strength, amount=amount,
                                  multipass=multipass))


class Tint(Filter):
    """Callable form of :func:`tint`."""
    spec = TINT

    def __init__(self, color: Sequence[float] | str | float = (1.0, 1.0, 1.0),
                 strength: float = 0.1, *, amount: float = 1.0, multipass: int = 1) -> None:
        super().__init__(color=color, strength=strength, amount=amount, multipass=multipass)


# -- lighten ----------------------------------------------------------------------------------
def _lighten(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    return rgb * (1.0 + p.strength)


LIGHTEN = FilterSpec("lighten", (
    Param("strength", 0.1, lo=-1.0, hi=100.0, aliases=("Lighten",)),
), _lighten)


def lighten(image: Any, strength: float = 0.1, *, amount: float = 1.0,
            multipass: int = 1) -> mi.TensorXf:
    """Brighten by a factor (GO-Draaw ``Lighten``).

    ``f(c) = (1 + strength) · c``; the result is ``lerp(c, f(c), amount) = c · (1 + amount ·
    strength)``, repeated ``multipass`` times.

    Deviation: GO-Draaw's shader does not multiply its colour by the blend weight, so its net
    effect is ``c · (Lighten + 1 - amount)``, which is not the input at ``amount = 0`` and
    darkens as ``amount`` grows. Here ``amount`` is a true blend and ``strength`` the added
    fraction (GO-Draaw at ``amount = 0`` equals this filter at ``amount = 1``).

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        strength: GO-Draaw ``Lighten``. Default 0.1, range [-1, 100] (negative darkens).
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> [round(v, 3) for v in post.lighten(np.ones((1, 1, 3), np.float32), 0.5).array]
        [1.5, 1.5, 1.5]
    """
    return LIGHTEN.apply(image, dict(strength=strength, amount=amount, multipass=multipass))


class Lighten(Filter):
    """Callable form of :func:`lighten`."""
    spec = LIGHTEN

    def __init__(self, strength: float = 0.1, *, amount: float = 1.0,
                 multipass: int = 1) -> None:
        super().__init__(strength=strength, amount=amount, multipass=multipass)


# -- colour mapping (quantisation) ------------------------------------------------------------
QUANT_TOLERANCE = 2.0 ** -22


def _color_mapping(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    # N·(1 + 2⁻²²): quantised values k/N (rounded to float32) map back to k, so the filter is
    # idempotent; it moves the level boundaries by a relative 2.4e-7 only
    # a true division, by an opaque N: k * (1/N) (which Dr.Jit makes of a division by a
    # literal) rounded levels k past ~2^21 off k/N, and a second pass moved them up a level
    n = per_channel(rgb, [v * (1.0 + QUANT_TOLERANCE) for v in p.levels])
    levels = per_channel(rgb, [float(v) for v in p.levels])
    if isinstance(levels, float):
        levels = dr.opaque(mi.Float, levels)
    x = rgb.array
    q = dr.floor(x * n) / levels
    # straight-through estimator: forward = quantised, backward = identity
    return mi.TensorXf(dr.replace_grad(q, x), rgb.shape)


COLOR_MAPPING = FilterSpec("color_mapping", (
    Param("levels", (16, 16, 16), "levels", lo=1, hi=65535,
          components=("ColorR", "ColorG", "ColorB")),
), _color_mapping, aliases=("colorMapping", "quantize", "quantise", "posterize"))


def color_mapping(image: Any, levels: int | Sequence[int] = 16, *, amount: float = 1.0,
                  multipass: int = 1) -> mi.TensorXf:
    """Quantise every channel to ``levels`` steps per unit (GO-Draaw ``colorMapping``).

    ``f(c) = floor(c · N · (1 + 2⁻²²)) / N`` per channel with N = ``levels`` (or
    ``levels[channel]``); the 2⁻²² tolerance makes quantised values fixed points despite float32
    rounding (``f(f(c)) = f(c)`` while ``c · N < 2^21``, and up to ``2.8e6`` where measured:
    c < 32 at 65535 levels, c < 8224 at 255; above that float32's rounding outgrows the
    tolerance). The result is
    ``lerp(c, f(c), amount)``, repeated ``multipass`` times. HDR values quantise to the same 1/N grid above 1.

    Gradients pass straight through (``dr.replace_grad``): ∂f/∂c is taken as 1, so the whole
    filter has gradient 1 for any ``amount`` (the true derivative of ``floor`` is 0 almost
    everywhere and would stop optimisation).

    Deviation: GO-Draaw does not multiply the quantised colour by the blend weight, so its net
    effect is ``q + c · (1 - amount)`` (brightening, not the input at ``amount = 0``); here
    ``amount`` is a true blend.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        levels: GO-Draaw ``ColorR``/``ColorG``/``ColorB``: one integer or three. Default 16,
            range [1, 65535] (GO-Draaw allows 0, which divides by zero).
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.array([[[0.30, 0.55, 1.70]]], np.float32)
        >>> [round(v, 3) for v in post.color_mapping(img, 4).array]
        [0.25, 0.5, 1.5]
    """
    return COLOR_MAPPING.apply(image, dict(levels=levels, amount=amount, multipass=multipass))


class ColorMapping(Filter):
    """Callable form of :func:`color_mapping`."""
    spec = COLOR_MAPPING

    def __init__(self, levels: int | Sequence[int] = 16, *, amount: float = 1.0,
                 multipass: int = 1) -> None:
        super().__init__(levels=levels, amount=amount, multipass=multipass)

