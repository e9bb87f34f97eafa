"""GO-Draaw's benchmark, kept: frame-time statistics per version along its camera path.

Set-up as GO-Draaw's `Benchmark` build (go-draaw-spec.md §7.1): monkey.obj scaled ×75, a light
at (0, 1500, 1000), FOV 45°, 400×304, depth 3, the three hard-coded keyframes interpolated
over 10 s at 60 fps with GO-Draaw's own easing (600 frames). Per version: mean, std, min, p10,
median, p90, max frame time and the error against a `path` ground truth on a few frames.
GO-Draaw's point light has no distance fall-off; Mitsuba's does, so the intensity is scaled
to light the monkey at its distance (~1800 units).

    .venv/bin/python benchmarks/go_draaw_frame_times.py [--frames 600] [--spp 1]
"""
from __future__ import annotations

import argparse
import os
import platform

import draaw_mi
from draaw_mi.bench import frame_times
from draaw_mi.scene.camera_path import GO_DRAAW_BENCHMARK_PATH
from draaw_mi.io import write_text

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "go-draaw"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "go_draaw_frame_times_latest.md"))
    args = ap.parse_args()
    if not os.path.isdir(DATA):
        raise SystemExit(f"GO-Draaw data not found at {DATA}")
    k0 = GO_DRAAW_BENCHMARK_PATH[0]
    scene = draaw_mi.load_scene({
        "render": {"resolution": [400, 304], "max_depth": 3, "spp": args.spp},
        "camera": {"position": list(k0[:3]), "angles": list(k0[3:]), "fov": 45},
        "shapes": [{"type": "mesh", "file": os.path.join(DATA, "monkey.obj"), "scale": 75}],
        "lights": [{"type": "point", "position": [0, 1500, 1000], "intensity": 2 * 1800.0 ** 2}],
    })
    rows = frame_times(scene, GO_DRAAW_BENCHMARK_PATH, versions=("v1", "v2", "v3", "v4", "path"),
                       frames=args.frames, spp=args.spp, faithful=True, error_frames=4, gt_spp=1024)
    lines = ["# GO-Draaw's benchmark path: frame times per version", "",
             f"Command: `.venv/bin/python benchmarks/go_draaw_frame_times.py --frames {args.frames} --spp {args.spp}`  ",
             f"monkey.obj ×75, 400×304, depth 3, {args.spp} spp, {args.frames} frames along GO-Draaw's keyframes "
             f"(faithful easing); machine {platform.machine()}, {os.cpu_count()} cores. Times in ms; error vs "
             "`path` at 1024 spp on 4 evenly spaced frames.", "",
             "| version | mean | std | min | p10 | median | p90 | max | RMSE | ΔE00 |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['version']} | {1e3 * r['mean_s']:.1f} | {1e3 * r['std_s']:.1f} | {1e3 * r['min_s']:.1f} | "
                     f"{1e3 * r['p10_s']:.1f} | {1e3 * r['median_s']:.1f} | {1e3 * r['p90_s']:.1f} | "
                     f"{1e3 * r['max_s']:.1f} | {r.get('rmse', float('nan')):.4f} | {r.get('ciede2000', float('nan')):.2f} |")
    write_text(args.out, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
