"""Fitted light values written back into a scene description: the ``[[lights]]`` table (or
the emitting ``[[shapes]]`` table) a traverse key belongs to gets the value as its
``intensity`` / ``color`` (or ``emission``), so that the saved scene renders as fitted.

A light's radiance in a scene file is ``intensity × color``; a fitted RGB value keeps the
intensity and becomes the colour (``color = value / intensity``), so the file still reads as
"this bright, this hue". A scalar (an environment map's ``scale``) is the intensity.

>>> desc = {"lights": [{"type": "point", "intensity": 4.0}]}
>>> write_light(desc, "point_light0.intensity.value", [2.0, 1.0, 0.0])
True
>>> desc["lights"][0]
{'type': 'point', 'intensity': 4.0, 'color': [0.5, 0.25, 0.0]}
"""
from __future__ import annotations

import numpy as np

from .description import SHAPE_NAME
from .light_dicts import LIGHT_NAME

#: what follows a light's name in its traverse keys, by the value it holds
RGB_PARAMS = ("emitter.radiance", "radiance", "intensity", "irradiance")
SCALAR_PARAMS = ("scale",)


def _split(key: str) -> tuple[str, str]:
    name, _, param = key.partition(".")
    return name, param.removesuffix(".value")


def _named(tables, default: str):
    """``{name: table}`` as the scene builder names them (``name``, else ``default``)."""
    out = {}
    for i, t in enumerate(tables or []):
        if isinstance(t, dict):
            out[str(t.get("name", default.format(kind=t.get("type", "mesh"), i=i)))] = t
    return out


def light_names(desc: dict) -> list[str]:
    """The names of the description's ``[[lights]]`` (as the scene builder gives them)."""
    return list(_named(desc.get("lights"), LIGHT_NAME))


def is_light_key(desc: dict, key: str) -> bool:
    """Whether ``key`` is a light value :func:`write_light` can write into ``desc``."""
    name, param = _split(key)
    if param in RGB_PARAMS + SCALAR_PARAMS and name in _named(desc.get("lights"), LIGHT_NAME):
        return True
    shape = _named(desc.get("shapes"), SHAPE_NAME).get(name)
    return param == "emitter.radiance" and shape is not None and "emission" in shape


def write_light(desc: dict, key: str, value) -> bool:
    """Write the fitted ``value`` of ``key`` into ``desc`` (in place); False when ``key`` is
    not a light of the description."""
    if not is_light_key(desc, key):
        return False
    name = _split(key)[0]
    v = np.asarray(value, dtype=np.float64).ravel()
    light = _named(desc.get("lights"), LIGHT_NAME).get(name)
    if light is None:                                   # an emitting shape
        shape = _named(desc.get("shapes"), SHAPE_NAME)[name]
        shape["emission"] = [float(x) for x in np.broadcast_to(v, 3)]
        shape.pop("emission_color", None)
        return True
    if v.size == 1:                                     # (an envmap's scale)
        light["intensity"] = float(v[0])
        return True
    intensity = float(light.get("intensity", 1.0))
    if intensity <= 0.0:
        intensity = light["intensity"] = 1.0
    light["color"] = [float(x) / intensity for x in v]
    return True


__all__ = ["write_light", "is_light_key", "light_names"]
