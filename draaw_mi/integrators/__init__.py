"""Render versions as Mitsuba integrator plugins: ``draaw_v1`` .. ``draaw_v4`` (see design.md §4).

``register()`` registers every integrator module present; ``VERSION_ALIASES`` maps the names
users type (``v4``, ``V2M``, ``path``, ...) to Mitsuba integrator plugin names.
"""
from __future__ import annotations

import mitsuba as mi

# name typed by a user (lower-cased) -> Mitsuba integrator plugin name
VERSION_ALIASES: dict[str, str] = {
    "path": "path",
    "prb": "prb",
}

_REGISTERED = False


def register() -> None:
    """Register the draaw_v* integrators with Mitsuba (idempotent)."""
    global _REGISTERED
    if _REGISTERED:
        return
    _REGISTERED = True
