"""Independent numpy/scipy implementations of the ``draaw_mi.post`` formulas (test oracles).

Written from the formulas in the docstrings / GO-Draaw spec §6 with plain numpy and
``scipy.ndimage``; nothing here calls draaw_mi. Every function takes an (H, W, 3|4) float array
and keeps its dtype (float64 in the accuracy tests, float32 in the speed benchmark). Pixels
outside the image come from ``np.pad`` (reflect = 'symmetric', mirror = 'reflect', nearest =
'edge', wrap, zero = 'constant'); fractional offsets are read bilinearly.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

NDI_MODE = {"reflect": "reflect", "mirror": "mirror", "nearest": "nearest", "wrap": "wrap",
            "zero": "constant"}
PAD_MODE = {"reflect": "symmetric", "mirror": "reflect", "nearest": "edge", "wrap": "wrap",
            "zero": "constant"}


def passes(img, effect, amount=1.0, multipass=1):
    """lerp(c, effect(c), amount) on the RGB channels, ``multipass`` times; alpha copied."""
    img = np.asarray(img)
    rgb, alpha = img[..., :3], img[..., 3:]
    if amount != 0:
        for _ in range(multipass):
            f = effect(rgb)
            rgb = f if amount == 1 else rgb + amount * (f - rgb)
    return np.concatenate([rgb, alpha], axis=-1) if alpha.shape[-1] else rgb.copy()


def shifted(a, dy, dx, boundary):
    """out[y, x] = a(y + dy, x + dx), bilinear for fractional offsets, padded per ``boundary``."""
    H, W = a.shape[:2]
    py, px = int(math.ceil(abs(dy))) + 2, int(math.ceil(abs(dx))) + 2
    pad = [(py, py), (px, px)] + [(0, 0)] * (a.ndim - 2)
    P = np.pad(a, pad, mode=PAD_MODE[boundary])
    iy, ix = math.floor(dy), math.floor(dx)
    fy, fx = dy - iy, dx - ix

    def at(oy, ox):
        return P[py + oy:py + oy + H, px + ox:px + ox + W]

    top = (1 - fx) * at(iy, ix) + fx * at(iy, ix + 1) if fx else at(iy, ix)
    if not fy:
        return top
    bottom = (1 - fx) * at(iy + 1, ix) + fx * at(iy + 1, ix + 1) if fx else at(iy + 1, ix)
    return (1 - fy) * top + fy * bottom


def _col(values, dtype):
    return np.asarray(values, dtype=dtype).reshape(1, 1, 3)


# -- colour -----------------------------------------------------------------------------------
def contrast(img, contrast=1.0, pivot=0.5, amount=1.0, multipass=1):
    return passes(img, lambda c: (c - pivot) * contrast + pivot, amount, multipass)


def tint(img, color=(1.0, 1.0, 1.0), strength=0.1, amount=1.0, multipass=1):
    return passes(img, lambda c: c * (1 - strength) + _col(color, c.dtype) * strength,
                  amount, multipass)


def lighten(img, strength=0.1, amount=1.0, multipass=1):
    return passes(img, lambda c: c * (1 + strength), amount, multipass)


def color_mapping(img, levels=16, amount=1.0, multipass=1):
    n = np.broadcast_to(np.asarray(levels, dtype=np.float64), (3,))

    def effect(c):
        return (np.floor(c * _col(n * (1 + 2.0 ** -22), c.dtype)) / _col(n, c.dtype)).astype(
            c.dtype)
    return passes(img, effect, amount, multipass)


# -- bloom, sharpen -----------------------------------------------------------------------------
def _gauss5(sigma):
    w = np.exp(-np.arange(-2, 3) ** 2 / (2.0 * sigma * sigma))
    return w / w.sum()


_BLOOM = ((1.0, 0.5), (2.0, 0.3), (4.0, 0.3))
_Y = (0.2126, 0.7152, 0.0722)


def _bloom_finish(c, b, threshold, intensity, clamp):
    glow = (c + b) * intensity
    if clamp:
        glow = np.minimum(glow, 1.0)
    y = c[..., 0] * _Y[0] + c[..., 1] * _Y[1] + c[..., 2] * _Y[2]
    return np.where((y < threshold)[..., None], c, glow)


def bloom(img, threshold=0.05, intensity=1.1, clamp=True, boundary="reflect", amount=1.0,
          multipass=3):
    mode = NDI_MODE[boundary]

    def effect(c):
        b = sum(weight * ndimage.correlate1d(ndimage.correlate1d(c, _gauss5(s), axis=1,
                                                                 mode=mode),
                                             _gauss5(s), axis=0, mode=mode)
                for s, weight in _BLOOM)
        return _bloom_finish(c, b, threshold, intensity, clamp)
    return passes(img, effect, amount, multipass)


def bloom_v2(img, threshold=0.05, intensity=1.1, spread=0.7, clamp=True, boundary="reflect",
             amount=1.0, multipass=3):
    # the 25 taps of the combined kernel, each read bilinearly at spread·(i, j)
    w2 = sum(weight * np.outer(_gauss5(s), _gauss5(s)) for s, weight in _BLOOM)

    def effect(c):
        b = np.zeros_like(c)
        for i in range(-2, 3):
            for j in range(-2, 3):
                b = b + float(w2[i + 2, j + 2]) * shifted(c, i * spread, j * spread, boundary)
        return _bloom_finish(c, b, threshold, intensity, clamp)
    return passes(img, effect, amount, multipass)


def sharpen(img, sharpness=1.0, boundary="reflect", amount=1.0, multipass=1):
    k = np.array([[0, -1, 0], [-1, 5, -1], [0, -1, 0]], dtype=np.float64)[:, :, None]

    def effect(c):
        kc = ndimage.correlate(c, k.astype(c.dtype), mode=NDI_MODE[boundary])
        return c + (kc - c) * sharpness
    return passes(img, effect, amount, multipass)


# -- edges, aberration --------------------------------------------------------------------------
def edge_detection(img, distance=1.0, color=(1.0, 1.0, 1.0), boundary="reflect", amount=1.0,
                   multipass=1):
    d = distance

    def effect(c):
        lum = (c[..., 0] + c[..., 1] + c[..., 2]) / 3
        s = {(dy, dx): shifted(lum, dy * d, dx * d, boundary)
             for dy in (-1, 0, 1) for dx in (-1, 0, 1)}
        gx = (s[-1, 1] + 2 * s[0, 1] + s[1, 1]) - (s[-1, -1] + 2 * s[0, -1] + s[1, -1])
        gy = (s[1, -1] + 2 * s[1, 0] + s[1, 1]) - (s[-1, -1] + 2 * s[-1, 0] + s[-1, 1])
        e = np.sqrt(gx * gx + gy * gy)
        return c + e[..., None] * _col(color, c.dtype)
    return passes(img, effect, amount, multipass)


def chromatic_aberration(img, shift=2.0, boundary="reflect", amount=1.0, multipass=1):
    def effect(c):
        out = c.copy()
        out[..., 0] = shifted(c[..., 0], 0, -shift, boundary)
        out[..., 2] = shifted(c[..., 2], 0, shift, boundary)
        return out
    return passes(img, effect, amount, multipass)


# -- CRT ----------------------------------------------------------------------------------------
def pcg_hash(v):
    v = np.asarray(v, dtype=np.uint32)
    state = v * np.uint32(747796405) + np.uint32(2891336453)
    word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


def crt(img, base=0.5, glow=1.5, radius=16.0, seed=0, clamp=True, boundary="reflect",
        amount=1.0, multipass=1):
    golden = math.pi * (3 - math.sqrt(5))
    weights = 1.0 / (1.0 + np.sqrt(np.arange(32)))

    def effect(c):
        H, W, _ = c.shape
        ys, xs = np.mgrid[0:H, 0:W]
        h = pcg_hash(np.arange(H * W, dtype=np.uint32) + np.uint32((seed * 2654435769) % 2**32))
        theta = ((h >> np.uint32(8)).astype(np.float64) * (2 * math.pi / 2**24)).reshape(H, W)
        pad = int(math.ceil(radius)) + 2
        P = np.pad(c, ((pad, pad), (pad, pad), (0, 0)), mode=PAD_MODE[boundary])
        acc = c * float(weights[0])
        for i in range(1, 32):
            r = radius * math.sqrt(i / 32)
            px = xs + r * np.cos(theta + i * golden)
            py = ys + r * np.sin(theta + i * golden)
            x0, y0 = np.floor(px), np.floor(py)
            fx, fy = (px - x0)[..., None], (py - y0)[..., None]
            x0, y0 = x0.astype(np.int64) + pad, y0.astype(np.int64) + pad
            tap = ((1 - fy) * ((1 - fx) * P[y0, x0] + fx * P[y0, x0 + 1])
                   + fy * ((1 - fx) * P[y0 + 1, x0] + fx * P[y0 + 1, x0 + 1]))
            acc = acc + float(weights[i]) * tap.astype(c.dtype)
        blur = acc / float(weights.sum())
        clr = glow * blur * (1 - base) + c * base
        k = clr * 0.6 + clr * clr * 0.4
        if clamp:
            k = np.clip(k, 0.0, 1.0)
        u, v = (xs + 0.5) / W, (ys + 0.5) / H
        vignette = (40 * u * (1 - u) * v * (1 - v)) ** 0.3
        n = H // 480 + 1
        scan = 1 - 0.3 * np.mod((ys + 0.5) / n, 1.0)
        factor = (vignette * scan * 1.4).astype(c.dtype)[..., None]
        return k * _col((0.95, 1.05, 0.95), c.dtype) * factor
    return passes(img, effect, amount, multipass)


# -- tone curves --------------------------------------------------------------------------------
def linear(img, gamma=0.25, scale=255.0, clamp=True, amount=1.0, multipass=1):
    def effect(c):
        out = (scale * np.maximum(c, 0)) ** (1 / (3 * gamma)) / scale
        return np.minimum(out, 1.0) if clamp else out
    return straight_passes(img, effect, amount, multipass)


def log(img, gamma=0.25, scale=255.0, clamp=True, amount=1.0, multipass=1):
    def effect(c):
        out = np.log2(scale * np.maximum(c, 0) + 1) ** ((3 * gamma + 1) / (3 * gamma)) / scale
        return np.minimum(out, 1.0) if clamp else out
    return straight_passes(img, effect, amount, multipass)


def srgb(img, inverse=False, amount=1.0, multipass=1):
    def effect(c):
        if inverse:
            return np.where(c <= 0.04045, c / 12.92,
                            ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)
        return np.where(c <= 0.0031308, c * 12.92,
                        1.055 * np.maximum(c, 0.0031308) ** (1 / 2.4) - 0.055)
    return straight_passes(img, effect, amount, multipass)


def straight_passes(img, effect, amount, multipass):
    """:func:`passes` of a display curve: on RGBA (colour premultiplied by alpha) it acts on
    c / a and multiplies a back, a taken in (0, 1] (alpha 0 or not finite: the colour as it is)."""
    img = np.asarray(img)
    if img.shape[-1] != 4:
        return passes(img, effect, amount, multipass)
    alpha = img[..., 3:]
    with np.errstate(invalid="ignore"):
        a = np.where((alpha > 0) & np.isfinite(alpha), np.minimum(alpha, 1.0), 1.0)
    out = passes(np.concatenate([img[..., :3] / a, alpha], axis=-1), effect, amount, multipass)
    out[..., :3] *= a
    return out


FUNCTIONS = {f.__name__: f for f in (contrast, tint, bloom, bloom_v2, sharpen, color_mapping,
                                     chromatic_aberration, edge_detection, lighten, crt, linear,
                                     log, srgb)}


def chain(img, entries):
    """Apply ``[(name, params), ...]`` in order (RGBA: alpha copied by every step)."""
    for name, params in entries:
        img = FUNCTIONS[name](img, **params)
    return img
