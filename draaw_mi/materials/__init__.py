"""Materials: the ``draaw`` BSDF plugin (metallic/roughness model + GO-Draaw's legacy knobs)."""
from __future__ import annotations

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
