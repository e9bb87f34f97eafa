"""Slider change -> frame sent, for the tuner's two frame channels, in a Jupyter kernel.

``MaterialTuner(frame_channel="rfb")`` (jupyter_rfb's canvas: the worker thread hands each frame
to the kernel's event loop, which encodes and sends it) against ``frame_channel="image"``
(``ipywidgets.Image``: the worker thread encodes and sets the widget's value itself). Cornell box
at ``--size``², the scene's V4 preview, a 256-spp refinement budget (frames keep coming, as while
a user works). Per change: a random 0.3-0.45 s pause with the loop free, one ``metal.roughness``
value, and the clock runs until the channel sends a frame rendered after the change (rfb: the
canvas's ``send``; image: the widget's value set). The browser's acknowledgement of each rfb
frame is simulated at once (no browser: what is measured is the kernel's side). ``--changes``
changes per channel and round, the first 4 of each dropped (warm-up), channels alternating over
``--rounds`` rounds; medians and 90th percentiles.

Usage::

    .venv/bin/python benchmarks/tuner_channels.py        # writes benchmarks/results/tuner_channels.md
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
OUT = os.path.join(HERE, "results", "tuner_channels.md")

# runs in the kernel: top-level await keeps the event loop free between changes, as in a
# notebook whose user is moving a slider
SETUP = r'''
import asyncio, random, time
import draaw_mi
from draaw_mi.widgets import MaterialTuner

async def measure(channel, size, changes, seed):
    scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "cornell.toml"), resolution=(size, size))
    t = MaterialTuner(scene, max_spp=256, frame_channel=channel)
    sent, current = [], [-1]
    # the generation of the frame being handed over (the first frame callback, before the
    # tuner's own) and, for the image channel, the moment the widget's value was set (the last)
    t.preview._callbacks.insert(0, lambda f: current.__setitem__(0, f.generation))
    if channel == "rfb":
        c = t.canvas
        def send(msg, buffers=None):
            sent.append((time.perf_counter(), current[0]))
            asyncio.get_running_loop().call_soon(setattr, c, "_frame_feedback", {
                "index": msg["index"], "timestamp": msg["timestamp"], "localtime": msg["timestamp"]})
        c.send = send
        c._has_visible_views = True
    else:
        t.preview.on_frame(lambda f: sent.append((time.perf_counter(), f.generation)))
    rng, lat = random.Random(seed), []
    try:
        for i in range(changes + 4):
            await asyncio.sleep(0.3 + 0.15 * rng.random())
            t0 = time.perf_counter()
            t.controls["metal"]["roughness"].value = 0.1 + 0.03 * (i % 10) + 0.001 * i
            g = t.preview.generation
            while True:
                await asyncio.sleep(0.001)
                hit = [s for s, gen in sent if s > t0 and gen >= g]
                if hit or time.perf_counter() - t0 > 10:
                    lat.append(hit[0] - t0 if hit else float("nan"))
                    break
    finally:
        t.close()
    return lat[4:]
'''


def run_in_kernel(args) -> dict:
    import nbclient
    import nbformat
    rounds = [f"res[{ch!r}] += await measure({ch!r}, {args.size}, {args.changes}, {r})"
              for r in range(args.rounds) for ch in ("rfb", "image")]
    cells = [f"import os, json\nROOT = {ROOT!r}\n" + SETUP + "\nres = {'rfb': [], 'image': []}",
             *rounds, "print(json.dumps(res))"]
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in cells])
    nbclient.NotebookClient(nb, kernel_name="python3", timeout=1800, resources={"metadata": {"path": ROOT}}).execute()
    text = "".join(o.get("text", "") for o in nb.cells[-1].outputs if o.output_type == "stream")
    return json.loads(text.strip().splitlines()[-1])


def report(res: dict, args, argv) -> str:
    def q90(x):
        return sorted(x)[int(0.9 * (len(x) - 1))]
    lines = ["# Tuner frame channels: slider change -> frame sent (benchmarks/tuner_channels.py)", "",
             f"Command: `.venv/bin/python benchmarks/tuner_channels.py {' '.join(argv)}`  ",
             f"Machine: {platform.machine()}, {os.cpu_count()} cores (load average {os.getloadavg()[0]:.1f} "
             "at the end, this job included). Cornell box at "
             f"{args.size}², V4 preview, in a Jupyter kernel (nbclient); {args.changes} changes per channel "
             f"and round, {args.rounds} rounds alternating the channels. See the script's docstring for "
             "what is timed.", "",
             "| channel | changes | median | p90 | max |", "|---|---|---|---|---|"]
    for ch, name in (("rfb", "jupyter_rfb canvas (`OrbitCanvas`)"), ("image", "`ipywidgets.Image`")):
        x = [v for v in res[ch] if v == v]
        lost = len(res[ch]) - len(x)
        lines.append(f"| {name} | {len(x)}{f' ({lost} never sent)' if lost else ''} | "
                     f"{statistics.median(x) * 1e3:.0f} ms | {q90(x) * 1e3:.0f} ms | {max(x) * 1e3:.0f} ms |")
    lines += ["", "Raw data (ms): " + "; ".join(f"{ch}: " + ", ".join(f"{v * 1e3:.0f}" for v in res[ch])
                                               for ch in res), ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--changes", type=int, default=20)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--out", default=OUT)
    args = p.parse_args(argv)
    text = report(run_in_kernel(args), args, argv)
    from draaw_mi.io import print_report
    print_report(text, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
