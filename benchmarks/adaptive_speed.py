"""Adaptive subsampling (block 8) vs full sampling, both at 1 spp: speed-up and error.

Interleaved timings (median of repeats after a warm-up; every call ends with dr.eval +
dr.sync_thread via np.array), on the sample scenes at 256x256 and 1024x1024. Error against a
`path` ground truth is measured at 256x256 (RMSE and CIEDE2000 of both images).

    .venv/bin/python benchmarks/adaptive_speed.py [--repeats 7] [--out benchmarks/results/adaptive_speed.md]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import draaw_mi
from draaw_mi.bench.metrics import errors
from draaw_mi.io import write_text

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ["cornell", "material_spheres", "thesis"]


def timed(fn):
    t0 = time.perf_counter()
    out = np.array(fn())
    return out, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--version", default="v4")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "adaptive_speed.md"))
    args = ap.parse_args()
    rows = []
    for name in SCENES:
        for res in ((256, 256), (1024, 1024)):
            scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", f"{name}.toml"), resolution=res)
            full = lambda s: draaw_mi.render(scene, version=args.version, spp=1, seed=s, post=[])
            adap = lambda s: draaw_mi.render(scene, version=args.version, spp=1, seed=s, post=[], adaptive=8)
            timed(lambda: full(0))
            timed(lambda: adap(0))                     # warm-up: compile both
            tf, ta = [], []
            for r in range(args.repeats):
                img_f, t = timed(lambda: full(r + 1))
                tf.append(t)
                img_a, t = timed(lambda: adap(r + 1))
                ta.append(t)
            _, info = draaw_mi.render(scene, version=args.version, spp=1, adaptive=8, return_info=True, post=[])
            row = {"scene": name, "res": f"{res[0]}x{res[1]}", "full_ms": 1e3 * np.median(tf),
                   "adaptive_ms": 1e3 * np.median(ta), "ratios": np.median(np.array(tf) / np.array(ta)),
                   "traced": info["adaptive"]["traced_fraction"]}
            if res == (256, 256):
                gt = np.array(draaw_mi.render(scene, version="path", spp=1024, seed=99, post=[]))
                ef, ea = errors(img_f, gt), errors(img_a, gt)
                row.update({"rmse_full": ef["rmse"], "rmse_adaptive": ea["rmse"], "de_full": ef["ciede2000"],
                            "de_adaptive": ea["ciede2000"]})
            rows.append(row)
            print(row, flush=True)
    lines = ["# Adaptive subsampling (block 8) vs full sampling, 1 spp", "",
             f"Command: `.venv/bin/python benchmarks/adaptive_speed.py --repeats {args.repeats}`  ",
             f"Version {args.version}; medians of {args.repeats} interleaved repeats after a warm-up; "
             f"speed-up = median of per-repeat ratios. Machine: {platform.machine()}, {os.cpu_count()} cores, "
             f"load average at the end {os.getloadavg()[0]:.1f}. Error vs `path` at 1024 spp (256x256 only).", "",
             "| scene | resolution | full (ms) | adaptive (ms) | speed-up | traced pixels | RMSE full | RMSE adaptive | ΔE00 full | ΔE00 adaptive |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        err = (f"{r['rmse_full']:.4f} | {r['rmse_adaptive']:.4f} | {r['de_full']:.2f} | {r['de_adaptive']:.2f}"
               if "rmse_full" in r else "– | – | – | –")
        lines.append(f"| {r['scene']} | {r['res']} | {r['full_ms']:.1f} | {r['adaptive_ms']:.1f} | "
                     f"{r['ratios']:.2f}× | {100 * r['traced']:.1f} % | {err} |")
    lines += ["", "At 256x256 one 1-spp frame costs tens of milliseconds and adaptive's fixed costs "
              "(a Python trace of the integrator and of the signature kernel per level, numpy bookkeeping) "
              "are of the same size, so it gains little; at 1024x1024 the traced fraction decides."]
    write_text(args.out, "\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
