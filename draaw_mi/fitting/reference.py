"""What :func:`draaw_mi.fit` compares its renders with: references read from EXR/PNG files or
arrays (:func:`load_reference`), which pixels of a display image count
(:func:`unclipped_mask`), and the checks of a reference against the scene and the post chain.

>>> import numpy as np
>>> load_reference(np.full((2, 2), 0.5, np.float32))[0, 0].tolist()
[0.5, 0.5, 0.5]
"""
from __future__ import annotations

import os
from typing import TYPE_CHECKING

import mitsuba as mi
import numpy as np

from ..errors import IOFailure, ParameterError
from ..io import read_exr, srgb_decode, to_numpy
from ..post import display_encoded
from ..post.chain import Chain

if TYPE_CHECKING:
    from ..scene import DraawScene

# references read from these are display images: clipped to [0, 1] (and 8-bit)
DISPLAY_SUFFIXES = (".png", ".jpg", ".jpeg")
# a display reference's values at or above this (linear; 254/255 in sRGB) may have been clipped
SATURATED = 0.99


def is_display_reference(ref) -> bool:
    """Whether reference ``ref`` is a display image (a PNG/JPEG path), whose values were
    clipped to [0, 1] when it was written: its saturated pixels say only "at least 1", so the
    loss leaves them out (:func:`unclipped_mask`)."""
    return isinstance(ref, (str, os.PathLike)) and os.fspath(ref).lower().endswith(DISPLAY_SUFFIXES)


def unclipped_mask(ref: np.ndarray) -> np.ndarray:
    """1 where a display reference's channel is below :data:`SATURATED`, else 0.

    >>> unclipped_mask(np.array([[[0.2, 0.995, 1.0]]], dtype=np.float32)).tolist()
    [[[1.0, 0.0, 0.0]]]
    """
    return (ref < SATURATED).astype(np.float32)


def load_reference(ref, encoded: bool = False, who: str = "fit") -> np.ndarray:
    """An (H, W, 3) float32 reference from an EXR/PNG path or an (H, W[, 1 | 3 | 4]) float
    array/tensor. A PNG/JPEG is decoded from sRGB to linear, unless ``encoded`` (the fit's
    post chain ends in a display curve, ``srgb`` or a grade, :func:`draaw_mi.post.display_encoded`: its renders are
    compared display-encoded, as ``draaw-mi render --post ... --png`` stored them). An EXR's
    colour is its R, G, B channels, a grey Y, or the R, G, B of its one layer
    (``ViewLayer.Combined.R``, ...). ``who``: the caller, as errors name it.

    >>> load_reference(np.zeros((2, 3), np.float32)).shape
    (2, 3, 3)
    >>> load_reference(np.zeros((2, 3, 3), np.uint8))
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: fit: reference array of dtype uint8; expected float values (linear): divide 8-bit values by 255 and decode sRGB, or pass the PNG file
    """
    if isinstance(ref, os.PathLike):
        ref = os.fspath(ref)
    if isinstance(ref, str):
        if ref.lower().endswith(".exr"):
            arr = _exr_colour(ref, *read_exr(ref, with_names=True), who)
        elif ref.lower().endswith(DISPLAY_SUFFIXES):
            arr = _display_file(ref, who)
            if not encoded:
                arr = srgb_decode(arr)
        else:
            raise IOFailure(f"{who}: reference {ref!r} must be an .exr or .png file")
    else:
        arr = _array_reference(ref, who)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.shape[2] == 1:
        arr = np.repeat(arr, 3, axis=2)
    arr = arr[..., :3].astype(np.float32)
    bad_px = ~np.all(np.isfinite(arr), axis=2)
    if bad_px.any():
        bad = int(np.count_nonzero(bad_px))
        y, x = np.argwhere(bad_px)[0]
        what = f"reference {ref!r}" if isinstance(ref, str) else "a reference image"
        raise ParameterError(f"{who}: {what} has {bad} pixel(s) with NaN or Inf (first at x={x}, y={y})")
    return arr


def _display_file(path: str, who: str) -> np.ndarray:
    """A PNG or JPEG reference's values as stored, in [0, 1] (sRGB-encoded), alpha dropped: read
    by Mitsuba's bitmap, which keeps a 16-bit file's precision (matplotlib's reader had cut a
    16-bit RGB PNG to 8 bits)."""
    try:
        bitmap = mi.Bitmap(path)
    except Exception as e:  # noqa: BLE001  (a missing or corrupt file: Mitsuba's message)
        raise IOFailure(f"{who}: cannot read reference {path!r}: {e}") from None
    pf = mi.Bitmap.PixelFormat
    fmt = bitmap.pixel_format()
    if fmt not in (pf.Y, pf.YA, pf.RGB, pf.RGBA):
        raise ParameterError(f"{who}: reference {path!r} has {bitmap.channel_count()} channels "
                             f"({fmt.name}); expected a grey or colour image")
    target = pf.Y if fmt in (pf.Y, pf.YA) else pf.RGB
    out = bitmap.convert(target, mi.Struct.Type.Float32, srgb_gamma=bool(bitmap.srgb_gamma()))
    return np.array(out, dtype=np.float32).reshape(out.height(), out.width(), -1)


def _exr_colour(path: str, arr: np.ndarray, names: list, who: str) -> np.ndarray:
    """The colour of an EXR reference (see :func:`load_reference`), or an error that lists
    its channels (a layered EXR's channels in name order, A, B, G, are not its colour)."""
    index = {n: i for i, n in enumerate(names)}
    if all(c in index for c in "RGB"):
        return arr[..., [index["R"], index["G"], index["B"]]]
    if "Y" in index and not {"X", "Z", "RY", "BY"} & set(index):    # (not CIE XYZ, chroma)
        return arr[..., [index["Y"]]]
    layers = sorted({n[:-2] for n in names if n.endswith(".R")
                     and all(n[:-2] + "." + c in index for c in "GB")})
    if len(layers) == 1:
        return arr[..., [index[f"{layers[0]}.{c}"] for c in "RGB"]]
    found = ", ".join(sorted(names)[:12]) + (", ..." if len(names) > 12 else "")
    which = f"; it has the layers {', '.join(layers)}: keep one" if layers else ""
    raise ParameterError(f"{who}: reference {path!r} has the channels {found}; expected R, G, B, "
                         f"a grey Y, or the R, G, B of one layer{which}")


def _array_reference(ref, who: str) -> np.ndarray:
    """An array/tensor reference as (H, W[, 1 | 3 | 4]) float32 values, or an error (an 8-bit
    array would be taken as linear values of 0-255, a channel-first one as a 3-pixel-high
    image)."""
    if isinstance(ref, mi.Bitmap) and ref.component_format() not in (mi.Struct.Type.Float16, mi.Struct.Type.Float32,
                                                                      mi.Struct.Type.Float64):
        # (else an 8-bit PNG's bitmap is taken as linear values of 0-255: a loss of 12455)
        raise ParameterError(f"{who}: reference mi.Bitmap of component format {ref.component_format()}; "
                             "expected float values (linear): pass the PNG file, or "
                             "bitmap.convert(component_format=mi.Struct.Type.Float32, srgb_gamma=False)")
    try:
        raw = np.asarray(ref) if not isinstance(ref, (mi.TensorXf, mi.Bitmap)) else None
    except ValueError:                               # (nested lists of unequal lengths)
        raw = np.asarray(ref, dtype=object)
    if raw is not None and (raw.dtype == object or raw.ndim not in (2, 3)):
        stacked = " (one reference per view: pass a list of (H, W, C) arrays)" if raw.ndim == 4 else ""
        raise ParameterError(f"{who}: reference of shape {raw.shape} and dtype {raw.dtype}; expected "
                             f"an (H, W) or (H, W, C) array of floats{stacked}")
    if raw is not None and not np.issubdtype(raw.dtype, np.floating):
        raise ParameterError(f"{who}: reference array of dtype {raw.dtype}; expected float values "
                             "(linear): divide 8-bit values by 255 and decode sRGB, or pass the PNG file")
    arr = to_numpy(ref)
    if arr.shape[2] not in (1, 3, 4):
        raise ParameterError(f"{who}: reference of shape {arr.shape}; expected (H, W), (H, W, 1), "
                             "(H, W, 3) or (H, W, 4) (channels last)")
    return arr


def display_encoded_post(post) -> bool:
    """Whether the ``post`` chain (a list of filter tables or a ``Chain``) ends display-encoded;
    a function of the user's own cannot say: its PNG references are decoded."""
    return (isinstance(post, Chain) or not callable(post)) and display_encoded(post)


def check_reference_size(scene: DraawScene, w: int, h: int, reference) -> None:
    """A reference of another size than the scene's film is fitted at its own size when it
    has the same aspect ratio (a smaller reference makes a faster fit); another aspect ratio
    would stretch the image, and is refused (a 48x24 reference of a 24x24 scene, say)."""
    sw, sh = scene.resolution
    what = reference if isinstance(reference, (str, os.PathLike)) else "the reference"
    if abs(w * sh - h * sw) > 0.02 * max(w * sh, h * sw):
        raise ParameterError(f"fit: {what} is {w}x{h}, the scene renders {sw}x{sh}: another aspect "
                         "ratio; render the reference with the scene's camera and film")
    if not scene.resizable:
        raise ParameterError(f"fit: {what} is {w}x{h}, the scene renders {sw}x{sh}; a scene given as "
                         "mi.Scene keeps its film's size: give a reference of that size (or "
                         "load the scene from its file)")
