"""Render versions as Mitsuba integrator plugins: ``draaw_v1`` .. ``draaw_v4`` (design.md §4).

=============  =================================================================================
``draaw_v1``   classic: Whitted mirror recursion + Lambert/Phong direct light from every
               emitter + ``scatter`` one-bounce diffuse gather rays (biased by design)
``draaw_v2``   energy-conserving Phong-family path tracer with next-event estimation
``draaw_v3``   the ``draaw`` PBR model, next-event estimation, plain NDF sampling, no MIS
               (``distribution = "ggx" | "beckmann"``); the accuracy reference of the ladder
``draaw_v4``   the same model and expectation as V3 with VNDF sampling, MIS, Russian roulette
               and a kernel specialised to the scene
=============  =================================================================================

``register()`` registers them (idempotent); ``VERSION_ALIASES`` maps the names users type
(GO-Draaw's ``V1``, ``V2``, ``V2M``, ``V4``, ..., ``v1`` .. ``v4``, ``path``, ``prb``,
``scene`` for a Mitsuba scene's own integrator) to
Mitsuba integrator plugin names, and ``resolve_version(name)`` looks one up.
"""
from __future__ import annotations

from .._lazy import old_names
from . import v1, v2, v3, v4
from .features import FEATURE_NAMES, detect_features
from .versions import (MAIN_VERSIONS, PLUGINS, SCENE_VERSION, VERSION_ALIASES, VERSION_GRADES, is_draaw,
                       resolve_version, version_key)

_REGISTERED = False


def register() -> None:
    """Register the draaw_v* integrators with Mitsuba (idempotent)."""
    global _REGISTERED
    if _REGISTERED:
        return
    for module in (v1, v2, v3, v4):
        module.register()
    _REGISTERED = True


__all__ = ["FEATURE_NAMES", "MAIN_VERSIONS", "PLUGINS", "SCENE_VERSION", "VERSION_ALIASES", "VERSION_GRADES", "detect_features",
           "is_draaw", "register", "resolve_version", "version_key"]

# names the earlier release had here, served from their new modules with a DeprecationWarning
__getattr__ = old_names(__name__, dict.fromkeys(("RenderError", "suggest"), "draaw_mi.errors"))
