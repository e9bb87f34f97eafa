"""Peak resident memory of a CLI render, V4 against ``path`` (issue 45's memory point).

Each render is a fresh ``draaw-mi render`` process under ``/usr/bin/time -v`` (its "Maximum
resident set size"), integrators alternating, ``--repeats`` times each; the report gives the
median peak per integrator and V4's ratio to ``path``. Usage::

    .venv/bin/python benchmarks/render_memory.py                       # 1024^2, 256 spp, Cornell
    .venv/bin/python benchmarks/render_memory.py --res 512 --spp 64 --out ''

Writes ``benchmarks/results/render_memory.md`` unless ``--out`` says otherwise (``''``:
printed only).
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLI = os.path.join(os.path.dirname(sys.executable), "draaw-mi")


def peak_mib(version: str, scene: str, res: int, spp: int, folder: str) -> tuple[float, float]:
    """``(peak resident MiB, wall seconds)`` of one ``draaw-mi render`` process."""
    out = os.path.join(folder, f"{version}.exr")
    cmd = ["/usr/bin/time", "-v", CLI, "render", scene, "-o", out, "--version", version,
           "--spp", str(spp), "--resolution", f"{res}x{res}", "--no-progress"]
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"render_memory: {' '.join(cmd[2:])} failed:\n{proc.stderr[-2000:]}")
    kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr).group(1))
    return kb / 1024.0, wall


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="scenes/cornell.toml")
    ap.add_argument("--res", type=int, default=1024)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "render_memory_latest.md"))
    args = ap.parse_args(argv)
    peaks = {"path": [], "v4": []}
    walls = {"path": [], "v4": []}
    with tempfile.TemporaryDirectory() as folder:
        for r in range(args.repeats):
            for v in ("path", "v4"):
                mib, wall = peak_mib(v, args.scene, args.res, args.spp, folder)
                peaks[v].append(mib)
                walls[v].append(wall)
                print(f"[{r}] {v}: {mib:.0f} MiB, {wall:.1f} s", file=sys.stderr, flush=True)
    med = {v: statistics.median(p) for v, p in peaks.items()}
    lines = ["# Peak resident memory of `draaw-mi render` (benchmarks/render_memory.py)", "",
             f"{time.strftime('%Y-%m-%d %H:%M')}: `{args.scene}` at {args.res}x{args.res}, {args.spp} spp, "
             f"{args.repeats} processes per integrator (alternating), `/usr/bin/time -v`.", "",
             "| integrator | peak MiB (median) | each run | wall s (median) |", "|---|---|---|---|"]
    for v in ("path", "v4"):
        lines.append(f"| {v} | {med[v]:.0f} | {', '.join(f'{p:.0f}' for p in peaks[v])} | "
                     f"{statistics.median(walls[v]):.1f} |")
    lines += ["", f"V4 / path: **{med['v4'] / med['path']:.2f}x** (issue 45's limit: 1.25x)."]
    report = "\n".join(lines) + "\n"
    print(report)
    if args.out:
        with open(args.out, "w") as f:
            f.write(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
