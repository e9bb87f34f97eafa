"""Write notebooks/accuracy_vs_time.ipynb (no outputs): python notebooks/make_accuracy_vs_time.py

CI executes it with DRAAW_MI_NOTEBOOK_SMALL=1: it then runs a tiny study live (32x32) instead of
reading the recorded one (tests/test_notebooks_jupyter.py).
"""
from __future__ import annotations

import os

import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _nbgen  # noqa: E402  (notebooks/_nbgen.py, beside this script)


CELLS = [
    ("md", """# What accuracy costs in time

The study behind `draaw-mi bench`: every version (V1..V4, Mitsuba's `path` as the peer) at
1..1024 spp, adaptive subsampling, and OIDN-denoised renders (**biased**: a learned filter,
not an estimator), each timed (median of repeats) and compared with a 4096-spp ground truth.
This notebook plots the recorded results (`benchmarks/study/`, `benchmarks/study_denoise/`)
interactively.

Set `DRAAW_MI_NOTEBOOK_SMALL=1` to run a tiny study live instead (32x32, seconds) - CI does."""),
    ("code", """import json
import os

import matplotlib.pyplot as plt

from draaw_mi import bench
from draaw_mi.rendering.denoiser import available as denoiser_available

SMALL = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL") == "1"
ROOT = os.path.abspath(os.path.join(os.getcwd(), "..")) if os.path.basename(os.getcwd()) == "notebooks" else os.getcwd()
rows = []
if SMALL:
    # the small study's files: out/accuracy_vs_time beside this notebook (DRAAW_MI_NOTEBOOK_OUT names another folder)
    out = os.path.join(os.environ.get("DRAAW_MI_NOTEBOOK_OUT", "out"), "accuracy_vs_time")
    study = bench.run_study([os.path.join(ROOT, "scenes", "cornell.toml")], versions=("v4", "path"),
                            spps=(1, 4, 16), adaptive=(None,), repeats=2, resolution=(32, 32), gt_spp=256,
                            out_dir=out, progress=False, denoise_spp=(1, 4) if denoiser_available() else ())
    rows = study["rows"]
    print(f"small study: 32x32, {len(rows)} settings in {out}")
else:
    for folder in ("study", "study_denoise"):
        path = os.path.join(ROOT, "benchmarks", folder, "results.json")
        if os.path.isfile(path):
            with open(path) as fh:
                rows += [dict(r, study=folder) for r in json.load(fh)["rows"]]
    print(f"{len(rows)} recorded settings")
scenes = sorted({r["scene"] for r in rows})
labels = sorted({r["label"] for r in rows})
print("scenes:", ", ".join(scenes), "| settings:", ", ".join(labels))"""),
    ("md", """## Error against time

One line per setting (numbers: spp). Dotted lines with squares are denoised (biased) settings:
they can sit left of the Monte Carlo lines for the display-oriented metrics and still carry an
error that more samples never remove."""),
    ("code", """%matplotlib inline
# (the study's report switched matplotlib to its file backend; back to inline figures)
METRICS = {"rmse": "RMSE (linear)", "relmse": "relative MSE", "ciede2000": "mean CIEDE2000"}

def plot(scene=scenes[0], metric="rmse", show=tuple(labels)):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for lab in show:
        pts = sorted((r["time_s"], r[metric], r["spp"]) for r in rows
                     if r["scene"] == scene and r["label"] == lab and r.get(metric) is not None)
        if not pts:
            continue
        t, e, s = zip(*pts)
        ax.plot(t, e, "s:" if "oidn" in lab else "o--" if "adaptive" in lab else "o-", label=lab, ms=4)
        for ti, ei, si in pts:
            ax.annotate(str(si), (ti, ei), fontsize=6, alpha=0.6)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per image [s] (median)")
    ax.set_ylabel(METRICS[metric])
    ax.set_title(f"{scene}: {METRICS[metric]} vs time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    plt.show()

for sc in scenes:          # static plots (also in the saved notebook)
    plot(sc, "rmse")"""),
    ("md", "## Interactive: pick the scene, the metric and the settings"),
    ("code", """try:
    import ipywidgets as widgets
except ImportError:
    print("the interactive plot needs ipywidgets: pip install 'draaw-mi[notebooks]'")
else:
    widgets.interact(plot, scene=scenes, metric=list(METRICS),
                     show=widgets.SelectMultiple(options=labels, value=tuple(labels), rows=min(10, len(labels))))"""),
    ("md", """## Denoised few samples vs many raw samples

The acceptance question of the denoiser: does OIDN on 4 spp beat 64 raw spp? Per scene and
version, the three error metrics side by side (lower is better)."""),
    ("code", """few, many = (1, 16) if SMALL else (4, 64)
print(f"{'scene':18s} {'version':8s} {'metric':10s} {f'{few} spp+OIDN':>12s} {f'{many} spp raw':>12s}  winner")
for sc in scenes:
    for v in sorted({r["version"] for r in rows if r["scene"] == sc}):
        d = [r for r in rows if r["scene"] == sc and r["version"] == v and r.get("denoise") and r["spp"] == few]
        raw = [r for r in rows if r["scene"] == sc and r["version"] == v and not r.get("denoise")
               and not r.get("adaptive") and r["spp"] == many]
        if d and raw:
            for m in METRICS:
                a, b = d[0][m], raw[0][m]
                print(f"{sc:18s} {v:8s} {m:10s} {a:12.4f} {b:12.4f}  {'OIDN' if a < b else 'raw'}")"""),
]


def build():
    return _nbgen.build(CELLS)


if __name__ == "__main__":
    _nbgen.write(CELLS, "accuracy_vs_time")
