"""Fitted maps a user can take elsewhere: image files (:func:`save_maps`), the error of each
map against a known truth (:func:`map_errors`) and a figure of maps, truths, error maps and
the loss (:func:`plot_maps`).

>>> import numpy as np
>>> e = map_errors({"m.roughness": np.full((2, 2, 1), 0.3, np.float32)},
...                {"m.roughness": np.full((2, 2, 1), 0.5, np.float32)})
>>> round(e["m.roughness"]["mae"], 3)
0.2
"""
from __future__ import annotations

import os

import numpy as np

from ..errors import ParameterError
from ..io import atomic_path, srgb_encode, write_exr, write_png
from ..plotting import save, subplots
from .maps import material_parameter

#: file kinds :func:`save_maps` writes
FORMATS = ("exr", "png", "png16")


def _is_colour(name: str) -> bool:
    base = material_parameter(name)
    return base == "base_color" or "reflectance" in base or "transmittance" in base


def save_maps(values: dict, folder: str, formats=FORMATS) -> list:
    """Write every texture in ``values`` (name -> ``(H, W, C)`` array) into ``folder`` as
    ``<name>.exr`` (linear float32), ``<name>.png`` (8-bit) and ``<name>.16bit.png``; a colour
    map (base colour, reflectance) is sRGB-encoded in the PNGs, a data map (roughness,
    metallic) is stored as it is (0..1 -> 0..max). Atomic writes; returns the files written.
    """
    import mitsuba as mi

    unknown = sorted(set(formats) - set(FORMATS))
    if unknown:
        raise ParameterError(f"save_maps: formats {unknown}; expected some of {', '.join(FORMATS)}")
    written = []
    for name, value in values.items():
        if not isinstance(value, np.ndarray) or value.ndim != 3:
            continue
        stem = os.path.join(os.fspath(folder), name.removesuffix(".data"))
        arr = np.nan_to_num(value.astype(np.float32))
        shown = srgb_encode(np.clip(arr, 0.0, 1.0)) if _is_colour(name) else np.clip(arr, 0.0, 1.0)
        if "exr" in formats:
            channels = {1: ["Y"], 3: ["R", "G", "B"]}.get(arr.shape[2])
            write_exr(stem + ".exr", arr, channels=channels)
            written.append(stem + ".exr")
        if "png" in formats:
            write_png(stem + ".png", shown, encoded=True)
            written.append(stem + ".png")
        if "png16" in formats:
            bits = np.round(shown * 65535.0).astype(np.uint16)
            bitmap = mi.Bitmap(bits[..., 0] if bits.shape[2] == 1 else bits,
                               pixel_format=mi.Bitmap.PixelFormat.Y if bits.shape[2] == 1
                               else mi.Bitmap.PixelFormat.RGB)
            path = stem + ".16bit.png"
            with atomic_path(path, ".png") as tmp:
                bitmap.write(tmp)
            written.append(path)
    return written


def truth_like(who: str, name: str, truth, shape: tuple, dtype) -> np.ndarray:
    """``truth`` of the map ``name`` as an array of the fitted map's ``shape`` ((H, W) for an
    (H, W, 1) map too), or an error naming both shapes.

    >>> truth_like("map_errors", "m.roughness", np.zeros((8, 8)), (4, 4, 1), np.float64)
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: map_errors: the truth of m.roughness has shape (8, 8); the fitted map has (4, 4, 1) (a grey map may be given as (H, W))
    """
    t = np.asarray(truth, dtype=dtype)
    if t.shape == tuple(shape) or (t.ndim == 2 and shape[-1] == 1 and t.shape == tuple(shape[:2])):
        return t.reshape(shape)
    raise ParameterError(f"{who}: the truth of {name} has shape {t.shape}; the fitted map has {tuple(shape)}"
                         + (" (a grey map may be given as (H, W))" if shape[-1] == 1 else ""))


def map_errors(values: dict, truth: dict, observed: dict | None = None) -> dict:
    """Per map named in ``truth``: ``mae`` and ``psnr`` (peak 1) over the observed texels
    (all where ``observed`` has no entry for it)."""
    out = {}
    for name, t in truth.items():
        if name not in values:
            raise ParameterError(f"map_errors: truth names {name!r}, which was not fitted "
                                 f"(fitted: {', '.join(values)})")
        v = np.asarray(values[name], dtype=np.float64)
        t = truth_like("map_errors", name, t, v.shape, np.float64)
        seen = np.ones(v.shape[:2], bool) if observed is None or name not in observed else observed[name]
        d = (v - t)[seen]
        mse = float(np.mean(d * d)) if d.size else float("nan")
        out[name] = {"mae": float(np.mean(np.abs(d))) if d.size else float("nan"),
                     "psnr": float(-10 * np.log10(max(mse, 1e-12))), "observed": float(seen.mean())}
    return out


def plot_maps(values: dict, truth: dict | None = None, losses=None, observed: dict | None = None,
              path: str | None = None):
    """A row per map: the fitted map, the truth and the error (|fit - truth|, unobserved
    texels hatched out) when ``truth`` has it; and the loss over iterations. Saved to ``path``
    if given (else shown where pyplot shows)."""
    names = [n for n, v in values.items() if isinstance(v, np.ndarray) and v.ndim == 3]
    if not names:
        raise ParameterError("plot_maps: the fit has no texture maps to show")
    cols = 3 if truth else 1
    rows = len(names) + (1 if losses is not None else 0)
    if path is None:
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.0 * rows), squeeze=False)
    else:
        fig, axes = subplots(rows, cols, figsize=(3.2 * cols, 3.0 * rows), squeeze=False)
    for r, name in enumerate(names):
        v = values[name]
        colour = _is_colour(name)
        show = (lambda a: srgb_encode(np.clip(a, 0, 1))) if colour else (lambda a: np.clip(a[..., 0], 0, 1))
        kw = {} if colour else {"cmap": "viridis", "vmin": 0.0, "vmax": 1.0}
        axes[r][0].imshow(show(v), **kw)
        axes[r][0].set_title(f"{name}: fitted", fontsize=9)
        if truth and name in truth:
            t = truth_like("plot_maps", name, truth[name], v.shape, np.float32)
            axes[r][1].imshow(show(t), **kw)
            axes[r][1].set_title("truth", fontsize=9)
            err = np.abs(v - t).mean(axis=2)
            if observed and name in observed:
                err = np.ma.masked_where(~observed[name], err)
            im = axes[r][2].imshow(err, cmap="magma", vmin=0.0, vmax=0.5)
            axes[r][2].set_title("|error| (unobserved: blank)", fontsize=9)
            fig.colorbar(im, ax=axes[r][2], fraction=0.046)
        for a in axes[r]:
            a.set_xticks([])
            a.set_yticks([])
    if losses is not None:
        a = axes[-1][0]
        a.semilogy(np.asarray(losses))
        a.set_xlabel("iteration")
        a.set_title("loss", fontsize=9)
        for a in axes[-1][1:]:
            a.axis("off")
    fig.tight_layout()
    if path is not None:
        save(fig, path, dpi=100)
    return fig
