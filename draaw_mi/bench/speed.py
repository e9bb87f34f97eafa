"""Speed suite measurement: time to reach ``path``'s 64-spp error, per scene kind (the scenes
are in :mod:`draaw_mi.bench.suite`). Run it as ``draaw-mi bench --suite speed`` or
``python benchmarks/speed_suite.py``.

For each resolution and scene:

1. a reference: ``path`` at ``--ref-spp`` (a multiple of 64, at least 128) in 64-spp passes
   with distinct seeds, cached as EXR (mean and the per-pixel variance of the mean, estimated
   from the passes) in ``--cache``, under a name that holds a hash of the scene's content (an
   edited scene gets a new reference);
2. every integrator is compiled (a warm-up render), then ``--repeats`` cycles render each
   integrator back to back (A B A B ...) at ``--spp`` with a fresh seed per render; each render
   gives one time and one squared error;
3. ``MSE_X`` = mean squared error over the cycles minus the reference's own noise (the mean
   per-pixel variance of the reference, the same for every integrator), and
   ``t_equal / path = median over cycles of (t_X / t_path) * MSE_X / MSE_path``: Monte Carlo
   MSE falls as 1/spp and time grows as spp, so this is the time ``X`` needs to reach the
   error ``path`` reaches at ``--spp``, relative to ``path``'s time.

Integrators are given as ``plugin[:key=value,...]`` (e.g. ``draaw_v4:rr_depth=5``), so
variants of one integrator are compared in the same interleaved run. ``--sampler`` gives
every integrator (``path`` included) the same sampler.

Usage::

    .venv/bin/python benchmarks/speed_suite.py                      # 128 and 256, all scenes
    .venv/bin/python benchmarks/speed_suite.py --res 128 --scenes cornell,metal_018 --out ''

The report is printed and written to ``--out`` (default
``benchmarks/results/speed_suite_latest.md``; ``''``: printed only). The curated record,
``benchmarks/results/speed_suite.md``, is edited by hand from such reports.

The machine is usually shared: times are medians of back-to-back ratios, never single runs.
"""
from __future__ import annotations

import argparse
import gc
import math
import os
import platform
import statistics
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import suggest
from ..integrators import adaptive_sampling as ads
from ..integrators import guide_cache, guiding
from ..integrators.spp_map import pass_sums
from ..io import print_report, read_exr, write_exr
from ..rendering.session import session_of
from ..scene.loading import release_wrapped, wrap
from . import suite as ss
from .code_digest import code_digest
from .study import load_note

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))   # the repository
CACHE = os.path.join(os.path.expanduser("~"), ".cache", "draaw-mi", "speed_refs")
REF_PASS_SPP = 64         # the reference renders in passes of this many spp, at least two
DEFAULT_OUT = os.path.join(ROOT, "benchmarks", "results", "speed_suite_latest.md")


def check_ref_spp(spp) -> str | None:
    """Why ``spp`` cannot be a reference's spp, or ``None``: it renders in
    :data:`REF_PASS_SPP`-spp passes, at least two (the reference's noise, subtracted from every
    MSE, is estimated from their spread).

    >>> check_ref_spp(1024) is None, check_ref_spp(100)
    (True, 'expected a multiple of 64 that is at least 128 (64-spp passes, two or more for the noise estimate)')
    """
    if isinstance(spp, int) and spp >= 2 * REF_PASS_SPP and spp % REF_PASS_SPP == 0:
        return None
    return (f"expected a multiple of {REF_PASS_SPP} that is at least {2 * REF_PASS_SPP} "
            f"({REF_PASS_SPP}-spp passes, two or more for the noise estimate)")


def parse_integrator(spec: str, depth: int) -> dict:
    plugin, _, opts = spec.partition(":")
    d = {"type": plugin, "max_depth": depth}
    for kv in filter(None, opts.split(",")):
        k, v = kv.split("=")
        for conv in (int, float):
            try:
                v = conv(v)
                break
            except ValueError:
                pass
        if v in ("true", "false"):
            v = v == "true"
        d[k] = v
    return d


def timed_render(scene, integ, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """``(image as float64, seconds)`` of one traced pass of ``scene`` (an ``mi.Scene``) with
    ``integ``, evaluated and synchronised (:meth:`~draaw_mi.rendering.session.Session.render_pass`)."""
    wrapper = wrap(scene)                # not load_scene's: that keeps recent wrappers alive
    session = session_of(wrapper)
    t = time.perf_counter()
    img = session.render_pass(integ, spp, seed, freeze=False)
    return np.array(img, dtype=np.float64), time.perf_counter() - t


def render(scene, integ, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """``(RGB image, seconds)``: :func:`timed_render` without AOV channels."""
    img, dt = timed_render(scene, integ, spp, seed)
    return img[..., :3], dt


def reference(name: str, res: int, scene, depth: int, spp: int, cache: str, digest: str = ""):
    """(mean, per-pixel variance of the mean, seconds) of ``path`` at ``spp`` (see
    :func:`check_ref_spp`); cached as EXR in ``cache`` under a name with ``digest``, the scene's
    content hash (:func:`draaw_mi.bench.suite.digest`), and the hash of the code that renders
    it (:func:`draaw_mi.bench.code_digest.code_digest`: a fixed ``draaw`` BSDF renders it anew)."""
    why = check_ref_spp(spp)
    if why:
        raise ValueError(f"draaw_mi.bench.speed.reference: spp {spp!r}; {why}")
    path = os.path.join(cache, f"{name}_{res}_d{depth}_{spp}{'_' + digest if digest else ''}_c{code_digest()}.exr")
    if cache and os.path.exists(path):
        arr = read_exr(path).astype(np.float64)
        return arr[..., :3], arr[..., 3:6], 0.0
    integ = mi.load_dict({"type": "path", "max_depth": depth})
    chunk = REF_PASS_SPP
    n = spp // chunk
    t0 = time.perf_counter()
    s1 = s2 = 0.0
    for i in range(n):
        img, _ = render(scene, integ, chunk, 1_000_000 + 7919 * i)
        s1, s2 = s1 + img, s2 + img * img
    mean = s1 / n
    var = np.maximum(s2 / n - mean * mean, 0.0) / max(n - 1, 1)   # variance of the mean
    if cache:
        write_exr(path, np.concatenate([mean, var], -1), ["R", "G", "B", "v0.R", "v1.G", "v2.B"])
    return mean, var, time.perf_counter() - t0


LEARN_REPEATS = 3                   # learnings timed per scene and integrator (the median counts)


def learning_time(integ, scene, spp: int) -> float:
    """Seconds ``draaw_v4`` takes to decide on and learn ``scene``'s guide for a render of
    ``spp`` (:meth:`GuideCache.for_primal <draaw_mi.integrators.guide_cache.GuideCache.for_primal>`),
    measured on a fresh cache that then replaces the integrator's: where adaptive sampling's
    pilot decides, the training pass (the share is the one the warm-up render's pilot read;
    the pilot itself is part of every render) from the pilot's recorded paths, plus what
    recording them adds to the pilot (:func:`recording_cost`); elsewhere the decision pilot
    and the training pass. The timed renders are then the scene's later ones: a guided
    scene's are guided throughout, where its first render's pilot (1/16 of the samples) was
    not. 0 for other integrators, ``guiding = "off"`` and scenes with media."""
    guides = getattr(integ, "guides", None)
    if guides is None or guides.mode == "off" or integ.features(scene)["media"]:
        return 0.0
    fresh = type(guides)(guides.mode)
    sensor = scene.sensors()[0]
    share = guides.share(integ.selection_key(scene))       # None: the warm-up did not decide
    t = time.perf_counter()
    _, decide = fresh.for_primal(integ, scene, sensor, spp, integ.adaptive_applies(scene, sensor, 1, spp, guides=fresh))
    extra = 0.0
    if isinstance(decide, guide_cache.PilotDecision):    # (its records, made by pilots timed apart)
        paused = time.perf_counter()
        extra = recording_cost(integ, scene, spp, decide)
        t += time.perf_counter() - paused
    if decide is not None:
        decide(guiding.indirect_share(integ, scene) if share is None else share)
        integ._guide = None          # (decide sets it for the main pass; none follows here)
    dr.sync_thread()
    integ.guides = fresh
    return time.perf_counter() - t + extra


def recording_cost(integ, scene, spp: int, decide, repeats: int = 3) -> float:
    """Seconds that recording its paths for ``decide`` (a
    :class:`~draaw_mi.integrators.guide_cache.PilotDecision`) adds to the adaptive pilot of a
    render of ``spp`` (the median of ``repeats`` pilots with and without, after a warm-up of
    each); leaves ``decide`` holding the last records, as a render's pilot would."""
    sensor = scene.sensors()[0]
    w, h = (int(v) for v in sensor.film().crop_size())
    a = max(2, spp // ads.PILOT_FRACTION)
    if decide.records(a * w * h) is None:          # (the training traces its own)
        return 0.0
    times = {True: [], False: []}
    for k in range(repeats + 1):
        for record in (False, True):
            rec = decide.records(a * w * h) if record else None
            dr.sync_thread()
            t = time.perf_counter()
            pass_sums(integ, scene, sensor, a, 1 + k, False, False, pilot=True,
                           gather_first=True, record=rec)
            dr.sync_thread()
            if k:
                times[record].append(time.perf_counter() - t)
    return max(statistics.median(times[True]) - statistics.median(times[False]), 0.0)


def bench(name: str, res: int, args) -> dict | None:
    d = ss.build(name, res, args.sampler)
    if d is None:
        print(f"[{name}] skipped: its GO-Draaw data is absent (looked for {ss.GO_DRAAW}/monkey.obj)", file=sys.stderr)
        return None
    scene = ss.load_built(d)                       # a fixed emitter order
    depth = ss.max_depth(name)
    ref_dict = d if args.sampler == "independent" else ss.build(name, res)
    ref_scene = scene if args.sampler == "independent" else ss.load_built(ref_dict)
    ref, ref_var, t_ref = reference(name, res, ref_scene, depth, args.ref_spp, args.cache,
                                    ss.digest(ref_dict))
    noise = float(ref_var.mean())
    specs = args.integrators.split(";")
    integs = [mi.load_dict(parse_integrator(s, depth)) for s in specs]
    for it in integs:
        render(scene, it, args.spp, 1)                 # compile
    # V4's guide (its decision and training pass) is learned once per scene: counted in every
    # render's time, as if each were the scene's first (the median of LEARN_REPEATS learnings:
    # one measurement of 10-20 ms swung the glossy panel's 128^2 time ratio by 0.06)
    learn = [statistics.median(learning_time(it, scene, args.spp) for _ in range(LEARN_REPEATS))
             for it in integs]
    times = [[] for _ in specs]
    errs = [[] for _ in specs]
    for c in range(args.repeats):
        for k, it in enumerate(integs):
            img, dt = render(scene, it, args.spp, 100 + 7 * c)
            times[k].append(dt + learn[k])
            errs[k].append(float(np.mean((img - ref) ** 2)))
    mse = [max(float(np.mean(e)) - noise, 1e-30) for e in errs]
    rows = []
    for k, s in enumerate(specs):
        t_ratio = statistics.median(a / b for a, b in zip(times[k], times[0]))
        rows.append(dict(spec=s, time=statistics.median(times[k]), mse=mse[k],
                         mse_se=float(np.std(errs[k], ddof=1) / np.sqrt(len(errs[k]))),
                         t_ratio=t_ratio, mse_ratio=mse[k] / mse[0],
                         ratio=t_ratio * mse[k] / mse[0]))
    for row, t_learn in zip(rows, learn):
        row["learn"] = t_learn
    r = dict(name=name, res=res, depth=depth, rows=rows, noise=noise, t_ref=t_ref,
             ref_mean=float(ref.mean()), kind=ss.SCENES[name][0])
    line = "  ".join(f"{row['spec']}: {_fmt(row['ratio'])} (t {row['t_ratio']:.2f}, mse "
                     f"{_fmt(row['mse_ratio'])}{', guide %.2fs' % row['learn'] if row['learn'] else ''})"
                     for row in rows[1:])
    print(f"[{res} {name}] path {rows[0]['time']:.3f}s  {line}", file=sys.stderr, flush=True)
    return r


def _fmt(x: float) -> str:
    """Two decimals, or two significant digits below 0.1 (a ratio of 0.004 is not 0.00);
    never an exponent.

    Below 1e-4 (an MSE under the reference's own noise is clamped to 1e-30): ``<0.0001``.

    >>> _fmt(0.534), _fmt(0.0041), _fmt(0.00041), _fmt(1e-30), _fmt(0.0)
    ('0.53', '0.0041', '0.00041', '<0.0001', '0.00')
    """
    if not x > 0 or x >= 0.1:
        return f"{x:.2f}"
    if x < 1e-4:
        return "<0.0001"
    return f"{x:.{1 - math.floor(math.log10(x))}f}"


def report(results: list[dict], args) -> str:
    specs = args.integrators.split(";")
    out = ["# Speed suite: time to reach `path`'s error (draaw_mi/bench/speed.py)", "",
           f"Command: `{args.command}`  ",
           f"Machine: {platform.machine()}, {os.cpu_count()} cores ({load_note()}), "
           f"Dr.Jit threads {dr.thread_count()}, Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}; "
           f"{time.strftime('%Y-%m-%d %H:%M')}  ",
           f"Each scene's own pixel filter (box unless its row says), sampler `{args.sampler}` "
           f"for every integrator; V4's guide learning (its decision, training pass; the median "
           f"of {LEARN_REPEATS}) added to each of its render times; reference `path` at "
           f"{args.ref_spp} spp (its own noise subtracted from every MSE); {args.repeats} "
           f"interleaved cycles at {args.spp} spp, one seed per render.", "",
           "Cells: **time to reach `path`'s {0}-spp RMSE, relative to `path`** = median over "
           "cycles of the back-to-back time ratio x MSE ratio; in brackets (time ratio, MSE "
           "ratio). Below 1: faster than `path`.".format(args.spp), ""]
    for res in sorted({r["res"] for r in results}):
        rr = [r for r in results if r["res"] == res]
        out += [f"## {res}x{res}", "",
                "| scene | kind | depth | path s @ spp | " + " | ".join(f"`{s}`" for s in specs[1:]) + " |",
                "|---|---|---|---|" + "---|" * (len(specs) - 1)]
        for r in rr:
            cells = [f"**{_fmt(row['ratio'])}** ({row['t_ratio']:.2f}, {_fmt(row['mse_ratio'])})"
                     for row in r["rows"][1:]]
            out.append(f"| {r['name']} | {r['kind']} | {r['depth']} | {r['rows'][0]['time']:.3f} | "
                       + " | ".join(cells) + " |")
        meds = [statistics.median(r["rows"][k]["ratio"] for r in rr) for k in range(1, len(specs))]
        worst = [max(r["rows"][k]["ratio"] for r in rr) for k in range(1, len(specs))]
        out.append("| **median** | | | | " + " | ".join(f"**{_fmt(m)}** (max {_fmt(w)})"
                                                    for m, w in zip(meds, worst)) + " |")
        out.append("")
    return "\n".join(out) + "\n"


def main(argv=None, command: str | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", default="128,256")
    ap.add_argument("--scenes", default=",".join(ss.SCENES))
    ap.add_argument("--integrators", default="path;draaw_v4",
                    help="';'-separated specs plugin[:k=v,...]; the first is the baseline")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--repeats", type=int, default=6)
    ap.add_argument("--sampler", default="independent")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--cache", default=CACHE)
    ap.add_argument("--out", default=DEFAULT_OUT,
                    help="report file (default benchmarks/results/speed_suite_latest.md; '': print "
                    "only); benchmarks/results/speed_suite.md is the hand-curated record")
    args = ap.parse_args(argv)
    for opt, value in (("--spp", args.spp), ("--repeats", args.repeats)):
        if value < 1:          # (--spp 0 would render at the sampler's 64 spp and report 0)
            ap.error(f"{opt} {value}; expected an integer >= 1")
    why = check_ref_spp(args.ref_spp)
    if why:
        ap.error(f"--ref-spp {args.ref_spp}; {why}")
    try:
        resolutions = [int(x) for x in args.res.split(",")]
    except ValueError:
        resolutions = [0]
    if not resolutions or min(resolutions) < 1:
        ap.error(f"--res {args.res!r}; expected comma-separated integers >= 1")
    args.command = command or ("python benchmarks/speed_suite.py " + " ".join(sys.argv[1:] if argv is None else argv))
    unknown = [n for n in args.scenes.split(",") if n not in ss.SCENES]
    if unknown:
        raise SystemExit(f"speed suite: unknown scene {unknown[0]!r}{suggest(unknown[0], list(ss.SCENES))}")
    if args.threads:
        dr.set_thread_count(args.threads)
    results = []
    for res in resolutions:
        for name in args.scenes.split(","):
            r = bench(name, res, args)
            if r is not None:
                results.append(r)
            # each scene measured as the only one loaded: the bare scenes that draaw_mi.render
            # keeps to replay, and cycles, let go (live scenes' BSDFs are traced into every
            # loop: six scenes kept alive took the glossy panel's guide learning from 11 to 41 ms)
            release_wrapped()
            gc.collect()
    if not results:          # (an empty table and exit 0 would look like a finished run)
        raise SystemExit("speed suite: every requested scene was skipped; nothing was measured")
    text = report(results, args)
    print_report(text, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
