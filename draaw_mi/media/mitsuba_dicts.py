"""A :class:`VoxelGrid` as standard Mitsuba scene objects.

* Smoke: a ``cube`` shape with a ``null`` BSDF whose ``interior`` is Mitsuba's own
  ``heterogeneous`` medium: ``sigma_t`` and ``albedo`` are ``gridvolume``\\ s holding the grid's
  density and smoke colour, ``scale`` multiplies the density, the phase function is ``hg``.
  The same dict renders in Mitsuba's ``volpath`` / ``prbvolpath`` and in ``draaw_v1..v4``.
  Parameters reachable through ``mi.traverse``: ``<id>.interior_medium.sigma_t.data``,
  ``...albedo.data``, ``...scale``, ``...phase_function.g``.
* Solid voxels: :func:`draaw_mi.media.faces.solid_meshes`.

    >>> import numpy as np, mitsuba as mi, draaw_mi
    >>> from draaw_mi.media import VoxelGrid
    >>> from draaw_mi.media.mitsuba_dicts import smoke_shape
    >>> g = VoxelGrid.from_arrays(density=np.ones((4, 4, 4)))
    >>> shape = mi.load_dict(smoke_shape(g, g_phase=0.3))
    >>> str(shape.interior_medium().phase_function()).split("[")[0]   # Henyey-Greenstein
    'HGPhaseFunction'
    >>> params = mi.traverse(shape)
    >>> round(float(params["interior_medium.phase_function.g"][0]), 6)
    0.3
"""
from __future__ import annotations

import math
import numbers

import mitsuba as mi
import numpy as np

from ..errors import ParameterError
from ..limits import FLOAT32_MAX, HG_G_MAX

FILTERS = ("nearest", "trilinear")


def unit_cube_to_box(bbox_min, bbox_max):
    """``mi.ScalarTransform4f`` mapping [0, 1]^3 onto the box (how ``gridvolume`` is placed)."""
    lo = np.asarray(bbox_min, float)
    hi = np.asarray(bbox_max, float)
    return mi.ScalarTransform4f().translate(lo.tolist()).scale((hi - lo).tolist())


def check_g(g_phase, where: str = "smoke") -> float:
    """The Henyey-Greenstein g, which must be finite with |g| <= :data:`~draaw_mi.limits.HG_G_MAX`."""
    # numpy scalars are numbers (np.float32(0.5) too)
    if isinstance(g_phase, bool) or not isinstance(g_phase, numbers.Real)\
            or not math.isfinite(g_phase) or abs(float(g_phase)) > HG_G_MAX:
        raise ParameterError(f"{where}: g={g_phase!r}; expected a Henyey-Greenstein g in "
                             f"[-{HG_G_MAX}, {HG_G_MAX}]")
    return float(g_phase)


def smoke_medium(grid, g_phase: float = 0.0, scale: float = 1.0, filter_type: str = "trilinear",
                 albedo=None) -> dict:
    """Mitsuba dict of a ``heterogeneous`` medium from ``grid.density`` / ``grid.smoke_color``
    (or a constant RGB ``albedo``)."""
    g_phase = check_g(g_phase, "smoke_medium")
    if isinstance(scale, bool) or not (isinstance(scale, numbers.Real) and math.isfinite(scale)
                                                   and 0 <= scale <= FLOAT32_MAX):
        raise ParameterError(f"smoke_medium: scale={scale!r}; expected a finite value >= 0 (float32: <= 3.4e38)")
    scale = float(scale)
    if filter_type not in FILTERS:
        raise ParameterError(f"smoke_medium: filter={filter_type!r}; expected one of {', '.join(FILTERS)}")
    grid.validate("smoke_medium")
    peak = float(np.max(grid.density)) * scale if grid.density.size else 0.0
    if peak > FLOAT32_MAX:                 # (it would be stored as inf: V4 black, V1/V2 NaN)
        raise ParameterError(f"smoke_medium: scale={scale!r} times the densest voxel "
                             f"({float(np.max(grid.density))!r}) is {peak:.3g}, beyond float32 (3.4e38)")
    to_world = unit_cube_to_box(grid.bbox_min, grid.bbox_max)
    dens = np.ascontiguousarray(grid.density.transpose(2, 1, 0)[..., None], dtype=np.float32)
    if albedo is None:
        alb = np.ascontiguousarray(np.clip(grid.smoke_color, 0, 1).transpose(2, 1, 0, 3), dtype=np.float32)
        albedo_d = {"type": "gridvolume", "data": mi.TensorXf(alb), "to_world": to_world,
                    "filter_type": filter_type}
    else:
        try:
            a = [float(v) for v in np.broadcast_to(np.asarray(albedo, float), (3,))]
        except (TypeError, ValueError):
            raise ParameterError(f"smoke_medium: albedo={albedo!r}; expected one number or 3 (RGB)") from None
        if not all(0 <= v <= 1 for v in a):
            raise ParameterError(f"smoke_medium: albedo={albedo!r}; expected values in [0, 1]")
        albedo_d = {"type": "rgb", "value": a}
    return {"type": "heterogeneous",
            "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(dens), "to_world": to_world,
                        "filter_type": filter_type},
            "albedo": albedo_d, "scale": float(scale),
            "phase": {"type": "hg", "g": g_phase}}


def smoke_shape(grid, **medium_kw) -> dict:
    """A ``cube`` with a ``null`` BSDF around the grid's box, the smoke as its interior."""
    lo, hi = np.asarray(grid.bbox_min, float), np.asarray(grid.bbox_max, float)
    to_world = mi.ScalarTransform4f().translate(((lo + hi) / 2).tolist()).scale(((hi - lo) / 2).tolist())
    return {"type": "cube", "to_world": to_world, "bsdf": {"type": "null"},
            "interior": smoke_medium(grid, **medium_kw)}
