"""Materials: the ``draaw`` BSDF plugin (metallic/roughness model + GO-Draaw's legacy knobs)."""
from __future__ import annotations

from .._lazy import old_names
from .checks import check_value
from .draaw_bsdf import register_draaw_bsdf

_REGISTERED = False


def register() -> None:
    """Register the ``draaw`` BSDF with Mitsuba (idempotent)."""
    global _REGISTERED
    if _REGISTERED:
        return
    register_draaw_bsdf()
    _REGISTERED = True


__all__ = ["check_value", "register"]

# names the earlier release had here, served from their new modules with a DeprecationWarning
__getattr__ = old_names(__name__, {
    **dict.fromkeys(("FLOAT32_MAX", "FOV_RANGE"), "draaw_mi.limits"), "ParameterError": "draaw_mi.errors"})
