"""Which effects a scene calls for: ``detect_features(scene) -> dict[str, bool]``.

The draaw integrators look at a scene once per render (when ``sample()`` is traced) and use
these flags as *Python-level* branches, so code for an absent feature never enters the JIT
kernel (design.md §5, guide §7). ``draaw-mi info`` shows the same dictionary.

Keys (always present, in this order):

======================  =====================================================================
``area_lights``         an ``area`` emitter on some shape
``point_lights``        a ``point`` emitter
``spot_lights``         a ``spot`` emitter
``directional_lights``  a ``directional`` (or other delta-direction) emitter
``envmap``              an ``envmap`` emitter
``constant_env``        a ``constant`` emitter
``environment``         the scene has an environment emitter (``scene.environment()``)
``delta_lights``        some emitter is a delta light (point, spot, directional, ...)
``hittable_lights``     some emitter can be hit by a BSDF-sampled ray (area or environment)
``textures``            some BSDF or area emitter reads a bitmap or procedural texture (uv);
                        a normal map alone is ``normal_maps``
``normal_maps``         some BSDF applies a normal or bump map
``draaw_materials``     some shape uses the ``draaw`` BSDF
``other_materials``     some shape uses another BSDF, one that reflects light (below)
``black_surfaces``      some shape has the black surface draaw-mi gives a TOML scene's area
                        light (:func:`is_black`): the integrators treat it as absorbing,
                        without the code of other BSDFs
``delta_bsdfs``         some BSDF has a delta lobe (smooth glass, mirror conductor, ...) or
                        is ``null`` (below)
``other_glossy``        some BSDF other than ``draaw`` has a glossy lobe (``roughconductor``,
                        ``principled``, ``roughdielectric``, ...)
``anisotropic``         some BSDF is anisotropic (``roughconductor`` with ``alpha_u`` !=
                        ``alpha_v``, ``principled`` with ``anisotropic`` > 0): its lobes need
                        the shading frame's tangent along dp/du, which only full surface
                        interactions carry
``media``               a shape or sensor references a participating medium
``aovs``                the scene's integrator outputs AOVs
``sdf``                 the scene has SDF objects (``[[sdf]]``; ``draaw_mi.sdf``)
``null_surfaces``       some shape has a ``null`` BSDF (a medium's index-matched boundary, a
                        smoke box): it also turns ``delta_bsdfs`` and ``other_materials`` on,
                        since V3 and V4 cross such a surface outside media as a delta event
                        of another BSDF (without them a null sphere's pixels render 22 % dark)
======================  =====================================================================

Example::

    >>> import draaw_mi, mitsuba as mi
    >>> from draaw_mi.integrators.features import detect_features
    >>> f = detect_features(mi.load_dict(mi.cornell_box()))
    >>> f['area_lights'], f['environment'], f['draaw_materials']
    (True, False, False)
"""
from __future__ import annotations

import mitsuba as mi

from ..materials.draaw_bsdf import ALL_PARAMS, DraawBSDF
from ..materials.textures import is_spatially_varying
from ..sdf.scene import find as _find_sdf

FEATURE_NAMES: tuple[str, ...] = (
    "area_lights", "point_lights", "spot_lights", "directional_lights", "envmap",
    "constant_env", "environment", "delta_lights", "hittable_lights", "textures",
    "normal_maps", "draaw_materials", "other_materials", "black_surfaces", "delta_bsdfs", "other_glossy",
    "anisotropic", "media", "aovs", "sdf", "null_surfaces",
)

_EMITTER_CLASSES = {
    "AreaLight": "area_lights",
    "PointLight": "point_lights",
    "SpotLight": "spot_lights",
    "DirectionalEmitter": "directional_lights",
    "EnvironmentMapEmitter": "envmap",
    "ConstantBackgroundEmitter": "constant_env",
}
_NORMALMAP_CLASSES = ("NormalMap", "BumpMap")
_NORMALMAP_KEYS = ("normalmap", "bumpmap")


def _is_draaw(bsdf) -> bool:
    return isinstance(bsdf, DraawBSDF)


def _bsdf_features(bsdf, f: dict[str, bool]) -> None:
    flags = bsdf.flags()
    if mi.has_flag(flags, mi.BSDFFlags.Delta):
        f["delta_bsdfs"] = True
    if mi.has_flag(flags, mi.BSDFFlags.Anisotropic):
        f["anisotropic"] = True
    # (by the parameters, not the BSDF's SpatiallyVarying flag: a normal map sets it too, and
    # V1 / V2, which ignore normal maps, would trace uv and dp/du for it)
    for name in textured_parameters(bsdf):
        f["normal_maps" if any(p in _NORMALMAP_KEYS for p in name.split(".")) else "textures"] = True
    if _is_draaw(bsdf):
        f["draaw_materials"] = True
        return
    if is_black(bsdf):
        f["black_surfaces"] = True
        return
    f["other_materials"] = True
    if bsdf.class_name() == "Null":
        f["null_surfaces"] = True
    if mi.has_flag(flags, mi.BSDFFlags.Glossy):
        f["other_glossy"] = True


#: the id prefix of the black surfaces draaw-mi gives its area lights (:func:`is_black`)
BLACK_SURFACE_PREFIX = "draaw-black:"


def is_black(bsdf) -> bool:
    """Whether ``bsdf`` is a black surface draaw-mi made: the ``diffuse`` of reflectance 0
    that a TOML scene's area light is given (its id starts with :data:`BLACK_SURFACE_PREFIX`).
    Known by its id, not by reading its value: the flags are found while a render is traced or
    recorded, where reading a JIT value is not allowed.

    >>> black = {"type": "diffuse", "id": BLACK_SURFACE_PREFIX + "lamp", "reflectance": 0.0}
    >>> is_black(mi.load_dict(black)), is_black(mi.load_dict({"type": "diffuse", "reflectance": 0.0}))
    (True, False)
    """
    return bsdf.id().startswith(BLACK_SURFACE_PREFIX) and bsdf.class_name() == "SmoothDiffuse"


def textured_parameters(bsdf) -> list[str]:
    """The parameters of ``bsdf`` that vary over the surface, read at the hit's uv: textured
    ones (``"base_color"``) and normal or bump maps (``"normalmap"``).

    >>> textured_parameters(mi.load_dict({"type": "diffuse", "reflectance": {"type": "checkerboard"}}))
    ['reflectance']
    >>> textured_parameters(mi.load_dict({"type": "draaw", "roughness": 0.3}))
    []
    """
    if _is_draaw(bsdf):
        return [n for n in ALL_PARAMS if is_spatially_varying(getattr(bsdf, n))] +\
            (["normalmap"] if bsdf.normalmap is not None else [])
    found = ["normalmap"] if bsdf.class_name() in _NORMALMAP_CLASSES else []
    for key in mi.traverse(bsdf).keys():
        parts = key.split(".")
        if parts[-1] in ("data", "to_uv") or any(p in _NORMALMAP_KEYS for p in parts):
            name = ".".join(parts[:-1])
            if name not in found:
                found.append(name)
    return found


def scene_shapes(scene: mi.Scene) -> list:
    """The shapes whose surfaces a ray can hit: ``scene.shapes()``, with an ``instance``'s
    shape-group members in place of the instance (``scene.shapes()`` lists the instance only,
    with a default diffuse BSDF: instanced glass or textures would go unseen, and V3/V4
    render such scenes 8 % dark). The members are found through Mitsuba's traversal, run
    only when there is an instance.

    >>> d = {"type": "scene", "g": {"type": "shapegroup", "s": {"type": "sphere", "bsdf": {"type": "dielectric"}}},
    ...      "i": {"type": "instance", "shapegroup": {"type": "ref", "id": "g"}}}
    >>> [s.bsdf().class_name() for s in scene_shapes(mi.load_dict(d))]
    ['SmoothDielectric']
    """
    shapes = list(scene.shapes())
    if not any(s.class_name() == "Instance" for s in shapes):
        return shapes
    nodes = mi.traverse(scene).hierarchy           # every object the scene reaches, once
    members = [n for n in nodes if isinstance(n, mi.Shape)
               and n.class_name() not in ("Instance", "ShapeGroupPlugin")]      # (a shapegroup)
    return [s for s in shapes if s.class_name() != "Instance"] +\
        [m for m in members if all(m is not s for s in shapes)]


def detect_features(scene: mi.Scene) -> dict[str, bool]:
    """Return the feature flags of ``scene`` (see the module docstring for the keys).

    Cheap (a walk over the scene's emitters and distinct BSDFs, no kernel launch); the
    integrators call it each time they trace a render.
    """
    f = dict.fromkeys(FEATURE_NAMES, False)
    for em in scene.emitters():
        name = _EMITTER_CLASSES.get(em.class_name())
        flags = em.flags()
        if name is not None:
            f[name] = True
        elif mi.has_flag(flags, mi.EmitterFlags.DeltaDirection):
            f["directional_lights"] = True
        elif mi.has_flag(flags, mi.EmitterFlags.Surface):
            f["area_lights"] = True
        if mi.has_flag(flags, mi.EmitterFlags.Surface) and\
                mi.has_flag(flags, mi.EmitterFlags.SpatiallyVarying):
            f["textures"] = True                       # textured area light: needs uv
        if mi.has_flag(flags, mi.EmitterFlags.Delta):
            f["delta_lights"] = True
        else:
            f["hittable_lights"] = True
    f["environment"] = scene.environment() is not None

    seen: set[int] = set()
    for shape in scene_shapes(scene):
        if shape.interior_medium() is not None or shape.exterior_medium() is not None:
            f["media"] = True
        bsdf = shape.bsdf()
        if bsdf is None or id(bsdf) in seen:
            continue
        seen.add(id(bsdf))
        _bsdf_features(bsdf, f)
    for sensor in scene.sensors():
        if sensor.get_medium() is not None:
            f["media"] = True
    integrator = scene.integrator()
    if integrator is not None:
        f["aovs"] = len(integrator.aov_names()) > 0
    # SDF objects: hidden proxy shapes registered by draaw_mi.sdf.scene
    f["sdf"] = _find_sdf(scene) is not None
    return f


def describe(features: dict[str, bool]) -> str:
    """One line listing the features that are on, e.g. ``'area_lights, draaw_materials'``."""
    on = [k for k in FEATURE_NAMES if features.get(k)]
    return ", ".join(on) if on else "(none)"


# ---------------------------------------------------------------- plugin names
_SAMPLER_PLUGINS = {"IndependentSampler": "independent", "MultijitterSampler": "multijitter",
                    "StratifiedSampler": "stratified", "LowDiscrepancySampler": "ldsampler",
                    "OrthogonalSampler": "orthogonal"}


_FILTER_PLUGINS = {"BoxFilter": "box", "GaussianFilter": "gaussian", "TentFilter": "tent",
                   "LanczosSincFilter": "lanczos", "MitchellNetravaliFilter": "mitchell",
                   "CatmullRomFilter": "catmullrom"}


def _plugin_name(obj, names: dict) -> str:
    """A Mitsuba object's plugin name from its class name (what ``str(obj)`` starts with)."""
    name = str(obj).split("[")[0].strip()
    return names.get(name, name)


def filter_plugin(rfilter) -> str:
    """Plugin name of a Mitsuba reconstruction filter (``"gaussian"``: a film's default)."""
    return _plugin_name(rfilter, _FILTER_PLUGINS)


def sensor_gated_speedups(sensor) -> str | None:
    """What ``draaw_v4`` leaves off because of ``sensor``'s film or lens, as one sentence, or
    ``None``. Every pixel filter keeps them (:mod:`~draaw_mi.integrators.film_splat`); a lens
    aperture or an open shutter turns emission splitting off (its extra rays leave through a
    pinhole at the shutter's opening). (A film that samples beyond its border is refused:
    :func:`refuse_border_sampling`.)"""
    off = []
    if sensor.needs_aperture_sample() or sensor.shutter_open_time() > 0:
        off.append("emission splitting is off: the camera samples a lens aperture or an open shutter")
    return "; ".join(off) or None


def refuse_border_sampling(sensor, who: str, error) -> None:
    """Raise ``error`` (an exception class) where ``sensor``'s film samples beyond its border
    (``sample_border = true``): Mitsuba 3.9.1 then writes those samples past the end of its
    image block (Dr.Jit's debug mode: writes at 788 of 396 values), corrupting the heap, with
    its own ``path`` and ``prb`` as with V1..V4 ("corrupted size vs. prev_size", a segfault)."""
    if sensor.film().sample_border():
        raise error(f"{who}: the film samples beyond its border (sample_border = true), which "
                    "Mitsuba 3.9.1 writes past the end of its image block (memory corruption, with "
                    "path and prb too); set sample_border to false")


def sampler_plugin(sampler) -> str:
    """Plugin name of a Mitsuba sampler object (``"multijitter"``, ``"independent"``, ...)."""
    return _plugin_name(sampler, _SAMPLER_PLUGINS)
