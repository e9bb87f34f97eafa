"""Render version names: what users type (``V4``, ``V2M``, ``pbr``, ``path``) -> Mitsuba
integrator plugin names (:func:`resolve_version`), and GO-Draaw's graded version names."""
from __future__ import annotations

from ..errors import RenderError, suggest

PLUGINS: tuple[str, ...] = ("draaw_v1", "draaw_v2", "draaw_v3", "draaw_v4")

# name typed by a user (lower-cased) -> Mitsuba integrator plugin name
VERSION_ALIASES: dict[str, str] = {
    # plugin names and short forms
    **{p: p for p in PLUGINS},
    "v1": "draaw_v1", "v2": "draaw_v2", "v3": "draaw_v3", "v4": "draaw_v4",
    "1": "draaw_v1", "2": "draaw_v2", "3": "draaw_v3", "4": "draaw_v4",
    # GO-Draaw's UI names (go-draaw-spec.md §3): V2M and its graded variants are the
    # physically based rung (V3 here); the Lin/Log grades are tone curves in the post chain.
    "v2m": "draaw_v3",
    "v2-linear": "draaw_v3", "v2-log": "draaw_v3",
    "v2-linear-texture": "draaw_v3", "v2-log-texture": "draaw_v3",
    "v4-linear": "draaw_v4", "v4-log": "draaw_v4",
    "v4-linear-optim": "draaw_v4", "v4-log-optim": "draaw_v4",
    "v4-linear-optim-v2": "draaw_v4", "v4-log-optim-v2": "draaw_v4",
    "v4-optim-v2": "draaw_v4", "v4o2": "draaw_v4", "v4o3": "draaw_v4",
    # descriptive names
    "classic": "draaw_v1", "phong": "draaw_v2", "pbr": "draaw_v3", "optimised": "draaw_v4",
    "optimized": "draaw_v4",
    # Mitsuba's own
    "path": "path",
    "prb": "prb",
    # Mitsuba's volumetric path tracers (scenes with media)
    "volpath": "volpath",
    "prbvolpath": "prbvolpath",
    # the integrator a Mitsuba XML file or dict scene declares, as it declares it (``direct``,
    # ``aov``, ...: what Mitsuba itself would render it with)
    "scene": "scene",
}

#: the version that is the scene's own integrator object (:data:`VERSION_ALIASES`)
SCENE_VERSION = "scene"

# GO-Draaw's graded versions -> the post filter that is their colour grade (go-draaw-spec.md
# §2.10); the version itself renders linear light
VERSION_GRADES: dict[str, str] = {
    name: ("log" if "-log" in name else "linear")
    for name in VERSION_ALIASES if name.startswith(("v2-", "v4-")) and ("-log" in name or "-linear" in name)}

def version_key(name: str) -> str:
    """``name`` as :data:`VERSION_ALIASES` and :data:`VERSION_GRADES` spell it: lower case;
    plugin names with ``_`` (draaw_v4), GO-Draaw's with ``-`` (V4-Log-Optim), either accepted.

    >>> version_key(" V4_Log "), version_key("draaw-v4")
    ('v4-log', 'draaw_v4')
    """
    key = str(name).strip().lower()
    return key.replace("-", "_") if key.startswith("draaw") else key.replace("_", "-")


def resolve_version(name: str) -> str:
    """Mitsuba integrator plugin name for a render version name (case-insensitive).

    >>> resolve_version('V2M')
    'draaw_v3'

    Raises :class:`~draaw_mi.errors.RenderError` naming the bad value and the valid names.
    """
    if not isinstance(name, str):
        raise RenderError(f"render version {name!r} must be a string; {MAIN_VERSIONS}")
    key = version_key(name)
    if key in VERSION_ALIASES:
        return VERSION_ALIASES[key]
    hint = suggest(key, VERSION_ALIASES)
    hint = hint + "; " if hint.startswith("; did you mean") else "; "
    raise RenderError(f"render version {name!r} is unknown{hint}{MAIN_VERSIONS}")


def is_draaw(version: str) -> bool:
    """Whether ``version`` names one of draaw-mi's integrators (v1..v4), not one of Mitsuba's.

    >>> is_draaw("V2M"), is_draaw("path")
    (True, False)
    """
    return resolve_version(version) in PLUGINS


# the error's list: the names a user picks from (the 35 aliases would make one unreadable line)
MAIN_VERSIONS = ("expected v1, v2, v3, v4, path, prb, volpath, prbvolpath or scene (or a GO-Draaw name "
                 "such as V2M or V4-Log-Optim; all: draaw_mi.integrators.VERSION_ALIASES)")
