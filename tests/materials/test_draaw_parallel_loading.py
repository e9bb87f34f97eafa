"""Stress test of the plugin-construction race fixed in 440bb08: a ``draaw`` constructor that
re-entered Mitsuba's parser while the scene loader built other plugins on its worker threads
failed at random (``std::bad_alloc`` / ``basic_string`` errors inside a ``roughconductor``).

A scene mixing many ``draaw`` BSDFs (constants, RGB, a bitmap) with C++ BSDFs is loaded 60
times with Mitsuba's parallel loader; every load must succeed and build every BSDF.
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

import draaw_mi  # noqa: F401

LOADS = 60


def _mixed_scene(n=16):
    d = {"type": "scene"}
    tex = mi.TensorXf(np.full((2, 2, 3), 0.5, np.float32))
    for i in range(n):
        draaw = {"type": "draaw", "roughness": 0.1 + 0.05 * (i % 10), "metallic": (i % 3) / 2,
                 "base_color": {"type": "rgb", "value": [0.2 + 0.04 * i, 0.5, 0.3]}}
        if i % 4 == 0:
            draaw["base_color"] = {"type": "bitmap", "data": tex, "raw": True}
        cpp = [{"type": "roughconductor", "material": "Au", "alpha": 0.2},
               {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.4, 0.4, 0.4]}},
               {"type": "roughdielectric", "alpha": 0.1},
               {"type": "principled", "roughness": 0.4}][i % 4]
        d[f"a{i}"] = {"type": "sphere", "center": [i, 0, 0], "radius": 0.4, "bsdf": draaw}
        d[f"b{i}"] = {"type": "sphere", "center": [i, 1, 0], "radius": 0.4, "bsdf": cpp}
    return d


def test_parallel_loads_of_mixed_draaw_and_cpp_bsdfs_never_fail():
    failures = []
    for k in range(LOADS):
        try:       # a fresh dict each time: Mitsuba's bitmap plugin takes over a 'data' tensor
            scene = mi.load_dict(_mixed_scene(), parallel=True)
            names = [type(s.bsdf()).__name__ + str(s.bsdf()) for s in scene.shapes()]
            assert sum("DraawBSDF" in n for n in names) == 16, names
        except Exception as e:  # noqa: BLE001 - count every kind of failure
            failures.append(f"load {k}: {type(e).__name__}: {str(e)[:200]}")
    assert not failures, f"{len(failures)} of {LOADS} parallel loads failed:\n" + "\n".join(failures[:5])
