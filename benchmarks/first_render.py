"""A scene's first V4 render against its later ones, both against ``path`` at 64 spp: what a
``draaw-mi render`` user (one render per process) gets, where the speed suite times later
renders (``benchmarks/speed_suite.py``). Each first render is a fresh ``draaw_v4``, whose
adaptive pilot decides on guiding (from 2^20 samples); later renders reuse one integrator.

Usage (the speed suite's scenes and cached references)::

    .venv/bin/python benchmarks/first_render.py cornell,constant_env,spheres,mitsuba_cbox

Prints, per scene, the MSE and time ratios to ``path`` of first and later renders (median
time, mean MSE over ``--repeats`` interleaved cycles, the reference's noise subtracted);
``benchmarks/results/speed_suite.md`` records what was concluded.
"""
import argparse
import statistics

import mitsuba as mi
import numpy as np

import draaw_mi  # noqa: F401  (variant + plugins)
from draaw_mi.bench import speed as sp
from draaw_mi.bench import suite as ss


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", help="comma-separated speed-suite scenes")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=6)
    args = ap.parse_args()
    for name in args.scenes.split(","):
        d = ss.build(name, args.res)
        scene, depth = ss.load_built(d), ss.max_depth(name)
        ref, ref_var, _ = sp.reference(name, args.res, scene, depth, 1024 if args.res == 128 else 256,
                                       sp.CACHE, ss.digest(d))
        noise = float(ref_var.mean())
        path = mi.load_dict({"type": "path", "max_depth": depth})
        later = mi.load_dict({"type": "draaw_v4", "max_depth": depth})
        sp.render(scene, path, 64, 0)
        sp.render(scene, later, 64, 0)                       # decides, compiles
        err = {"path": [], "first": [], "later": []}
        sec = {k: [] for k in err}
        for c in range(args.repeats):
            for kind in err:
                integ = {"path": path, "later": later}.get(kind) or \
                    mi.load_dict({"type": "draaw_v4", "max_depth": depth})
                img, dt = sp.render(scene, integ, 64, 100 + 7 * c)
                err[kind].append(float(np.mean((img - ref) ** 2)))
                sec[kind].append(dt)
        mse_path, t_path = np.mean(err["path"]) - noise, statistics.median(sec["path"])
        cells = []
        for kind in ("first", "later"):
            m = (np.mean(err[kind]) - noise) / mse_path
            t = statistics.median(sec[kind]) / t_path
            cells.append(f"{kind}: {t * m:.2f} (t {t:.2f}, mse {m:.2f})")
        print(f"[{args.res} {name}] " + "  ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
