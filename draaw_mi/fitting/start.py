"""The parameters a fit moves and the values it starts from.

:func:`fit_parameters` resolves the names given to :func:`~draaw_mi.fitting.fit` into the
scene's keys, refuses what cannot be fitted (an XML scene's 8-bit texture, a non-differentiable or
plugin-declared non-differentiable parameter) and checks each start: ``init``'s value where
given (:func:`texture_start` shapes a texture's), else the scene's, finite and in range
(:func:`check_start`).
"""
from __future__ import annotations

import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..scene.schema import shown
from .params import FitParam, range_for


def fit_parameters(scene, params, init):
    """``(keys, names, FitParams, the scene's values, the values to start from)`` of the
    parameters named ``params`` (``init`` overrides the scene's)."""
    p = scene.all_params                 # mi.traverse plus the SDF objects' "sdf.NODE.PARAM"
    keys = [scene.key(name) for name in params]
    if len(set(keys)) != len(keys):
        raise ParameterError(f"fit: params name a parameter twice: {params}")
    names = dict(zip(keys, params))
    if init:
        unknown = sorted(set(init) - set(params) - set(keys))
        if unknown:
            raise ParameterError(f"fit: init names {unknown}, which are not in params {list(params)}")
    start = {k: type(p[k])(p[k]) for k in keys}
    initial = {k: p[k] for k in keys}
    prm: dict[str, FitParam] = {}
    for k in keys:
        if dr.is_tensor_v(p[k]) and not dr.is_float_v(p[k]):
            raise ParameterError(f"fit: parameter {names[k]!r} ({k}) is an 8-bit image texture, which "
                             "Mitsuba stores as integers (not differentiable) when it loads the file "
                             "itself (an XML scene); give the texture as a float image (EXR), or load "
                             "the scene from a TOML/JSON file or dict, whose image files are read as floats")
        if not dr.is_diff_v(p[k]) or not dr.is_float_v(p[k]):
            raise ParameterError(f"fit: parameter {names[k]!r} ({k}) is not differentiable")
        # what the plugin declares non-differentiable (a point light's position: its samples
        # are taken without gradients) would get a zero gradient and keep its start
        if k in scene.params and scene.params.flags(k) & int(mi.ParamFlags.NonDifferentiable):
            raise ParameterError(f"fit: parameter {names[k]!r} ({k}) is declared non-differentiable by "
                             "its Mitsuba plugin (it would keep its starting value)")
        prm[k] = FitParam(k, names[k], p[k], scene)
        if prm[k].space == "log" and dr.width(p[k]) != 1:
            prm[k].space = "linear"            # textures: optimise texels linearly
    for k in keys:
        given = bool(init) and (names[k] in init or k in init)
        as_given = init.get(names[k], init.get(k)) if given else p[k]
        value = as_given
        if given and prm[k].shape is not None:
            value = texture_start(names[k], value, prm[k].shape)
        elif given:
            value = value_start(names[k], value, p[k])
        check_start(scene, k, names[k], prm[k], value, given, as_given)
        if given:
            initial[k] = value
    return keys, names, prm, start, initial


def texture_start(name: str, value, shape: tuple) -> np.ndarray:
    """A texture's ``init`` as a float32 array of its ``shape`` (H x W x C): one number for
    every texel, C numbers (a colour) for every texel, or an array of that shape; else a
    :class:`ParameterError` naming the shape (a wrong one had raised numpy's reshape error, or
    Mitsuba's in the middle of the fit).

    >>> texture_start("m.base_color", [0.2, 0.5, 0.7], (2, 2, 3))[1, 1].tolist()
    [0.20000000298023224, 0.5, 0.699999988079071]
    >>> texture_start("m.base_color", np.zeros((4, 4, 3)), (2, 2, 3))
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: fit: init m.base_color: an array of shape (4, 4, 3); expected one number, 3 (a value per channel) or an array of the texture's shape (2, 2, 3)
    """
    v = np.asarray(np.array(value) if dr.is_array_v(value) else value, dtype=np.float32)
    if v.size == 1 or (v.ndim == 1 and v.size == shape[-1]):
        return np.broadcast_to(v.reshape(-1), shape).copy()
    if v.size == int(np.prod(shape)) and v.ndim >= 2:
        return v.reshape(shape)
    what = f"an array of shape {tuple(v.shape)}" if v.ndim else "a value"
    raise ParameterError(f"fit: init {name}: {what}; expected one number, {shape[-1]} (a value per "
                         f"channel) or an array of the texture's shape {tuple(shape)}")


def value_start(name: str, value, like):
    """A single value's or a vector's ``init`` (not a texture's) as a value of the type of
    ``like``, the parameter's value in the scene: as many numbers as it holds (a colour: one
    number, a grey, or three); else a :class:`ParameterError` naming them (a string or a wrong
    count had failed in Dr.Jit, inside the fit's first render).

    >>> value_start("m.base_color", 0.5, mi.Color3f(0.1, 0.2, 0.3))
    [[0.5, 0.5, 0.5]]
    >>> value_start("m.roughness", "0.5", mi.Float(0.3))
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: fit: init m.roughness='0.5' (a str); expected a number
    >>> value_start("m.base_color", [0.1, 0.2], mi.Color3f(0.1, 0.2, 0.3))
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: fit: init m.base_color=[0.1, 0.2] (2 numbers); expected one number or 3 (a value per channel)
    """
    t = type(like)
    channels = dr.size_v(t) if dr.depth_v(t) > 1 else 1
    width = dr.width(like)
    count = channels * width
    colour = t.__name__.startswith("Color")          # (mi.Color3f; a point or vector is not one)
    expected = ("a number" if count == 1 else
                f"one number or {channels} (a value per channel)" if width == 1 and colour else
                f"{count} numbers")
    v = None
    if not isinstance(value, (str, bytes, bool, dict)):
        try:
            v = np.asarray(np.array(value) if dr.is_array_v(value) else value)
        except (TypeError, ValueError):
            v = None
    if v is None or v.dtype.kind not in "iuf":
        raise ParameterError(f"fit: init {name}={value!r} (a {type(value).__name__}); expected {expected}")
    v = v.astype(np.float64)
    if channels > 1 and width > 1:
        # channel by channel, as Dr.Jit gives such a value ((C, N)); or as rows of C numbers
        # ((N, C), as a user writes points); flattened, the channels of one point are neighbours
        v = (v if v.shape == (channels, width) and dr.is_array_v(value) else
             v.T if v.shape == (width, channels) else
             v if v.shape == (channels, width) else v.reshape(-1, channels).T if v.size == count else v)
    else:
        v = v.ravel()
        if v.size == 1 and width == 1 and colour:
            v = np.repeat(v, channels)
    if v.size != count:
        raise ParameterError(f"fit: init {name}={shown(value)} ({v.size} numbers); expected {expected}")
    if channels == 1:
        return t(v.tolist()) if width > 1 else t(float(v[0]))
    if width == 1:
        return t(*[float(x) for x in v])
    return t(*[row.tolist() for row in v])


def check_start(scene, key: str, name: str, prm: FitParam, value, given: bool, as_given=None) -> None:
    """A parameter's start (its ``init``, where ``given``, else its value in the scene) within
    its range and finite, else a :class:`ParameterError` (showing ``as_given``, the ``init``
    as the caller wrote it, where given: one number for a whole texture); a warning where a
    log-space one starts near its floor. A value set through ``scene.params`` is not checked when it is set:
    a NaN one went on to a zero gradient, then "diverged to NaN"."""
    lo, hi = range_for(key, scene)
    v = np.asarray(np.array(value) if dr.is_array_v(value) else value, dtype=float)
    # projected as a step's are: a texture's texels, and an SDF object's own values (valid, as
    # the object checks them together; a round box's size at twice its radius sits just under
    # the optimiser's open range)
    projected = not given and (v.size > 4 or scene.sdf_param(key) is not None)
    if not np.all(np.isfinite(v)) or (not projected and lo is not None and np.any(v < lo)) or (
            not projected and hi is not None and np.any(v > hi)):
        expected = f"values in [{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"
        if given:
            raise ParameterError(f"fit: init {name}={shown(value if as_given is None else as_given)}; "
                                 f"expected {expected}")
        flat = v.ravel()
        at = (shown(float(flat[0])) if flat.size == 1 else shown(flat.tolist()) if flat.size <= 4
              else f"a texture with {int(np.sum(~np.isfinite(flat)))} non-finite texels")
        raise ParameterError(f"fit: {name} starts at {at} (its value in the scene); expected {expected}, "
                             f"or give init={{{name!r}: ...}}")
    medium_part = next((part for part in key.split(".") if part in ("albedo", "sigma_t")), None)
    if medium_part is not None and not np.any(v):
        # (a real collision with sigma_s = 0 ends the path, and a density of 0 everywhere
        # samples no collision: either way no path carries the derivative; voxels guide)
        warnings.warn(f"fit: {name} starts at 0 everywhere, where its gradient is exactly 0 (no path "
                      f"{'scatters' if medium_part == 'albedo' else 'collides'} in the medium to carry it): "
                      f"the fit cannot move it; start it from a small value, e.g. init={{{name!r}: 0.05}}",
                      RuntimeWarning, stacklevel=5)
    _warn_black_surface(scene, key, name, v)
    _warn_partial_gradient(scene, key, name)
    if "weight" in key.split(".") and v.size == 1 and float(v.ravel()[0]) in (lo, hi):
        warnings.warn(f"fit: {name} starts at {float(v.ravel()[0]):g}, where Mitsuba's blendbsdf clips its "
                      "weight: its gradient is exactly 0 there and the fit keeps it; start inside, e.g. "
                      f"init={{{name!r}: 0.5}}", RuntimeWarning, stacklevel=5)
    if prm.space == "log" and v.size == 1 and float(v.ravel()[0]) <= 2.0 * prm.lo:
        # (from roughness 0 or 0.02 a fit towards 0.26 reached 0.066 in 150 iterations; from
        # 0.1, 0.258: below about twice the floor the alpha clamp leaves little gradient)
        warnings.warn(f"fit: {name} starts at {float(v.ravel()[0]):g}, near {prm.lo:.3g}, below which every "
                      "value renders alike (the BSDF's alpha clamp): its gradient is small there and the "
                      f"fit may stay near it; start it higher, e.g. init={{{name!r}: 0.3}}",
                      RuntimeWarning, stacklevel=5)


def _warn_black_surface(scene, key: str, name: str, v) -> None:
    """Warn where a draaw material's ``base_color`` starts at exactly 0 in some channel on a
    material whose other lobe is off too (metallic 1, or specular 0): the BSDF is 0 there,
    path replay stops at a zero BSDF value, and the light it would reflect carries no
    gradient (measured: d image / d base_color 0.0 in V3, 0.01 in V4, against 0.05 by finite
    differences; at 1e-3 they agree)."""
    head, sep, _ = key.partition(".base_color.")
    if not sep or not np.any(v == 0):
        return
    p = scene.all_params
    other = {part: np.array(p[f"{head}.{part}.value"], dtype=float).ravel()
             for part in ("metallic", "specular") if f"{head}.{part}.value" in p.properties}
    if not (np.any(other.get("metallic", 0.0) >= 1.0) or np.any(other.get("specular", 1.0) <= 0.0)):
        return
    warnings.warn(f"fit: {name} starts with {int(np.sum(v == 0))} value(s) at exactly 0 on a material of "
                  f"{'metallic 1' if np.any(other.get('metallic', 0.0) >= 1.0) else 'specular 0'}, where the BSDF "
                  "is 0: path replay stops there and the light it would reflect gives no gradient, so the "
                  f"fit moves it slowly or not at all; start from a small value, e.g. init={{{name!r}: 0.02}}",
                  RuntimeWarning, stacklevel=6)


#: Mitsuba 3.9.1 plugins whose parameter is differentiated in part only: (class, parameter) ->
#: what was measured
PARTIAL_GRADIENTS = {("RoughPlastic", "alpha"): "its diffuse term's dependence on alpha is computed outside "
                                                "automatic differentiation: prb's gradient of an image's mean "
                                                "read -0.0062 against -0.080 by finite differences"}


def _warn_partial_gradient(scene, key: str, name: str) -> None:
    """Warn of a parameter whose plugin differentiates it only in part (Mitsuba's own code):
    a fit of it settles where the partial gradient vanishes, not at the best value."""
    entry = scene.params.properties.get(key)
    node = entry[2] if entry is not None else None
    part = key.split(".")[-1] if key.split(".")[-1] not in ("value", "data") else key.split(".")[-2]
    why = PARTIAL_GRADIENTS.get((node.class_name() if node is not None else None, part))
    if why is not None:
        warnings.warn(f"fit: {name} is a {node.class_name()} {part}, which Mitsuba 3.9.1 differentiates only in "
                      f"part ({why}): the fit may settle away from the best value; fit a roughconductor, "
                      "principled or draaw material's roughness instead where you can", RuntimeWarning,
                      stacklevel=6)

