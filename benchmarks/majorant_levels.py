"""Majorant grids: cells on voxel centres with a per-medium size (media/majorant.py, session 33)
against the scheme before it (16 cells per axis on voxel faces, dilated by one voxel), both
in draaw_v4, in one run.

Cases (the media benchmark's scenes, ``benchmarks/media_speed.py``):

* ``one_voxel`` -- a 64^3 grid, empty but for one voxel of density 1e4;
* ``blobs`` -- three blobs of density 200 in an empty 64^3 grid;
* ``smoke.toml`` -- the shipped plume scene;
* ``dense_4`` -- a 4^3 grid, empty but for one voxel of density 1e4 (the case that rendered
  too dark: flights through empty space ran past the trackers' step cap).

For each: the time per render (median of ``--repeats``, schemes interleaved, after a warm-up)
and the image mean at ``--mean-spp`` against Mitsuba's ``volpath`` at the same spp (its standard
error from ``--seeds`` renders of each).

Usage::

    .venv/bin/python benchmarks/majorant_levels.py      # writes benchmarks/results/majorant_levels.md
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

import draaw_mi  # noqa: F401  (variant + plugins)
import drjit as dr
import mitsuba as mi

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "tests", "media"))
import media_scenes as ms  # noqa: E402
import media_speed  # noqa: E402

import draaw_mi.integrators.volume as volume  # noqa: E402
import draaw_mi.media.majorant as majorant  # noqa: E402
from draaw_mi.bench.study import with_load_note  # noqa: E402
from draaw_mi.media import VoxelGrid  # noqa: E402
from draaw_mi.media.mitsuba_dicts import smoke_shape  # noqa: E402

NEW_LEVEL = majorant.choose_level


def faces_dilated_level(data, lo, hi, resolution=16, factor=1.0):
    """The scheme before: ``min(16, n)`` cells per axis with faces on voxel faces, each the
    maximum over the voxels it overlaps dilated by one (a reference kept for this comparison;
    ``factor``, the tracker's scale of the bounds, does not change its cells)."""
    n = np.asarray(data.shape)
    res = [int(min(resolution, s)) for s in n]
    out = data
    for a in range(3):
        edges = np.linspace(0, n[a], res[a] + 1)
        i0 = np.maximum(np.floor(edges[:-1]).astype(int) - 1, 0)
        i1 = np.minimum(np.ceil(edges[1:]).astype(int) + 1, n[a])
        out = np.concatenate([np.max(np.take(out, np.arange(s, e), axis=a), axis=a, keepdims=True)
                              for s, e in zip(i0, i1)], axis=a)
    return out, np.asarray(lo, float), np.asarray(hi, float), n / np.asarray(res)


SCHEMES = {"before (faces, dilated, 16)": faces_dilated_level, "centres, per medium": NEW_LEVEL}


def dense_4(integrator: str, res: int) -> mi.Scene:
    g = VoxelGrid.empty((4, 4, 4), (-1, -1, -1), (1, 1, 1))
    g.smoke_color[:] = 0.8
    g.density[2, 2, 2] = 1e4
    d = ms.base({"type": integrator, "max_depth": 8}, res)
    d["smoke"] = smoke_shape(g, g_phase=0.3)
    return mi.load_dict(d)


CASES = {
    "one_voxel": lambda k, r: media_speed.grid_scene("one_voxel", k, r),
    "blobs": lambda k, r: media_speed.grid_scene("blobs", k, r),
    "smoke.toml": media_speed.smoke_toml_scene,
    "dense_4": dense_4,
}


def use(scheme):
    """Majorant tables built from now on use ``scheme`` (a scene keeps the table of its first
    render: ``volume._TABLES`` is keyed by scene)."""
    majorant.choose_level = SCHEMES[scheme]


def timed(scene, spp, seed):
    t = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return time.perf_counter() - t, float(np.mean(np.array(img, dtype=np.float64)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, default=48)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--mean-spp", type=int, default=16)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--ref-res", type=int, default=16, help="resolution of the mean comparison")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "majorant_levels.md"))
    a = ap.parse_args(argv)
    lines = ["# Majorant grids: cells on voxel centres, sized per medium, vs the scheme before", "",
             f"`python benchmarks/majorant_levels.py` — draaw_v4, {a.res}x{a.res} at {a.spp} spp, median of "
             f"{a.repeats} interleaved repeats after a warm-up; image means at {a.ref_res}x{a.ref_res}, "
             f"{a.seeds} x {a.mean_spp} spp, against Mitsuba's volpath at the same spp (± its standard error). "
             f"Machine: {os.cpu_count()} cores, {dr.thread_count()} Dr.Jit threads, LOAD_NOTE.", "",
             "| scene | cells before | cells now | time before [s] | time now [s] | now / before | "
             "mean before | mean now | volpath mean ± s.e. |", "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for name, make in CASES.items():
        scenes, cells, times, means = {}, {}, {}, {}
        for s in SCHEMES:
            use(s)
            scenes[s] = make("draaw_v4", a.res)
            timed(scenes[s], a.spp, 0)                       # (builds its table, compiles)
            cells[s] = volume.media_table(scenes[s]).describe()[0].split(": ", 1)[1]
            times[s] = []
        for r in range(a.repeats):
            for s in SCHEMES:
                times[s].append(timed(scenes[s], a.spp, r + 1)[0])
        for s in SCHEMES:
            use(s)
            sc = make("draaw_v4", a.ref_res)
            means[s] = float(np.mean([timed(sc, a.mean_spp, 100 + i)[1] for i in range(a.seeds)]))
        ref = make("volpath", a.ref_res)
        rm = [timed(ref, a.mean_spp, 200 + i)[1] for i in range(a.seeds)]
        before, now = (statistics.median(times[s]) for s in SCHEMES)
        mb, mn = (means[s] for s in SCHEMES)
        cb, cn = (cells[s] for s in SCHEMES)
        lines.append(f"| {name} | {cb} | {cn} | {before:.3f} | {now:.3f} | {now / before:.2f} | {mb:.4f} | {mn:.4f} | "
                     f"{np.mean(rm):.4f} ± {np.std(rm, ddof=1) / np.sqrt(len(rm)):.4f} |")
        print(lines[-1], flush=True)
    use("centres, per medium")
    lines += ["", "The means' own noise: each is the mean of its seeds' image means; the draaw_v4 means carry a "
              "standard error like volpath's (same spp)."]
    from draaw_mi.io import write_text
    text = with_load_note("\n".join(lines) + "\n")      # the load measured at the end
    write_text(a.out, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
