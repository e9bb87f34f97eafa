"""``[materials.NAME]`` tables -> Mitsuba BSDF dicts: the ``draaw`` plugin's parameters, any
other Mitsuba BSDF's passed through, colours and image files as textures (checked for finite,
non-negative values)."""
from __future__ import annotations

import os
import warnings
from typing import TYPE_CHECKING

import mitsuba as mi
import numpy as np

from ..errors import user_stacklevel
from ..guard import exr_reading_threads
from ..materials.draaw_bsdf import ALL_PARAMS as DRAAW_PARAMS
from ..materials.draaw_bsdf import COLOR_PARAMS, NORMALMAP_SLACK, OPTIONS, SCALAR_PARAMS
from ..materials.checks import PLAIN_RANGES, PLUGIN_RANGES, bad_texels
from ..materials.textures import at_least_2x2, linear_image
from .context import BuildContext
from .schema import Where, boolean, check_keys, number, shown, string, vector

if TYPE_CHECKING:
    import mitsuba as mi

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr", ".hdr", ".bmp", ".tga", ".pfm", ".ppm")
# negative values a resampled image keeps (Lanczos overshoot) and that are let through
NEGATIVE_SLACK = 1e-2



def check_image_values(path: str, label: str, where: Where, what: str, nonneg: bool = True) -> "mi.Bitmap":
    """Refuse an image file Mitsuba cannot read (naming it), one of channels other than grey or
    colour (Y, YA, RGB, RGBA, XYZ[A]: a multi-layer EXR), or one with a non-finite value in its
    colour channels, or, with ``nonneg``, one below ``-NEGATIVE_SLACK`` (a half-float HDRI
    stores a sun above 65504 as +Inf: its environment map renders NaN / Inf pixels in V3, V4
    and Mitsuba's ``path``), naming the first bad pixel. Alpha and other layers are not looked
    at. Returns the image read (a draaw material's texture and an environment map's tint use
    it: the file is read once)."""
    try:
        with exr_reading_threads():
            bitmap = mi.Bitmap(path)
    except Exception as e:  # noqa: BLE001 - Mitsuba's reader: one line
        raise where.error(f"{what} {label!r} cannot be read as an image file (Mitsuba: "
                          f"{str(e).strip().splitlines()[-1]})") from None
    pf = mi.Bitmap.PixelFormat
    if bitmap.pixel_format() not in (pf.Y, pf.YA, pf.RGB, pf.RGBA, pf.XYZ, pf.XYZA):
        raise where.error(f"{what} {label!r} has {bitmap.channel_count()} channels "
                          f"({bitmap.pixel_format().name}); expected a grey (Y, YA) or colour (RGB, RGBA) "
                          "image")
    arr = np.asarray(bitmap)
    if np.issubdtype(arr.dtype, np.integer):
        return bitmap                             # 8/16-bit: finite and >= 0 by construction
    arr = arr.reshape(arr.shape[0], arr.shape[1], -1)[..., :3]
    bad = ~np.isfinite(arr) | (arr < -NEGATIVE_SLACK) if nonneg else ~np.isfinite(arr)
    if bad.any():
        y, x, c = (int(i[0]) for i in np.nonzero(bad))
        raise where.error(f"{what} {label!r} has the value {float(arr[y, x, c]):g} at pixel "
                          f"(x={x}, y={y}), channel {c}; expected finite values"
                          + (" >= 0" if nonneg else ""))
    return bitmap


def tinted_image(bitmap: "mi.Bitmap", color) -> "mi.Bitmap":
    """``bitmap`` as linear float RGB, each channel times ``color`` (an environment map's
    tint)."""
    linear = bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
    rgb = np.array(linear, dtype=np.float32).reshape(linear.height(), linear.width(), 3)
    return mi.Bitmap(rgb * np.asarray(color, np.float32))


def texture_value(value, name: str, ctx: BuildContext, where: Where, lo: float | None = None,
                  linear: bool = False):
    """Scene-file value -> what the draaw plugin (or a Mitsuba BSDF) accepts; ``lo``: the
    least a plain number or RGB triple may be (a reflectance's 0). An image file (a name, or a
    Mitsuba ``{type = "bitmap", filename = ...}`` table, whose ``raw`` defaults to true for a
    data parameter) is read and checked (:func:`check_image_values`); with ``linear`` (a draaw
    material) its texels are given as linear float32 values (:func:`linear_image`: an 8-bit
    PNG's too, so they take float values and have a gradient), else as the file."""
    value = plain(value, where)
    if isinstance(value, dict) and value.get("type") == "bitmap" and isinstance(value.get("filename"), str):
        table = dict(value)
        raw = table.setdefault("raw", not is_colour(name))
        if not isinstance(raw, bool):
            raise (where / "raw").error(f"{shown(raw)}; expected true or false")
        table.update(image_file(table.pop("filename"), raw, ctx, where, nonneg=is_colour(name), linear=linear))
        return table
    if isinstance(value, str):
        return image_file(value, not is_colour(name), ctx, where, nonneg=is_colour(name), linear=linear)
    if is_nested(value):
        value = nested_array(value, where)
    if isinstance(value, np.ndarray):
        if not np.issubdtype(value.dtype, np.floating):
            raise where.error(f"an array of {value.dtype} values; expected linear floats (an 8-bit "
                              "image's values: divide by 255, and decode sRGB for a colour, or give "
                              "the image's file name)")
        arr = value.astype(np.float32)
        if arr.ndim == 2:
            arr = arr[..., None]
        return {"type": "bitmap", "data": mi.TensorXf(np.ascontiguousarray(at_least_2x2(arr))), "raw": True}
    if isinstance(value, (list, tuple)):
        return {"type": "rgb", "value": vector(value, where, lo=lo)}
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        # finite, within float32, >= lo (a reflectance's -0.5 renders negative pixels; a
        # plastic's int_ior = nan, which TOML allows, NaN pixels), as a float: a BSDF's
        # numbers are floats, and its int_ior = 2 would fail in Mitsuba ("expected string")
        return number(value, where, lo=lo)
    return value


def plain(value, where: Where):
    """A dict scene's numpy number or 0-d array as a float, a 1-d array as a list (an RGB
    triple); a ``mi.Bitmap`` refused (the scene description is copied, and a Bitmap cannot
    be)."""
    if isinstance(value, np.generic) or (isinstance(value, np.ndarray) and value.ndim == 0):
        return value.item()
    if isinstance(value, np.ndarray) and value.ndim == 1:
        return value.tolist()
    if isinstance(value, mi.Bitmap):
        raise where.error("a mi.Bitmap; give its linear values as a numpy array (np.array(bitmap), "
                          "8-bit ones divided by 255) or the image's file name")
    return value


def image_file(file: str, raw: bool, ctx: BuildContext, where: Where, nonneg: bool, linear: bool) -> dict:
    """The ``bitmap`` texture entries for the image ``file`` (found from the scene's folder):
    ``filename`` and ``raw``, or with ``linear`` its texels (:func:`linear_image`) as ``data``,
    with ``nonneg`` (a colour) those in [-NEGATIVE_SLACK, 0) as 0 (a resampled EXR's overshoot,
    let through as a ``diffuse`` reflectance's file is; the draaw BSDF refuses values < 0)."""
    path = ctx.path(file)
    if not os.path.isfile(path):
        raise where.error(f"texture file {file!r} does not exist (looked for {path!r})")
    if not path.lower().endswith(IMAGE_SUFFIXES):
        raise where.error(f"{file!r} is not an image file; expected one of {', '.join(IMAGE_SUFFIXES)}")
    # (a draaw material's ranges are checked by material_dict, naming the file)
    bitmap = check_image_values(path, file, where, "texture", nonneg)
    if not linear:
        return {"type": "bitmap", "filename": path, "raw": raw}
    data = at_least_2x2(linear_image(bitmap, raw))
    if nonneg:
        data = np.maximum(data, np.float32(0.0))
    return {"type": "bitmap", "data": mi.TensorXf(np.ascontiguousarray(data)), "raw": True}


def is_colour(name: str) -> bool:
    """Whether the BSDF parameter ``name`` is a colour (an image file of it is sRGB-decoded,
    and its values must be >= 0), not data (roughness, metallic, alpha, eta: read raw).

    >>> [is_colour(n) for n in ("base_color", "specular_transmittance", "alpha", "eta")]
    [True, True, False, False]
    """
    return name == "base_color" or "reflectance" in name or "transmittance" in name


def is_nested(value) -> bool:
    return isinstance(value, (list, tuple)) and len(value) > 0 and isinstance(value[0], (list, tuple))


def nested_array(value, where: Where) -> np.ndarray:
    """A TOML/JSON array of rows (``[[0.1, 0.9], [0.5, 0.3]]``: a 2x2 texture; rows of RGB
    triples: a colour texture) as a float array."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise where.error(f"{shown(value)} is not a rectangular array of numbers (a texture: rows "
                          "of values, or rows of RGB triples)") from None
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3)) or arr.size == 0:
        # (an empty one, [[]], would load and then abort the process at the render)
        raise where.error(f"an array of shape {arr.shape}; a texture is rows of values (H, W) or "
                          "rows of RGB triples (H, W, 3), at least one of them")
    return arr


def check_texels(entry, value, lo: float | None, hi: float | None, lo_open: bool = False,
                 where: Where | None = None) -> None:
    """Refuse a draaw material's image file or array (``entry``: its ``bitmap`` dict, ``value``:
    as the scene gave it) with a texel outside [lo, hi], naming the scene key and the file (or
    the array) and the first bad texel: the BSDF's own check names neither. ``lo_open``: lo
    itself is refused too (an index of refraction > 0)."""
    data = entry.get("data", entry.get("value")) if isinstance(entry, dict) else None
    if data is None or isinstance(data, (int, float)):       # (numbers: checked by number())
        return
    arr = np.asarray(data, dtype=np.float64).reshape(np.shape(data)[:2] + (-1,) if np.ndim(data) >= 2 else (1, 1, -1))
    found = bad_texels(arr, lo, hi, lo_open)
    if found is None:
        return
    _, (y, x, c), bad = found
    expected = f"{'>' if lo_open else '>='} {lo:g}" if hi is None else f"in [{lo:g}, {hi:g}]"
    if np.ndim(data) < 2:                                       # an RGB triple
        raise where.error(f"{shown(value)} has the component {bad:g}; expected finite values {expected}")
    file = value.get("filename") if isinstance(value, dict) else value
    what = f"texture file {file!r}" if isinstance(file, str) else "texture array"
    raise where.error(f"{what} has the value {bad:g} at pixel (x={x}, y={y}), channel {c}; "
                      f"expected finite values {expected}")


def _above_one(where: Where, what: str) -> None:
    """Warn of a colour above 1: reflecting more than arrives is allowed, as Mitsuba allows
    it, yet it is what GO-Draaw's 0-255 colours (or a PNG's 8-bit values) give when copied
    over."""
    warnings.warn(f"{where}: {what} reflects more light than arrives (above 1); GO-Draaw's 0-255 "
                  "colours are divided by 255 here, and light is given off by a light or a shape's "
                  "emission = [r, g, b]", RuntimeWarning, stacklevel=user_stacklevel())


def material_dict(name: str, table: dict, ctx: BuildContext, where: Where, two_sided_default=True) -> dict:
    """A Mitsuba BSDF dict for one ``[materials.NAME]`` table (validated)."""
    if not isinstance(table, dict):
        raise where.error(f"expected a material table, got {table!r}")
    kind = table.get("type", "draaw")
    string(kind, where / "type")
    if kind == "draaw":
        check_keys(table, ("type",) + DRAAW_PARAMS + OPTIONS, where)
        out = {"type": "draaw", "two_sided": two_sided_default}
        for key, value in table.items():
            if key == "type":
                continue
            wk = where / key
            value = plain(value, wk)
            if key in SCALAR_PARAMS:
                lo, hi = SCALAR_PARAMS[key][1:]
                if isinstance(value, (int, float)):
                    out[key] = number(value, wk, lo=lo, hi=hi)
                else:
                    out[key] = texture_value(value, key, ctx, wk, linear=True)
                    check_texels(out[key], value, lo, hi, where=wk)
            elif key in COLOR_PARAMS:
                if isinstance(value, (int, float, list, tuple)) and not isinstance(value, bool)\
                        and not is_nested(value):
                    rgb = vector(value, wk, lo=0.0)
                    if max(rgb) > 1.0:
                        _above_one(wk, shown(value))
                    out[key] = {"type": "rgb", "value": rgb}
                else:
                    out[key] = texture_value(value, key, ctx, wk, linear=True)
                    check_texels(out[key], value, 0.0, None, where=wk)
                    data = out[key].get("data") if isinstance(value, (list, tuple, np.ndarray)) else None
                    if data is not None and np.nanmax(np.asarray(data)) > 1.0:
                        _above_one(wk, f"an array of values up to {float(np.nanmax(np.asarray(data))):g}")
            elif key == "normalmap":
                out[key] = texture_value(value, key, ctx, wk, linear=True)
                data = out[key].get("data") if isinstance(out[key], dict) else None
                if data is not None and data.shape[2] != 3:
                    raise wk.error(f"{shown(value)} has {data.shape[2]} channel(s); a normal map has 3 "
                                   "(RGB: x, y, z), and height or bump maps are not supported")
            elif key == "normalmap_encoding":
                out[key] = string(value, wk, ("unsigned", "signed"))
            elif key == "two_sided":
                out[key] = boolean(value, wk)
            elif key == "alpha_min":
                out[key] = number(value, wk, lo=0.0, hi=0.1, lo_open=True)
        if "normalmap" in out:           # (in its encoding's range, as the BSDF has it)
            lo, hi = (-1.0, 1.0) if out.get("normalmap_encoding") == "signed" else (0.0, 1.0)
            check_texels(out["normalmap"], plain(table["normalmap"], where), lo - NORMALMAP_SLACK,
                         hi + NORMALMAP_SLACK, where=where / "normalmap")
        return out
    # Any other Mitsuba BSDF: pass the parameters through, colours and files as textures,
    # whose values must be finite (a NaN texel of a diffuse reflectance renders NaN pixels in
    # every version), and >= 0 for reflectances and transmittances.
    out = {"type": kind}
    for key, value in table.items():
        if key != "type":
            nonneg = is_colour(key)
            if isinstance(value, str) and not value.lower().endswith(IMAGE_SUFFIXES):
                out[key] = value      # a plugin's own string: material = "Au", int_ior = "bk7",
                continue              # distribution = "beckmann" (none is a texture file)
            rng = PLUGIN_RANGES.get(kind, {}).get(key) or PLAIN_RANGES.get(key)
            value = plain(value, where / key)
            if rng is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
                out[key] = number(value, where / key, lo=rng[0], hi=rng[1], lo_open=rng[2])
                continue
            out[key] = texture_value(value, key, ctx, where / key, lo=0.0 if nonneg else None)
            if rng is not None:                    # an array of it (rows, numpy)
                check_texels(out[key], value, *rng, where=where / key)
            if isinstance(out[key], dict) and "data" in out[key]:     # an array (numpy or rows)
                arr = np.asarray(out[key]["data"], dtype=np.float64)
                if not np.isfinite(arr).all() or (nonneg and (arr < -NEGATIVE_SLACK).any()):
                    raise (where / key).error("texture array has a non-finite"
                                              + (" or negative" if nonneg else "") + " value")
    return out
