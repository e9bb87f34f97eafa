"""Integrator plugins made from render options: the Mitsuba properties of a version, depth,
hidden emitters, AOVs and further options (:func:`integrator_props`), and an error that names
the option Mitsuba refused (:func:`make_plugin`).

>>> integrator_props("V4", 3, aovs=("depth",))
{'type': 'draaw_v4', 'max_depth': 3, 'aovs': 'depth'}
"""
from __future__ import annotations

import re

import mitsuba as mi

from ..errors import RenderError, raise_if_interrupted, suggest
from ..integrators import resolve_version
from ..scene.mitsuba_load import mitsuba_error_message


def integrator_props(version: str, max_depth: int, hide_emitters: bool = False, aovs=(), **options) -> dict:
    """The ``mi.load_dict`` properties of ``version``'s integrator with these options."""
    props = {"type": resolve_version(version), "max_depth": int(max_depth)}
    if hide_emitters:
        props["hide_emitters"] = True
    if aovs:
        props["aovs"] = ",".join(aovs)
    props.update(options)
    return props


def make_plugin(props: dict):
    """``mi.load_dict(props)``, or a :class:`~draaw_mi.errors.RenderError` that says which
    option the integrator does not take."""
    try:
        return mi.load_dict(props)
    except Exception as e:  # noqa: BLE001 - Mitsuba reports every refusal as a RuntimeError
        raise_if_interrupted(e)                  # (Ctrl-C in a draaw integrator's constructor)
        raise _integrator_error(props["type"], props, e) from None


def _integrator_error(plugin: str, props: dict, e: Exception) -> RenderError:
    """A clear message for an integrator Mitsuba would not create from ``props``."""
    text = str(e)
    if props.get("aovs") and not plugin.startswith("draaw"):
        return RenderError(f"render: AOVs ({props['aovs']}) come from the draaw versions v1..v4; "
                           f"{plugin!r} renders colour only: drop aovs or pick v1..v4")
    names = re.findall(r'^\s*- \w+ "([^"]+)"', text, flags=re.M)
    if "unreferenced propert" in text and names:
        known = _plugin_parameters(plugin)
        hint = suggest(names[0], known) if known else ""
        return RenderError(f"render: the integrator {plugin!r} has no option "
                           f"{', '.join(repr(n) for n in names)}{hint}")
    return RenderError(f"render: cannot create integrator {plugin!r}: {mitsuba_error_message(e)}")


def _plugin_parameters(plugin: str) -> list[str]:
    """The parameters of a draaw integrator: its docstring table's (``* - name`` rows), the
    SDF tracer's and, for V1 / V2, the medium march's."""
    if not plugin.startswith("draaw"):
        return []
    try:
        doc = type(mi.load_dict({"type": plugin})).__doc__ or ""
    except Exception:  # noqa: BLE001 - only a hint
        return []
    names = re.findall(r"^\s*\* - (\w+)\s*$", doc, flags=re.M)
    names += ["sdf_epsilon", "sdf_max_steps", "sdf_relaxation", "sdf_silhouettes", "sdf_band", "sdf_creases"]
    if plugin in ("draaw_v1", "draaw_v2"):
        names.append("medium_steps")
    return sorted(set(names))
