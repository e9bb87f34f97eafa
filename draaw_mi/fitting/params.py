"""The parameters :func:`draaw_mi.fit` optimises: each one's range, and the space Adam moves
it in (roughness and alpha in log space, with a floor below which the BSDF's alpha clamp makes
every value render alike)."""
from __future__ import annotations

from typing import TYPE_CHECKING

import drjit as dr
import mitsuba as mi
import numpy as np

from ..materials.checks import PLUGIN_RANGES

if TYPE_CHECKING:
    from ..scene import DraawScene

# parameter name suffix -> (low, high) projection range
RANGES = {
    "roughness": (0.0, 1.0), "metallic": (0.0, 1.0), "specular": (0.0, 1.0),
    "reflection": (0.0, 1.0), "direct_to_scatter": (0.0, 1.0), "base_color": (0.0, 1.0),
    "reflectance": (0.0, 1.0), "alpha": (1e-3, 1.0), "radiance": (0.0, None), "intensity": (0.0, None),
    # Mitsuba's own BSDFs (roughplastic, roughconductor, dielectric, conductor); principled's
    # weights as a scene file holds them (materials.checks.PLUGIN_RANGES)
    **{k: (lo, hi) for k, (lo, hi, _) in PLUGIN_RANGES["principledthin"].items() if hi is not None},
    "diffuse_reflectance": (0.0, 1.0), "specular_reflectance": (0.0, 1.0),
    "specular_transmittance": (0.0, 1.0), "alpha_u": (1e-3, 1.0), "alpha_v": (1e-3, 1.0),
    "eta": (1e-3, None), "k": (0.0, None), "albedo": (0.0, 1.0), "sigma_t": (0.0, None),
    "weight": (0.0, 1.0),              # blendbsdf's (Mitsuba clips it: past a bound nothing changes)
}
# parameter name suffix -> space Adam works in ("log": the optimiser moves log(value))
SPACES = {"roughness": "log", "alpha": "log", "alpha_u": "log", "alpha_v": "log"}
# Smallest roughness the log-space optimiser visits, as a multiple of sqrt(alpha_min): with
# alpha = sqrt(roughness^4 + alpha_min^2) (draaw BSDF), roughness 0.6 * sqrt(alpha_min) gives
# alpha = 1.06 * alpha_min, so every roughness below it renders the same (0.019 for the default
# alpha_min = 1e-3; Mitsuba's principled clamps alpha at 1e-3 too).
ROUGHNESS_FLOOR_FACTOR = 0.6
DEFAULT_ALPHA_MIN = 1e-3


def range_for(key: str, scene: DraawScene | None = None):
    node_param = None if scene is None else scene.sdf_param(key)
    if node_param is not None:
        return scene.sdf.param_range(node_param)             # an SDF object's radius > 0, ...
    parts = key.split(".")
    if parts[-2:] == ["normalmap", "data"] and not key.startswith("sdf."):
        # its encoding's range, as the draaw BSDF loads it (unbounded, a fitted map of 2.1
        # would be saved and refused at the next load)
        return (-1.0, 1.0) if _owner_attr(scene, key, "normalmap_signed", False) else (0.0, 1.0)
    for p in reversed(parts):
        if p in RANGES:
            return RANGES[p]
    return (None, None)


class FitParam:
    """One optimised parameter: its ``mi.traverse`` key, range, and the space Adam moves it in.

    Linear space: Adam moves the value itself, projected onto [lo, hi] after every step.
    Log space (roughness, alpha): Adam moves ``u = log(value)``, projected onto
    [log(floor), log(hi)]; a step of ``lr`` is then a relative change of the value, so the
    optimiser resolves small roughnesses (0.05 vs 0.03) as finely as large ones and cannot
    fall into the flat region below the alpha clamp, where the gradient vanishes (see
    ``ROUGHNESS_FLOOR_FACTOR``).
    """
    def __init__(self, key: str, name: str, value, scene: DraawScene):
        self.key, self.name, self.type = key, name, type(value)
        # a texture (a tensor): its shape, to give the scene back a value it takes
        self.shape = tuple(value.shape) if dr.is_tensor_v(value) else None
        self.lo, self.hi = range_for(key, scene)
        if self.lo is None and self.hi is None and isinstance(value, mi.Color3f):
            self.lo = 0.0          # a colour with no entry above: at least not negative
        self.space = space_for(key)
        if self.space == "log":
            floor = self.lo if self.lo else 0.0
            if key.split(".")[-2:-1] == ["roughness"] or key.endswith("roughness"):
                floor = max(floor, ROUGHNESS_FLOOR_FACTOR * np.sqrt(alpha_min(scene, key)))
            self.lo = floor

    def clip(self, x):
        lo = -np.inf if self.lo is None else self.lo
        hi = np.inf if self.hi is None else self.hi
        if self.space == "log":
            return dr.clip(x, float(np.log(lo)), float(np.log(hi)) if np.isfinite(hi) else np.inf)
        return dr.clip(x, lo, hi)

    def to_latent(self, value):
        value = self.type(value)
        if self.space == "log":
            return self.clip(dr.log(dr.maximum(value, self.lo)))
        return self.clip(value)

    def from_latent(self, u):
        """The scene value for latent ``u``, attached to ``u`` for AD."""
        return dr.exp(u) if self.space == "log" else u

    def project_value(self, v: np.ndarray) -> np.ndarray:
        lo = -np.inf if self.lo is None else self.lo
        hi = np.inf if self.hi is None else self.hi
        return np.clip(v, lo, hi)


def space_for(key: str) -> str:
    if key.startswith("sdf."):
        return "linear"        # (an SDF node named 'alpha' or 'roughness' is no such parameter)
    for part in reversed(key.split(".")):
        if part in SPACES:
            return SPACES[part]
        if part in RANGES:
            return "linear"
    return "linear"


def alpha_min(scene: DraawScene, key: str) -> float:
    """``alpha_min`` of the draaw BSDF that owns ``key`` (default 1e-3 for other BSDFs)."""
    return float(_owner_attr(scene, key, "alpha_min", DEFAULT_ALPHA_MIN))


def _owner_attr(scene: DraawScene | None, key: str, name: str, default):
    """Attribute ``name`` of the BSDF that owns ``key`` (``default`` where there is none)."""
    owner = key.split(".")[0]
    try:
        for shape in scene.mi_scene.shapes():
            bsdf = shape.bsdf()
            if bsdf is not None and bsdf.id() == owner:
                return getattr(bsdf, name, default)
    except Exception:  # noqa: BLE001 - best effort
        pass
    return default
