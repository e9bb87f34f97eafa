"""What the sphere tracer's accuracy costs in time: the SDF part of ``draaw-mi bench``.

Mitsuba's ``path`` cannot see SDFs, so SDF scenes get their own study. For each tracer
setting (hit epsilon, iteration cap, over-relaxation; see :mod:`draaw_mi.sdf.tracer`) it
measures, with ``draaw_v4`` at a fixed spp:

* **time**: median of ``repeats`` timed renders (settings interleaved round-robin, after one
  warm-up render each that absorbs the JIT compilation);
* **tracer error**: RMSE against a reference rendered with a strict tracer (epsilon 1e-6,
  4096 steps, no relaxation) *with the same seeds* -- common random numbers cancel the Monte
  Carlo noise, so what remains is the error the tracer setting causes;
* **false misses**: the share of camera rays (pixel centres, depth-tested against the meshes)
  that hit an SDF with the strict tracer but miss with this setting (iteration cap reached or
  stopped short), and the mean number of march steps per camera ray.

Results: ``sdf_study.json``, ``sdf_study.csv``, ``sdf_study.md`` and ``sdf_error_vs_time.png``
in the output folder.
"""
from __future__ import annotations

import json
import os
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..io import write_text
from ..plotting import save, subplots
from ..progress import check_mode, closed_after, progress_bar
from ..rendering.renderer import render
from ..scene import load_scene
from ..sdf.tracer import TracerOptions, march

REFERENCE = {"sdf_epsilon": 1e-6, "sdf_max_steps": 4096, "sdf_relaxation": 1.0}


def default_settings(quick: bool = False) -> list[dict]:
    """One knob at a time around the default (epsilon 1e-5, 256 steps), plain and relaxed."""
    steps = (16, 64, 256) if quick else (16, 32, 64, 128, 256, 512)
    epss = (3e-6, 3e-5) if quick else (2e-6, 5e-6, 2e-5, 5e-5)
    out = []
    for relax in (1.0, 1.5):
        for s in steps:
            out.append({"sdf_epsilon": 1e-5, "sdf_max_steps": s, "sdf_relaxation": relax})
        for e in epss:
            out.append({"sdf_epsilon": e, "sdf_max_steps": 256, "sdf_relaxation": relax})
    return out


def label(s: dict) -> str:
    return f"eps={s['sdf_epsilon']:g} steps={s['sdf_max_steps']} relax={s['sdf_relaxation']:g}"


def camera_march(scene, opts: dict):
    """(hit, steps) of the camera rays through the pixel centres (depth-tested)."""
    W, H = scene.resolution
    sensor = scene.mi_scene.sensors()[0]
    ys, xs = np.mgrid[0:H, 0:W]
    u = ((xs + 0.5) / W).ravel().astype(np.float32)
    v = ((ys + 0.5) / H).ravel().astype(np.float32)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
    si = scene.mi_scene.ray_intersect(ray)
    tmax = dr.select(si.is_valid(), si.t, dr.inf)
    t_opts = TracerOptions(opts["sdf_epsilon"], opts["sdf_max_steps"], opts["sdf_relaxation"])
    _, hit, steps = march(scene.sdf, ray.o, ray.d, tmax, mi.Bool(True), t_opts)
    return np.array(hit), np.array(steps)


def _render(scene, opts, spp, seed):
    img = render(scene, version="v4", spp=spp, seed=seed, post=[], integrator_options=dict(opts))
    arr = np.array(img)[..., :3]
    dr.sync_thread()
    return arr


def run_sdf_study(scene, out_dir: str, settings=None, spp: int = 16, repeats: int = 3,
                  progress: bool | str = False, quick: bool = False) -> dict:
    """Run the tracer study on one SDF scene; write the report into ``out_dir``."""
    check_mode(progress, "sdf study")
    settings = settings or default_settings(quick)
    name = os.path.splitext(os.path.basename(scene.source or "scene"))[0]
    os.makedirs(out_dir, exist_ok=True)
    seeds = [11 + 7 * r for r in range(repeats)]
    refs = [_render(scene, REFERENCE, spp, s) for s in seeds]
    ref_hit, ref_steps = camera_march(scene, REFERENCE)
    with closed_after(progress_bar(len(settings) * (repeats + 1), f"sdf study {name}", "render", progress,
                                   where="sdf study")) as bar:
        for s in settings:                               # warm-up (compilation)
            _render(scene, s, spp, 1)
            if bar is not None:
                bar.update(1)
        times = {i: [] for i in range(len(settings))}
        errs = {i: [] for i in range(len(settings))}
        for r, seed in enumerate(seeds):                 # interleaved round-robin
            for i, s in enumerate(settings):
                t0 = time.perf_counter()
                img = _render(scene, s, spp, seed)
                times[i].append(time.perf_counter() - t0)
                errs[i].append(float(np.sqrt(np.mean((img - refs[r]) ** 2))))
                if bar is not None:
                    bar.update(1)
    n_ref = max(int(ref_hit.sum()), 1)
    rows = []
    for i, s in enumerate(settings):
        hit, steps = camera_march(scene, s)
        rows.append({**s, "label": label(s), "spp": spp, "time_s": float(np.median(times[i])),
                     "rmse": float(np.mean(errs[i])),
                     "false_miss_share": float(np.sum(ref_hit & ~hit) / n_ref),
                     "false_miss_rays": int(np.sum(ref_hit & ~hit)),
                     "mean_steps": float(steps.mean()),
                     "mean_steps_hit": float(steps[hit].mean()) if hit.any() else 0.0})
    result = {"scene": name, "resolution": list(scene.resolution), "spp": spp, "repeats": repeats,
              "reference": REFERENCE, "reference_mean_steps": float(ref_steps.mean()),
              "sdf_rays": int(ref_hit.sum()), "rows": rows}
    base = os.path.join(out_dir, f"sdf_study_{name}")
    write_text(base + ".json", json.dumps(result, indent=1))
    keys = ["sdf_epsilon", "sdf_max_steps", "sdf_relaxation", "time_s", "rmse",
            "false_miss_share", "mean_steps"]
    lines = [",".join(keys)] + [",".join(str(r[k]) for k in keys) for r in rows]
    write_text(base + ".csv", "\n".join(lines) + "\n")
    write_text(base + ".md", markdown(result))
    plot(result, os.path.join(out_dir, f"sdf_error_vs_time_{name}.png"))
    return result


def markdown(result: dict) -> str:
    lines = [f"# SDF tracer study: {result['scene']} ({result['resolution'][0]}x{result['resolution'][1]}, "
             f"{result['spp']} spp, draaw_v4, median of {result['repeats']} interleaved repeats)", "",
             f"Reference: {label(result['reference'])}; {result['sdf_rays']} camera rays hit an SDF; "
             f"reference mean steps per camera ray {result['reference_mean_steps']:.1f}. "
             "RMSE against the reference with the same seeds (tracer error only).", "",
             "| epsilon | max steps | relaxation | time (s) | RMSE | false misses | mean steps / camera ray |",
             "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        lines.append(f"| {r['sdf_epsilon']:g} | {r['sdf_max_steps']} | {r['sdf_relaxation']:g} | "
                     f"{r['time_s']:.3f} | {r['rmse']:.2e} | {100 * r['false_miss_share']:.2f} % | "
                     f"{r['mean_steps']:.1f} |")
    return "\n".join(lines) + "\n"


def plot(result: dict, path: str) -> None:
    fig, (a1, a2) = subplots(1, 2, figsize=(10, 4))
    for relax, marker in ((1.0, "o"), (1.5, "s")):
        for knob, color in (("steps", "tab:blue"), ("eps", "tab:orange")):
            rows = [r for r in result["rows"] if r["sdf_relaxation"] == relax and
                    ((knob == "steps" and r["sdf_epsilon"] == 1e-5) or
                     (knob == "eps" and r["sdf_max_steps"] == 256))]
            rows.sort(key=lambda r: r["time_s"])
            a1.plot([r["time_s"] for r in rows], [max(r["rmse"], 1e-7) for r in rows], marker=marker,
                    color=color, ls="-" if relax == 1.0 else "--",
                    label=f"{'iteration cap' if knob == 'steps' else 'hit epsilon'}, relax {relax:g}")
        rows = sorted([r for r in result["rows"] if r["sdf_relaxation"] == relax and r["sdf_epsilon"] == 1e-5],
                      key=lambda r: r["sdf_max_steps"])
        a2.plot([r["sdf_max_steps"] for r in rows], [100 * r["false_miss_share"] for r in rows],
                marker=marker, label=f"relax {relax:g}")
    a1.set_xlabel("time per render (s)")
    a1.set_ylabel("RMSE vs strict tracer (same seeds)")
    a1.set_yscale("log")
    a1.legend(fontsize=7)
    a1.set_title(f"{result['scene']}: tracer error vs time")
    a2.set_xscale("log", base=2)
    a2.set_xlabel("iteration cap")
    a2.set_ylabel("false misses (% of SDF camera rays)")
    a2.legend(fontsize=7)
    a2.set_title("rays ending as false misses")
    fig.tight_layout()
    save(fig, path, dpi=110)


def has_sdf(scene_file) -> bool:
    """Whether a scene file has ``[[sdf]]`` entries (without building the scene)."""
    try:
        return load_scene(scene_file).sdf is not None
    except Exception:  # noqa: BLE001 - the main study reports load errors
        return False
