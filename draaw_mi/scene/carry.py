"""Carry a scene's current parameter values into a reloaded copy of it.

:meth:`DraawScene.with_resolution <draaw_mi.scene.DraawScene.with_resolution>` reloads the
Mitsuba scene from its dict, which holds the values the file gave. Everything set through
``scene.params`` since (a material tuned in the preview, a light's radiance, a moved camera,
displaced vertices) would be lost: :func:`carry_values` writes it over. ``[[sdf]]`` objects
need nothing: both scenes trace the same :class:`~draaw_mi.sdf.scene.SDFScene`.
"""
from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

from ..guard import RENDER_GUARD
from .camera import scene_fov, x_fov

#: traverse keys not carried besides the films (what changes): faces cannot be edited
_SKIP_SUFFIXES = (".faces",)
#: written only when edited: writing a mesh buffer rebuilds the mesh's BVH
_GEOMETRY_SUFFIXES = (".vertex_positions", ".vertex_normals", ".vertex_texcoords")


def fov_for_aspect(old_x_fov: float, fov_axis: str, old_size, new_size) -> float:
    """The ``x_fov`` that keeps a camera's field of view along ``fov_axis`` (what its file
    fixed) when the film goes from ``old_size`` to ``new_size`` ((W, H) each).

    Mitsuba stores only ``x_fov``; on a ``fov_axis = "y"`` camera a new aspect ratio must
    change it, or the picture would zoom. ``tan(x_fov / 2)`` is proportional to the tangent
    of the fixed axis' half angle, by a factor ``x_fov(90, axis, W, H)`` gives.

    >>> round(fov_for_aspect(56.3736, "y", (32, 16), (16, 16)), 3)   # y-fov 30 degrees kept
    30.0
    >>> fov_for_aspect(40.0, "x", (32, 16), (16, 16))
    40.0
    """
    if fov_axis == "x" or tuple(old_size) == tuple(new_size):
        return float(old_x_fov)
    ratio = (math.tan(math.radians(x_fov(90.0, fov_axis, *new_size)) / 2)
             / math.tan(math.radians(x_fov(90.0, fov_axis, *old_size)) / 2))
    t = math.tan(math.radians(old_x_fov) / 2) * ratio
    return math.degrees(2 * math.atan(t))


def carry_values(src, dst) -> None:
    """Write the current values of ``src``'s ``mi.traverse`` parameters (a
    :class:`~draaw_mi.scene.DraawScene`) into ``dst``, a reload of the same description at
    another resolution, and update ``dst``. Keys ``dst`` lacks (Mitsuba's generated names of
    unnamed objects) are skipped; the sensor's ``x_fov`` is converted so that the file's
    ``fov_axis`` keeps its angle (:func:`fov_for_aspect`)."""
    sp, dp = src.own_traversal, dst.params        # (src.params may be keep()-ed)
    axis = scene_fov(src)[1]
    changed = False
    for key in dp.keys():
        if ".film." in key or key.endswith(_SKIP_SUFFIXES) or key not in sp:
            continue
        value = sp[key]
        if key.endswith(_GEOMETRY_SUFFIXES) and np.array_equal(np.asarray(value), np.asarray(dp[key])):
            continue
        if key.endswith("x_fov"):
            value = mi.Float(fov_for_aspect(float(value[0]), axis, src.resolution, dst.resolution))
        dp[key] = value
        changed = True
    if changed:
        with RENDER_GUARD:
            dp.update()
