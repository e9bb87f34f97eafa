"""Participating media: what the local majorant grid buys (draaw_v4) against Mitsuba's
``volpath`` (one global majorant, plain delta tracking).

Cases (48x48 images unless ``--res``, a point light + constant sky + diffuse floor, the
smoke in a null-BSDF cube, HG g = 0.3, albedo 0.8):

1. **one dense voxel**: a 64^3 grid, empty except one voxel of density 1e4, against the
   same grid entirely empty: time ratio (draaw_v4 and volpath, same spp);
2. **sparse blobs**: a 64^3 grid with three small blobs of density 200 in empty space: time
   to equal error of draaw_v4 vs volpath (MSE x time products against a high-spp reference,
   MSE ~ 1/spp);
3. **uniform dense grid**: 64^3, density 20 everywhere: the same equal-error comparison;
4. ``scenes/smoke.toml`` (plume + solid voxels): the same comparison (and V3).

Times: ``dr.eval(img); dr.sync_thread()``, after a warm-up render, integrators interleaved
(A B A B ...), median of ``--repeats``. The machine may be shared: ratios within one run.

Usage::

    .venv/bin/python benchmarks/media_speed.py            # writes benchmarks/results/media_speed.md
    .venv/bin/python benchmarks/media_speed.py --quick
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import numpy as np

import draaw_mi
import drjit as dr
import mitsuba as mi

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests", "media"))
import media_scenes as ms  # noqa: E402

from draaw_mi.bench.study import with_load_note  # noqa: E402
from draaw_mi.media import VoxelGrid  # noqa: E402
from draaw_mi.media.mitsuba_dicts import smoke_shape  # noqa: E402


def grid_scene(kind: str, integrator: str, res: int, max_depth: int = 8) -> mi.Scene:
    g = VoxelGrid.empty((64, 64, 64), (-1, -1, -1), (1, 1, 1))
    g.smoke_color[:] = 0.8
    if kind == "one_voxel":
        g.density[40, 30, 20] = 1e4
    elif kind == "blobs":
        c = g.centers()
        for p in ((-0.4, -0.2, 0.1), (0.3, 0.3, -0.2), (0.1, -0.5, 0.4)):
            g.density[np.linalg.norm(c - np.array(p), axis=-1) < 0.15] = 200.0
    elif kind == "uniform":
        g.density[:] = 20.0
    d = ms.base({"type": integrator, "max_depth": max_depth}, res)
    if kind == "empty":
        g.density[0, 0, 0] = 0.0
    d["smoke"] = smoke_shape(g, g_phase=0.3, filter_type="nearest")
    return mi.load_dict(d)


def smoke_toml_scene(integrator: str, res: int) -> mi.Scene:
    s = draaw_mi.load_scene(os.path.join(HERE, "..", "scenes", "smoke.toml"), resolution=(res, res))
    d = dict(s.mi_dict)
    d["integrator"] = {"type": integrator, "max_depth": 8}
    return mi.load_dict(d)


def timed(scene, spp, seed=0):
    t = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return time.perf_counter() - t, np.array(img, dtype=np.float64)


def time_pair(scenes: dict, spp: int, repeats: int) -> dict:
    for sc in scenes.values():
        timed(sc, spp)                               # warm-up (compile)
    times = {k: [] for k in scenes}
    for r in range(repeats):
        for k, sc in scenes.items():                 # interleaved
            times[k].append(timed(sc, spp, seed=r)[0])
    return {k: statistics.median(v) for k, v in times.items()}


def reference(make, res, spp_total, chunk=256):
    sc = make("volpath")
    acc = None
    n = max(1, spp_total // chunk)
    for i in range(n):
        img = np.array(mi.render(sc, spp=chunk, seed=10_000 + i), dtype=np.float64)
        acc = img if acc is None else acc + img
    return acc / n


def equal_error(make, res, spp, repeats, ref_spp, integrators=("volpath", "draaw_v4")) -> list[dict]:
    ref = reference(make, res, ref_spp)
    scenes = {k: make(k) for k in integrators}
    for sc in scenes.values():
        timed(sc, spp)
    rows = {k: {"t": [], "mse": []} for k in integrators}
    for r in range(repeats):
        for k, sc in scenes.items():
            t, img = timed(sc, spp, seed=100 + r)
            rows[k]["t"].append(t)
            rows[k]["mse"].append(float(np.mean((img - ref) ** 2)))
    out = []
    base = None
    for k in integrators:
        t = statistics.median(rows[k]["t"])
        mse = float(np.mean(rows[k]["mse"]))
        work = t * mse                                 # time to a fixed MSE ∝ t * MSE
        if base is None:
            base = work
        out.append({"integrator": k, "time_s": t, "mse": mse, "time_x_mse": work, "speedup": base / work})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "media_speed_latest.md"))
    a = ap.parse_args(argv)
    if a.quick:
        a.res, a.spp, a.repeats, a.ref_spp = 32, 16, 3, 1024
    lines = ["# Participating media: local majorant grid (draaw_v4) vs Mitsuba volpath", "",
             f"`python benchmarks/media_speed.py{' --quick' if a.quick else ''}` — {a.res}x{a.res}, "
             f"{a.spp} spp, median of {a.repeats} interleaved repeats after a warm-up; reference "
             f"{a.ref_spp} spp of volpath. Machine: {platform.machine()}, {os.cpu_count()} cores, "
             f"{dr.thread_count()} Dr.Jit threads, LOAD_NOTE (ratios are taken within "
             "one run).", ""]

    # 1. one dense voxel vs empty
    lines += ["## 1. One dense voxel (density 1e4) in an empty 64³ grid vs the empty grid", "",
              "| integrator | empty grid [s] | one dense voxel [s] | ratio |", "|---|---:|---:|---:|"]
    for integ in ("draaw_v4", "volpath"):
        sc = {"empty": grid_scene("empty", integ, a.res), "one": grid_scene("one_voxel", integ, a.res)}
        reps = a.repeats if integ == "draaw_v4" else max(1, min(a.repeats, 2))
        spp = a.spp if integ == "draaw_v4" else max(1, a.spp // 8)
        t = time_pair(sc, spp, reps)
        scale = a.spp / spp
        lines.append(f"| {integ} ({spp} spp{', times x' + str(int(scale)) if scale != 1 else ''}) | "
                     f"{t['empty'] * scale:.3f} | {t['one'] * scale:.3f} | {t['one'] / t['empty']:.2f} |")
        print(lines[-1], flush=True)
    lines.append("")

    # 2-4. equal error
    cases = [("sparse blobs (64³, three blobs of density 200)", lambda k: grid_scene("blobs", k, a.res)),
             ("uniform dense grid (64³, density 20)", lambda k: grid_scene("uniform", k, a.res)),
             ("scenes/smoke.toml", lambda k: smoke_toml_scene(k, a.res))]
    for title, make in cases:
        integs = ("volpath", "draaw_v4", "draaw_v3") if "smoke" in title else ("volpath", "draaw_v4")
        rows = equal_error(make, a.res, a.spp, a.repeats, a.ref_spp, integs)
        lines += [f"## Equal error: {title}", "",
                  "| integrator | time [s] | MSE | time x MSE | speed-up at equal error vs volpath |",
                  "|---|---:|---:|---:|---:|"]
        for r in rows:
            lines.append(f"| {r['integrator']} | {r['time_s']:.3f} | {r['mse']:.3e} | {r['time_x_mse']:.3e} | "
                         f"{r['speedup']:.2f}x |")
            print(lines[-1], flush=True)
        lines.append("")
    lines += ["Time to a given error ∝ time x MSE (Monte Carlo MSE ∝ 1/spp); MSE includes the reference's own "
              "noise (small at the reference spp)."]
    text = with_load_note("\n".join(lines) + "\n")      # the load measured at the end
    from draaw_mi.io import write_text
    write_text(a.out, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
