"""Turn a plugin property (float, RGB, file name, array or nested texture) into an mi.Texture.

Every material parameter is differentiable through ``mi.traverse`` under one naming scheme
(``<bsdf>.<name>.value`` for constants, ``<bsdf>.<name>.data`` for bitmaps). The ``draaw``
BSDF keeps a constant as a bare Dr.Jit array (:func:`as_parameter`; cheaper for ``dr.freeze``
to traverse than a uniform texture) under the key its texture would have had;
:func:`evaluate` / :func:`evaluate_1` read either form.
"""
from __future__ import annotations

import os

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError

# Parameters whose bitmaps hold data, not colours: read them without the sRGB decoding.
RAW_BY_DEFAULT = {"roughness", "metallic", "specular", "reflection", "direct_to_scatter", "normalmap"}


def _check_range(name, lo, hi, values, what):
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0:
        raise ParameterError(f"draaw BSDF: {name} {what} is empty")
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].flat[0]
        raise ParameterError(f"draaw BSDF: {name}={_fmt(bad)} ({what}) is not finite; expected finite values")
    if lo is not None and arr.min() < lo:
        raise ParameterError(f"draaw BSDF: {name}={_fmt(arr.min())} ({what}) is below {lo}; "
                             f"expected {_range(lo, hi)}")
    if hi is not None and arr.max() > hi:
        raise ParameterError(f"draaw BSDF: {name}={_fmt(arr.max())} ({what}) is above {hi}; "
                             f"expected {_range(lo, hi)}")


def _fmt(x):
    return f"{float(x):g}"


def _range(lo, hi):
    if hi is None:
        return f">= {lo}"
    return f"a value in [{lo}, {hi}]"


def constant_texture(value, color: bool) -> mi.Texture:
    """A constant texture, built through ``mi.Properties`` rather than a nested
    ``mi.load_dict``: plugin constructors run on Mitsuba's parallel scene-loading threads, and a
    parser re-entered from there races with other plugins being loaded (random
    ``std::bad_alloc`` / ``basic_string`` errors while a ``roughconductor`` reads its data)."""
    props = mi.Properties("constant")
    if color:
        props["value"] = mi.ScalarColor3f(*[float(v) for v in value])
        return props.get_unbounded_texture("value")
    props["value"] = float(value)
    return props.get_texture("value")


def linear_image(bitmap: mi.Bitmap, raw: bool, name: str = "texture") -> np.ndarray:
    """An image's pixels as the (H, W, 1 | 3) linear float32 values Mitsuba's ``bitmap``
    texture would look up: grey (Y, YA) as one channel, colour (RGB, RGBA, XYZ[A]) as RGB,
    alpha dropped; an sRGB-encoded file (8/16-bit PNG, JPEG) decoded unless ``raw`` (a data
    map: roughness 102/255 stays 0.4). Mitsuba keeps an 8-bit file's integers and decodes each
    texel on lookup, before filtering, so a texture of these values renders alike; stored as
    floats, its texels take float values (``params[...] = ...``) and have a gradient.

    >>> bm = mi.Bitmap(np.full((1, 1, 3), 188, np.uint8), pixel_format=mi.Bitmap.PixelFormat.RGB)
    >>> bm.set_srgb_gamma(True)
    >>> [round(float(linear_image(bm, raw)[0, 0, 0]), 4) for raw in (False, True)]
    [0.5029, 0.7373]
    """
    fmt = bitmap.pixel_format()
    pf = mi.Bitmap.PixelFormat
    if fmt in (pf.Y, pf.YA):
        target = pf.Y
    elif fmt in (pf.RGB, pf.RGBA, pf.XYZ, pf.XYZA):
        target = pf.RGB
    else:
        raise ParameterError(f"draaw BSDF: {name}: an image of {bitmap.channel_count()} channels "
                             f"({fmt.name}); expected a grey (Y, YA) or colour (RGB, RGBA) image")
    srgb = bool(bitmap.srgb_gamma())
    out = bitmap.convert(target, mi.Struct.Type.Float32, srgb_gamma=srgb if raw else False)
    return np.array(out, dtype=np.float32).reshape(out.height(), out.width(), -1)


def at_least_2x2(arr: np.ndarray) -> np.ndarray:
    """``arr`` (H, W, C) with an axis of one texel repeated to two. Mitsuba's bitmap takes no
    new values below 2x2 texels ("must be at least 2x2 pixels in size": a fit, the preview,
    ``--set`` and batch overrides of a 1x1 texture, or a mesh's 4x1 palette, failed); its
    lookups are the same, a texel's copy beside it.

    >>> at_least_2x2(np.zeros((1, 4, 3))).shape, at_least_2x2(np.zeros((3, 3, 1))).shape
    ((2, 4, 3), (3, 3, 1))
    """
    reps = (2 if arr.shape[0] == 1 else 1, 2 if arr.shape[1] == 1 else 1) + (1,) * (arr.ndim - 2)
    return np.tile(arr, reps) if max(reps) > 1 else arr


def bitmap_texture(source, raw: bool, name: str = "texture") -> mi.Texture:
    """A bitmap texture from a file name (its pixels as :func:`linear_image` gives them) or an
    (H, W[, C]) array (values as given, linear): float32 texels either way."""
    if isinstance(source, str):
        # found as Mitsuba finds a bitmap's file: an XML scene's folder is on the resolver's
        # path, not only the working directory
        path = str(mi.file_resolver().resolve(source))
        if not os.path.isfile(path):
            raise ParameterError(f"draaw BSDF: {name}={source!r}: texture file does not exist")
        try:
            bitmap = mi.Bitmap(path)
        except Exception as e:  # noqa: BLE001 - Mitsuba's reader: one line
            raise ParameterError(f"draaw BSDF: {name}={source!r} cannot be read as an image: "
                                 f"{str(e).strip().splitlines()[-1]}") from None
        source = linear_image(bitmap, raw, name)
    arr = np.asarray(source, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 3) or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ParameterError(f"draaw BSDF: {name} texture array of shape {arr.shape}; expected (H, W), "
                             "(H, W, 1) or (H, W, 3)")
    arr = at_least_2x2(arr)
    # (a Bitmap, not a tensor: a tensor three texels high made nanobind print "implicit
    # conversion ... failed!" three times as Mitsuba's parser tried it as a vector and colours)
    return mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(arr)), "raw": True},
                        parallel=False)


def texture_values(tex: mi.Texture):
    """The numeric values a constant or bitmap texture holds (for validation), or None."""
    params = mi.traverse(tex)
    for key in ("value", "data"):
        if key in params.keys():
            arr = np.array(params[key]).ravel()
            if np.issubdtype(arr.dtype, np.integer):
                # 8/16-bit image files keep their integer data; eval() maps it onto [0, 1]
                arr = arr.astype(np.float64) / np.iinfo(arr.dtype).max
            return arr
    return None


def nested_values(tex: mi.Texture) -> list:
    """``(key, values)`` for every ``value`` / ``data`` parameter of ``tex`` (key "" for the
    texture's own, e.g. "color0.value" for a checkerboard's colour): a texture nested in a
    material holds its numbers there (8/16-bit texels mapped onto [0, 1], as eval() reads them)."""
    own = texture_values(tex)
    if own is not None:
        return [("", own)]
    params = mi.traverse(tex)
    out = []
    for key in params.keys():
        if key.split(".")[-1] in ("value", "data"):
            arr = np.array(params[key]).ravel()
            if np.issubdtype(arr.dtype, np.integer):
                arr = arr.astype(np.float64) / np.iinfo(arr.dtype).max
            out.append((key, arr))
    return out


#: image files Mitsuba reads as linear values (never sRGB-decoded)
LINEAR_FILES = (".exr", ".hdr", ".pfm")


def _refuse_decoded_bitmap(name: str, tex: mi.Texture) -> None:
    """Refuse a Mitsuba ``bitmap`` texture for the data parameter ``name`` (roughness, a
    normal map, ...) that Mitsuba sRGB-decodes: not ``raw`` (Mitsuba's default) and of integer
    or half-float texels, what an 8/16-bit PNG or JPEG becomes (a roughness file's 0.4 would be
    looked up as 0.133, a flat normal map tilt 39 degrees). Float texels and the files of
    linear formats (:data:`LINEAR_FILES`: EXR, HDR, PFM, whose half floats are never decoded)
    pass."""
    if not tex.class_name().startswith("BitmapTexture"):
        return
    params = mi.traverse(tex)
    # (Mitsuba 3.9's bitmap texture states its raw flag only in its description)
    if "data" not in params.keys() or "raw = 0" not in str(tex):
        return
    kind = type(params["data"]).__name__
    if kind.endswith("Xf") or kind.endswith("Xf64"):      # float32 texels: read as they are
        return
    file = str(tex).split('"')[1] if '"' in str(tex) else "an image"      # (its name = "...")
    if file.lower().endswith(LINEAR_FILES):     # (half floats of an EXR are never decoded)
        return
    bits = "8-bit" if "u8" in kind else "16-bit"
    raise ParameterError(f"draaw BSDF: {name}: a bitmap texture of {bits} texels ({file}) read without "
                         "raw: Mitsuba would sRGB-decode this data map (0.4 in the file looked up as "
                         "0.133); expected raw: add <boolean name=\"raw\" value=\"true\"/> to the "
                         "<texture> (\"raw\": True in a dict), or give the file name as "
                         f"<string name=\"{name}\" value=\"...\"/> (read raw)")


def channels(tex) -> int | None:
    """The channel count of a bitmap texture's texels (None for any other texture)."""
    params = mi.traverse(tex) if isinstance(tex, mi.Texture) else None
    if params is not None and "data" in params.keys():
        return int(params["data"].shape[2])
    return None


def texture_property(props: mi.Properties, name: str, default, lo, hi, color: bool) -> mi.Texture:
    """Read property ``name`` as a texture, validating constants and bitmap contents."""
    if not (name in props):
        if default is None:
            raise ParameterError(f"draaw BSDF: parameter {name!r} is required")
        return constant_texture([default] * 3 if color else default, color)
    value = props[name]
    if isinstance(value, mi.Texture):
        tex = value
        if name in RAW_BY_DEFAULT:
            _refuse_decoded_bitmap(name, tex)
        # every value of it (a bitmap's texels, a constant, each of a checkerboard's colours):
        # finite always; in the parameter's range where there is one
        for key, vals in nested_values(tex):
            _check_range(name, lo, hi, vals, "texture values" if not key else f"texture's {key}")
        return tex
    if isinstance(value, bool):
        raise ParameterError(f"draaw BSDF: {name}={value!r}; expected a number or a texture")
    if isinstance(value, (int, float)):
        _check_range(name, lo, hi, [value], "value")
        return constant_texture([value] * 3 if color else value, color)
    if isinstance(value, str):
        # checked as a texture table's bitmap is (a file of NaN roughness renders NaN)
        tex = bitmap_texture(value, raw=(name in RAW_BY_DEFAULT), name=name)
        _check_range(name, lo, hi, texture_values(tex), "texture values")
        return tex
    try:
        arr = np.array(value, dtype=np.float64)
    except Exception:  # noqa: BLE001 - anything not numeric is a user error
        raise ParameterError(f"draaw BSDF: {name}={value!r}; expected a number, RGB triple, "
                             "file name, array or texture") from None
    if arr.ndim == 1 and arr.size == 3 and color:
        _check_range(name, lo, hi, arr, "value")
        return constant_texture(arr, color=True)
    if arr.ndim >= 2:
        _check_range(name, lo, hi, arr, "array values")
        return bitmap_texture(arr, raw=True, name=name)
    raise ParameterError(f"draaw BSDF: {name}={value!r}; expected "
                         + ("an RGB triple, a number" if color else "a number") + ", file name, array or texture")


def as_parameter(tex: mi.Texture):
    """``tex``'s value as a bare Dr.Jit array (made opaque) when ``tex`` is a constant texture
    (not spatially varying, one ``value`` parameter), else ``tex`` itself.

    A constant as an array is what a ``dr.freeze`` replay traverses cheaply (see
    :class:`~draaw_mi.materials.draaw_bsdf.DraawBSDF`); :func:`evaluate` reads either form.

    >>> import drjit as dr
    >>> v = as_parameter(constant_texture(0.25, color=False))
    >>> type(v).__name__, float(v[0])
    ('Float', 0.25)
    """
    if tex.is_spatially_varying():
        return tex
    params = mi.traverse(tex)
    if list(params.keys()) != ["value"]:
        return tex
    value = params["value"]
    out = type(value)(value)
    dr.make_opaque(out)
    return out


def evaluate(param, si, active):
    """Colour of a parameter at ``si``: ``param.eval`` for a texture, the array for a constant."""
    return param.eval(si, active) if isinstance(param, mi.Texture) else param


def evaluate_1(param, si, active):
    """Scalar of a parameter at ``si``: ``param.eval_1`` for a texture, the array for a constant."""
    return param.eval_1(si, active) if isinstance(param, mi.Texture) else param


def is_spatially_varying(tex) -> bool:
    return isinstance(tex, mi.Texture) and bool(tex.is_spatially_varying())


def describe(tex) -> str:
    """Short human-readable form of a texture parameter for ``to_string``."""
    if tex is None:
        return "none"
    if not isinstance(tex, mi.Texture):            # a constant (as_parameter)
        v = np.array(tex).ravel()
        return f"{v[0]:g}" if v.size == 1 else "(" + ", ".join(f"{x:g}" for x in v) + ")"
    params = mi.traverse(tex)
    if "value" in params.keys():
        v = np.array(params["value"]).ravel()
        return f"{v[0]:g}" if v.size == 1 else "(" + ", ".join(f"{x:g}" for x in v) + ")"
    if "data" in params.keys():
        shape = params["data"].shape
        return f"bitmap({shape[1]}x{shape[0]}x{shape[2]})"
    return type(tex).__name__
