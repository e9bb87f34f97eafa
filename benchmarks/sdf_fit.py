"""Shape fits of SDF parameters from rendered views, with and without the boundary terms
(``sdf_silhouettes``): recovery error and time per case.

    .venv/bin/python benchmarks/sdf_fit.py                  # every case, both modes
    .venv/bin/python benchmarks/sdf_fit.py --cases blob --modes on --iterations 60

Each case: an SDF scene with a lit floor and backdrop, two views at 96x96, references rendered
with ``draaw_v4`` at 1024 spp (Mitsuba's ``path`` does not see SDFs) and another seed, a fit with ``draaw_v4``
from starting values 20-30 % off. Writes ``benchmarks/results/sdf_fit.md`` (and ``.json``).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import draaw_mi  # noqa: E402

RES = 96
VIEWS = [{"origin": [0.0, 1.3, 4.2], "target": [0.0, 0.5, 0.0], "fov": 36},
         {"origin": [3.0, 1.8, 2.8], "target": [0.0, 0.5, 0.0], "fov": 36}]


def description(sdf: list) -> dict:
    """A clay-coloured SDF object on a grey floor before a white backdrop, a point light
    and a dim sky (every outline has a lit surface behind it)."""
    return {
        "render": {"resolution": [RES, RES], "spp": 16, "max_depth": 3, "filter": "box"},
        "camera": VIEWS[0],
        "materials": {"clay": {"base_color": [0.75, 0.32, 0.18], "roughness": 0.5},
                      "ground": {"base_color": [0.55, 0.55, 0.55], "roughness": 0.8},
                      "wall": {"base_color": [0.85, 0.85, 0.85], "roughness": 0.9}},
        "shapes": [{"type": "rectangle", "name": "floor", "material": "ground", "scale": 6.0,
                    "rotate": {"axis": [1, 0, 0], "angle": -90}},
                   {"type": "rectangle", "name": "backdrop", "material": "wall", "scale": 6.0,
                    "translate": [0.0, 0.0, -1.6]}],
        "lights": [{"type": "point", "position": [1.5, 3.5, 3.0], "intensity": 25.0},
                   {"type": "constant", "intensity": 0.35}],
        "sdf": sdf,
    }


# name: (sdf entries (truth), parameters, starting values)
CASES = {
    # the case: a ball smoothly merged into a slab; radius, centre and blend radius
    "blob": ([{"type": "sphere", "name": "ball", "material": "clay", "center": [0.12, 0.75, 0.0], "radius": 0.55},
              {"type": "box", "name": "slab", "material": "clay", "center": [0.0, 0.2, 0.0], "size": [1.8, 0.3, 1.0]},
              {"type": "smooth_union", "name": "blob", "children": ["ball", "slab"], "k": 0.25}],
             ["sdf.ball.radius", "sdf.ball.center", "sdf.blob.k"],
             {"sdf.ball.radius": 0.42, "sdf.ball.center": [-0.05, 0.75, 0.0], "sdf.blob.k": 0.18}),
    "sphere": ([{"type": "sphere", "name": "ball", "material": "clay", "center": [0.1, 0.65, 0.0], "radius": 0.6}],
               ["sdf.ball.radius", "sdf.ball.center"],
               {"sdf.ball.radius": 0.45, "sdf.ball.center": [-0.1, 0.8, 0.15]}),
    "box_size": ([{"type": "box", "name": "blk", "material": "clay", "center": [0.0, 0.5, 0.0],
                   "size": [1.2, 0.9, 0.8], "rotate": {"axis": [0, 1, 0], "angle": 25}}],
                 ["sdf.blk.size"], {"sdf.blk.size": [0.9, 1.15, 1.0]}),
    "smooth_k": ([{"type": "sphere", "name": "a", "material": "clay", "center": [-0.45, 0.6, 0.0], "radius": 0.45},
                  {"type": "sphere", "name": "b", "material": "clay", "center": [0.45, 0.6, 0.0], "radius": 0.45},
                  {"type": "smooth_union", "name": "u", "children": ["a", "b"], "k": 0.4}],
                 ["sdf.u.k"], {"sdf.u.k": 0.29}),
    "translate": ([{"type": "sphere", "name": "core", "material": "clay", "center": [0.0, 0.0, 0.0], "radius": 0.5,
                    "translate": [0.15, 0.6, 0.1]}],
                  ["sdf.core_xf.translate"], {"sdf.core_xf.translate": [-0.05, 0.75, -0.1]}),
}


def truth_of(sdf: list, params: list[str]) -> dict:
    scene = draaw_mi.load_scene(description(sdf))
    p = draaw_mi.sdf.parameters(scene)
    out = {}
    for k in params:
        v = np.array(p[k]).ravel()
        out[k] = v.tolist() if v.size > 1 else float(v[0])
    return out


def references(sdf: list, spp: int) -> list[np.ndarray]:
    scene = draaw_mi.load_scene(description(sdf))
    refs = []
    for v in VIEWS:
        d = description(sdf)
        d["camera"] = v
        refs.append(np.array(draaw_mi.render(draaw_mi.load_scene(d), version="v4", spp=spp, seed=7, post=[]))[..., :3])
    del scene
    return refs


def errors(fitted: dict, truth: dict) -> dict:
    out = {}
    for k, t in truth.items():
        out[k] = float(np.max(np.abs(np.array(fitted[k], float) - np.array(t, float))))
    return out


def run_case(name: str, mode: str, iterations: int, ref_spp: int, spp: int, lr: float, seed: int) -> dict:
    sdf, params, start = CASES[name]
    truth = truth_of(sdf, params)
    refs = references(sdf, ref_spp)
    scene = draaw_mi.load_scene(description(sdf))
    t0 = time.perf_counter()
    res = draaw_mi.fit(scene, refs, params=params, views=VIEWS, version="v4", spp=spp, iterations=iterations,
                       lr=lr, init=start, seed=seed, post=[], progress=False, average_last=0.2,
                       integrator_options={"sdf_silhouettes": mode == "on"})
    seconds = time.perf_counter() - t0
    fitted = {k: (np.array(v).ravel().tolist() if np.size(v) > 1 else float(np.ravel(v)[0]))
              for k, v in res.values.items()}
    err = errors(fitted, truth)
    start_err = errors({k: start[k] for k in truth}, truth)
    return {"case": name, "mode": mode, "seconds": seconds, "iterations": iterations, "truth": truth,
            "start": start, "fitted": fitted, "error": err, "start_error": start_err}


def table(rows: list[dict]) -> str:
    lines = ["| case | silhouettes | parameter | truth | start | fitted | abs. error | time (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for k in r["truth"]:
            def fmt(v):
                return "(" + ", ".join(f"{x:.3f}" for x in v) + ")" if isinstance(v, list) else f"{v:.3f}"
            lines.append(f"| {r['case']} | {r['mode']} | `{k}` | {fmt(r['truth'][k])} | {fmt(r['start'][k])} | "
                         f"{fmt(r['fitted'][k])} | {r['error'][k]:.4f} | {r['seconds']:.0f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--modes", default="on,off")
    ap.add_argument("--iterations", type=int, default=80)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--lr", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results", "sdf_fit"))
    a = ap.parse_args(argv)
    rows = []
    for name in a.cases.split(","):
        for mode in a.modes.split(","):
            r = run_case(name, mode, a.iterations, a.ref_spp, a.spp, a.lr, a.seed)
            rows.append(r)
            print(f"{name:10s} silhouettes={mode:3s} {r['seconds']:6.1f} s  " +
                  "  ".join(f"{k.split('.', 1)[1]} err {e:.4f}" for k, e in r["error"].items()), flush=True)
    md = table(rows)
    print(md)
    if a.out:
        with open(a.out + ".json", "w") as f:
            json.dump(rows, f, indent=1)
        with open(a.out + ".md", "w") as f:
            f.write("# SDF shape fits, with and without the boundary terms\n\n"
                    f"`{' '.join(['.venv/bin/python', 'benchmarks/sdf_fit.py'] + (argv or sys.argv[1:]))}`: "
                    f"two views at {RES}x{RES}, references `draaw_v4` at {a.ref_spp} spp, `draaw_v4` at {a.spp} spp, "
                    f"{a.iterations} Adam iterations, lr {a.lr}; errors are the largest absolute error over a "
                    "parameter's components (scene units).\n\n" + md + "\n")
    return rows


if __name__ == "__main__":
    main()
