"""What one iteration of a texture-map fit costs, its gradient passes traced or replayed.

The SVBRDF benchmark's problem (``svbrdf_fit.py``: a tile or sphere with 64x64 maps of base
colour, roughness and metallic, 8 captures under ``sweep`` + softboxes, 2 captures an
iteration, pyramid maps) fitted for ``--short`` and ``--long`` iterations; the difference of the
two fit() times over the difference of iterations is the cost of one iteration, without the
set-up, the first passes' tracing and recording, and the report. Per mode:
``traced`` (every gradient pass traced, ``draaw_mi.rendering.session.FREEZE = False``) and
``frozen`` (the default: each capture's pass replays a ``dr.freeze`` recording), interleaved,
``--repeats`` times; plus the kernels' share of the iteration (``dr.kernel_history``'s
execution times over the long fit's iterations).

Usage (repository root)::

    .venv/bin/python benchmarks/fit_iteration_cost.py --out benchmarks/results/fit_iteration_cost.md
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
import svbrdf_fit as sv  # noqa: E402

import draaw_mi  # noqa: E402
from draaw_mi.rendering import session as S  # noqa: E402

MODES = ("traced", "frozen")


def problem(obj: str, n: int, res: int, k: int, env: str, ref_spp: int):
    """``(references, captures, a function making the start scene)``."""
    caps = sv.captures(obj, k, "sweep")
    truth = draaw_mi.load_scene(sv.scene_description(obj, sv.truth_maps(n), env, res, k, "sweep", "softbox"))
    refs = sv.render_captures(truth, caps, ref_spp, 1000)
    half = np.full((n, n, 1), 0.5, np.float32)
    start = (np.full((n, n, 3), 0.5, np.float32), half, half)
    return refs, caps, lambda: draaw_mi.load_scene(sv.scene_description(obj, start, env, res, k, "sweep", "softbox"))


def fit_seconds(make, refs, caps, iterations: int, spp: int, mode: str) -> tuple:
    """``(seconds of fit(), kernel execution seconds)`` of a fit of ``iterations``."""
    S.FREEZE = mode == "frozen"
    history = dr.flag(dr.JitFlag.KernelHistory)
    kernels = []
    real = dr.kernel_history

    def collect(*a, **kw):                  # fit() reads (and so clears) the history each iteration
        out = real(*a, **kw)
        kernels.extend(out)
        return out
    dr.kernel_history = collect
    try:
        scene = make()
        t = time.perf_counter()
        draaw_mi.fit(scene, refs, sv.PARAMS, captures=caps, spp=spp, iterations=iterations, batch=2,
                     progress=False)
        seconds = time.perf_counter() - t
    finally:
        dr.kernel_history = real
        dr.set_flag(dr.JitFlag.KernelHistory, history)
        S.FREEZE = True
    execution = sum(e.get("execution_time", 0.0) for e in kernels if e["type"] == dr.KernelType.JIT) / 1000
    return seconds, execution


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", nargs="+", default=["tile", "sphere"])
    ap.add_argument("--spp", nargs="+", type=int, default=[4, 16])
    ap.add_argument("--image", type=int, default=128)
    ap.add_argument("--textures", type=int, default=64)
    ap.add_argument("--short", type=int, default=10)
    ap.add_argument("--long", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    if not 0 < args.short < args.long:
        ap.error(f"--short {args.short} --long {args.long}: expected 0 < short < long")
    if args.repeats < 1:
        ap.error(f"--repeats {args.repeats}: expected at least 1")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        env = sv.environment(os.path.join(tmp, "env.exr"))
        for obj in args.objects:
            refs, caps, make = problem(obj, args.textures, args.image, 8, env, 256)
            for spp in args.spp:
                per = {m: [] for m in args.modes}
                share = {m: [] for m in args.modes}
                for mode in args.modes:                           # warm-up: compile the kernels
                    fit_seconds(make, refs, caps, args.short, spp, mode)
                for _ in range(args.repeats):
                    for mode in args.modes:                       # interleaved
                        short, _ = fit_seconds(make, refs, caps, args.short, spp, mode)
                        long, execution = fit_seconds(make, refs, caps, args.long, spp, mode)
                        per[mode].append((long - short) / (args.long - args.short))
                        share[mode].append(execution / args.long / per[mode][-1])
                row = {"object": obj, "spp": spp, **{m: statistics.median(per[m]) for m in args.modes},
                       **{m + "_all": per[m] for m in args.modes},
                       **{m + "_kernels": statistics.median(share[m]) for m in args.modes}}
                rows.append(row)
                print(row, flush=True)
    lines = ["| object | spp | " + " | ".join(f"{m} (s / iteration)" for m in args.modes)
             + (" | frozen / traced" if len(args.modes) == 2 else "")
             + " | " + " | ".join(f"kernels' share, {m}" for m in args.modes) + " |",
             "|---|---|" + "---|" * (2 * len(args.modes) + (len(args.modes) == 2))]
    for r in rows:
        cells = [f"{r[m]:.3f} ({', '.join(f'{x:.3f}' for x in r[m + '_all'])})" for m in args.modes]
        ratio = [f"{r['frozen'] / r['traced']:.2f}"] if len(args.modes) == 2 else []
        lines.append(f"| {r['object']} | {r['spp']} | " + " | ".join(cells + ratio + [
            f"{r[m + '_kernels']:.0%}" for m in args.modes]) + " |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(f"Command: `.venv/bin/python benchmarks/fit_iteration_cost.py {' '.join(argv or sys.argv[1:])}`\n\n"
                    f"Recorded {time.strftime('%Y-%m-%d %H:%M')}, {os.cpu_count()} CPUs, `{mi.variant()}`; "
                    f"{args.image}x{args.image} images, {args.textures}x{args.textures} maps, 8 captures, batch 2, "
                    f"iterations {args.long} minus {args.short}, medians of {args.repeats} (each run in brackets).\n\n"
                    + text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
