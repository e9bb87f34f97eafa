"""Shared helpers of the SDF tests: scenes with an SDF and their Mitsuba-shape twins, seed
stacks and per-pixel z-scores."""
from __future__ import annotations

import copy

import numpy as np

import draaw_mi
import drjit as dr
import mitsuba as mi


def base_description(res=(32, 24), light="point"):
    """A draaw-material ball on a mesh floor, a mesh cube occluding part of it, shadows."""
    lights = [{"type": "point", "position": [2.0, 4.0, 3.0], "intensity": 40.0},
              {"type": "constant", "intensity": 0.3}]
    if light == "area":
        lights = [{"type": "area", "position": [1.5, 3.0, 1.5], "target": [0, 0, 0], "size": 1.0,
                   "intensity": 12.0}, {"type": "constant", "intensity": 0.2}]
    return {
        "render": {"resolution": list(res), "spp": 16, "max_depth": 3, "filter": "box"},
        "camera": {"origin": [0.0, 1.2, 5.0], "target": [0.0, 0.6, 0.0], "fov": 38},
        "materials": {
            "ball": {"base_color": [0.8, 0.3, 0.2], "roughness": 0.35, "metallic": 0.3},
            "ground": {"base_color": [0.6, 0.6, 0.6], "roughness": 0.8},
            "blocker": {"base_color": [0.2, 0.4, 0.7], "roughness": 0.6},
        },
        "shapes": [
            {"type": "rectangle", "name": "floor", "material": "ground", "scale": 4.0,
             "rotate": {"axis": [1, 0, 0], "angle": -90}},
            {"type": "cube", "name": "occluder", "material": "blocker", "scale": [0.25, 0.35, 0.25],
             "translate": [-0.55, 0.35, 1.6]},
        ],
        "lights": lights,
    }


def twin_scenes(kind="sphere", res=(32, 24), light="point"):
    """(Mitsuba-shape scene, SDF scene) that describe the same geometry."""
    a = base_description(res, light)
    b = copy.deepcopy(a)
    if kind == "sphere":
        a["shapes"].append({"type": "sphere", "name": "obj", "material": "ball",
                            "center": [0.0, 0.8, 0.0], "radius": 0.8})
        b["sdf"] = [{"type": "sphere", "name": "obj", "material": "ball",
                     "center": [0.0, 0.8, 0.0], "radius": 0.8}]
    else:   # Mitsuba's cube is [-1, 1]^3: scaled (0.6, 0.5, 0.4), rotated 30 deg about y
        xf = {"scale": [0.6, 0.5, 0.4], "rotate": {"axis": [0, 1, 0], "angle": 30},
              "translate": [0.1, 0.5, 0.0]}
        a["shapes"].append({"type": "cube", "name": "obj", "material": "ball", **xf})
        b["sdf"] = [{"type": "box", "name": "obj", "material": "ball", "size": [1.2, 1.0, 0.8],
                     "rotate": xf["rotate"], "translate": xf["translate"]}]
    return draaw_mi.load_scene(a), draaw_mi.load_scene(b)


def render_np(scene, version, spp, seed, **opts):
    img = draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[],
                          integrator_options=opts or None)
    return np.array(img, dtype=np.float64)


def seed_stack(scene, version, spp, seeds, **opts):
    return np.stack([render_np(scene, version, spp, 1000 + 7919 * s, **opts) for s in seeds])


def zscores(a: np.ndarray, b: np.ndarray, floor: float = 1e-6):
    """Per-pixel z-scores of the difference of two independent seed stacks' means, and the
    largest absolute mean difference where both stacks have no variance."""
    ma, mb = a.mean(0), b.mean(0)
    se = np.sqrt(a.var(0, ddof=1) / len(a) + b.var(0, ddof=1) / len(b))
    mask = se > floor
    z = (ma[mask] - mb[mask]) / se[mask]
    flat = np.abs(ma[~mask] - mb[~mask]).max() if (~mask).any() else 0.0
    return z, flat


def check_same_expectation(a, b):
    z, flat = zscores(a, b)
    s = {"n": z.size, "frac_gt3": float(np.mean(np.abs(z) > 3)), "mean": float(z.mean()),
         "std": float(z.std()), "max": float(np.abs(z).max()), "flat": float(flat)}
    assert s["n"] > 0.3 * a[0].size, s
    assert s["frac_gt3"] <= 0.02, s
    assert abs(s["mean"]) <= 0.25, s
    assert 0.7 <= s["std"] <= 1.4, s
    assert s["flat"] < 1e-4, s
    return s


def kernel_ops(fn) -> int:
    """operation_count of the largest JIT kernel launched by ``fn()``."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        out = fn()
        dr.eval(out)
        dr.sync_thread()
        ks = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return max(k["operation_count"] for k in ks)


_ = mi
