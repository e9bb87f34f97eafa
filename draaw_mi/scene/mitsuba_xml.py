"""What a Mitsuba XML scene file refers to: the files it reads and whether it names an integrator.

Mitsuba loads the scene itself (``mi.load_file``); this module only reads the XML text again,
after a successful load, to learn what the load depended on:

- the **files** it reads (``<include>`` files, meshes, textures, environment maps, volume
  grids, spectra: every ``filename``), so that batch frames of the scene go stale when one of
  them changes (:func:`draaw_mi.batch.planner.files_hash`), as for TOML scenes;
- whether it, or a file it includes, declares an ``<integrator>`` (which then becomes the
  scene's render version);
- names for its shapes in ``draaw-mi info`` (:func:`shape_names`: Mitsuba merges the unnamed
  meshes of one material into one shape without an id) and for its integrator
  (:func:`integrator_name`).

Relative names are looked up where Mitsuba may find them: beside the file that names them,
beside the scene file and in the folders of ``<path>`` tags; ``$name`` takes the value of a
``<default name=...>``. A name found in none of them is left out (Mitsuba would have failed
the load). Listing a file Mitsuba did not read costs at most a needless re-render, so every
candidate that exists is kept, not only the one Mitsuba's resolver picks.

Example::

    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> _ = open(os.path.join(d, "tex.png"), "wb").write(b"x")
    >>> _ = open(os.path.join(d, "s.xml"), "w").write(
    ...     '<scene version="3.0.0"><default name="t" value="tex.png"/>'
    ...     '<bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
    ...     '<string name="filename" value="$t"/></texture></bsdf></scene>')
    >>> files, named = xml_references(os.path.join(d, "s.xml"))
    >>> [os.path.basename(f) for f in files], named
    (['tex.png'], False)
"""
from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET

import mitsuba as mi

from .xml_text import parse_xml_file, without_comments

#: includes deeper than this are not followed (Mitsuba's own limit is 15)
MAX_INCLUDE_DEPTH = 15


def xml_references(path: str, defines: dict | None = None) -> tuple[list[str], bool]:
    """``(files, names_integrator)`` of the Mitsuba XML scene ``path``: the absolute paths of
    the existing files it and its includes read (``path`` itself not included), and whether
    any of them declares an ``<integrator>``. ``defines``: the ``$name`` values it is loaded
    with (they win over its ``<default>`` values)."""
    path = os.path.abspath(path)
    scene_dir = os.path.dirname(path)
    files: list[str] = []
    named = [False]
    seen: set[str] = set()

    def visit(file: str, defaults: dict, search: list[str], depth: int) -> None:
        if file in seen or depth > MAX_INCLUDE_DEPTH:
            return
        seen.add(file)
        root = _parse(file)
        if root is None:
            named[0] |= _names_integrator_text(file)
            return
        here = os.path.dirname(file)
        defaults = dict(defaults)
        for node in root.iter("default"):
            if node.get("name") is not None and node.get("value") is not None:
                defaults.setdefault(node.get("name"), node.get("value"))
        search = search + [_resolve_dir(_subst(n.get("value", ""), defaults), here)
                           for n in root.iter("path")]
        for node in root.iter():
            if node.tag == "integrator":
                named[0] = True
            if node.tag == "include" and node.get("filename"):
                for inc in _find(_subst(node.get("filename"), defaults), [here, scene_dir] + search):
                    _add(files, inc)
                    visit(inc, defaults, search, depth + 1)
                continue
            name = None
            if node.get("name", "").endswith("filename") and node.get("value"):
                name = node.get("value")                     # <string name="filename" value=...>
            elif node.tag == "spectrum" and node.get("filename"):
                name = node.get("filename")                  # <spectrum filename=...>
            if name:
                for found in _find(_subst(name, defaults), [here, scene_dir] + search):
                    _add(files, found)

    visit(path, dict(defines or {}), [], 0)
    return files, named[0]


def _parse(file: str):
    try:
        return parse_xml_file(file)
    except (ET.ParseError, OSError, ValueError):
        return None


def _names_integrator_text(file: str) -> bool:
    """The text test for a file ElementTree cannot parse (comments dropped)."""
    try:
        with open(file, encoding="utf-8", errors="replace") as fh:
            text = without_comments(fh.read())
    except OSError:
        return False
    return re.search(r"<integrator\b", text) is not None


def _subst(value: str, defaults: dict) -> str:
    if "$" not in value:
        return value
    # longest names first, so that $spp_max is not read as $spp followed by "_max"
    for name in sorted(defaults, key=len, reverse=True):
        value = value.replace("$" + name, str(defaults[name]))
    return value


def _resolve_dir(value: str, here: str) -> str:
    return value if os.path.isabs(value) else os.path.join(here, value)


def _find(name: str, folders: list[str]) -> list[str]:
    """Every existing file ``name`` can mean: Mitsuba's resolver order (the ``<path>`` folders
    first, an include's folder only while it is parsed) is not copied here, and a file listed
    that Mitsuba did not read costs at most a re-render, while one left out is a stale frame."""
    if "$" in name:                   # a parameter given only at load time: cannot be known here
        return []
    name = os.path.expanduser(name)
    if os.path.isabs(name):
        return [name] if os.path.isfile(name) else []
    found = []
    for folder in folders:
        candidate = os.path.normpath(os.path.join(folder, name))
        if os.path.isfile(candidate) and candidate not in found:
            found.append(candidate)
    return found


def _add(files: list[str], path: str) -> None:
    if path not in files:
        files.append(path)


# Mitsuba integrators whose printed or class name is not their plugin name
_PLUGIN_NAMES = {"VolumetricSimplePathIntegrator": "volpath", "VolumetricMisPathIntegrator": "volpathmis",
                 "ParticleTracerIntegrator": "ptracer", "BasicPRBIntegrator": "prb_basic",
                 "PRBVolpathIntegrator": "prbvolpath", "DirectProjectiveIntegrator": "direct_projective",
                 "PathProjectiveIntegrator": "prb_projective", "MomentIntegrator": "moment",
                 "AOVIntegrator": "aov"}


#: the classes a Python integrator reports (its own name is what it prints: a ``Tracer``)
_BASE_CLASSES = ("SamplingIntegrator", "MonteCarloIntegrator", "AdjointIntegrator", "Integrator")


def integrator_name(integrator) -> str:
    """The plugin name of a loaded Mitsuba integrator, from what it prints or its C++ class
    (``DirectIntegrator`` -> ``direct``; ``moment`` prints its nested scene, ``volpath`` a
    class of another name).

    >>> import mitsuba as mi
    >>> [integrator_name(mi.load_dict({"type": t, "n": {"type": "path"}} if t == "moment" else {"type": t}))
    ...  for t in ("direct", "volpath", "ptracer", "moment", "prb_basic")]
    ['direct', 'volpath', 'ptracer', 'moment', 'prb_basic']
    """
    kind = str(integrator).split("[", 1)[0].strip()
    draaw = re.fullmatch(r"DraawV(\d)Integrator", kind)
    if draaw:                                   # (draaw_v4, as --version and the XML spell it)
        return f"draaw_v{draaw.group(1)}"
    cls = integrator.class_name()
    for name in (kind, cls):
        if name in _PLUGIN_NAMES:
            return _PLUGIN_NAMES[name]
    if not kind.endswith("Integrator") and cls not in _BASE_CLASSES:
        kind = cls                              # (what it prints is not its class)
    return kind.removesuffix("Integrator").lower() or kind


def shape_names(mi_scene, xml_path: str | None = None) -> list[str]:
    """A name for each shape of ``mi_scene`` (SDF proxies left out): its id; for a shape
    without one, what the XML file says of its material's shapes that are not in the scene
    under their own ids (each one's id, else its mesh file, else its type) and the material:
    ``"merged mesh of 3 shapes: floor, a.obj, cube (material white)"`` where Mitsuba joined the
    meshes of one material into one shape."""
    shapes = [sh for sh in mi_scene.shapes() if not sh.id().startswith("__sdf_")]
    ids = {sh.id() for sh in shapes if sh.id()}
    absent = {bsdf: [label for label, sid in group if sid not in ids]
              for bsdf, group in (_xml_shapes(xml_path) if xml_path else {}).items()}
    unnamed: dict = {}
    for sh in shapes:
        if not sh.id():
            unnamed.setdefault(_bsdf_id(sh), []).append(sh)
    names = []
    for sh in shapes:
        if sh.id():
            names.append(sh.id())
            continue
        bsdf = _bsdf_id(sh)
        material = f"material {bsdf}" if bsdf else "its own material"
        labels, mine = absent.get(bsdf, []), unnamed[bsdf]
        if len(mine) == 1 and len(labels) > 1:
            shown = ", ".join(labels[:8]) + (", ..." if len(labels) > 8 else "")
            names.append(f"merged mesh of {len(labels)} shapes: {shown} ({material})")
        elif len(mine) == len(labels):
            names.append(f"{labels[mine.index(sh)]} ({material})")
        else:
            kind = "mesh" if isinstance(sh, mi.Mesh) else str(sh).split("[", 1)[0].strip().lower()
            names.append(f"unnamed {kind} ({material})")
    return names


def _bsdf_id(shape) -> str:
    try:
        bsdf = shape.bsdf()
        return bsdf.id() if bsdf is not None else ""
    except Exception:  # noqa: BLE001 - a shape without a BSDF
        return ""


def _xml_shapes(path: str) -> dict:
    """``{material id: [(label, id or None), ...]}`` of the top-level shapes of ``path`` that
    refer to a declared material (label: the id, else the mesh file's name, else the type)."""
    root = _parse(path)
    if root is None:
        return {}
    out: dict = {}
    for shape in root.findall("shape"):
        ref = shape.find("ref")
        if ref is None or not ref.get("id"):
            continue
        file = next((n.get("value") for n in shape if n.get("name") == "filename" and n.get("value")), None)
        label = shape.get("id") or (os.path.basename(file) if file else shape.get("type", "shape"))
        out.setdefault(ref.get("id"), []).append((label, shape.get("id")))
    return out

__all__ = ["integrator_name", "shape_names", "xml_references"]
