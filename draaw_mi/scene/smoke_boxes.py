"""Where ``[[volumes]]`` smoke boxes may lie: not overlapping each other, not around the
camera. Plain geometry on the boxes' bounds (``volume_info`` as
:func:`~draaw_mi.scene.volume_dicts.volume_dicts` returns it: ``name``, ``mode``,
``bounds``), without the voxel machinery of :mod:`draaw_mi.media`: the preview and the batch
planner check every camera they are given against it.

>>> from draaw_mi.scene.schema import Where
>>> boxes = [{"name": "plume", "mode": "smoke", "bounds": [[-1, 0, -1], [1, 2, 1]]}]
>>> check_camera_outside_smoke([0, 1, 5], boxes, Where("scene.toml"), reach=0.01)
>>> check_camera_outside_smoke([0, 1, 0], boxes, Where("scene.toml"), reach=0.01)
Traceback (most recent call last):
draaw_mi.errors.SceneError: scene.toml: camera: the camera at [0.0, 1.0, 0.0] is inside smoke volume 'plume' ...
"""
from __future__ import annotations

import numpy as np


def check_smoke_boxes_disjoint(volume_info: list, where) -> None:
    """Two ``[[volumes]]`` smoke boxes that overlap are refused: each box is a null cube with
    its medium inside, so where they overlap a ray carries one medium, not the sum, and on
    leaving the inner box it carries none while still inside the outer one (volpath and
    every version render light leaking through the overlap). Boxes may touch: a ray crossing
    a shared face leaves one medium for the other."""
    smoke = [(i, v, *(np.asarray(b, float) for b in v["bounds"]))
             for i, v in enumerate(volume_info) if v["mode"] == "smoke"]
    for a in range(len(smoke)):
        for b in range(a):
            i, v, lo, hi = smoke[a]
            _, u, lo2, hi2 = smoke[b]
            # (overlaps thinner than 1e-6 of the boxes are rounding: 0.1 + 0.2 against 0.3)
            tol = 1e-6 * float(np.max(np.concatenate([hi - lo, hi2 - lo2])))
            if np.all(np.minimum(hi, hi2) - np.maximum(lo, lo2) > tol):
                raise (where / "volumes" / i / "bounds").error(
                    f"smoke volume {v['name']!r} (bounds {lo.tolist()} - {hi.tolist()}) overlaps smoke "
                    f"volume {u['name']!r} (bounds {lo2.tolist()} - {hi2.tolist()}); overlapping smoke "
                    "boxes do not add up: merge them into one grid, or move them apart (they may touch)")


def check_camera_outside_smoke(origin, volume_info: list, where, reach: float) -> None:
    """A camera inside a ``[[volumes]]`` smoke box would render as if the smoke were not around
    it (the sensor's medium is not set, so every version, and volpath, starts each camera
    ray in vacuum: density 1e6 looks like no smoke at all). Refused until it is supported.
    ``reach``: how far from the origin the camera's rays start (its near clip along the
    corner rays, :func:`draaw_mi.scene.camera.near_reach`): a camera on a box's face, or
    closer to it than that, starts its rays inside the smoke without crossing the face and
    renders it absent as well."""
    o = np.asarray(origin, float)
    for v in volume_info:
        lo, hi = (np.asarray(b, float) for b in v["bounds"])
        if v["mode"] == "smoke" and np.all(o >= lo - reach) and np.all(o <= hi + reach):
            near = "" if np.all(o > lo) and np.all(o < hi) else f" or within its near clip ({reach:.3g}) of it"
            raise (where / "camera").error(
                f"the camera at {[float(f'{x:.6g}') for x in o]} is inside smoke volume {v['name']!r}{near} (bounds "
                f"{lo.tolist()} - {hi.tolist()}); a camera inside a [[volumes]] box is not supported: move it outside")
