"""Same expectation (V3, V4 vs Mitsuba's ``path``) and bias of V1/V2, per pixel.

For each scene of ``--scenes`` (files in ``scenes/``) at ``--res`` x ``--res``: ``--seeds`` independent renders of
``--spp`` spp per integrator (distinct seeds per integrator); per-pixel means and standard
errors; z = (mean_a - mean_b) / sqrt(se_a^2 + se_b^2) over all pixels and channels with
non-zero variance. For N(0, 1) z-scores: |z| > 3 for 0.27 %, |z| > 2 for 4.6 %, mean 0,
std 1. V1/V2: relative bias of the image mean and the mean absolute per-pixel bias against
the ``path`` mean.

Usage: ``.venv/bin/python benchmarks/integrators_expectation.py [--res 32 --spp 4096
--seeds 16 --scenes cornell,material_spheres] [--out FILE]`` (default ``benchmarks/results/integrators_expectation.md``).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

import draaw_mi
import drjit as dr
import mitsuba as mi

from draaw_mi.io import write_text

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KINDS = ("path", "draaw_v4", "draaw_v3", "draaw_v2", "draaw_v1")


def stack(scene, kind, spp, seeds, depth):
    integ = mi.load_dict({"type": kind, "max_depth": depth})
    return np.stack([np.array(mi.render(scene, integrator=integ, spp=spp, seed=s),
                              dtype=np.float64) for s in seeds])


def zsummary(a, b):
    k = len(a)
    se = np.sqrt(a.var(0, ddof=1) / k + b.var(0, ddof=1) / k)
    m = se > 1e-6
    z = (a.mean(0) - b.mean(0))[m] / se[m]
    return dict(n=int(z.size), gt3=float(np.mean(np.abs(z) > 3)),
                gt2=float(np.mean(np.abs(z) > 2)), mean=float(z.mean()), std=float(z.std()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--scenes", default="cornell,material_spheres",
                    help="comma-separated scene names in scenes/ (e.g. thesis)")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results",
                                                  "integrators_expectation.md"))
    args = ap.parse_args(argv)
    out = ["# Integrators: same expectation and bias (benchmarks/integrators_expectation.py)",
           "", f"Command: `.venv/bin/python benchmarks/integrators_expectation.py "
           f"{' '.join(sys.argv[1:])}`  ",
           f"{args.res}x{args.res}, box filter, {args.seeds} seeds x {args.spp} spp per "
           f"integrator (distinct seeds), Mitsuba {mi.__version__}, {mi.variant()}, "
           f"{time.strftime('%Y-%m-%d')}.", "",
           "Reference values for N(0, 1): |z|>3 0.27 %, |z|>2 4.55 %, mean 0, std 1.", ""]
    for name in args.scenes.split(","):
        sc = draaw_mi.load_scene(os.path.join(ROOT, "scenes", f"{name}.toml"),
                                 resolution=(args.res, args.res))
        depth = int(sc.settings.get("max_depth", 6))
        st = {k: stack(sc.mi_scene, k, args.spp, range(1000 * i, 1000 * i + args.seeds), depth)
              for i, k in enumerate(KINDS)}
        out += [f"## {name} (max_depth {depth})", "",
                "| pair | values | abs(z)>3 | abs(z)>2 | mean z | std z |", "|---|---|---|---|---|---|"]
        for a, b in (("path", "draaw_v4"), ("path", "draaw_v3"), ("draaw_v4", "draaw_v3")):
            s = zsummary(st[a], st[b])
            out.append(f"| {a} vs {b} | {s['n']} | {100 * s['gt3']:.2f} % | "
                       f"{100 * s['gt2']:.2f} % | {s['mean']:+.3f} | {s['std']:.3f} |")
        ref = st["path"].mean(0)
        out += ["", "| biased version | image-mean bias | mean abs pixel bias / mean | "
                "pixels with abs(z)>3 vs path |", "|---|---|---|---|"]
        for k in ("draaw_v2", "draaw_v1"):
            m = st[k].mean(0)
            s = zsummary(st["path"], st[k])
            out.append(f"| {k} | {100 * (m.mean() / ref.mean() - 1):+.2f} % | "
                       f"{100 * np.abs(m - ref).mean() / ref.mean():.1f} % | "
                       f"{100 * s['gt3']:.1f} % |")
        out.append("")
        del sc
        dr.flush_malloc_cache()
    text = "\n".join(out) + "\n"
    print(text)
    if args.out:
        write_text(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
