"""Resident memory that learning a guide takes (issue 45: under 64 MiB at 256x256): the
speed suite's glossy panel, its training pass sized as ``draaw_v4`` sizes it for a 64-spp
render, with and without the light paths (``guiding.LIGHT_PER_CAMERA``). Linux only (reads
``/proc/self/status`` and resets the high-water mark through ``/proc/self/clear_refs``).

Run from the repository root, one process per measurement::

    .venv/bin/python benchmarks/guide_memory.py 256 light
    .venv/bin/python benchmarks/guide_memory.py 256 camera
"""
from __future__ import annotations

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import draaw_mi  # noqa: E402,F401  (variant, plugins)
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
from draaw_mi.bench import suite  # noqa: E402
from draaw_mi.integrators import guiding  # noqa: E402


def status_mib(field: str) -> float:
    """``field`` (``VmHWM``, ``VmRSS``) of ``/proc/self/status`` in MiB."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"guide_memory: no {field} in /proc/self/status")


def main(argv: list[str]) -> int:
    if len(argv) != 2 or argv[1] not in ("light", "camera"):
        print(__doc__, file=sys.stderr)
        return 2
    res = int(argv[0])
    if argv[1] == "camera":
        guiding.LIGHT_PER_CAMERA = 1e-9          # one light path: the camera paths' memory
    scene = suite.load("glossy_diffuse", res)
    plain = mi.load_dict({"type": "draaw_v4", "max_depth": 6, "guiding": "off"})
    dr.eval(mi.render(scene, integrator=plain, spp=64, seed=1))     # kernels, film, scene
    dr.flush_malloc_cache()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")                              # the high-water mark := resident now
    base = status_mib("VmRSS")
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 6, "guiding": "on"})
    paths = int(np.clip(64 * res * res // guiding.TRAIN_SHARE, guiding.MIN_TRAIN_PATHS, guiding.TRAIN_PATHS))
    guide = guiding.learn_guide(integ, scene, paths)
    peak = status_mib("VmHWM") - base
    held = 2 * 4 * dr.width(guide.prob) / 2 ** 20
    print(f"glossy_diffuse {res}x{res}, {argv[1]} ({paths} camera paths, "
          f"{int(paths * guiding.LIGHT_PER_CAMERA)} light paths): peak while learning "
          f"+{peak:.0f} MiB over {base:.0f} MiB resident; the guide {guide.res}^3 cells, {held:.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
