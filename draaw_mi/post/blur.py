"""Neighbourhood filters: :func:`bloom`, :func:`bloom_v2`, :func:`sharpen` (GO-Draaw ``bloom``,
``bloomV2``, ``sharpen``, spec §6), as fused ``dr.gather`` kernels.

Offsets are in pixels. Pixels outside the image are read according to ``boundary``
(``'reflect'`` by default; GO-Draaw's texture reads give transparent black, i.e. ``'zero'``).
"""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import drjit as dr
import mitsuba as mi

from ._spec import BOUNDARIES, Filter, FilterSpec, Param
from ._util import from_pixels, gather_taps, luminance, pixels, separable_taps

#: Bloom's three Gaussians: (σ in pixels, weight); the weights sum to 1.1 as in GO-Draaw.
BLOOM_GAUSSIANS = ((1.0, 0.5), (2.0, 0.3), (4.0, 0.3))


def gauss5(sigma: float) -> list[float]:
    """Normalised 1-D Gaussian weights at the integer offsets -2..2."""
    w = [math.exp(-(i * i) / (2.0 * sigma * sigma)) for i in range(-2, 3)]
    s = sum(w)
    return [v / s for v in w]


def bloom_blur(rgb: mi.TensorXf, spread: float, boundary: str) -> mi.Color3f:
    """Per pixel B = Σ_k weight_k · G_σk ∗ I, 5×5 Gaussians with taps ``spread`` pixels apart."""
    H, W, _ = rgb.shape
    kernels = []
    for sigma, weight in BLOOM_GAUSSIANS:
        g = gauss5(sigma)
        kernels.append(([(i * spread, w * weight) for i, w in zip(range(-2, 3), g)],
                        [(i * spread, w) for i, w in zip(range(-2, 3), g)]))
    return separable_taps(rgb.array, mi.Color3f, H, W, kernels, boundary)


def _bloom(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    spread = getattr(p, "spread", 1.0)
    c = pixels(rgb)
    b = bloom_blur(rgb, spread, p.boundary)
    glow = (c + b) * p.intensity
    if p.clamp:
        glow = dr.minimum(glow, 1.0)
    return from_pixels(dr.select(luminance(c) < p.threshold, c, glow), rgb.shape)


def _bloom_params(extra: tuple[Param, ...] = ()) -> tuple[Param, ...]:
    return (
        Param("threshold", 0.05, lo=0.0, aliases=("BloomThreshold",)),
        Param("intensity", 1.1, lo=0.0, hi=10.0, aliases=("BloomIntensity",)),
        *extra,
        Param("clamp", True, "bool"),
        Param("boundary", "reflect", "choice", choices=BOUNDARIES),
    )


BLOOM = FilterSpec("bloom", _bloom_params(), _bloom, multipass=3)
BLOOM_V2 = FilterSpec("bloom_v2", _bloom_params(
    (Param("spread", 0.7, lo=0.0, hi=8.0, aliases=("BloomSpread",)),)), _bloom,
    aliases=("bloomV2",), multipass=3)


def bloom(image: Any, threshold: float = 0.05, intensity: float = 1.1, *, clamp: bool = True,
          boundary: str = "reflect", amount: float = 1.0, multipass: int = 3) -> mi.TensorXf:
    """GO-Draaw's ``bloom``: pixels at or above the luminance ``threshold`` get their blurred
    neighbourhood added (and, with ``clamp``, are clipped to 1); darker pixels are left as they
    are, so no glow spreads into them, and with ``clamp`` an HDR highlight loses its energy
    (``clamp=False`` keeps it).

    ``B = 0.5·G₁ ∗ c + 0.3·G₂ ∗ c + 0.3·G₄ ∗ c`` where G_σ is a normalised 5×5 Gaussian (weights
    exp(-(x²+y²)/2σ²) at integer pixel offsets -2..2); then per pixel ``f(c) = c`` if
    ``Y(c) < threshold`` (Y = 0.2126 r + 0.7152 g + 0.0722 b) else ``min((c + B) · intensity,
    1)``. The result is ``lerp(c, f(c), amount)``, repeated ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        threshold: GO-Draaw ``BloomThreshold``: luminance below which a pixel is left alone.
            Default 0.05, range [0, inf) (above 1 is meaningful for HDR input).
        intensity: GO-Draaw ``BloomIntensity``. Default 1.1, range [0, 10].
        clamp: apply the shader's ``min(·, 1)``. Default True (GO-Draaw); False keeps HDR
            values.
        boundary: how pixels outside the image are read: ``'reflect'`` (default),
            ``'nearest'``, ``'mirror'``, ``'wrap'``, ``'zero'`` (GO-Draaw reads zeros).
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 3 (GO-Draaw's default), range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape. The threshold is a hard switch: gradients do not
        see it move.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.zeros((9, 9, 3), np.float32); img[4, 4] = 0.5
        >>> out = post.bloom(img, multipass=1)
        >>> round(float(out[4, 4, 0].array[0]), 4), float(out[0, 0, 0].array[0]) == 0.0
        (0.6125, True)
    """
    return BLOOM.apply(image, dict(threshold=threshold, intensity=intensity, clamp=clamp,
                                   boundary=boundary, amount=amount, multipass=multipass))


class Bloom(Filter):
    """Callable form of :func:`bloom`."""
    spec = BLOOM

    def __init__(self, threshold: float = 0.05, intensity: float = 1.1, *, clamp: bool = True,
                 boundary: str = "reflect", amount: float = 1.0, multipass: int = 3) -> None:
        super().__init__(threshold=threshold, intensity=intensity, clamp=clamp,
                         boundary=boundary, amount=amount, multipass=multipass)


def bloom_v2(image: Any, threshold: float = 0.05, intensity: float = 1.1, spread: float = 0.7,
             *, clamp: bool = True, boundary: str = "reflect", amount: float = 1.0,
             multipass: int = 3) -> mi.TensorXf:
    """Bloom with a stretchable kernel (GO-Draaw ``bloomV2``).

    As :func:`bloom`, but the 5×5 taps sit at ``spread · (i, j)`` pixels (i, j = -2..2) with the
    unchanged weights exp(-(i²+j²)/2σ²) (GO-Draaw scales offsets and σ together, so the kernel
    is only stretched). Fractional tap positions are read with bilinear interpolation.
    ``spread = 0`` (degenerate in GO-Draaw) is the limit: all taps at the centre, B = 1.1·c.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        threshold: ``BloomThreshold``, default 0.05, range [0, inf).
        intensity: ``BloomIntensity``, default 1.1, range [0, 10].
        spread: ``BloomSpread``, tap spacing in pixels. Default 0.7, range [0, 8].
        clamp: apply the shader's ``min(·, 1)``; default True.
        boundary: ``'reflect'`` (default), ``'nearest'``, ``'mirror'``, ``'wrap'``, ``'zero'``.
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 3, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.full((5, 5, 3), 0.2, np.float32)
        >>> round(float(post.bloom_v2(img, spread=1.5, multipass=1)[2, 2, 1].array[0]), 4)
        0.462
    """
    return BLOOM_V2.apply(image, dict(threshold=threshold, intensity=intensity, spread=spread,
                                      clamp=clamp, boundary=boundary, amount=amount,
                                      multipass=multipass))


class BloomV2(Filter):
    """Callable form of :func:`bloom_v2`."""
    spec = BLOOM_V2

    def __init__(self, threshold: float = 0.05, intensity: float = 1.1, spread: float = 0.7,
                 *, clamp: bool = True, boundary: str = "reflect", amount: float = 1.0,
                 multipass: int = 3) -> None:
        super().__init__(threshold=threshold, intensity=intensity, spread=spread, clamp=clamp,
                         boundary=boundary, amount=amount, multipass=multipass)


# -- sharpen ----------------------------------------------------------------------------------
def _sharpen(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    H, W, _ = rgb.shape
    s = p.sharpness
    stencil = {(0, 0): 1.0 + 4.0 * s, (-1, 0): -s, (1, 0): -s, (0, -1): -s, (0, 1): -s}
    return from_pixels(gather_taps(rgb.array, mi.Color3f, H, W, stencil, p.boundary),
                       rgb.shape)


SHARPEN = FilterSpec("sharpen", (
    Param("sharpness", 1.0, lo=0.0, hi=10.0),
    Param("boundary", "reflect", "choice", choices=BOUNDARIES),
), _sharpen)


def sharpen(image: Any, sharpness: float = 1.0, *, boundary: str = "reflect",
            amount: float = 1.0, multipass: int = 1) -> mi.TensorXf:
    """Laplacian sharpening (GO-Draaw ``sharpen``).

    ``K ∗ c`` with K = [[0,-1,0],[-1,5,-1],[0,-1,0]] at 1-pixel offsets, then
    ``f(c) = mix(c, K ∗ c, sharpness) = c + sharpness · (4c - c_up - c_down - c_left -
    c_right)``. The result is ``lerp(c, f(c), amount)``, repeated ``multipass`` times.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        sharpness: GO-Draaw ``Sharpness``. Default 1.0, range [0, 10].
        boundary: ``'reflect'`` (default), ``'nearest'``, ``'mirror'``, ``'wrap'``, ``'zero'``.
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape, not clamped (can go below 0 next to edges;
        GO-Draaw's [0, 1] clamp is its 8-bit storage).

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged (GO-Draaw sharpens alpha too).

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.zeros((3, 3, 3), np.float32); img[1, 1] = 1.0
        >>> out = post.sharpen(img, 0.5)
        >>> float(out[1, 1, 0].array[0]), float(out[0, 1, 0].array[0])
        (3.0, -0.5)
    """
    return SHARPEN.apply(image, dict(sharpness=sharpness, boundary=boundary, amount=amount,
                                     multipass=multipass))


class Sharpen(Filter):
    """Callable form of :func:`sharpen`."""
    spec = SHARPEN

    def __init__(self, sharpness: float = 1.0, *, boundary: str = "reflect",
                 amount: float = 1.0, multipass: int = 1) -> None:
        super().__init__(sharpness=sharpness, boundary=boundary, amount=amount,
                         multipass=multipass)
