"""Mitsuba's own loaders, made safe for draaw-mi's scenes: a fixed emitter order, SDF proxies
and equal materials kept apart, and Mitsuba's errors cut to their useful line."""
from __future__ import annotations

import difflib
import hashlib
import os
import re
import tempfile
import xml.etree.ElementTree as ET

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import DraawError, SceneError, raise_if_interrupted, suggest
from ..guard import RENDER_GUARD, exr_reading_threads, note_registry_change
from ..materials.draaw_bsdf import ALL_PARAMS, OPTIONS
from ..sdf.scene import PROXY_PREFIX
from .xml_film import film_sized_xml
from .xml_text import parse_xml_file


_ROUGH = "distribution alpha alpha_u alpha_v sample_visible"
_IOR = "int_ior ext_ior"
#: parameters of Mitsuba 3.9's common BSDFs (its documentation), for a misspelt one's "did you mean"
_BSDF_PARAMETERS = {
    "diffuse": "reflectance",
    "dielectric": f"{_IOR} specular_reflectance specular_transmittance",
    "thindielectric": f"{_IOR} specular_reflectance specular_transmittance",
    "roughdielectric": f"{_ROUGH} {_IOR} specular_reflectance specular_transmittance",
    "conductor": "material eta k specular_reflectance",
    "roughconductor": f"{_ROUGH} material eta k specular_reflectance",
    "plastic": f"{_IOR} diffuse_reflectance specular_reflectance nonlinear",
    "roughplastic": f"distribution alpha sample_visible {_IOR} diffuse_reflectance specular_reflectance nonlinear",
    "principled": "base_color roughness anisotropic metallic spec_trans eta specular spec_tint sheen sheen_tint "
                  "flatness clearcoat clearcoat_gloss",
    "principledthin": "base_color roughness anisotropic spec_trans eta spec_tint sheen sheen_tint flatness "
                      "diff_trans",
    "blendbsdf": "weight", "mask": "opacity", "bumpmap": "scale", "normalmap": "normalmap"}


def _unreferenced_message(text: str) -> str | None:
    """Mitsuba's "Found N unreferenced properties in bsdf plugin of type "dielectric": - float
    "int_iro": 1.5" as one line naming the object, its plugin and each unknown parameter (with
    the closest of the draaw BSDF's parameters for a ``draaw`` one). The list's last line
    alone, ``- float "int_iro": 1.5``, names neither the material nor the problem."""
    m = re.search(r'unreferenced propert\w* in (?:(\w+) )?plugin of type "([^"]+)"', text)
    if m is None:
        return None
    kind, plugin = m.group(1), m.group(2)
    names = re.findall(r'^\s*-\s*\w+\s+"([^"]+)"', text[m.end():], re.M)
    node = re.search(r'While loading dictionary node "([^"]+)"', text)
    line = re.search(r"\((line \d+, col \d+)\)", text[:m.start()])      # an XML file's
    place = f"{node.group(1)!r}: " if node else f"{line.group(1)}: " if line else ""
    what, hint = f"Mitsuba's {plugin!r} {kind}" if kind and kind != "unknown" else f"the {plugin!r} plugin", ""
    if plugin == "draaw":                   # ours: its parameters are known
        what, hint = "the 'draaw' BSDF", suggest(names[0], ALL_PARAMS + OPTIONS) if names else ""
    elif names and plugin in _BSDF_PARAMETERS:       # Mitsuba's: a close name only (the table is partial)
        close = difflib.get_close_matches(names[0], _BSDF_PARAMETERS[plugin].split(), n=1, cutoff=0.6)
        hint = f"; did you mean {close[0]!r}?" if close else ""
    listed = ", ".join(repr(n) for n in names) or "?"
    return (f"{place}{listed} {'is not a parameter' if len(names) == 1 else 'are not parameters'} "
            f"of {what}{hint}")


#: Mitsuba's BSDF and texture plugins, for a misspelt one's "did you mean" (those this build has)
_PLUGIN_NAMES = ("diffuse", "dielectric", "thindielectric", "roughdielectric", "conductor", "roughconductor",
                 "plastic", "roughplastic", "pplastic", "principled", "principledthin", "twosided", "bumpmap",
                 "normalmap", "blendbsdf", "mask", "null", "hair", "measured", "polarizer", "retarder",
                 "circular", "bitmap", "checkerboard", "mesh_attribute", "volume")


def _unknown_plugin_message(text: str) -> str | None:
    """Mitsuba's "At dictionary node "glass": failed to instantiate unknown plugin of type
    "dielectirc": [PluginManager] Plugin "dielectirc" not found!" as one line naming the node and
    the closest of Mitsuba's plugins (a TOML material of another BSDF goes to Mitsuba as is)."""
    m = re.search(r'Plugin "([^"]+)" not found', text)
    if m is None:
        return None
    node = re.search(r'At dictionary node "([^"]+)"', text)
    manager = mi.PluginManager.instance()
    known = [n for n in _PLUGIN_NAMES if manager.plugin_type(n) != mi.ObjectType.Unknown]
    hint = suggest(m.group(1), known)
    return (f"{node.group(1)!r}: " if node else "") + f"no Mitsuba plugin of type {m.group(1)!r}" + \
        (hint if "did you mean" in hint else "")


def mitsuba_error_message(err: Exception) -> str:
    """The useful line of a Mitsuba loader error (our own DraawError text when it is inside)."""
    text = str(err)
    for cls in ("ParameterError", "SceneError", "DraawError"):
        m = re.search(rf"{cls}: (.+)", text)
        if m:
            return m.group(1).strip()
    unused = re.findall(r"^\s*-\s*\$([A-Za-z0-9_]+=.*)$", text, re.M) if "unused parameters" in text else []
    if unused:                                  # (a define, -D NAME=VALUE, of no $NAME)
        names = ", ".join("$" + u.split("=", 1)[0] for u in unused)
        return f"define {', '.join(u.strip() for u in unused)}: the file and its includes use no {names}"
    unknown = _unreferenced_message(text) or _unknown_plugin_message(text)
    if unknown:
        return unknown
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    msg = lines[-1] if lines else type(err).__name__
    # (Mitsuba's source locations, "[properties.h:868] ", wherever they are in the line)
    return re.sub(r"\[[A-Za-z0-9_]+\.(?:h|cpp|py):\d+\]\s*", "", re.sub(r"^\[[^\]]*\]\s*", "", msg))


# Mitsuba's scene optimisation merges meshes through a hash table keyed by object addresses
# (shapes/merge.cpp), so the order of a scene's shapes changes from run to run. The order of
# the emitters attached to shapes follows it, and the emitter order decides which light a
# sample picks: a scene with two or more area lights rendered with one seed would give different
# images in different processes (a resumed batch frame would not be bit-identical). Such scenes
# load without the optimisation (declaration order); the others keep the merged meshes, which
# are cheaper for dr.freeze to traverse (about 0.02 ms per shape and frozen render).
# Scenes with [[sdf]] objects load without it too: the merge swallows the proxy meshes of two
# SDF objects with equal materials into one shape without an id, and the tracer, which finds
# its objects by their proxies' ids, would draw nothing (GO-Draaw's sphere lists, whose spheres
# mostly share the default colour, would render as an empty floor).
def _emitting_shapes(d: dict) -> int:
    return sum(1 for v in d.values() if isinstance(v, dict) and isinstance(v.get("emitter"), dict))


def _has_sdf_proxies(d: dict) -> bool:
    return any(isinstance(k, str) and k.startswith(PROXY_PREFIX) for k in d)


def _canonical(v):
    """A hashable form of a plugin dict's value, for telling equal materials apart (arrays by
    their shape and bytes, other objects by identity)."""

    if isinstance(v, dict):
        return tuple(sorted((k, _canonical(x)) for k, x in v.items() if k != "id"))
    if isinstance(v, (list, tuple)):
        return tuple(_canonical(x) for x in v)
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    try:
        arr = np.ascontiguousarray(np.asarray(v))
        if arr.dtype != object:
            return ("array", arr.shape, str(arr.dtype), hashlib.sha1(arr.tobytes()).hexdigest())
    except Exception:  # noqa: BLE001 - not array-like: identity
        pass
    return ("object", id(v))


def _has_equal_materials(d: dict) -> bool:
    """Whether two of the BSDFs the shapes of ``d`` refer to (``{"type": "ref"}``) are equal."""
    ids = {b.get("id") for v in d.values() if isinstance(v, dict)
           for b in [v.get("bsdf")] if isinstance(b, dict) and b.get("type") == "ref"}
    forms = [_canonical(d[i]) for i in ids if isinstance(d.get(i), dict)]
    return len(set(forms)) < len(forms)


def load_mitsuba_dict(d: dict):
    """``mi.load_dict(d)`` with the scene's emitters in a fixed order, its SDF proxies kept
    apart and every material its own BSDF (see above).

    The optimisation also merges *equal* objects: two materials with the same values become
    one BSDF, and the second one's parameters are gone (``no parameter 'b.roughness'``: two
    materials that start alike cannot be tuned, fitted or animated apart). Such scenes load
    without it too."""
    optimize = _emitting_shapes(d) < 2 and not _has_sdf_proxies(d) and not _has_equal_materials(d)
    with exr_reading_threads():
        scene = mi.load_dict(_tensors_shared(d), optimize=optimize)
    note_registry_change()                     # (its objects joined Dr.Jit's registry)
    return scene


#: the channel counts Mitsuba's plugins take as ``data`` tensors: given to them as a Bitmap or a
#: VolumeGrid where the tensor is three high or deep (see :func:`_tensors_shared`)
_QUIET_CHANNELS = {"bitmap": (1, 3), "gridvolume": (1, 3, 6)}


def _tensors_shared(d):
    """``d`` with every tensor a new reference to the same data. Mitsuba's ``bitmap`` moves
    the tensor it is given out of the dict, leaving it empty (shape ``()``), so loading ``d``
    itself would leave no texture for the next load (:meth:`DraawScene.with_resolution`, a
    user's dict loaded twice).

    >>> t = mi.TensorXf([1.0, 2.0])
    >>> _tensors_shared({"a": {"data": t}})["a"]["data"] is t, t.shape
    (False, (2,))
    """
    if isinstance(d, dict):
        out = {k: _tensors_shared(v) for k, v in d.items()}
        data = out.get("data")
        kind = out.get("type")
        if (kind in _QUIET_CHANNELS and data is not None and dr.is_tensor_v(data) and data.shape[:1] == (3,)
                and data.shape[-1] in _QUIET_CHANNELS[kind] and not dr.grad_enabled(data)):
            # Mitsuba's dict parser tries a value of length 3 (a texture three texels high, a
            # grid three deep) as a vector and a colour before a tensor, and nanobind prints
            # "implicit conversion ... failed!" for each try: given as the object the plugin
            # makes of the tensor instead (the same values, the same "data" parameter), where
            # the plugin's data path would take it (its channel counts; not a tensor tracking
            # gradients, which the copy would drop): anything else keeps Mitsuba's own error
            del out["data"]
            if out["type"] == "bitmap":
                out["bitmap"] = mi.Bitmap(np.array(data))
            else:
                out["grid"] = mi.VolumeGrid(np.array(data))
        return out
    if dr.is_tensor_v(d):
        return type(d)(d)
    return d


def _xml_shape_bsdfs(path: str) -> set:
    """The ids of a Mitsuba XML file's top-level ``<bsdf>`` elements that its shapes refer to
    with ``<ref id=...>`` (best effort: an unreadable file gives none; Mitsuba reports its
    errors itself)."""
    try:
        root = parse_xml_file(path)
    except (ET.ParseError, OSError, ValueError):
        return set()
    declared = {b.get("id") for b in root.findall("bsdf") if b.get("id")}
    return {r.get("id") for shape in root.iter("shape") for r in shape.findall("ref")} & declared


def load_mitsuba_file(path: str, defines: dict | None = None, size: tuple | None = None):
    """``mi.load_file(path, **defines)`` with the scene's emitters in a fixed order and every
    material its own BSDF (see above). Whether a file has two or more emitting shapes, or equal
    materials, shows only once it is loaded, so such files are parsed twice. ``defines``: values
    of the file's ``$name`` parameters (strings, :func:`~draaw_mi.scene.xml_film.check_defines`);
    ``size``: ``(width, height)`` of the first sensor's film, loaded from a resized copy of the
    text (:func:`~draaw_mi.scene.xml_film.film_sized_xml`)."""
    defines = dict(defines or {})
    if size is None:
        return _load_file(path, path, defines)
    text, defines = film_sized_xml(path, *size, defines)
    with tempfile.TemporaryDirectory(prefix="draaw-mi-xml-") as folder:
        copy = os.path.join(folder, os.path.basename(path))
        with open(copy, "w", encoding="utf-8") as fh:
            fh.write(text)
        try:
            return _load_file(copy, path, defines)
        except RuntimeError as e:          # (Mitsuba's errors name the file it read: the user's)
            if copy not in str(e):
                raise
            raise RuntimeError(str(e).replace(copy, path)) from None


def _load_file(path: str, source: str, defines: dict):
    with exr_reading_threads():
        scene = mi.load_file(path, **defines)
        merged = not _xml_shape_bsdfs(path) <= {sh.bsdf().id() for sh in scene.shapes()}
        if merged or sum(1 for e in scene.emitters() if e.get_shape() is not None) >= 2:
            scene = mi.load_file(path, optimize=False, **defines)
    note_registry_change()
    return scene


def load_dict_or_error(d: dict, source: str):
    try:
        with RENDER_GUARD:            # (see load_scene; with_resolution comes here directly)
            return load_mitsuba_dict(d)
    except DraawError:
        raise
    except Exception as e:  # noqa: BLE001 - Mitsuba reports everything as RuntimeError
        raise_if_interrupted(e)                  # (Ctrl-C in a draaw plugin's constructor)
        raise SceneError(f"{source}: {mitsuba_error_message(e)}") from None
