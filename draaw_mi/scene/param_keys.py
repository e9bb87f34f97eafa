"""Parameter names as people write them, resolved to ``mi.traverse`` keys of a scene
(:meth:`DraawScene.key <draaw_mi.scene.draaw_scene.DraawScene.key>`): ``material.parameter``
without Mitsuba's ``.value`` / ``.data``, a light's or medium's own id, and a hint naming the
closest parameter otherwise."""
from __future__ import annotations

import re

import mitsuba as mi

from ..errors import ParameterError, SceneError, suggest

#: the draaw material's options that are settings, fixed when the scene loads (not parameters)
SETTINGS = ("two_sided", "normalmap_encoding", "alpha_min")


def scene_media(mi_scene) -> list:
    """The media of ``mi_scene``'s shapes (inside and outside) and sensors, each as often as
    it is held."""
    media = [m for sh in mi_scene.shapes() for m in (sh.interior_medium(), sh.exterior_medium())]
    media += [sn.get_medium() for sn in mi_scene.sensors()]
    return [m for m in media if m is not None]


def resolve_key(scene, name: str) -> str:
    """``name`` (``material.parameter``, a full traverse key, an SDF object's
    ``sdf.NODE.PARAM``, or ``ID.PARAM`` of a light's or medium's own id) as a key of
    ``scene.all_params`` (``scene``: a :class:`~draaw_mi.scene.draaw_scene.DraawScene`); a
    :class:`~draaw_mi.errors.SceneError` naming the closest parameter otherwise.

    >>> import draaw_mi
    >>> resolve_key(draaw_mi.load_scene("scenes/cornell.toml", resolution=(8, 8)), "white.roughness")
    'white.roughness.value'
    """
    if not isinstance(name, str):
        raise ParameterError(f"{scene.source}: parameter name {name!r}; expected a string such as "
                             "'metal.roughness'")
    keys = list(scene.all_params.keys())
    # (a medium's albedo: "fog.albedo.value.value", a texture of a spectrum)
    for cand in (name, f"{name}.value", f"{name}.data", f"{name}.value.value"):
        if cand in keys:
            return cand
    emitter_key = _own_id_key(scene, name)
    if emitter_key is not None:
        return emitter_key
    # the names people write: material.parameter (not Mitsuba's .value / .data keys)
    short = sorted({re.sub(r"(\.value|\.data)+$", "", k) for k in keys})
    ending = [k for k in short if k.endswith("." + name)]
    if ending:                 # a bare parameter name ("roughness"): the materials that have it
        shown = ", ".join(repr(k) for k in ending[:6]) + (", ..." if len(ending) > 6 else "")
        raise SceneError(f"{scene.source}: no parameter {name!r}; name the material too: {shown}")
    material = name.split(".")[0]
    if material in scene.info.get("unused_materials", ()):
        raise SceneError(f"{scene.source}: no parameter {name!r}: material {material!r} is used by no "
                         "shape, so it is left out of the scene; give a shape material = "
                         f"{material!r} to tune it")
    if material in scene.info.get("volume_materials", ()):
        raise SceneError(f"{scene.source}: no parameter {name!r}: material {material!r} is copied into "
                         "the voxels of the [[volumes]] that use it, which have no parameters of their own; "
                         "change the material in the scene file")
    setting = name.rsplit(".", 1)[-1]
    if setting in SETTINGS and material in (scene.info.get("materials") or ()):
        raise SceneError(f"{scene.source}: no parameter {name!r}: {setting} is a setting of material "
                         f"{material!r}, read when the scene loads, not a parameter (no gradient, not in "
                         "mi.traverse); change it in the scene file")
    hint = suggest(name, short)
    if "; did you mean" not in hint:
        hint = suggest(name, keys)
    if hint.startswith("; valid:") and len(short) > 12:
        hint = "; `draaw-mi info` lists the scene's materials"
    raise SceneError(f"{scene.source}: no parameter {name!r}{hint}")


def _own_id_key(scene, name: str) -> str | None:
    """The key of ``ID.PARAM`` where ``ID`` is an emitter's or a medium's own id (an XML
    area light or medium in a shape without an id, whose keys Mitsuba names
    ``object_<address>.emitter...``, a name that changes from run to run), else ``None``."""
    light, sep, param = name.partition(".")
    if not sep:
        return None
    for obj in list(scene.mi_scene.emitters()) + scene_media(scene.mi_scene):
        if obj.id() != light:
            continue
        own = mi.traverse(obj)
        for cand in (param, f"{param}.value", f"{param}.data", f"{param}.value.value"):
            if cand in own.keys():
                node = own.properties[cand][2]
                return next((k for k, entry in scene.params.properties.items()
                             if entry[2] is node and k.endswith("." + cand)), None)
    return None
