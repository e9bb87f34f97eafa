"""Where a suite scene's noise comes from, per sample: the per-pixel variance of K renders and
their time, for `path` at full depth and at depth 2 (direct light), Mitsuba's `direct` with 1,
2 and 4 emitter samples, and V4 without adaptive sampling. Two questions it answered for
issue 45 (results/speed_suite.md, "Measured, not pursued"): would filter importance sampling
(each sample in one pixel) keep V4's gains under a gaussian filter, and would more shadow rays
at the first hit pay? And (the doorway) would light tracing's strategies, bidirectional path
tracing's addition, sample what V4 misses?

Run from the repository root (128x128, 16 spp, 8 renders each)::

    .venv/bin/python benchmarks/variance_parts.py spheres_gauss
    .venv/bin/python benchmarks/variance_parts.py spheres path6,path2
    .venv/bin/python benchmarks/variance_parts.py doorway path6,path2,v4_6,v4_2,ptracer6,ptracer2
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import draaw_mi  # noqa: E402,F401  (variant, plugins)
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
from draaw_mi.bench import suite  # noqa: E402

INTEGRATORS = {
    "path6": {"type": "path", "max_depth": 6},
    "path2": {"type": "path", "max_depth": 2},
    "direct_e1": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 1},
    "direct_e2": {"type": "direct", "emitter_samples": 2, "bsdf_samples": 1},
    "direct_e4": {"type": "direct", "emitter_samples": 4, "bsdf_samples": 1},
    "v4_6": {"type": "draaw_v4", "max_depth": 6, "adaptive": False},
    "v4_2": {"type": "draaw_v4", "max_depth": 2, "adaptive": False},
    # light tracing (paths from the lights, each vertex connected to the camera): the
    # strategies bidirectional path tracing would add to V4's
    "ptracer6": {"type": "ptracer", "max_depth": 6},
    "ptracer2": {"type": "ptracer", "max_depth": 2},
}


def variance_and_time(scene, integrator, renders: int = 8, spp: int = 16) -> tuple:
    """(mean per-pixel variance over ``renders`` renders of ``spp``, mean seconds per render)."""
    mi.render(scene, integrator=integrator, spp=spp, seed=99)          # compile first
    images, seconds = [], 0.0
    for k in range(renders):
        t = time.perf_counter()
        img = mi.render(scene, integrator=integrator, spp=spp, seed=100 + k)
        dr.eval(img)
        dr.sync_thread()
        seconds += time.perf_counter() - t
        images.append(np.array(img))
    return float(np.stack(images).var(axis=0, ddof=1).mean()), seconds / renders


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] not in suite.SCENES:
        print(f"usage: variance_parts.py SCENE [NAMES]; SCENE one of {', '.join(suite.SCENES)}", file=sys.stderr)
        return 2
    names = argv[1].split(",") if len(argv) > 1 else list(INTEGRATORS)
    unknown = [n for n in names if n not in INTEGRATORS]
    if unknown:
        print(f"variance_parts.py: unknown {', '.join(unknown)}; expected some of {', '.join(INTEGRATORS)}",
              file=sys.stderr)
        return 2
    scene = suite.load_built(suite.build(argv[0], 128, spp=16))
    print(f"| {argv[0]} | variance / pixel | ms / render | variance x time |\n|---|---|---|---|")
    for name in names:
        v, t = variance_and_time(scene, mi.load_dict(INTEGRATORS[name]))
        print(f"| {name} | {v:.3e} | {1000 * t:.0f} | {v * t:.3e} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
