"""Guiding's constants swept on one speed-suite scene: V4 forced to guide (``guiding=on``,
adaptive sampling off), its MSE and time against ``path`` at 64 spp, with the guide's
training time (learned on a fresh cache; counted as the scene's first render would pay it).

Each configuration is ``NAME=VALUE[,NAME=VALUE...]`` over :mod:`draaw_mi.integrators.guiding`'s
module constants (``''``: the defaults). Usage::

    .venv/bin/python benchmarks/guiding_sweep.py doorway 128 "" "TRAIN_SHARE=4" \\
        "TRAIN_SHARE=4,RECORDS_PER_CELL=8000,UNIFORM_SHARE=0.05"

The reference is the speed suite's (cached in ``~/.cache/draaw-mi/speed_refs``; 1024 spp at
128^2, 256 spp otherwise). Results are printed; ``benchmarks/results/speed_suite.md`` records
what was concluded from them.
"""
import statistics
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

import draaw_mi  # noqa: F401  (variant + plugins)
from draaw_mi.bench import speed as sp
from draaw_mi.bench import suite as ss
from draaw_mi.integrators import guiding


def errors(scene, integ, ref, noise: float, repeats: int = 4) -> tuple[float, float]:
    """(MSE minus the reference's noise, median seconds) of ``repeats`` 64-spp renders."""
    errs, times = [], []
    for c in range(repeats):
        img, dt = sp.render(scene, integ, 64, 100 + 7 * c)
        errs.append(float(np.mean((img - ref) ** 2)))
        times.append(dt)
    return max(float(np.mean(errs)) - noise, 1e-30), statistics.median(times)


def configure(spec: str) -> dict:
    """Set the constants of ``spec``; returns their old values."""
    old = {}
    for kv in filter(None, spec.split(",")):
        name, value = kv.split("=")
        if not hasattr(guiding, name):
            raise SystemExit(f"guiding_sweep: no constant {name!r} in draaw_mi.integrators.guiding")
        old[name] = getattr(guiding, name)
        setattr(guiding, name, type(old[name])(float(value)))
    return old


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    name, res, specs = argv[0], int(argv[1]), argv[2:] or [""]
    d = ss.build(name, res)
    scene, depth = ss.load_built(d), ss.max_depth(name)
    ref, ref_var, _ = sp.reference(name, res, scene, depth, 1024 if res == 128 else 256, sp.CACHE, ss.digest(d))
    noise = float(ref_var.mean())
    path = mi.load_dict({"type": "path", "max_depth": depth})
    sp.render(scene, path, 64, 1)
    mse_path, t_path = errors(scene, path, ref, noise)
    print(f"[{res} {name}] path: mse {mse_path:.3e}, {t_path:.3f} s")
    for spec in specs:
        old = configure(spec)
        try:
            integ = mi.load_dict({"type": "draaw_v4", "max_depth": depth, "guiding": "on", "adaptive": False})
            integ.guides.for_render(integ, scene, scene.sensors()[0], 64)    # compiles
            integ.guides = type(integ.guides)("on")
            t = time.perf_counter()
            guide = integ.guides.for_render(integ, scene, scene.sensors()[0], 64)
            dr.sync_thread()
            learn = time.perf_counter() - t
            sp.render(scene, integ, 64, 1)
            mse, sec = errors(scene, integ, ref, noise)
        finally:
            for k, v in old.items():
                setattr(guiding, k, v)
        t_ratio = (sec + learn) / t_path
        print(f"  {spec or 'defaults'}: grid {guide.res if guide else None}^3, learn {learn:.2f} s, "
              f"mse {mse / mse_path:.3f}x, time {t_ratio:.2f}x, time to path's error {t_ratio * mse / mse_path:.3f}x",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
