"""Variance x time against a baseline, without a reference image.

Both estimators compared here are unbiased (tests/integrators check V4 against ``path`` per
pixel), so the per-pixel variance over N independent renders is their MSE; no reference, whose
own noise would have to be subtracted, is needed. This is the robust way to compare on scenes
whose error sits in a few pixels (the glass scene's glints), where the speed suite's
reference-based MSE swings from run to run.

Usage::

    .venv/bin/python benchmarks/variance_study.py glass 256 16 "path;draaw_v4;draaw_v4:adaptive=false" [spp]

A spec may end in ``@SAMPLER`` (``path@sobol``, ``draaw_v4@orthogonal``): that integrator renders
the scene with that Mitsuba sampler (default ``independent``), for low-discrepancy comparisons;
the baseline keeps its own.

Prints, per integrator spec (the first is the baseline): median time, mean per-pixel variance
(and from each half of the renders, to show its spread), image mean, and
``t*var/path`` = time ratio x variance ratio (below 1: faster than the baseline to equal error).
Environment: ``MINF``, ``CAP``, ``CF`` override ``draaw_mi.integrators.adaptive_sampling``'s MIN_FRACTION,
SCORE_CAP and COST_FIXED (for tuning runs).
"""
import os
import sys
import time

import numpy as np

import drjit as dr
import mitsuba as mi

import draaw_mi.integrators.adaptive_sampling as ads
from draaw_mi.bench import suite as ss
from draaw_mi.bench.speed import parse_integrator


def main(argv) -> int:
    if len(argv) < 4:
        print(__doc__)
        return 2
    name, res, n, specs = argv[0], int(argv[1]), int(argv[2]), argv[3].split(";")
    spp = int(argv[4]) if len(argv) > 4 else 64
    for env, attr in (("MINF", "MIN_FRACTION"), ("CAP", "SCORE_CAP"), ("CF", "COST_FIXED")):
        if os.environ.get(env):
            setattr(ads, attr, float(os.environ[env]))
    depth = ss.max_depth(name)
    samplers = [s.partition("@")[2] or "independent" for s in specs]
    scenes = {smp: ss.load(name, res, smp) for smp in set(samplers)}
    integs = [mi.load_dict(parse_integrator(s.partition("@")[0], depth)) for s in specs]
    imgs = {s: [] for s in specs}
    times = {s: [] for s in specs}
    for it, smp in zip(integs, samplers):                 # compile
        dr.eval(mi.render(scenes[smp], integrator=it, spp=spp, seed=999))
        dr.sync_thread()
    for k in range(n):                                    # interleaved
        for s, it, smp in zip(specs, integs, samplers):
            t0 = time.perf_counter()
            img = mi.render(scenes[smp], integrator=it, spp=spp, seed=1000 * k + 7)
            dr.eval(img)
            dr.sync_thread()
            times[s].append(time.perf_counter() - t0)
            imgs[s].append(np.array(img)[..., :3])
    vb = np.var(np.stack(imgs[specs[0]]), axis=0, ddof=1).mean()
    tb = np.median(times[specs[0]])
    for s in specs:
        a = np.stack(imgs[s])
        v, t = np.var(a, axis=0, ddof=1).mean(), np.median(times[s])
        h1 = np.var(a[: n // 2], axis=0, ddof=1).mean()
        h2 = np.var(a[n // 2:], axis=0, ddof=1).mean()
        print(f"{s:40s} t={t:.3f}s var={v:.3e} (halves {h1:.2e},{h2:.2e}) mean={a.mean():.4f}  "
              f"t*var/path={t * v / (tb * vb):.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
