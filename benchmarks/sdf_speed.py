"""SDF sphere tracing cost (issue 14).

1. The same scene with Mitsuba's analytic ``sphere`` and with an SDF sphere (same draaw
   material, mesh floor, point light + sky), ``draaw_v3`` and ``draaw_v4``: render time ratio
   (medians of interleaved A B A B ... repeats) and mean march steps per camera ray.
2. ``scenes/sdf_csg.toml``: plain vs over-relaxed (omega = 1.5) sphere tracing: march steps per
   camera ray and render time (interleaved).

Usage: .venv/bin/python benchmarks/sdf_speed.py [--repeats 7] [--out benchmarks/results/sdf_speed.md]
"""
from __future__ import annotations

import argparse
import copy
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import draaw_mi  # noqa: E402
import drjit as dr  # noqa: E402
from draaw_mi.bench.study import with_load_note  # noqa: E402
from draaw_mi.io import atomic_path  # noqa: E402
from draaw_mi.bench.sdf_study import camera_march  # noqa: E402


def twin(res=128):
    base = {
        "render": {"resolution": [res, res], "spp": 16, "max_depth": 4, "filter": "box"},
        "camera": {"origin": [0.0, 1.2, 5.0], "target": [0.0, 0.6, 0.0], "fov": 38},
        "materials": {"ball": {"base_color": [0.8, 0.3, 0.2], "roughness": 0.35, "metallic": 0.3},
                      "ground": {"base_color": [0.6, 0.6, 0.6], "roughness": 0.8}},
        "shapes": [{"type": "rectangle", "name": "floor", "material": "ground", "scale": 4.0,
                    "rotate": {"axis": [1, 0, 0], "angle": -90}}],
        "lights": [{"type": "point", "position": [2.0, 4.0, 3.0], "intensity": 40.0},
                   {"type": "constant", "intensity": 0.3}],
    }
    ball = {"type": "sphere", "name": "obj", "material": "ball", "center": [0.0, 0.8, 0.0], "radius": 0.8}
    a, b = copy.deepcopy(base), copy.deepcopy(base)
    a["shapes"].append(ball)
    b["sdf"] = [ball]
    return draaw_mi.load_scene(a), draaw_mi.load_scene(b)


def timed(scene, version, spp, seed, opts=None):
    t0 = time.perf_counter()
    img = draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[], integrator_options=opts)
    np.array(img)
    dr.sync_thread()
    return time.perf_counter() - t0


def interleaved(cases, repeats, spp):
    """cases: {name: (scene, version, opts)} -> {name: [times]} (one warm-up each)."""
    for sc, v, o in cases.values():
        timed(sc, v, spp, 0, o)
    out = {k: [] for k in cases}
    for r in range(repeats):
        for k, (sc, v, o) in cases.items():
            out[k].append(timed(sc, v, spp, 1 + r, o))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "sdf_speed_latest.md"))
    args = ap.parse_args(argv)
    dr.set_thread_count(2)
    lines = ["# SDF sphere tracing: cost", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
             f"{dr.thread_count()} Dr.Jit threads, Mitsuba {draaw_mi.__version__ and __import__('mitsuba').__version__}; "
             "LOAD_NOTE; ratios come from "
             f"one run with the cases interleaved (A B A B ...), medians of {args.repeats} repeats after a warm-up.",
             "", "Command: `.venv/bin/python benchmarks/sdf_speed.py`", ""]

    # ---- 1. analytic sphere vs SDF sphere
    ana, sdf = twin(128)
    hit, steps = camera_march(sdf, {"sdf_epsilon": 1e-5, "sdf_max_steps": 256, "sdf_relaxation": 1.0})
    cases = {}
    for v in ("v3", "v4"):
        cases[f"{v} analytic"] = (ana, v, None)
        cases[f"{v} sdf"] = (sdf, v, None)
    t = interleaved(cases, args.repeats, args.spp)
    med = {k: float(np.median(x)) for k, x in t.items()}
    lines += ["## Mitsuba's analytic sphere vs an SDF sphere (128x128, "
              f"{args.spp} spp, max_depth 4, point light + sky, mesh floor)", "",
              "| version | analytic sphere (s) | SDF sphere (s) | ratio |", "|---|---|---|---|"]
    for v in ("v3", "v4"):
        a, b = med[f"{v} analytic"], med[f"{v} sdf"]
        lines.append(f"| {v} | {a:.3f} | {b:.3f} | {b / a:.2f}x |")
    lines += ["", f"March steps per camera ray (pixel centres, depth-tested against the floor): "
              f"mean {steps.mean():.2f} over all rays ({(steps == 0).mean() * 100:.0f} % skip the march: "
              f"they miss the sphere's bounding box), {steps[hit].mean():.2f} over the "
              f"{hit.mean() * 100:.0f} % of rays that hit the sphere, "
              f"{steps[(~hit) & (steps > 0)].mean() if ((~hit) & (steps > 0)).any() else 0:.2f} over marched misses.", ""]

    # ---- 2. plain vs over-relaxed on the showcase
    csg = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "sdf_csg.toml"), resolution=(160, 90))
    rows = []
    cases = {}
    for relax in (1.0, 1.5):
        o = {"sdf_epsilon": 1e-5, "sdf_max_steps": 256, "sdf_relaxation": relax}
        h, s = camera_march(csg, o)
        rows.append((relax, h, s))
        cases[f"relax {relax:g}"] = (csg, "v4", o)
    t = interleaved(cases, args.repeats, args.spp)
    lines += [f"## Plain vs over-relaxed sphere tracing (scenes/sdf_csg.toml, 160x90, {args.spp} spp, v4)", "",
              "| relaxation | render time (s) | mean steps / camera ray | mean steps / hitting ray | hits |",
              "|---|---|---|---|---|"]
    for relax, h, s in rows:
        lines.append(f"| {relax:g} | {np.median(t[f'relax {relax:g}']):.3f} | {s.mean():.2f} | "
                     f"{s[h].mean():.2f} | {h.sum()} |")
    lines.append("")
    text = with_load_note("\n".join(lines) + "\n")      # the load measured at the end
    with atomic_path(args.out, ".tmp") as tmp:
        with open(tmp, "w") as f:
            f.write(text)
    print(text)


if __name__ == "__main__":
    main()
