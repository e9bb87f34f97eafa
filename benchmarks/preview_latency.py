"""Preview latency and 1-second refinement error of ``draaw_mi.rendering.preview.Preview``.

What is measured (Cornell box at 256², the scene's V4 integrator and ``max_depth``):

* **Latency**: "change -> new frame available". The worker thread keeps refining; after a
  random 0-150 ms pause (a frame is usually in flight, as when a user drags a slider) one
  material value changes (``metal.roughness`` / ``metal.base_color`` alternately) and the clock
  runs until a frame showing that change is published (rendered, and denoised when asked).
  20 changes per configuration, configurations interleaved in rounds of 5 (A B C D A B ...);
  medians and 90th percentiles. Kernel cache misses are counted with ``dr.kernel_history()``
  over all measured changes (after one warm-up change per configuration).
* **Per-frame render time** of the 1-spp render, plain vs ``dr.freeze`` replay (medians over
  the same run's frames).
* **Error after 1 s of idle refinement**, with and without OIDN: after a change, the frame
  available 1.0 s later is compared with a V4 reference of ``--ref-spp`` samples (linear RMSE,
  RMSE of the sRGB-encoded display image, and the study's relative MSE). 3 repeats each,
  interleaved, medians.

By default the measurement runs inside a fresh Jupyter kernel (ipykernel via nbclient), the
way a notebook user runs the preview; ``--inline`` runs it in this process.

Usage::

    .venv/bin/python benchmarks/preview_latency.py            # writes benchmarks/results/preview_latency.md
    .venv/bin/python benchmarks/preview_latency.py --inline --changes 10 --ref-spp 256
"""
from __future__ import annotations

import argparse
import os
import platform
import random
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
OUT = os.path.join(HERE, "results", "preview_latency_latest.md")

CONFIGS = [  # name, Preview options
    ("plain", dict(freeze=False)),
    ("frozen", dict(freeze=True)),
    ("frozen + half-res first frame", dict(freeze=True, interactive_scale=0.5)),
    ("frozen + half-res first frame + OIDN", dict(freeze=True, interactive_scale=0.5, denoise=True)),
]


def _values(i):
    if i % 2:
        return {"metal.roughness": 0.15 + 0.1 * (i % 7)}
    return {"metal.base_color": [0.95, 0.77 - 0.05 * (i % 5), 0.45]}


def measure(args) -> str:
    import drjit as dr
    import numpy as np

    import draaw_mi
    from draaw_mi.bench.metrics import relmse
    from draaw_mi.io import read_exr, srgb_encode, write_exr
    from draaw_mi.rendering.preview import Preview

    if args.threads:
        dr.set_thread_count(args.threads)
    load0 = os.getloadavg()
    scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "cornell.toml"), resolution=(args.size, args.size))
    rng = random.Random(0)
    previews = [(name, Preview(scene, **opts)) for name, opts in CONFIGS]
    for name, pv in previews:                      # warm-up: compile / record, one change each
        pv.start()
        pv.wait(spp=2, timeout=120)
        g = pv.update(_values(0))
        pv.wait(g, spp=1, timeout=120)
        pv.stop()
    lat = {name: [] for name, _ in previews}
    frame_s = {name: [] for name, _ in previews}
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    misses = 0
    i = 1
    per_round = max(1, args.changes // 4)
    for _round in range(-(-args.changes // per_round)):
        for name, pv in previews:
            frames = []
            pv.on_frame(frames.append)
            pv.start()
            pv.wait(spp=1, timeout=60)
            for _ in range(per_round):
                if len(lat[name]) >= args.changes:
                    break
                time.sleep(rng.uniform(0.0, 0.15))
                t0 = time.perf_counter()
                g = pv.update(_values(i))
                f = pv.wait(g, timeout=60)
                lat[name].append(f.t_ready - t0)
                i += 1
            pv.stop()
            pv._callbacks.clear()
            frame_s[name] += [f.render_s for f in frames if not f.interactive]
            misses += sum(1 for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT and not k["cache_hit"])
    dr.set_flag(dr.JitFlag.KernelHistory, False)

    # ---- reference and 1 s refinement error
    # cached beside the speed suite's references (not in the repository), by the code that
    # renders it (a changed renderer renders it anew)
    from draaw_mi.bench.code_digest import code_digest
    cache = os.path.join(os.path.expanduser("~"), ".cache", "draaw-mi", "preview_refs")
    os.makedirs(cache, exist_ok=True)
    ref_path = os.path.join(cache, f"preview_ref_{args.size}_{args.ref_spp}_c{code_digest()}.exr")
    if os.path.isfile(ref_path):
        ref = read_exr(ref_path)[..., :3]
    else:
        ref = np.array(draaw_mi.render(scene, spp=args.ref_spp, seed=12345, pass_spp=16, post=[]))[..., :3]
        write_exr(ref_path, ref)

    def errs(img):
        return (float(np.sqrt(np.mean((img - ref) ** 2))),
                float(np.sqrt(np.mean((srgb_encode(img) - srgb_encode(ref)) ** 2))),
                relmse(img, ref))

    idle = {False: [], True: []}
    pvs = {d: Preview(scene, freeze=True, denoise=d) for d in (False, True)}
    for d, pv in pvs.items():
        pv.start()
        pv.wait(spp=2, timeout=60)
    for rep in range(3):
        for d in (False, True):
            pv = pvs[d]
            t0 = time.perf_counter()
            pv.update({"metal.roughness": 0.35})          # the file's value: the reference's scene
            time.sleep(max(0.0, 1.0 - (time.perf_counter() - t0)))
            f = pv.frame
            idle[d].append((f.spp,) + errs(f.image))
    for pv in pvs.values():
        pv.stop()

    def q90(x):
        return sorted(x)[max(0, int(round(0.9 * len(x))) - 1)]
    lines = [
        "# Preview latency (draaw_mi.rendering.preview)", "",
        f"Command: `.venv/bin/python benchmarks/preview_latency.py "
        f"{os.environ.get('DRAAW_MI_BENCH_ARGS', ' '.join(sys.argv[1:]))}`".replace(" `", "`"),
        f"Run inside: {'a Jupyter kernel (ipykernel via nbclient)' if os.environ.get('DRAAW_MI_IN_KERNEL') else 'a plain Python process'}.",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Dr.Jit threads {dr.thread_count()}, "
        f"Python {platform.python_version()}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. "
        "The configurations were interleaved so that any load hit them alike. Load average (1 min) at the "
        f"start {load0[0]:.1f}, at the end {os.getloadavg()[0]:.1f} (2 cores: above 2 means other jobs waited "
        "for the CPU too).", "",
        f"Scene `scenes/cornell.toml` at {args.size}x{args.size}, version {scene.settings['version']}, "
        f"max_depth {scene.settings['max_depth']}, 1 spp per frame.", "",
        "## Change -> new frame available", "",
        f"{args.changes} material changes per configuration (roughness / base colour), each after a random "
        "0-150 ms pause while the worker refines.", "",
        "| configuration | median latency | p90 latency | median 1-spp render (full res) |",
        "|---|---|---|---|",
    ]
    for name, _ in previews:
        fs = frame_s[name]
        lines.append(f"| {name} | {statistics.median(lat[name]) * 1e3:.0f} ms | {q90(lat[name]) * 1e3:.0f} ms | "
                     f"{statistics.median(fs) * 1e3:.0f} ms (n={len(fs)}) |" if fs else
                     f"| {name} | {statistics.median(lat[name]) * 1e3:.0f} ms | {q90(lat[name]) * 1e3:.0f} ms | - |")
    lines += ["", f"Kernel cache misses over all {sum(len(v) for v in lat.values())} measured changes "
              f"and their frames: **{misses}** (after one warm-up change per configuration).", "",
              "## Error after 1 s of idle refinement", "",
              f"Reference: V4 at {args.ref_spp} spp (same scene, another seed). Frame taken 1.0 s after a "
              "change; medians of 3 interleaved repeats.", "",
              "| preview | spp reached | RMSE (linear) | RMSE (sRGB display) | relMSE |", "|---|---|---|---|---|"]
    for d in (False, True):
        rows = idle[d]
        med = [statistics.median(r[k] for r in rows) for k in range(4)]
        lines.append(f"| {'OIDN-denoised (biased)' if d else 'raw running mean'} | {med[0]:.0f} | {med[1]:.4f} | "
                     f"{med[2]:.4f} | {med[3]:.4f} |")
    lines += ["", "Raw data (latencies in ms): " + "; ".join(
        f"{n}: " + ", ".join(f"{x * 1e3:.0f}" for x in lat[n]) for n, _ in previews), ""]
    return "\n".join(lines)


def in_kernel(argv) -> str:
    import nbclient
    import nbformat
    code = (f"import os, sys\nos.environ['DRAAW_MI_IN_KERNEL'] = '1'\n"
            f"os.environ['DRAAW_MI_BENCH_ARGS'] = {' '.join(a for a in argv if a != '--inline')!r}\n"
            f"sys.argv = {['preview_latency.py'] + argv!r}\n"
            f"sys.path.insert(0, {HERE!r})\nimport preview_latency as pl\nprint(pl.measure(pl.parse(sys.argv[1:])))")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)])
    nbclient.NotebookClient(nb, kernel_name="python3", timeout=3600, resources={"metadata": {"path": ROOT}}).execute()
    return "".join(o.get("text", "") for o in nb.cells[0].outputs if o.output_type == "stream").strip() + "\n"


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=256)
    p.add_argument("--changes", type=int, default=20)
    p.add_argument("--ref-spp", type=int, default=1024)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--inline", action="store_true", help="measure in this process, not in a Jupyter kernel")
    p.add_argument("--out", default=OUT)
    return p.parse_args(argv)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    args = parse(argv)
    text = measure(args) if args.inline else in_kernel([a for a in argv if a != "--inline"] + ["--inline"])
    print(text)
    from draaw_mi.io import atomic_path
    with atomic_path(args.out, ".tmp") as tmp:
        with open(tmp, "w") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
