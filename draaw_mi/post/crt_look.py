"""CRT look: spiral blur + glow, vignette, green tint and scan lines (GO-Draaw ``CRT``, which
its README calls "Vignette"; spec §6)."""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import drjit as dr
import mitsuba as mi

from ._spec import BOUNDARIES, Filter, FilterSpec, Param
from ._util import bilinear_rgb, from_pixels, pixels

TAPS = 32
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))     # 2.39996... rad
WEIGHTS = [1.0 / (1.0 + math.sqrt(i)) for i in range(TAPS)]
WEIGHT_SUM = sum(WEIGHTS)                            # 8.09...
TINT = (0.95, 1.05, 0.95)


def pcg_hash(v: mi.UInt32) -> mi.UInt32:
    """PCG-RXS-M-XS 32-bit hash (Jarkko/O'Neill), identical in numpy's uint32 arithmetic."""
    state = v * 747796405 + 2891336453
    word = ((state >> ((state >> 28) + 4)) ^ state) * 277803737
    return (word >> 22) ^ word


def start_angle(pix: mi.UInt32, seed: int) -> mi.Float:
    """Per-pixel random start angle in [0, 2π): top 24 bits of ``pcg_hash(pixel + seed·φ32)``."""
    h = pcg_hash(pix + ((seed * 2654435769) & 0xFFFFFFFF))
    return mi.Float(h >> 8) * (2.0 * math.pi / 16777216.0)


def _crt(rgb: mi.TensorXf, p: SimpleNamespace) -> mi.TensorXf:
    H, W, _ = rgb.shape
    src = rgb.array
    pix = dr.arange(mi.Int32, H * W)
    x = pix % W
    y = pix // W
    centre = pixels(rgb)

    # ---- 32-tap golden-angle spiral blur, weights 1 / (1 + √i), normalised ----
    blur = centre * WEIGHTS[0]
    if p.radius > 0.0:
        s, c = dr.sincos(start_angle(mi.UInt32(pix), p.seed))
        step = p.radius / math.sqrt(TAPS)
        reach = p.radius + 2.0
        for i in range(1, TAPS):
            r = step * math.sqrt(i)
            ci, si = r * math.cos(i * GOLDEN_ANGLE), r * math.sin(i * GOLDEN_ANGLE)
            ox = c * ci - s * si                     # r·cos(θ₀ + i·golden angle)
            oy = s * ci + c * si
            fox, foy = dr.floor(ox), dr.floor(oy)    # split: exact integer part + fraction
            tap = bilinear_rgb(src, x + mi.Int32(fox), y + mi.Int32(foy), ox - fox, oy - foy,
                               W, H, p.boundary, reach)
            blur += tap * WEIGHTS[i]
    else:
        blur = centre * WEIGHT_SUM
    blur *= 1.0 / WEIGHT_SUM

    # ---- glow, curve, vignette, tint, scan lines ----
    # (lerp's a + (b - a) t would read inf - inf = NaN where blur * glow overflows float32)
    clr = blur * (p.glow * (1.0 - p.base)) + centre * p.base
    out = clr * 0.6 + clr * clr * 0.4           # (lerp(clr, clr^2, 0.4), finite where clr^2 overflows)
    if p.clamp:
        out = dr.clip(out, 0.0, 1.0)
    u = (mi.Float(x) + 0.5) * (1.0 / W)
    v = (mi.Float(y) + 0.5) * (1.0 / H)
    vignette = dr.power(40.0 * u * (1.0 - u) * v * (1.0 - v), 0.3)
    period = H // 480 + 1
    frac = mi.Float((2 * y + 1) % (2 * period)) * (1.0 / (2 * period))   # fract((y+0.5)/n)
    scan = 1.0 - 0.3 * frac
    out = out * mi.Color3f(*TINT) * (vignette * scan * 1.4)
    return from_pixels(out, rgb.shape)


CRT_SPEC = FilterSpec("crt", (
    Param("base", 0.5, lo=0.0, hi=1.0, aliases=("Base",)),
    Param("glow", 1.5, lo=0.0, hi=80.0, aliases=("Glow",)),
    Param("radius", 16.0, lo=0.0, hi=100.0, aliases=("Radius",)),
    Param("seed", 0, "int", lo=0, hi=2**31 - 1),
    Param("clamp", True, "bool"),
    Param("boundary", "reflect", "choice", choices=BOUNDARIES),
), _crt, aliases=("CRT", "vignette"))


def crt(image: Any, base: float = 0.5, glow: float = 1.5, radius: float = 16.0, *,
        seed: int = 0, clamp: bool = True, boundary: str = "reflect", amount: float = 1.0,
        multipass: int = 1) -> mi.TensorXf:
    """Old-monitor look (GO-Draaw ``CRT``, the README's "Vignette").

    Per pixel (x, y) of an H × W image, with c its colour:

    * blur: 32 taps, tap i at distance ``radius · √(i / 32)`` pixels and angle
      ``θ₀ + i · 2.39996`` (golden angle), weight ``1 / (1 + √i)``, normalised by their sum
      (8.09); θ₀ is a per-pixel random angle from an integer hash of the pixel index and
      ``seed``; taps are read with bilinear interpolation;
    * ``clr = mix(glow · blur, c, base)``; ``k = mix(clr, clr², 0.4)``, clamped to [0, 1] when
      ``clamp``;
    * vignette ``(40 · u(1-u) · v(1-v))^0.3`` with u = (x + ½)/W, v = (y + ½)/H; tint
      (0.95, 1.05, 0.95); scan lines ``1 - 0.3 · fract((y + ½) / n)``, n = ⌊H / 480⌋ + 1;
      ``f(c) = 1.4 · k · tint · vignette · scanlines``.

    The result is ``lerp(c, f(c), amount)``, repeated ``multipass`` times.

    Deviations: GO-Draaw's ``Radius`` is in texel units (fractions of the texture), which puts
    every tap but the centre outside the image, so its blur is just c / 8.09; here ``radius`` is
    in pixels, as the effect was designed. GO-Draaw's hash of x is not specified; a PCG hash is
    used (deterministic, ``seed`` selects another pattern). Alpha passes through.

    Args:
        image: (H, W, 3) or (H, W, 4) tensor or float array.
        base: GO-Draaw ``Base``, weight of the sharp image. Default 0.5, range [0, 1].
        glow: GO-Draaw ``Glow``, gain of the blur. Default 1.5, range [0, 80].
        radius: GO-Draaw ``Radius``, blur radius in pixels. Default 16, range [0, 100].
        seed: selects the per-pixel angle pattern. Default 0, range [0, 2³¹ - 1].
        clamp: the shader's clamp of ``k`` to [0, 1]. Default True (GO-Draaw); False keeps HDR.
        boundary: ``'reflect'`` (default), ``'nearest'``, ``'mirror'``, ``'wrap'``, ``'zero'``
            (GO-Draaw reads zeros).
        amount: blend with the input, default 1.0, range [0, 1].
        multipass: number of passes, default 1, range [1, 100].

    Returns:
        ``mi.TensorXf`` of the input's shape.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}; alpha unchanged.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.full((4, 4, 3), 0.5, np.float32)
        >>> round(float(post.crt(img)[1, 1, 1].array[0]), 4)
        0.8406
    """
    return CRT_SPEC.apply(image, dict(base=base, glow=glow, radius=radius, seed=seed,
                                      clamp=clamp, boundary=boundary, amount=amount,
                                      multipass=multipass))


class CRT(Filter):
    """Callable form of :func:`crt`."""
    spec = CRT_SPEC

    def __init__(self, base: float = 0.5, glow: float = 1.5, radius: float = 16.0, *,
                 seed: int = 0, clamp: bool = True, boundary: str = "reflect",
                 amount: float = 1.0, multipass: int = 1) -> None:
        super().__init__(base=base, glow=glow, radius=radius, seed=seed, clamp=clamp,
                         boundary=boundary, amount=amount, multipass=multipass)
