"""Kernel sizes (``operation_count`` of the primal render kernel) of the render versions.

Two tables: (1) every integrator on the official scenes and Mitsuba's own Cornell box;
(2) draaw_v4 on ``reference_scenes.feature_scene`` with every feature on, then with each
feature removed in turn (design.md §5: an absent feature adds nothing to the kernel).

Usage: ``.venv/bin/python benchmarks/integrators_kernels.py [--out FILE]``
(default ``benchmarks/results/integrators_kernels.md``).
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
import time

import draaw_mi
import drjit as dr
import mitsuba as mi

from draaw_mi.bench import reference_scenes as rs
from draaw_mi.integrators.features import describe, detect_features
from draaw_mi.io import write_text

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KINDS = ("path", "prb", "draaw_v4", "draaw_v3", "draaw_v2", "draaw_v1")
ALL = dict(area=True, point=True, spot=True, envmap=True, texture=True, normalmap=True,
           glass=True, conductor=True, two_sided=True)


def render_ops(scene, integ) -> tuple[int, int]:
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.kernel_history()
    img = mi.render(scene, integrator=integ, spp=4, seed=0)
    dr.eval(img)
    dr.sync_thread()
    ks = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    k = max(ks, key=lambda k: k["operation_count"])
    return k["operation_count"], k["ir"].getvalue().count("\n")


def scenes():
    for name in ("cornell", "material_spheres"):
        path = os.path.join(ROOT, "scenes", f"{name}.toml")
        yield f"scenes/{name}.toml", lambda p=path: draaw_mi.load_scene(p, resolution=(16, 16)).mi_scene
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=16, height=16, rfilter={"type": "box"})
    yield "mi.cornell_box() (diffuse)", lambda d=d: mi.load_dict(d)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results",
                                                  "integrators_kernels_latest.md"))
    args = ap.parse_args(argv)
    out = ["# Integrators: kernel sizes (benchmarks/integrators_kernels.py)", "",
           f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}, {mi.variant()}, "
           f"{time.strftime('%Y-%m-%d')}. `operation_count` of the largest JIT kernel of one "
           "primal render (4 spp, 16x16, max_depth 6).", "",
           "## Every integrator", "",
           "| scene | features | " + " | ".join(KINDS) + " | v4 / path |",
           "|---|---|" + "---|" * len(KINDS) + "---|"]
    for label, make in scenes():
        gc.collect()
        scene = make()
        n = {k: render_ops(scene, mi.load_dict({"type": k, "max_depth": 6}))[0] for k in KINDS}
        out.append(f"| {label} | {describe(detect_features(scene))} | "
                   + " | ".join(str(n[k]) for k in KINDS)
                   + f" | {n['draaw_v4'] / n['path']:.3f} |")
        del scene
    out += ["", "## draaw_v4: one feature removed at a time (feature_scene at 8x8, 4 spp, max_depth 5, "
            "aovs='all')", "",
            "| scene | ops | change |", "|---|---|---|"]

    def v4_ops(aovs="all", **opts):
        gc.collect()
        scene = mi.load_dict(rs.feature_scene(res=8, spp=4, **opts))
        n = render_ops(scene, mi.load_dict({"type": "draaw_v4", "max_depth": 5,
                                            "aovs": aovs}))[0]
        del scene
        return n

    full = v4_ops(**ALL)
    out.append(f"| all features | {full} | |")
    for f in ALL:
        n = v4_ops(**dict(ALL, **{f: False}))
        out.append(f"| without {f} | {n} | {n - full:+d} |")
    n = v4_ops(aovs="", **ALL)
    out.append(f"| without AOVs | {n} | {n - full:+d} |")
    n = v4_ops(area=True)
    out.append(f"| area light only, no other feature | {n} | {n - full:+d} |")
    text = "\n".join(out) + "\n"
    print(text)
    if args.out:
        write_text(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
