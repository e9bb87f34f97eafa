"""The colour channels a film stores (its ``pixel_format``), and the check that a post chain
or the denoiser gets R, G, B."""
from __future__ import annotations

import re

import numpy as np

from ..errors import RenderError
from ..io import DEFAULT_NAMES
from .session import session_of


def film_colour_names(film) -> list[str]:
    """The colour channels a Mitsuba film stores, from its ``pixel_format`` (``rgb``, ``rgba``,
    ``xyz``, ``xyza``, ``y``, ``ya``; Mitsuba exposes it only in the film's description), by
    their count where the description names none.

    >>> import mitsuba as mi
    >>> film_colour_names(mi.load_dict({"type": "hdrfilm", "pixel_format": "xyza"}))
    ['X', 'Y', 'Z', 'A']
    """
    n = int(film.base_channels_count())
    fmt = re.search(r"pixel_format = (\w+)", str(film))
    names = [c.upper() for c in fmt.group(1)] if fmt else []
    return names if len(names) == n else list(DEFAULT_NAMES[n])


def scene_colour_names(scene, sensor: int = 0) -> list[str]:
    """:func:`film_colour_names` of the film of the scene's sensor ``sensor`` (an index), found
    once per scene (a film's pixel format is fixed at loading; read after the kernels are
    launched, the lookup waits for a core: 0.1 ms a small render)."""
    memo = session_of(scene).memo
    key = ("film colour", sensor)
    names = memo.get(key)
    if names is None:
        names = memo[key] = film_colour_names(scene.mi_scene.sensors()[sensor].film())
    return list(names)


def sensor_index(scene, sensor, who: str = "render") -> int:
    """The index of ``sensor`` among the scene's sensors: an index, or a sensor's id in the
    scene file; a :class:`RenderError` naming the sensors otherwise.

    >>> import draaw_mi
    >>> sensor_index(draaw_mi.load_scene("scenes/cornell.toml", resolution=(8, 8)), 0)
    0
    """
    sensors = scene.mi_scene.sensors()
    ids = [s.id() for s in sensors]
    if isinstance(sensor, str) and sensor in ids:
        return ids.index(sensor)
    if isinstance(sensor, (int, np.integer)) and not isinstance(sensor, bool) and 0 <= sensor < len(sensors):
        return int(sensor)
    raise RenderError(f"{who}: sensor={sensor!r}; {scene.source} has {len(sensors)} sensor(s): expected an "
                      f"index in [0, {len(sensors) - 1}] or an id ({', '.join(map(repr, ids))})")


def sensor_spp(scene, sensor: int) -> int:
    """The samples per pixel a render of the scene's sensor ``sensor`` (an index) takes by
    default: the scene's ``render.spp`` for the first, another's own sampler's count."""
    if not sensor:
        return int(scene.settings["spp"])
    return int(scene.mi_scene.sensors()[sensor].sampler().sample_count())


def check_film_colour(scene, what: str, sensor: int = 0) -> None:
    """A post chain and the denoiser read R, G, B (and A) colour: a film storing luminance or
    XYZ (an XML scene's pixel_format) is refused before the render, not after it (else a post
    chain fails with a shape error, the denoiser reads Y and two AOV channels as colour, and
    both read X, Y, Z as R, G, B)."""
    names = scene_colour_names(scene, sensor)
    if names[:3] != ["R", "G", "B"]:
        fmt = {"y": "luminance", "ya": "luminance_alpha"}.get("".join(names).lower(), "".join(names).lower())
        raise RenderError(f"render: the film of {scene.source} stores {', '.join(names)} colour "
                          f"(pixel_format {fmt!r}); {what} needs rgb or rgba: "
                          "set the film's pixel_format to rgb, or drop post/denoise")
