"""Roughness / metallic recovery accuracy of ``draaw_mi.fit`` (issue 6).

For every ground truth (roughness, metallic) on a spread over [0.05, 0.95]^2, render a
reference of ``scenes/fit_sphere.toml`` with Mitsuba's own ``path`` integrator at high spp
(an integrator independent of the one that fits), then fit both parameters from
(0.5, 0.5) with ``draaw_v4`` and record truth, fit, error, wall time and iterations.
Writes a Markdown report (default ``benchmarks/fit_accuracy.md``) that names the exact command.

Run from the repository root::

    .venv/bin/python benchmarks/fit_accuracy.py                  # full table, about 6 minutes
    .venv/bin/python benchmarks/fit_accuracy.py --quick          # 4 truths at 64x64
    .venv/bin/python benchmarks/fit_accuracy.py --iterations 100 --polish 30   # the record, ~13 min

The fit times are wall-clock on whatever else the machine is doing; they are a record, not a
test (see design.md section 9).
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import shlex
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "fit_sphere.toml")

# 12 truths: the 3x3 grid {0.05, 0.5, 0.95}^2 (corners and edges of the square) plus three inside.
TRUTHS = [(0.05, 0.05), (0.05, 0.5), (0.05, 0.95), (0.5, 0.05), (0.5, 0.95),
          (0.95, 0.05), (0.95, 0.5), (0.95, 0.95), (0.25, 0.8), (0.75, 0.25), (0.15, 0.35),
          (0.5, 0.5)]
QUICK_TRUTHS = [(0.05, 0.95), (0.95, 0.05), (0.25, 0.8), (0.75, 0.25)]
# environment-only light (the scene's lamps off, its sky replaced by a procedural environment
# map: sky, banded ground, a sun, two coloured lamps), near-mirror to rough
ENV_TRUTHS = [(0.05, 0.9), (0.08, 0.3), (0.1, 0.05), (0.12, 0.6), (0.15, 0.95), (0.4, 0.5)]
TOL = 0.01
TIME_LIMIT = 60.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="4 truths at 64x64 (about a minute)")
    ap.add_argument("--resolution", type=int, default=None, help="square image size (default 128)")
    ap.add_argument("--spp", type=int, default=16, help="samples per pixel per iteration (default 16)")
    ap.add_argument("--iterations", type=int, default=150, help="Adam iterations (default 150)")
    ap.add_argument("--lr", type=float, default=0.05, help="learning rate (default 0.05)")
    ap.add_argument("--ref-spp", type=int, default=4096, help="reference spp (default 4096)")
    ap.add_argument("--version", default="v4", help="integrator that fits (default v4)")
    ap.add_argument("--threads", type=int, default=2, help="Dr.Jit threads (default 2)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the fits (default 0)")
    ap.add_argument("--polish", type=int, default=0, help="fit(polish=N): N last iterations at --polish-spp "
                    "(default 0: none)")
    ap.add_argument("--polish-spp", type=int, default=None, help="spp of the polish (default 8x --spp)")
    ap.add_argument("--lighting", default="both", choices=["studio", "environment", "both"],
                    help="the scene's lamps and sky, an environment map alone, or both sets of truths")
    ap.add_argument("--out", default=None, help="Markdown report (default benchmarks/fit_accuracy.md, "
                                                "benchmarks/fit_accuracy_quick.md with --quick)")
    args = ap.parse_args(argv)
    res = args.resolution or (64 if args.quick else 128)
    out = args.out or os.path.join(ROOT, "benchmarks", "fit_accuracy_quick.md" if args.quick else "fit_accuracy.md")
    truths = [("studio", t) for t in (QUICK_TRUTHS if args.quick else TRUTHS)] if args.lighting != "environment" else []
    if args.lighting != "studio":
        truths += [("environment", t) for t in (ENV_TRUTHS[:2] if args.quick else ENV_TRUTHS)]

    import drjit as dr
    import mitsuba as mi

    import draaw_mi

    dr.set_thread_count(args.threads)
    scenes = {"studio": draaw_mi.load_scene(SCENE, resolution=(res, res))}
    if args.lighting != "studio":
        scenes["environment"] = environment_scene(res)
    rows = []
    for i, (lighting, (r, m)) in enumerate(truths):
        scene = scenes[lighting]
        p = scene.params
        p["target.roughness.value"], p["target.metallic.value"] = r, m
        p.update()
        t0 = time.perf_counter()
        ref = np.array(draaw_mi.render(scene, version="path", spp=args.ref_spp, seed=1_000_003 + 17 * i))
        t_ref = time.perf_counter() - t0
        fit = draaw_mi.fit(scene, ref, ["target.roughness", "target.metallic"], version=args.version,
                           spp=args.spp, iterations=args.iterations, lr=args.lr, seed=args.seed + i,
                           init={"target.roughness": 0.5, "target.metallic": 0.5}, progress=False,
                           polish=args.polish, polish_spp=args.polish_spp)
        fr, fm = fit.values["target.roughness"], fit.values["target.metallic"]
        finite = bool(np.isfinite(fit.losses).all() and np.isfinite(fit.image).all())
        row = dict(lighting=lighting, r=r, m=m, fr=fr, fm=fm, er=fr - r, em=fm - m, t=fit.seconds, t_ref=t_ref,
                   it=fit.iterations, finite=finite, converged=fit.converged, compiles=fit.kernel_compiles)
        row["ok"] = abs(row["er"]) <= TOL and abs(row["em"]) <= TOL and row["t"] < TIME_LIMIT and finite
        rows.append(row)
        print(f"{lighting:11s} truth ({r:.2f}, {m:.2f})  fit ({fr:.4f}, {fm:.4f})  error ({row['er']:+.4f}, {row['em']:+.4f})  "
              f"{row['t']:.1f} s  {'ok' if row['ok'] else 'MISS'}", flush=True)

    given = sys.argv[1:] if argv is None else list(argv)
    cmd = ".venv/bin/python benchmarks/fit_accuracy.py" + (" " + shlex.join(given) if given else "")
    write_report(out, rows, args, res, cmd, mi, dr)
    print(f"wrote {os.path.relpath(out, ROOT)}")
    return 0 if all(r["ok"] for r in rows) else 1


def write_report(path, rows, args, res, cmd, mi, dr):
    n_ok = sum(r["ok"] for r in rows)
    err_r = np.abs([r["er"] for r in rows])
    err_m = np.abs([r["em"] for r in rows])
    times = np.array([r["t"] for r in rows])
    lines = [
        "# Roughness / metallic recovery accuracy (`draaw_mi.fit`)",
        "",
        f"Command (repository root): `{cmd}`",
        "",
        f"Recorded {datetime.datetime.now().strftime('%Y-%m-%d %H:%M')} on {platform.machine()} "
        f"({os.cpu_count()} CPUs, Dr.Jit threads {args.threads}), Python {platform.python_version()}, "
        f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}, variant `{mi.variant()}`. Times are wall "
        "clock on a shared machine: a record, not a limit test.",
        "",
        "Set-up: scene `scenes/fit_sphere.toml` (a sphere on a tile, both of material `target`, "
        f"see the scene file for why it looks as it does), {res}x{res}, box filter. Reference: "
        f"Mitsuba's `path` integrator, {args.ref_spp} spp, per truth. Fit: `draaw_mi.fit(..., "
        f"[\"target.roughness\", \"target.metallic\"], version=\"{args.version}\", spp={args.spp}, "
        f"iterations={args.iterations}, lr={args.lr}" + (f", polish={args.polish}, polish_spp="
                                                           f"{args.polish_spp or 8 * args.spp}" if args.polish else "")
        + ")` from roughness 0.5, metallic 0.5; Adam "
        "(beta_2 0.9) on log(roughness) and metallic, cosine learning-rate decay to 10 %" + (
            ", then the polish: a second fit from the first's values at the polish's spp, a fresh Adam at "
            "0.4x lr, constant" if args.polish else "") + "; the "
        "reported value is the mean of the last 25 % of the (polish's) iterates. Time = the whole `fit()` call "
        "(first-iteration kernel compilation included), reference rendering excluded.",
        "",
        f"Pass = |error| <= {TOL} for both parameters, time < {TIME_LIMIT:.0f} s, no NaN/Inf in the "
        f"losses or the final image. **{n_ok} / {len(rows)} pass.** Largest |error|: roughness "
        f"{err_r.max():.4f}, metallic {err_m.max():.4f}; median time {np.median(times):.1f} s, "
        f"max {times.max():.1f} s.",
        "",
        "| light | truth (roughness, metallic) | fit | error | fit time (s) | iterations | reference time (s) | "
        "converged | pass |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['lighting']} | ({r['r']:.2f}, {r['m']:.2f}) | ({r['fr']:.4f}, {r['fm']:.4f}) | "
                     f"({r['er']:+.4f}, {r['em']:+.4f}) | {r['t']:.1f} | {r['it']} | {r['t_ref']:.1f} | "
                     f"{'yes' if r['converged'] else 'no'} | {'yes' if r['ok'] else '**no**'} |")
    lines += [
        "",
        "Notes",
        "",
        "* Roughness below about 0.02 is not identifiable: the draaw BSDF uses "
        "alpha = sqrt(roughness^4 + alpha_min^2) with alpha_min = 1e-3, so roughness 0 and 0.02 "
        "differ by 8 % in alpha. `fit()` therefore moves roughness in log space with a floor at "
        "0.6 * sqrt(alpha_min) = 0.019.",
        "* `environment`: the same scene with its three lamps off and its constant sky replaced by "
        "a procedural environment map (sky gradient, banded ground, a sun, two coloured lamps; "
        "`benchmarks/svbrdf_fit.py`'s `environment()`), which alone lights it.",
        "* Near-mirror targets under the environment alone: the environment map (128x64, 2.8 degrees "
        "a texel; its sun a Gaussian of 4.6 degrees) has no detail near the size of the reflection "
        "lobe, so the expected loss is flat within its estimate's noise from roughness 0.035 to 0.06 "
        "(truth (0.05, 0.9); unbiased two-render estimate at 256 spp with common random numbers, three "
        "trials: 0.6-3.0e-5 there, 2.4-4.7e-5 at 0.065, 6.7-8.6e-5 at 0.07, 23-25e-5 at 0.08). Its "
        "minimum is at the truth: the 4096-spp reference's noise moves the linearised optimum by 0.0017. The gradient there is unbiased (path replay against finite "
        "differences at roughness 0.06 and 0.067) but noisy: its signal-to-noise ratio per iteration "
        "at roughness 0.067 is 0.17 at 16 spp, 0.61 at 64, 2.1 at 256 with independent samples (variance ~ 1 / (spp * "
        "spp_grad): both factors of `2 (I - ref) dI` are noise there). At 16 spp the fit stops at "
        "0.064-0.070 (seeds 3, 4, 12); 300 iterations reach 0.060, 64 spp throughout 0.064, "
        "beta_2 0.99 for the whole fit 0.095, lr 0.1 overshoots the studio's near-mirrors into the flat region "
        "(0.030-0.039 for 0.05). The polish (`fit(polish=...)`) is what settles it: with independent "
        "samples 0.0571 in the 2026-12-04 table (seed 12), 0.0589 with seed 0 (`--lighting environment`); "
        "the same schedule as two separate fits, seeds 12 / 3 / 4: 0.0554 / 0.0584 / 0.0589 (without it, "
        "150 iterations: 0.0674 in the 2026-12-02 table, 17 / 18, its one miss); with V4's stratified "
        "gradient passes 0.0553 in the table.",
        "* (0.10, 0.05) under the environment, a dielectric whose reflection is 4 % of the light. With "
        "independent samples (before 2026-12-05) it ended at 0.098-0.111 over nine polished runs (mean "
        "0.1041, sd 0.0039; the table's seed 14: 0.1109, one miss), the polish at 512 spp at 0.1041 and "
        "0.1046 but in 146-149 s. Since V4 draws its gradient passes from its own stratified sampler "
        "(`draaw_mi/integrators/strata_sampler.py`; the gradient's sd at 16 spp, 16 seeds at roughness "
        "0.115: 2.5e-3 against 12.2e-3 independent; at 128 spp 6.1e-4 against 4.7e-4) it ends at 0.1031 "
        "in the table and 0.0981-0.1072 over five more seeds (mean 0.1031, sd 0.0035: all six within "
        "0.01, the largest error 0.0072; an sd of 0.0035 still leaves a miss in some tens of runs). "
        "(0.08, 0.30): 0.0810-0.0861 over four runs; (0.05, 0.90): 0.0543-0.0553 over three "
        "(`/tmp`-script: the benchmark's fit and reference, seeds 100 k + the row).",
        "* `converged` is `fit()`'s own plateau test on the averaged iterates (tol 5e-3); it is "
        "informational.",
        "",
    ]
    from draaw_mi.io import write_text
    write_text(path, "\n".join(lines))


def environment_scene(res: int):
    """``scenes/fit_sphere.toml`` lit by an environment map alone (its lamps and sky removed)."""
    import tempfile
    import tomllib

    import draaw_mi
    from svbrdf_fit import environment
    with open(SCENE, "rb") as f:
        desc = tomllib.load(f)
    folder = tempfile.mkdtemp(prefix="fit-accuracy-")
    desc["lights"] = [{"type": "envmap", "name": "env", "file": environment(os.path.join(folder, "env.exr"))}]
    desc["render"]["resolution"] = [res, res]
    return draaw_mi.load_scene(desc)


if __name__ == "__main__":
    sys.exit(main())
