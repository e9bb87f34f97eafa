"""Mitsuba XML scenes at another size, and their ``$name`` parameters.

A Mitsuba XML file declares ``<default name="res" value="256"/>`` and uses ``$res``;
``mi.load_file(path, res=64)`` loads it with another value. :func:`check_defines` checks such
values (``draaw-mi render -D res=64``, ``load_scene(path, defines={"res": 64})``).

The film's size is not a scene parameter (``mi.traverse`` does not list it), so a scene is
loaded at another resolution from a copy of its text whose first sensor's film has that
``width`` and ``height`` (:func:`film_sized_xml`); the copy names the original's folder in a
``<path>`` tag, so that its relative meshes, textures and includes are found as before. A
film with a crop window (``crop_*``) renders its window: the size asked for is the window's,
and the film and the window's offset are scaled with it (:func:`scaled_crop`), so the image
shows the same part of the view.

Example::

    >>> text, kept = film_sized_xml_text(
    ...     '<scene version="3.0.0"><default name="res" value="256"/><sensor type="perspective">'
    ...     '<film type="hdrfilm"><integer name="width" value="$res"/>'
    ...     '<integer name="height" value="$res"/></film></sensor></scene>', "/scenes", 64, 48,
    ...     {"res": "128"})
    >>> 'value="64"' in text and 'value="48"' in text and '<path value="/scenes"' in text, kept
    (True, {})
"""
from __future__ import annotations

import os
import re
import warnings
import xml.etree.ElementTree as ET

from ..errors import SceneError, user_stacklevel
from .xml_text import parse_xml_file, parse_xml_text

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
#: a film's crop window (Mitsuba's ``crop_*`` properties)
CROP = ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")
FILM_SIZE = ("width", "height") + CROP
#: Mitsuba's film size where a film gives none
DEFAULT_FILM = (768, 576)


def scaled_crop(film: dict, width: int, height: int) -> dict:
    """The ``width``, ``height`` and ``crop_*`` of a film whose crop window renders a ``width``
    x ``height`` image of the part of the view that the crop window of ``film`` (its
    ``width``, ``height`` and ``crop_*`` as ints; an absent one Mitsuba's default) shows: the
    film and the window's offset are scaled by the ratio of the new window to the old one,
    rounded, with the window inside the film.

    >>> scaled_crop({"width": 32, "height": 32, "crop_width": 16, "crop_height": 16,
    ...              "crop_offset_x": 8, "crop_offset_y": 8}, 24, 12)
    {'width': 48, 'height': 24, 'crop_offset_x': 12, 'crop_offset_y': 6, 'crop_width': 24, 'crop_height': 12}
    """
    out: dict = {}
    for axis, (size, crop, offset, want, default) in enumerate(
            (("width", "crop_width", "crop_offset_x", width, DEFAULT_FILM[0]),
             ("height", "crop_height", "crop_offset_y", height, DEFAULT_FILM[1]))):
        full = film.get(size) if film.get(size) is not None else default
        window = film.get(crop) if film.get(crop) is not None else full
        ratio = want / max(int(window), 1)
        out[size] = max(int(want), round(full * ratio))
        out[offset] = min(round((film.get(offset) or 0) * ratio), out[size] - int(want))
        out[crop] = int(want)
    return {k: out[k] for k in ("width", "height") + CROP}


def _int_value(value: str, known: dict) -> int | None:
    """A film property's integer: a number, or ``$name`` of a known define or default;
    ``None`` otherwise."""
    m = re.fullmatch(r"\s*\$([A-Za-z_][A-Za-z0-9_]*)\s*", value)
    if m:
        value = known.get(m.group(1))
    try:
        return int(str(value).strip())
    except (TypeError, ValueError):
        return None


def check_defines(defines, source: str) -> dict:
    """``defines`` (``{name: value}``, values str, int, float or bool) as the strings Mitsuba's
    loader takes; a :class:`SceneError` naming the bad entry otherwise."""
    if defines is None:
        return {}
    if not isinstance(defines, dict):
        raise SceneError(f"{source}: defines={defines!r}; expected a dict of $name values, e.g. "
                         "{'res': 64}")
    out = {}
    for name, value in defines.items():
        if not isinstance(name, str) or not _NAME.match(name):
            raise SceneError(f"{source}: define {name!r}: expected a parameter name (letters, digits, "
                             "'_'), as the file's $name")
        if isinstance(value, bool):
            value = "true" if value else "false"
        if not isinstance(value, (str, int, float)) or (isinstance(value, str) and not value.strip()):
            raise SceneError(f"{source}: define {name}={value!r}: expected a string or number")
        out[name] = str(value)
    return out


def declared_defaults(path: str) -> list[str]:
    """The names of the ``<default>`` parameters ``path`` declares (best effort)."""
    try:
        root = parse_xml_file(path)
    except (ET.ParseError, OSError, ValueError):
        return []
    return [n.get("name") for n in root.iter("default") if n.get("name")]


def film_sized_xml(path: str, width: int, height: int, defines: dict) -> tuple[str, dict]:
    """``(text, defines)``: the XML of ``path`` with its first sensor's film ``width`` x
    ``height``, and the ``defines`` to load it with: all but those that only sized the film (a
    ``-D res=...`` used nowhere else, in the file or its includes at any depth, would be an
    unused parameter, which Mitsuba refuses)."""
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as e:
        raise SceneError(f"{path}: cannot read it ({e})") from None
    return film_sized_xml_text(text, os.path.dirname(os.path.abspath(path)), width, height, defines,
                               source=path)


def film_sized_xml_text(text: str, folder: str, width: int, height: int, defines: dict,
                        source: str = "<xml>") -> tuple[str, dict]:
    """:func:`film_sized_xml` of the XML ``text`` of a file in ``folder``."""
    try:
        root = parse_xml_text(text)
    except ET.ParseError as e:
        raise SceneError(f"{source}: cannot set its film size: the XML does not parse ({e})") from None
    sensor = root.find("sensor")
    if sensor is None:
        raise SceneError(f"{source}: cannot set its film size: no <sensor> in the file itself (one "
                         "in an <include>d file is sized by its own $parameters: give them with -D "
                         "/ defines=)")
    film = sensor.find("film")
    if film is None:                                  # (Mitsuba's default film)
        film = ET.SubElement(sensor, "film", {"type": "hdrfilm"})
    nodes = {n.get("name"): n for n in film if n.get("name") in FILM_SIZE}
    sizes = {"width": int(width), "height": int(height)}
    if set(nodes) & set(CROP):                        # a crop window: scaled with the film
        known = dict(defines)                         # (defines win over <default>s)
        for node in root.findall("default"):
            known.setdefault(node.get("name"), node.get("value"))
        read = {name: _int_value(node.get("value", ""), known) for name, node in nodes.items()}
        unread = sorted(name for name, value in read.items() if value is None)
        if unread:
            bad = ", ".join(f"{k}={nodes[k].get('value')!r}" for k in unread)
            warnings.warn(f"{source}: film {bad}: cannot read its crop window, so it is dropped at "
                          f"resolution {width}x{height} (the whole view renders); expected numbers or "
                          "$names of <default>s or defines", RuntimeWarning, stacklevel=user_stacklevel())
            sizes = {"width": int(width), "height": int(height), **{k: None for k in CROP}}
        else:
            sizes = scaled_crop(read, int(width), int(height))
    replaced: set[str] = set()          # the $names of the film's size and crop it rewrites
    for name, value in sizes.items():
        node = nodes.get(name)
        if node is None:
            if value is None:
                continue
            node = ET.SubElement(film, "integer", {"name": name})
        replaced.update(re.findall(r"\$([A-Za-z_][A-Za-z0-9_]*)", node.get("value", "")))
        if value is None:                             # (a crop window dropped)
            film.remove(node)
            continue
        node.tag = "integer"
        node.set("value", str(int(value)))
    root.insert(0, ET.Element("path", {"value": folder}))
    out = ET.tostring(root, encoding="unicode")
    # only a define that sized the film and is used nowhere else is dropped; any other is
    # passed on, used or not, as without a resolution (Mitsuba names an unused one)
    kept = {k: v for k, v in defines.items() if k not in replaced
            or re.search(rf"\${re.escape(k)}(?![A-Za-z0-9_])", out) or _used_by_includes(root, folder, folder, k)}
    return out, kept


def _used_by_includes(root, here: str, folder: str, name: str, seen: set | None = None) -> bool:
    """Whether an ``<include>`` of ``root`` (a file in ``here``; the scene's folder ``folder``),
    or an include of one of them at any depth, may use ``$name``. Each file is read as text; one
    that cannot be found, read or parsed, or whose name has a ``$``, counts as using it (Mitsuba
    then says what is wrong)."""
    seen = set() if seen is None else seen
    pattern = re.compile(rf"\${re.escape(name)}(?![A-Za-z0-9_])")
    for inc in root.iter("include"):
        file = inc.get("filename", "")
        if "$" in file:
            return True
        found = [f for f in ([file] if os.path.isabs(file) else [os.path.join(here, file), os.path.join(folder, file)])
                 if os.path.isfile(f)]
        if not found:
            return True
        file = os.path.realpath(found[0])
        if file in seen:
            continue
        seen.add(file)
        try:
            with open(file, encoding="utf-8", errors="replace") as fh:
                text = fh.read()
            if pattern.search(text):
                return True
            if _used_by_includes(parse_xml_text(text), os.path.dirname(file), folder, name, seen):
                return True
        except (OSError, ET.ParseError, ValueError):
            return True
    return False


__all__ = ["check_defines", "declared_defaults", "film_sized_xml", "film_sized_xml_text"]
