"""World bounds of a scene description's geometry, for automatic cameras."""
from __future__ import annotations

import mitsuba as mi
import numpy as np


def scene_bounds(shape_entries: dict, sdf_scene=None):
    """Approximate world bounds ``(lo, hi)`` of the shapes and of the ``[[sdf]]`` objects.

    The SDF objects count through their roots' boxes (:meth:`SDFScene.bboxes
    <draaw_mi.sdf.scene.SDFScene.bboxes>`); their proxy shapes (a point at the centre of all
    the SDF boxes) are skipped, and so are unbounded roots (a plane). Nothing bounded: the
    unit box around the origin."""

    skip = set(sdf_scene.proxy_ids) if sdf_scene is not None else set()
    los, his = [], []
    for key, d in shape_entries.items():
        if key in skip:
            continue
        try:
            shape = d if not isinstance(d, dict) else\
                mi.load_dict({k: v for k, v in d.items() if k not in ("bsdf", "emitter", "interior")})
        except Exception:  # noqa: BLE001 - bounds are best effort
            continue
        bb = shape.bbox()
        los.append(np.array(bb.min))
        his.append(np.array(bb.max))
    for bb in (sdf_scene.bboxes() if sdf_scene is not None else []):
        lo, hi = np.array(list(bb.min), float), np.array(list(bb.max), float)
        if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi):
            los.append(lo)
            his.append(hi)
    if not los:
        return np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])
    return np.min(los, axis=0), np.max(his, axis=0)
