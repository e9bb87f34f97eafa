"""Image error metrics of the benchmarks: RMSE, relative MSE and CIEDE2000 (colour-science)
against a ground truth.

>>> import numpy as np
>>> errors(np.full((2, 2, 3), 0.5), np.full((2, 2, 3), 0.5))["rmse"]
0.0
"""
from __future__ import annotations

import numpy as np

from ..io import srgb_encode


def rmse(img: np.ndarray, gt: np.ndarray) -> float:
    return float(np.sqrt(np.mean((img - gt) ** 2)))


def relmse(img: np.ndarray, gt: np.ndarray) -> float:
    return float(np.mean((img - gt) ** 2 / (gt ** 2 + 1e-2)))


def _colour():
    """colour-science, imported without its side effect: its import sets numpy's print options
    to ``legacy='1.13'`` for the whole process (a user's notebook would then print arrays
    and scalars the old way after the first benchmark)."""
    options = np.get_printoptions()
    try:
        import colour  # (0.9 s to import: paid by CIEDE2000 only)
    finally:
        np.set_printoptions(**options)
    return colour


def delta_e2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """Per-element CIEDE2000 colour difference of CIELAB arrays (..., 3) (colour-science).

    >>> round(float(delta_e2000(np.array([50.0, 2.6772, -79.7751]), np.array([50.0, 0.0, -82.7485]))), 4)
    2.0425
    """
    return _colour().delta_E(lab1, lab2, method="CIE 2000")


def srgb_to_lab(img: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of a linear-sRGB image after display encoding (clipped to [0, 1])."""
    colour = _colour()
    enc = srgb_encode(img[..., :3])
    xyz = colour.sRGB_to_XYZ(enc)                     # decodes the sRGB transfer function
    return colour.XYZ_to_Lab(xyz)


def ciede2000(img: np.ndarray, gt: np.ndarray) -> float:
    """Mean CIEDE2000 between the sRGB-encoded (display-referred, clipped) images."""
    return float(np.mean(delta_e2000(srgb_to_lab(img), srgb_to_lab(gt))))


def errors(img: np.ndarray, gt: np.ndarray) -> dict:
    """RMSE, relative MSE and CIEDE2000 of ``img`` against ``gt``; NaN and inf pixels are taken
    as 0 (one bad pixel would make every metric NaN): :func:`draaw_mi.bench.study.measure_group`'s ``finite``
    column says whether there were any."""
    img = np.nan_to_num(img[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    return {"rmse": rmse(img, gt), "relmse": relmse(img, gt), "ciede2000": ciede2000(img, gt)}
