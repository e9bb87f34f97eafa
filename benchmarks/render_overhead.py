"""Time outside kernels for small repeated renders (``draaw_mi.render``, frozen vs traced).

For each version, renders the Cornell box (``scenes/cornell.toml``) at ``--res``² and
``--spp`` spp ``--repeats`` times with new seeds (after warm-up calls), with
frozen (the render session's recorded pass), traced (``mi.render``) and whole
``draaw_mi.render`` calls, interleaved.
Per call: the time until the call returns (host: Python tracing or frozen replay), the wall
time to the evaluated image, and the summed execution time of the kernels it launched
(``dr.kernel_history``). Reports medians.

Then the same render repeated back to back (as a fit loop or a preview repeats it), per
version and mode; then Dr.Jit's own floor: what a plain ``dr.freeze`` of ``mi.render`` with
Mitsuba's ``path`` spends outside kernels, on this scene and on Mitsuba's ``mi.cornell_box()``
(no draaw-mi code in the call), beside a frozen function that takes the scene and does nothing.

Usage::

    .venv/bin/python benchmarks/render_overhead.py            # 64x64, 4 spp, V1..V4 and path
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import draaw_mi
import drjit as dr
import mitsuba as mi

import importlib
from draaw_mi.rendering.session import session_of  # noqa: E402
from draaw_mi.guard import COLLECTOR_PAUSED  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def timed(call):
    """(wall, host, kernels) seconds of ``call()``: ``host`` = until it returns (kernels run
    asynchronously), ``wall`` = until its result is evaluated, ``kernels`` = the summed
    execution time of the JIT kernels it launched (``dr.kernel_history``)."""
    dr.kernel_history_clear()
    t = time.perf_counter()
    out = call()
    host = time.perf_counter() - t
    dr.eval(out)
    dr.sync_thread()
    wall = time.perf_counter() - t
    kern = sum(k.get("execution_time", 0.0) for k in dr.kernel_history()
               if k["type"] == dr.KernelType.JIT) / 1000.0
    return wall, host, kern


def one(scene, version, spp, seed, mode):
    """:func:`timed` of one render (``api``: the whole call, which waits for its image).
    ``mode``: ``frozen`` (the integrator's recorded render), ``traced`` (``mi.render``),
    ``api`` (``draaw_mi.render`` as a user calls it: the frozen render plus its argument
    handling)."""
    session = session_of(scene)
    integ = session.integrator(version, scene.settings["max_depth"])
    if mode == "frozen":
        return timed(lambda: session.recording(integ, spp)(scene.mi_scene, dr.opaque(mi.UInt32, seed), scene, session))
    if mode == "api":
        return timed(lambda: draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[]))
    return timed(lambda: mi.render(scene.mi_scene, integrator=integ, spp=spp, seed=seed))


def floor_rows(scene, args) -> list:
    """Report lines: the time outside kernels of frozen calls with no draaw-mi code in them,
    interleaved, ``args.repeats`` each after warm-up. Rows: a frozen function taking only the
    seed (Dr.Jit's replay alone), one taking the scene too and returning ``seed + 1`` (the
    walk over the scene's variables, before and after the replay), ``dr.freeze`` of
    ``mi.render`` with Mitsuba's ``path`` on this scene and on ``mi.cornell_box()`` at the
    same size and spp, and draaw-mi's frozen ``path`` on this scene for comparison."""
    res = args.res
    box = mi.cornell_box()
    box["sensor"]["film"].update(width=res, height=res, rfilter={"type": "box"})
    box_scene = mi.load_dict(box)
    path = mi.load_dict({"type": "path", "max_depth": scene.settings["max_depth"]})
    seed_only = dr.freeze(lambda seed: seed + 1, auto_opaque=False)
    with_scene = dr.freeze(lambda sc, seed: seed + 1, auto_opaque=False)
    mi_render = dr.freeze(lambda sc, seed: mi.render(sc, integrator=path, seed=seed, spp=args.spp),
                          auto_opaque=False)
    session = session_of(scene)
    ours = session.recording(session.integrator("path", scene.settings["max_depth"]), args.spp)
    calls = {
        "frozen `seed + 1`, seed only": lambda s: seed_only(s),
        "frozen `seed + 1`, taking the scene": lambda s: with_scene(scene.mi_scene, s),
        "`dr.freeze(mi.render)`, `path`, this scene": lambda s: mi_render(scene.mi_scene, s),
        "`dr.freeze(mi.render)`, `path`, `mi.cornell_box()`": lambda s: mi_render(box_scene, s),
        "draaw-mi's frozen `path`, this scene": lambda s: ours(scene.mi_scene, s, scene, session),
    }
    data = {k: [] for k in calls}
    for i in range(args.repeats + 3):
        for name, call in calls.items():
            wall, _, kern = timed(lambda: call(dr.opaque(mi.UInt32, 3000 + i)))
            if i >= 3:                                              # after warm-up / recording
                data[name].append((wall, kern))
    lines = ["", f"Dr.Jit's own floor: frozen calls with no draaw-mi code in them, {args.repeats} "
             "interleaved calls each after 3 warm-up calls, medians (outside = wall - summed JIT "
             "kernel time):", "", "| frozen call | wall ms | outside ms | outside |", "|---|---|---|---|"]
    for name, d in data.items():
        wall = statistics.median(w for w, _ in d)
        outside = statistics.median(w - k for w, k in d)
        frac = statistics.median((w - k) / w for w, k in d)
        lines.append(f"| {name} | {1e3 * wall:.2f} | {1e3 * outside:.3f} | {100 * frac:.1f} % |")
    return lines


def step_rows(scene, args) -> list:
    """Report lines: draaw-mi's own host steps before a frozen replay (what
    ``frozen.freeze_render``'s call does before handing over to Dr.Jit), each timed right
    after the previous render's kernels (cold caches, as in a repeated render), V4 and
    ``path``, ``args.repeats`` renders each, medians in microseconds."""
    F = importlib.import_module("draaw_mi.rendering.frozen")
    names = ("recording lookup", "live-BSDF check", "scene_scalars", "V4 freeze_state",
             "Dr.Jit frozen call (host)")
    lines = ["", "draaw-mi's own steps before a frozen replay, each timed right after the previous "
             f"render's kernels, medians of {args.repeats} renders (us):", "",
             "| version | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    session = session_of(scene)
    for version in ("v4", "path"):
        integ = session.integrator(version, scene.settings["max_depth"])
        state_of = getattr(integ, "freeze_state", None)
        rows = []
        for i in range(args.repeats + 3):
            t = [time.perf_counter()]
            call = session.recording(integ, args.spp)
            t.append(time.perf_counter())
            live = F.other_live_bsdfs(scene.mi_scene, session)
            t.append(time.perf_counter())
            scalars = F.scene_scalars(scene.mi_scene, scene, session)
            t.append(time.perf_counter())
            state = None if state_of is None else state_of(scene.mi_scene, session.memo)
            t.append(time.perf_counter())
            with COLLECTOR_PAUSED:                        # as freeze_render's call does
                img = call.frozen(scene.mi_scene, scalars, dr.opaque(mi.UInt32, 5000 + i), state, live, ())
            t.append(time.perf_counter())
            dr.eval(img)
            dr.sync_thread()
            if i >= 3:
                rows.append([b - a for a, b in zip(t, t[1:])])
        cells = [f"{1e6 * statistics.median(r[j] for r in rows):.0f}" for j in range(len(names))]
        if state_of is None:
            cells[3] = "-"
        lines.append(f"| {version} | " + " | ".join(cells) + " |")
    return lines


def live_scene_rows(scene, args) -> list:
    """Report lines: a frozen V4 render of the Cornell box while 0, 1 and 3 other scenes
    (``scenes/material_spheres.toml``) are loaded in the process, and a frozen function that
    takes the Cornell box and only adds 1 to the seed. Dr.Jit's replay walks every registered
    shape, emitter and sensor of the variant, and a BSDF call records every live BSDF, other
    scenes' too: what a notebook that keeps several scenes alive pays on each render."""
    session = session_of(scene)
    integ = session.integrator("v4", scene.settings["max_depth"])
    lines = ["", "A frozen V4 render of this scene while other scenes (`scenes/material_spheres.toml`, "
             f"{args.res}x{args.res}) are loaded in the process, {args.repeats} renders each after "
             "3 warm-up renders, medians; *walk* = a frozen function that takes this scene and only "
             "adds 1 to the seed:", "",
             "| other scenes loaded | wall ms | kernel ms | outside ms | outside | walk ms |",
             "|---|---|---|---|---|---|"]
    others = []
    for count in (0, 1, 3):
        while len(others) < count:
            others.append(draaw_mi.load_scene(os.path.join(ROOT, "scenes", "material_spheres.toml"),
                                              resolution=(args.res, args.res)))
        walk = dr.freeze(lambda sc, seed: seed + 1, auto_opaque=False)
        call = session.recording(integ, args.spp)
        data, walks = [], []
        for i in range(args.repeats + 3):
            seed = dr.opaque(mi.UInt32, 7000 + i)
            wall, _, kern = timed(lambda: call(scene.mi_scene, seed, scene, session))
            walks.append(timed(lambda: walk(scene.mi_scene, seed))[0])
            if i >= 3:
                data.append((wall, kern))
        wall = statistics.median(w for w, _ in data)
        kern = statistics.median(k for _, k in data)
        outside = statistics.median(w - k for w, k in data)
        frac = statistics.median((w - k) / w for w, k in data)
        lines.append(f"| {count} | {1e3 * wall:.2f} | {1e3 * kern:.2f} | {1e3 * outside:.3f} | "
                     f"{100 * frac:.1f} % | {1e3 * statistics.median(walks[3:]):.3f} |")
    del others
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=100)
    ap.add_argument("--versions", default="v1,v2,v3,v4,path")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "render_overhead_latest.md"))
    args = ap.parse_args(argv)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "cornell.toml"),
                                resolution=(args.res, args.res))
    versions = args.versions.split(",")
    modes = ("frozen", "traced", "api")
    data = {(v, m): [] for v in versions for m in modes}
    for v in versions:
        for m in modes:
            for s in range(3):
                one(scene, v, args.spp, 1000 + s, m)       # compile / record
    for i in range(args.repeats):
        for v in versions:
            # the mode after a traced render finds the caches cold: rotate which one it is
            for m in modes[i % 3:] + modes[:i % 3]:
                data[(v, m)].append(one(scene, v, args.spp, 7 + i, m))
    out = ["# Time outside kernels, small repeated renders (benchmarks/render_overhead.py)", "",
           f"Command: `.venv/bin/python benchmarks/render_overhead.py {' '.join(sys.argv[1:])}`  ",
           f"Machine: {platform.machine()}, {os.cpu_count()} cores (load average "
           f"{os.getloadavg()[0]:.1f} at the end, this job included), Dr.Jit "
           f"threads {dr.thread_count()}; {time.strftime('%Y-%m-%d %H:%M')}  ",
           f"`draaw_mi.render(scenes/cornell.toml, {args.res}x{args.res}, spp={args.spp}, new seed "
           f"each call)`: the integrator render call as `draaw_mi.render` makes it for such small "
           f"renders (frozen: the session's recording, seed `dr.opaque`; traced: `mi.render`), medians of "
           f"{args.repeats} interleaved calls after warm-up (the order of the three modes rotated). *host* = time until the call returns "
           "(Python tracing, or the frozen replay's dispatch; kernels run asynchronously), "
           "*outside* = wall - summed kernel execution time (`dr.kernel_history`; includes "
           "thread wake-ups and, on a shared machine, waiting for a core). *api* = the same "
           "frozen render through `draaw_mi.render(scene, version, spp, seed, post=[])`, "
           "argument handling included (what a user's call costs); the last column is the median "
           "over repeats of the difference between the api and frozen calls of one repeat.", "",
           "| version | frozen: wall ms | host ms | host / wall | outside | traced: wall ms | host ms "
           "| host / wall | outside | api: wall ms | outside | api - frozen outside, paired ms |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for v in versions:
        cells = []
        for m in modes:
            d = data[(v, m)]
            wall = statistics.median(w for w, _, _ in d)
            host = statistics.median(h for _, h, _ in d)
            frac_h = statistics.median(h / w for w, h, _ in d)
            frac_o = statistics.median((w - k) / w for w, _, k in d)
            if m == "api":
                cells.append(f"{1e3 * wall:.1f} | {100 * frac_o:.1f} %")
            else:
                cells.append(f"{1e3 * wall:.1f} | {1e3 * host:.1f} | {100 * frac_h:.1f} % | {100 * frac_o:.1f} %")
        paired = statistics.median((wa - ka) - (wf - kf) for (wa, _, ka), (wf, _, kf)
                                   in zip(data[(v, "api")], data[(v, "frozen")]))
        cells.append(f"{1e3 * paired:+.3f}")
        out.append(f"| {v} | " + " | ".join(cells) + " |")
    # The same render repeated back to back, as a fit loop or a preview repeats it (the table
    # above interleaves versions and traced renders, which leave the caches and threads cold)
    out += ["", f"Back to back: per version, {args.repeats} calls of one mode in a row after 3 warm-up "
            "calls (frozen, then api), medians:", "",
            "| version | frozen: wall ms | outside | api: wall ms | outside |", "|---|---|---|---|---|"]
    for v in versions:
        cells = []
        for m in ("frozen", "api"):
            for s in range(3):
                one(scene, v, args.spp, 500 + s, m)
            d = [one(scene, v, args.spp, 600 + i, m) for i in range(args.repeats)]
            wall = statistics.median(w for w, _, _ in d)
            frac_o = statistics.median((w - k) / w for w, _, k in d)
            cells.append(f"{1e3 * wall:.1f} | {100 * frac_o:.1f} %")
        out.append(f"| {v} | " + " | ".join(cells) + " |")
    out += floor_rows(scene, args)
    out += step_rows(scene, args)
    out += live_scene_rows(scene, args)
    text = "\n".join(out) + "\n"
    from draaw_mi.io import print_report
    print_report(text, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
