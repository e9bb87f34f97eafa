"""Values about to be written into a loaded scene's parameters, checked as a scene file's
tables check them: :func:`check_value` (the preview, the batch planner and the fit use it)."""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from ..errors import ParameterError, shown
from ..limits import FLOAT32_MAX, FOV_RANGE, HG_G_MAX
from .draaw_bsdf import NORMALMAP_SLACK, SCALAR_PARAMS

# the parameters whose values check_value knows (a texture nested in one of them holds its
# values: ``m.roughness.color0.value`` is a checkerboard's colour, a roughness)
KNOWN_PARAMS = (*SCALAR_PARAMS, "base_color", "normalmap", "radiance", "intensity", "irradiance")
# Ranges (lo, hi, lo_open) of plain Mitsuba BSDFs' numeric parameters, for a number or an
# array given in a scene file: outside them Mitsuba renders without an error yet wrongly
# (int_ior = 0: most pixels NaN; principled metallic = 3: brighter than its light; a
# negative alpha). Image files and nested textures of them are passed as they are.
_POSITIVE, _NONNEG, _UNIT = (0.0, None, True), (0.0, None, False), (0.0, 1.0, False)
PLAIN_RANGES = {"int_ior": _POSITIVE, "ext_ior": _POSITIVE,
                "alpha": _NONNEG, "alpha_u": _NONNEG, "alpha_v": _NONNEG,
                "weight": _UNIT}           # blendbsdf's (it clips: 2 renders as 1, a fit drifts past)
# Mitsuba 3.9's principled and principledthin: their weights in [0, 1] (diff_trans in [0, 2])
_PRINCIPLED = {**dict.fromkeys(("metallic", "roughness", "specular", "spec_tint", "spec_trans",
                                "sheen", "sheen_tint", "clearcoat", "clearcoat_gloss", "anisotropic",
                                "flatness"), _UNIT), "eta": _POSITIVE}
PLUGIN_RANGES = {"principled": _PRINCIPLED, "principledthin": {**_PRINCIPLED, "diff_trans": (0.0, 2.0, False)}}
# any of their names, as check_value finds it in a parameter's key (they name nothing else)
MITSUBA_RANGES = {**PLAIN_RANGES, **PLUGIN_RANGES["principledthin"]}
# Mitsuba's colour parameters that are at least 0 (a diffuse reflectance of -0.5 rendered
# negative pixels)
NONNEG_COLOURS = ("reflectance", "diffuse_reflectance", "specular_reflectance", "specular_transmittance")
# a normal map's range when its encoding is not known here: the signed encoding's, with the
# slack a scene file allows (unsigned maps are in [0, 1], inside it)
NORMALMAP_RANGE = (-1.0 - NORMALMAP_SLACK, 1.0 + NORMALMAP_SLACK)


def check_value(who: str, name: str, key: str, v, conductor: bool = False, medium: bool = False,
                emitter: bool = False) -> None:
    """Check a value about to be written to the scene parameter ``key`` (``name`` as the user
    wrote it): finite numbers, three for a colour, and the draaw BSDF's ranges for its
    parameters (roughness in [0, 1], ...; colours and light intensities >= 0), and a medium's
    as a scene file's ``[[volumes]]`` table has them (``phase_function.g``: |g| <= 0.999,
    ``scale`` >= 0, ``albedo`` in [0, 1]; a g of 1.5 would render negative pixels). Raises
    :class:`~draaw_mi.errors.ParameterError` naming ``who`` (the caller), the value and the
    range. Mitsuba values (transforms, colours) pass as they are. The preview and the batch
    planner check their overrides with it. ``conductor``: ``key`` is a conductor's, whose
    ``eta`` may be 0 (Mitsuba's default material ``none``, a perfect mirror: eta 0, k 1);
    ``medium`` / ``emitter``: ``key`` is a medium's or an emitter's where its name does not say
    so (an XML ``<medium id="fog">``'s ``fog.phase_function.g``, an envmap's ``sky.scale``).
    Dr.Jit values (a ``TensorXf`` of texels, a ``Color3f``) are read and checked as numbers are.

    >>> check_value("demo", "ball.roughness", "ball.roughness.value", 0.3)
    >>> check_value("demo", "ball.roughness", "ball.roughness.value", 3.0)
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: demo: ball.roughness=3.0; expected a number in [0.0, 1.0]
    """
    parts = key.split(".")
    if "film" in parts and parts[-1] in ("size", "crop_size", "crop_offset"):
        raise ParameterError(f"{who}: {name}={shown(v)}: the film's size is the scene's resolution, not a "
                             "parameter; give load_scene(..., resolution=(w, h)) or scene.with_resolution(w, h)")
    if isinstance(v, list) and v and isinstance(v[0], list) and parts[-1] == "data":
        try:                                    # texels as nested lists: checked as an array
            v = np.array(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"{who}: {name}={shown(v)}; expected texels of numbers") from None
    if type(v).__module__.split(".")[0] in ("drjit", "mitsuba") and (dr.is_tensor_v(v) or (
            dr.is_array_v(v) and dr.width(v) == 1 and "Matrix" not in type(v).__name__)):
        # (a tensor of texels, one number or one colour; a mesh's vertex array passes as it is)
        v = np.array(v, dtype=np.float64)       # (NaN texels as a TensorXf had gone unchecked)
        v = v.reshape(-1) if v.ndim == 2 and v.shape[1] == 1 else v     # (a Color3f: (3, 1))
        v = float(v.reshape(-1)[0]) if v.size == 1 else v               # (a Float of one value)
    in_medium = medium or any(p.endswith("medium") for p in parts[:-1])
    # the material parameter a ``<shape>.<param>.value`` / ``.data`` key sets, also through a
    # nested texture (``<shape>.<param>.color0.value``): the first known name after the
    # object's; None otherwise
    param = None
    if len(parts) >= 3 and parts[-1] in ("value", "data"):
        param = next((p for p in parts[1:-1] if p in KNOWN_PARAMS), parts[-2])
    nums = None
    if isinstance(v, (bool, np.bool_, str, bytes)) or v is None:
        raise ParameterError(f"{who}: {name}={v!r}; expected a number")
    if isinstance(v, (int, float, np.number)) or (isinstance(v, np.ndarray) and v.ndim == 0):
        nums = [float(v)]                    # (numpy scalars too: np.float32(7) is checked as 7.0)
    elif isinstance(v, np.ndarray) and v.ndim > 1:
        if in_medium:
            _check_medium_grid(who, name, key, v)    # (NaN or negative densities render NaN)
        elif param in SCALAR_PARAMS or param == "base_color":
            # a material texture's texels (NaN texels are refused, not zeroed, as the same
            # values in a scene file are); value_like checks their shape
            lo, hi = SCALAR_PARAMS[param][1:] if param in SCALAR_PARAMS else (0.0, FLOAT32_MAX)
            _check_texels(who, name, v, lo, hi)
        elif param == "normalmap":                # (a texel of 1e30 renders black patches)
            _check_texels(who, name, v, *NORMALMAP_RANGE)
        elif any(p in NONNEG_COLOURS for p in parts):
            _check_texels(who, name, v, 0.0, FLOAT32_MAX)     # (reflectance texels of -2 rendered negative)
        else:                                     # (an environment map, ...)
            _check_texels(who, name, v, -FLOAT32_MAX, FLOAT32_MAX)
        return
    elif isinstance(v, (list, tuple, np.ndarray)):
        try:
            nums = [float(x) for x in v]
        except (TypeError, ValueError):
            raise ParameterError(f"{who}: {name}={shown(v)}; expected numbers"
                                 + (" (a transform: mi.ScalarTransform4f)" if parts[-1] == "to_world" else "")) from None
        if param in SCALAR_PARAMS and len(nums) != 1:     # (3 numbers would make a 3-wide Float)
            lo, hi = SCALAR_PARAMS[param][1:]
            raise ParameterError(f"{who}: {name}={v!r}; expected a number in [{lo}, {hi}]")
        if param not in SCALAR_PARAMS and len(nums) != 3:
            raise ParameterError(f"{who}: {name}={v!r}; expected 3 numbers (an RGB colour)")
    if nums is None:
        return                                   # a Mitsuba value (transform, colour): as is
    if not all(math.isfinite(x) and abs(x) <= FLOAT32_MAX for x in nums):   # (stored as float32)
        raise ParameterError(f"{who}: {name}={v!r}; expected finite numbers (in float32, |x| <= 3.4e38)")
    if parts[-1] == "x_fov":
        if not all(FOV_RANGE[0] <= x <= FOV_RANGE[1] for x in nums):
            raise ParameterError(f"{who}: {name}={v!r}; expected a field of view in "
                                 f"[{FOV_RANGE[0]}, {FOV_RANGE[1]}] degrees")
        return
    if in_medium:
        _check_medium_value(who, name, parts, v, nums)
        return
    if (parts[-1] == "sampling_weight" or (emitter and parts[-1] == "scale")) and min(nums) < 0:
        raise ParameterError(f"{who}: {name}={v!r}; expected values >= 0")
    if parts[-1] == "near_clip" and min(nums) <= 0:        # (Mitsuba refuses it at load; later: blank)
        raise ParameterError(f"{who}: {name}={v!r}; expected a near clip distance > 0")
    if param in SCALAR_PARAMS:
        lo, hi = SCALAR_PARAMS[param][1:]
        if not all(lo <= x <= hi for x in nums):
            raise ParameterError(f"{who}: {name}={v!r}; expected a number in [{lo}, {hi}]")
    elif param == "normalmap":
        lo, hi = NORMALMAP_RANGE
        if not all(lo <= x <= hi for x in nums):
            raise ParameterError(f"{who}: {name}={v!r}; expected normal-map components in [{lo:g}, {hi:g}]")
    elif param in ("base_color", "radiance", "intensity", "irradiance") and min(nums) < 0:
        raise ParameterError(f"{who}: {name}={v!r}; expected values >= 0")
    else:                  # Mitsuba's own BSDFs, as a scene file's plain materials are checked
        names = parts[1:-1] if parts[-1] in ("value", "data") else parts[1:]     # (dielectric.eta)
        plain = next((p for p in names if p in MITSUBA_RANGES), None)
        if plain is not None:
            lo, hi, lo_open = _NONNEG if conductor and plain == "eta" else MITSUBA_RANGES[plain]
            if not all((x > lo if lo_open else x >= lo) and (hi is None or x <= hi) for x in nums):
                span = f"{'(' if lo_open else '['}{lo:g}, {'inf)' if hi is None else format(hi, 'g') + ']'}"
                raise ParameterError(f"{who}: {name}={v!r}; expected a number in {span}")
        elif any(p in NONNEG_COLOURS for p in names) and min(nums) < 0:
            raise ParameterError(f"{who}: {name}={v!r}; expected values >= 0")


def bad_texels(texels, lo: float | None, hi: float | None, lo_open: bool = False):
    """``(count, index of the first, its value)`` of the values of ``texels`` that are not finite
    or lie outside ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``; ``None``: no bound), else ``None``.

    >>> bad_texels([[0.5, 2.0], [float("nan"), 0.1]], 0.0, 1.0)
    (2, (0, 1), 2.0)
    """
    a = np.asarray(texels, np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(a)
        if hi is not None:
            bad |= a > hi
        if lo is not None:
            bad |= (a <= lo) if lo_open else (a < lo)
    if not bad.any():
        return None
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    return int(bad.sum()), first, float(a[first])


def _check_texels(who: str, name: str, texels, lo: float, hi: float) -> None:
    """A texture's texels: finite, in ``[lo, hi]`` (+-``FLOAT32_MAX``: what float32 holds)."""
    found = bad_texels(texels, lo, hi)
    if found is not None:
        count, first, value = found
        span = "[" + ", ".join("3.4e38" if abs(x) == FLOAT32_MAX and x > 0 else "-3.4e38" if abs(x) == FLOAT32_MAX
                               else f"{x:g}" for x in (lo, hi)) + "]"
        raise ParameterError(f"{who}: {name}: {count} texel value(s) outside {span} "
                             f"(the first, {value!r}, at {list(first)}); expected finite values in {span}")


def _check_medium_grid(who: str, name: str, key: str, grid: np.ndarray) -> None:
    """A medium's grid (``*.sigma_t.data``, ``*.albedo.data``): finite values >= 0 that
    float32 holds, albedos at most 1."""
    a = np.asarray(grid, np.float64)
    albedo = ".albedo." in f".{key}."
    hi = 1.0 if albedo else FLOAT32_MAX
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(a) | (a < 0) | (a > hi)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ParameterError(f"{who}: {name}: {int(bad.sum())} value(s) outside [0, {hi:g}] (the first, "
                             f"{float(a[first])!r}, at {list(first)}); expected {'albedos' if albedo else 'densities'} "
                             f"in [0, {hi:g}]")


def _check_medium_value(who: str, name: str, parts: list, v, nums: list) -> None:
    """:func:`check_value` for a participating medium's parameter (``parts``: its key split
    at the dots, e.g. ``plume.interior_medium.phase_function.g``)."""
    if parts[-2:] == ["phase_function", "g"]:
        # (read back from Mitsuba as float32: a scene's 0.999 is 0.9990000128746033)
        if not all(abs(x) <= float(np.float32(HG_G_MAX)) for x in nums):
            raise ParameterError(f"{who}: {name}={v!r}; expected a Henyey-Greenstein g in "
                                 f"[-{HG_G_MAX}, {HG_G_MAX}]")
    elif parts[-1] == "scale":
        if not all(0.0 <= x <= FLOAT32_MAX for x in nums):
            raise ParameterError(f"{who}: {name}={v!r}; expected a density scale >= 0 (finite in float32)")
    elif "albedo" in parts:
        if not all(0.0 <= x <= 1.0 for x in nums):
            raise ParameterError(f"{who}: {name}={v!r}; expected values in [0, 1]")
    elif "sigma_t" in parts and min(nums) < 0:
        raise ParameterError(f"{who}: {name}={v!r}; expected an extinction >= 0")
