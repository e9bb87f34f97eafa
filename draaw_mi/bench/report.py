"""Reports of the benchmark study: JSON, CSV, Markdown summary, error-vs-time plots, error images."""
from __future__ import annotations

import contextlib
import csv
import io
import json
import os

import numpy as np

from ..io import srgb_encode, write_text
from ..plotting import save, subplots
from .bias import pareto_front

COLUMNS = ["scene", "label", "version", "adaptive", "max_depth", "spp", "time_s", "time_min_s", "compile_s",
           "rmse", "rmse_min", "rmse_max", "relmse", "ciede2000", "tail_share", "fireflies", "bias_rmse",
           "bias_resolved", "bias_method", "finite", "resolution", "denoise"]


def time_to_error(points: list[tuple[float, float]], target: float, extrapolate: bool = False) -> float:
    """Time a method needs to reach RMSE ``target``, interpolating its (time, rmse) points in
    log-log space; ``inf`` if it never gets there. With ``extrapolate``, a target below the
    method's lowest measured error is extrapolated from its most accurate point with the Monte
    Carlo law (MSE ∝ 1/spp, time ∝ spp, so time ∝ RMSE^-2).

    >>> round(time_to_error([(1.0, 0.4), (4.0, 0.1)], 0.2), 3)
    2.0
    >>> round(time_to_error([(1.0, 0.4), (4.0, 0.1)], 0.05, extrapolate=True), 3)
    16.0
    """
    pts = sorted(points)
    best = np.inf
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 > target >= e1 and e0 > 0 and e1 > 0:
            f = (np.log(target) - np.log(e0)) / (np.log(e1) - np.log(e0))
            best = min(best, float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0)))))
    for t, e in pts:
        if e <= target:
            best = min(best, t)
    if extrapolate and not np.isfinite(best) and pts and target > 0:
        t_last, e_last = min(pts, key=lambda p: p[1])
        best = t_last * (e_last / target) ** 2
    return best


def pareto_check(rows: list[dict], scene: str, depth: int, subject: str = "v4",
                 rivals=("v3", "path")) -> dict:
    """At every RMSE level reached by ``rivals``, is ``subject`` the fastest to reach it?"""
    by_label: dict = {}
    for r in rows:
        if r["scene"] == scene and r["max_depth"] == depth and not r["adaptive"] and not r.get("denoise"):
            by_label.setdefault(r["label"], []).append((r["time_s"], r["rmse"]))
    rivals = [lab for lab in rivals if lab in by_label]          # (the ones measured)
    if subject not in by_label or not rivals:
        return {}
    levels = sorted({e for lab in rivals for _, e in by_label[lab]})
    won, details = 0, []
    for e in levels:
        times = {lab: time_to_error(pts, e) for lab, pts in by_label.items()}
        extrapolated = not np.isfinite(times[subject])
        if extrapolated:          # the subject stopped at the grid's largest spp before this level
            times[subject] = time_to_error(by_label[subject], e, extrapolate=True)
        fastest = min(times, key=times.get)
        ok = times[subject] <= times[fastest] * 1.0000001
        won += ok
        # the margin: the subject against the best of the others (below 1: it wins by that)
        others = {lab: t for lab, t in times.items() if lab != subject}
        rival = min(others, key=others.get) if others else subject
        details.append({"rmse": e, "fastest": fastest, "subject_s": times[subject],
                        "fastest_s": times[fastest], "extrapolated": extrapolated,
                        "rival": rival, "rival_s": times[rival]})
    return {"levels": len(levels), "subject_fastest": won, "details": details, "rivals": rivals}


FIREFLY_NOTE = ("hollow: firefly-dominated (its repeats' RMSEs differ 2x or more: a few samples worth thousands "
                "of times their pixel); its error jumps and can rise with spp while the expected MSE falls")


def error_vs_time_figure(rows, scene, depth):
    """The error-vs-time plot of one scene and depth: per setting its mean RMSE over the
    repeats against the median time, bars from the lowest to the highest repeat, hollow
    markers where the error is a few fireflies (``fireflies``), and per version a dashed
    horizontal line at its bias (the RMSE it converges to against the ground truth; dotted: an
    upper bound). Curves: plain settings solid, adaptive ones dashed, denoised ones dotted (the
    legend's title says both). The legend is outside the axes."""
    sel = [r for r in rows if r["scene"] == scene and r["max_depth"] == depth]
    fig, ax = subplots(figsize=(9.4, 5.0))
    labels = sorted({r["label"] for r in sel})
    any_fireflies = any(r.get("fireflies") for r in sel)
    for lab in labels:
        rs = sorted((r for r in sel if r["label"] == lab), key=lambda r: (r["time_s"], r["spp"]))
        t = [r["time_s"] for r in rs]
        e = [r["rmse"] for r in rs]
        style = "--" if "adaptive" in lab else ":" if "oidn" in lab else "-"
        line, = ax.plot(t, e, style, label=lab, lw=1.2)
        colour = line.get_color()
        if all("rmse_min" in r for r in rs):
            lo = [max(r["rmse"] - r["rmse_min"], 0.0) for r in rs]
            hi = [max(r["rmse_max"] - r["rmse"], 0.0) for r in rs]
            ax.errorbar(t, e, yerr=[lo, hi], fmt="none", ecolor=colour, elinewidth=0.8, capsize=2, alpha=0.7)
        for r in rs:
            hollow = bool(r.get("fireflies"))
            ax.plot([r["time_s"]], [r["rmse"]], "o", ms=5 if hollow else 4, color=colour,
                    mfc="white" if hollow else colour)
        for r in rs[:: max(1, len(rs) // 4)]:
            ax.annotate(str(r["spp"]), (r["time_s"], r["rmse"]), fontsize=6, alpha=0.6)
        bias = rs[-1].get("bias_rmse")
        if bias and rs[-1].get("bias_method") == "converged":
            resolved = rs[-1].get("bias_resolved", True)
            ax.axhline(bias, color=colour, ls="--" if resolved else ":", lw=1.0, alpha=0.8,
                       label=f"{lab} bias {'' if resolved else '≤ '}{bias:.3g}")
    allp = [(r["time_s"], r["rmse"]) for r in sel]
    front = pareto_front(allp)
    fp = sorted(allp[i] for i in front)
    ax.plot([p[0] for p in fp], [p[1] for p in fp], "k-", lw=2.5, alpha=0.35, label="Pareto front")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time per image [s] (median)")
    ax.set_ylabel("RMSE vs ground truth (mean of repeats; bars: lowest-highest)")
    ax.set_title(f"{scene}: error vs time (max_depth {depth}; numbers = spp)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    # outside the axes, on the right: it covered the data inside them
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
              title="curves: solid, +adaptive dashed, +oidn dotted;\nhorizontal lines: a version's bias "
                    "(converged\nerror), dashed; dotted: an upper bound", title_fontsize=6)
    if any_fireflies:
        fig.text(0.01, 0.01, FIREFLY_NOTE, fontsize=6.5, ha="left", va="bottom")
    fig.tight_layout(rect=(0, 0.03 if any_fireflies else 0, 1, 1))
    return fig


def _plot_error_vs_time(rows, scene, depth, path):
    save(error_vs_time_figure(rows, scene, depth), path, dpi=110)


def _plot_error_images(images, gts, scene, spp, path):
    items = [(s, img) for (sc, s), img in images.items() if sc == scene and s.spp == spp and not s.adaptive]
    items += [(s, img) for (sc, s), img in images.items() if sc == scene and s.adaptive]
    if not items:
        return
    gt = gts[scene]
    n = len(items) + 1
    fig, axes = subplots(2, n, figsize=(2.4 * n, 5), squeeze=False)
    axes[0, 0].imshow(srgb_encode(gt))
    axes[0, 0].set_title("ground truth", fontsize=8)
    axes[1, 0].axis("off")
    vmax = max(float(np.percentile(np.abs(img[..., :3] - gt).mean(axis=2), 99)) for _, img in items) or 1.0
    for k, (s, img) in enumerate(items, start=1):
        axes[0, k].imshow(srgb_encode(img[..., :3]))
        axes[0, k].set_title(f"{s.label} {s.spp} spp", fontsize=8)
        axes[1, k].imshow(np.abs(img[..., :3] - gt).mean(axis=2), cmap="magma", vmin=0, vmax=vmax)
        axes[1, k].set_title("|error|", fontsize=8)
    for a in axes.ravel():
        a.set_xticks([])
        a.set_yticks([])
    fig.tight_layout()
    save(fig, path, dpi=100)


def _bias_note(result: dict) -> str:
    if result.get("bias_from", "spp levels") == "converged renders":
        return ("*Bias*: the RMSE between the image a version converges to and the ground truth, "
                f"from two more renders of it at {result['ground_truth_spp'] // 2} spp each (their "
                "noise and the ground truth's taken out; adaptive and denoised settings: from their "
                "highest spp levels); `< x`: not resolved from the noise, at most x. A version's "
                "RMSE cannot fall below its bias (the dashed lines of the plots): V1 and V2 render "
                "their own models (truncated transport, Phong), not the ground truth's.")
    return ("*Bias*: the RMSE that does not fall with spp, pooled over the highest spp levels, "
            "the ground truth's own noise taken out; `< x`: not resolved from the noise of "
            f"{result['repeats']} repeats, at most x.")


def summary_markdown(result: dict) -> str:
    rows = result["rows"]
    lines = ["# draaw-mi benchmark: what accuracy costs in time", "",
             f"Ground truth: Mitsuba `path` (`volpath` for scenes with media, V4 for scenes with "
             f"SDF objects), {result['ground_truth_spp']} spp, same materials, at the deepest "
             "max_depth studied (-1: unbounded). "
             + (f"Times: median of {result['repeats']} renders" if result["repeats"] > 1 else "Times: one render")
             + " after warm-up (compile time separate). "
             f"Machine: {result['machine']}" + (f"; {result['load']}." if result.get("load") else "."), "",
             _bias_note(result), "",
             "*Fireflies* (†): settings whose repeats' RMSEs differ by 2x or more: their error is "
             "a few samples worth thousands of times their pixel (V1 and V2 light "
             "near-mirror Phong lobes by emitter sampling alone, without MIS). Their RMSE over "
             f"{result['repeats']} repeats depends on whether such samples fell, so it jumps and "
             "can rise with spp (the expected MSE still falls as 1 / spp); *RMSE range* is the "
             "lowest and highest repeat.", ""]
    scenes = sorted({r["scene"] for r in rows})
    for sc in scenes:
        depths = sorted({r["max_depth"] for r in rows if r["scene"] == sc})
        for d in depths:
            sel = [r for r in rows if r["scene"] == sc and r["max_depth"] == d]
            res = sel[0]["resolution"]
            lines += [f"## {sc} ({res[0]}×{res[1]}, max_depth {d})", "",
                      f"![error vs time](error_vs_time_{sc}_d{d}.png)", "",
                      "| setting | spp | time [s] | compile [s] | RMSE | RMSE range | relMSE | ΔE2000 | bias (RMSE) |",
                      "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
            for r in sorted(sel, key=lambda r: (r["label"], r["spp"])):
                bias = ("" if r["bias_rmse"] is None else f"{r['bias_rmse']:.4f}" if r.get("bias_resolved", True)
                        else f"< {r['bias_rmse']:.4f}")
                spread = (f"{r['rmse_min']:.4f}–{r['rmse_max']:.4f}" if "rmse_min" in r else "")
                lines.append(f"| {r['label']} | {r['spp']} | {r['time_s']:.4f} | {r['compile_s']:.3f} | "
                             f"{r['rmse']:.4f}{' †' if r.get('fireflies') else ''} | {spread} | "
                             f"{r['relmse']:.4f} | {r['ciede2000']:.3f} | {bias} |")
            chk = pareto_check(rows, sc, d)
            if chk:
                named = " and ".join("`path`" if lab == "path" else lab.upper() for lab in chk["rivals"])
                lines += ["", f"V4 is the fastest to reach {chk['subject_fastest']} of the {chk['levels']} "
                              f"error levels that {named} reach{'es' if len(chk['rivals']) == 1 else ''} "
                              "(time to reach a level is interpolated "
                              "in log-log between measured spp; * = below V4's lowest measured error, "
                              "extrapolated with time ∝ RMSE⁻²):", "",
                          "| RMSE level | fastest | its time [s] | V4 time [s] | V4 / fastest "
                          "| best other | V4 / best other |",
                          "|---:|---|---:|---:|---:|---|---:|"]
                for det in chk["details"]:
                    star = "*" if det.get("extrapolated") else ""
                    lines.append(f"| {det['rmse']:.4f} | {det['fastest']} | {det['fastest_s']:.4f} | "
                                 f"{det['subject_s']:.4f}{star} | {det['subject_s'] / det['fastest_s']:.3f} | "
                                 f"{det['rival']} | {det['subject_s'] / det['rival_s']:.3f} |")
            lines.append("")
    return "\n".join(lines) + "\n"


def rewrite_summary(out_dir: str) -> None:
    """Regenerate ``summary.md`` from ``results.json`` (after a change of the report format)."""
    with open(os.path.join(out_dir, "results.json")) as f:
        result = json.load(f)
    write_text(os.path.join(out_dir, "summary.md"), summary_markdown(result))


def write_report(result: dict, images: dict, gts: dict, out_dir: str) -> None:
    """The study's files in ``out_dir``: the plots first, then ``results.csv``,
    ``results.json`` and last ``summary.md``, the page that shows the rest; a previous run's
    ``results.json`` and ``summary.md`` go before anything is written, so a run stopped
    midway leaves no summary of another run's numbers beside its own plots."""
    os.makedirs(out_dir, exist_ok=True)
    for name in ("summary.md", "results.json"):
        with contextlib.suppress(FileNotFoundError):
            os.remove(os.path.join(out_dir, name))
    _write_plots(result["rows"], images, gts, out_dir)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, extrasaction="ignore")
    w.writeheader()
    for r in result["rows"]:
        w.writerow(r)
    write_text(os.path.join(out_dir, "results.csv"), buf.getvalue())
    write_text(os.path.join(out_dir, "results.json"), json.dumps(result, indent=1, default=str))
    write_text(os.path.join(out_dir, "summary.md"), summary_markdown(result))


def _write_plots(rows: list, images: dict, gts: dict, out_dir: str) -> None:
    for sc in sorted({r["scene"] for r in rows}):
        for d in sorted({r["max_depth"] for r in rows if r["scene"] == sc}):
            _plot_error_vs_time(rows, sc, d, os.path.join(out_dir, f"error_vs_time_{sc}_d{d}.png"))
        spps = sorted({r["spp"] for r in rows if r["scene"] == sc and not r["adaptive"]})
        if spps:
            _plot_error_images(images, gts, sc, spps[len(spps) // 2], os.path.join(out_dir, f"error_images_{sc}.png"))
