"""Time outside kernels for small repeated renders (``draaw_mi.render``, frozen vs traced).

For each version, renders the Cornell box (``scenes/cornell.toml``) at ``--res``² and
``--spp`` spp ``--repeats`` times with new seeds (after warm-up calls), with
``draaw_mi.render.FREEZE`` on and off, interleaved. Per call: wall time (``draaw_mi.render``
returns an evaluated image) and the summed execution time of the kernels it launched
(``dr.kernel_history``); the difference is time spent outside kernels (Python tracing, kernel
look-up, launches, copies). Reports medians.

Usage::

    .venv/bin/python benchmarks/render_overhead.py            # 64x64, 4 spp, V1..V4 and path
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import draaw_mi
import drjit as dr
import mitsuba as mi

import importlib
R = importlib.import_module("draaw_mi.render")    # the module (draaw_mi.render is the function)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def one(scene, version, spp, seed):
    dr.kernel_history_clear()
    t = time.perf_counter()
    img = draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[])
    dr.eval(img)
    dr.sync_thread()
    wall = time.perf_counter() - t
    kern = sum(k.get("execution_time", 0.0) for k in dr.kernel_history()
               if k["type"] == dr.KernelType.JIT) / 1000.0
    return wall, kern


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--versions", default="v1,v2,v3,v4,path")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "render_overhead.md"))
    args = ap.parse_args(argv)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "cornell.toml"),
                                resolution=(args.res, args.res))
    versions = args.versions.split(",")
    data = {(v, f): [] for v in versions for f in (True, False)}
    for v in versions:
        for f in (True, False):
            R.FREEZE = f
            for s in range(3):
                one(scene, v, args.spp, 1000 + s)          # compile / record
    for i in range(args.repeats):
        for v in versions:
            for f in (True, False):
                R.FREEZE = f
                data[(v, f)].append(one(scene, v, args.spp, 7 + i))
    R.FREEZE = True
    out = ["# Time outside kernels, small repeated renders (benchmarks/render_overhead.py)", "",
           f"Command: `.venv/bin/python benchmarks/render_overhead.py {' '.join(sys.argv[1:])}`  ",
           f"Machine: {platform.machine()}, {os.cpu_count()} cores (shared with other jobs), Dr.Jit "
           f"threads {dr.thread_count()}; {time.strftime('%Y-%m-%d %H:%M')}  ",
           f"`draaw_mi.render(scenes/cornell.toml, {args.res}x{args.res}, spp={args.spp}, new seed "
           f"each call)`, medians of {args.repeats} interleaved calls after warm-up. *outside* = "
           "wall - summed kernel execution time (`dr.kernel_history`).", "",
           "| version | frozen: wall ms | kernels ms | outside | traced: wall ms | kernels ms | outside |",
           "|---|---|---|---|---|---|---|"]
    for v in versions:
        cells = []
        for f in (True, False):
            walls = [w for w, _ in data[(v, f)]]
            kerns = [k for _, k in data[(v, f)]]
            frac = statistics.median((w - k) / w for w, k in data[(v, f)])
            cells.append(f"{1e3 * statistics.median(walls):.1f} | {1e3 * statistics.median(kerns):.1f} | "
                         f"{100 * frac:.1f} %")
        out.append(f"| {v} | " + " | ".join(cells) + " |")
    text = "\n".join(out) + "\n"
    print(text)
    if args.out:
        from draaw_mi.io import atomic_path
        with atomic_path(args.out, ".md") as tmp, open(tmp, "w") as fh:
            fh.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
