"""Small scenes with participating media, shared by the media tests and benchmarks."""
from __future__ import annotations

import numpy as np

import draaw_mi  # noqa: F401
import mitsuba as mi

from draaw_mi.media import VoxelGrid
from draaw_mi.media.mitsuba_dicts import smoke_medium, smoke_shape


def base(integrator: dict, res: int = 12, sensor_medium=None, origin=(0.0, 0.3, 3.5)) -> dict:
    sensor = {"type": "perspective", "fov": 40,
              "to_world": mi.ScalarTransform4f().look_at(list(origin), [0, 0, 0], [0, 1, 0]),
              "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}}
    if sensor_medium is not None:
        sensor["medium"] = sensor_medium
    return {"type": "scene", "integrator": integrator, "sensor": sensor,
            "light": {"type": "point", "position": [1.5, 2.5, 1.5], "intensity": 10.0},
            "env": {"type": "constant", "radiance": 0.4},
            "floor": {"type": "rectangle",
                      "to_world": mi.ScalarTransform4f().translate([0, -1.05, 0]).rotate([1, 0, 0], -90).scale(3),
                      "bsdf": {"type": "diffuse", "reflectance": 0.5}}}


def grid(kind: str, n: int = 8) -> VoxelGrid:
    rng = np.random.default_rng(7)
    g = VoxelGrid.empty((n, n, n), (-1, -1, -1), (1, 1, 1))
    g.smoke_color[:] = 0.8
    if kind == "uniform":
        g.density[:] = 2.0
    elif kind == "gradient":
        g.density[:] = np.linspace(0.0, 6.0, n)[:, None, None]
    elif kind == "blobs":
        c = g.centers()
        for p in rng.uniform(-0.6, 0.6, (3, 3)):
            g.density[np.linalg.norm(c - p, axis=-1) < 0.3] = 40.0
    elif kind == "albedo":
        g.density[:] = rng.uniform(0.5, 3.0, g.shape)
        g.smoke_color[:] = rng.uniform(0.1, 0.95, g.shape + (3,))
    else:
        raise ValueError(kind)
    return g


def scene_dict(kind: str, integrator: dict, res: int = 12, g_phase: float = 0.3,
               fog_sigma_t: float = 0.5) -> dict:
    """``uniform``, ``gradient``, ``blobs``, ``albedo`` (grid smoke in a null cube),
    ``mesh`` (a grid medium inside a null-BSDF sphere), ``homogeneous`` (Mitsuba's
    homogeneous medium in a null cube), ``inside`` (the camera inside a grid medium), ``fog``
    (the camera in an unbounded homogeneous medium, which is all space: no environment light,
    since ``volpath`` ends a path that leaves the scene inside a medium; ``fog_sigma_t``),
    ``fog_sun`` (the same under a directional light), ``fog_floor`` (the fog declared as the
    floor's exterior too: a medium transition at an opaque surface)."""
    if kind in ("uniform", "gradient", "blobs", "albedo"):
        d = base(integrator, res)
        d["smoke"] = smoke_shape(grid(kind), g_phase=g_phase)
        return d
    if kind == "mesh":
        d = base(integrator, res)
        d["ball"] = {"type": "sphere", "radius": 0.9, "bsdf": {"type": "null"},
                     "interior": smoke_medium(grid("gradient"), g_phase=g_phase)}
        return d
    if kind == "homogeneous":
        d = base(integrator, res)
        d["smoke"] = {"type": "cube", "bsdf": {"type": "null"},
                      "interior": {"type": "homogeneous", "sigma_t": 1.5,
                                   "albedo": {"type": "rgb", "value": [0.9, 0.7, 0.5]},
                                   "phase": {"type": "hg", "g": g_phase}}}
        return d
    if kind == "inside":
        g = grid("albedo")
        g.density *= 0.3
        medium = mi.load_dict(smoke_medium(g, g_phase=g_phase))
        d = base(integrator, res, sensor_medium=medium, origin=(0.1, 0.2, 0.6))
        d["smoke"] = {"type": "cube", "bsdf": {"type": "null"}, "interior": medium}
        return d
    if kind in ("fog", "fog_sun", "fog_floor"):
        fog = mi.load_dict({"type": "homogeneous", "sigma_t": fog_sigma_t, "albedo": 0.8,
                            "phase": {"type": "hg", "g": g_phase}})
        d = base(integrator, res, sensor_medium=fog)
        del d["env"]
        if kind == "fog_sun":                  # a directional light instead of the point light
            d["light"] = {"type": "directional", "direction": [-0.4, -1.0, -0.3], "irradiance": 3.0}
        if kind == "fog_floor":
            d["floor"]["exterior"] = fog
        return d
    raise ValueError(kind)


def scene(kind: str, integrator: str = "draaw_v4", res: int = 12, max_depth: int = 6, **kw) -> mi.Scene:
    return mi.load_dict(scene_dict(kind, {"type": integrator, "max_depth": max_depth}, res, **kw))
