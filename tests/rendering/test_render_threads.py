"""Renders from several threads of one process: a preview's worker beside render(), a fit or
a batch in the same notebook, or the user's own threads.

Dr.Jit 1.5's ``dr.freeze`` recording breaks when another thread traces a render meanwhile
(:mod:`draaw_mi.guard`): before the guard, two threads rendering two scenes
aborted the process on LLVM IR that did not parse (3 runs in 3), and a preview running while
the notebook rendered another scene died with ``jit_var(r223): unknown variable!``; with the
renders alone guarded, a batch beside the preview rendered 4 of 8 frames wrong. The
scenarios run in a child process, since the failure is an abort (or a hang after it).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

CHILD = r'''
import sys, threading, time
import numpy as np
import draaw_mi
from draaw_mi.rendering.preview import Preview

SECONDS = float(sys.argv[1])

def description(red, light):
    return {"render": {"resolution": [16, 16]},
        "materials": {"m": {"base_color": [red, 0.5, 0.5], "roughness": 0.3}},
        "shapes": [{"type": "sphere", "material": "m"},
                   {"type": "rectangle", "translate": [0, -1, 0], "scale": 3,
                    "rotate": {"axis": [1, 0, 0], "angle": -90}}],
        "lights": [light], "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}}

def scene(red, light):
    return draaw_mi.load_scene(description(red, light))

a = scene(0.2, {"type": "constant"})
b = scene(0.8, {"type": "point", "position": [0, 3, 2], "intensity": 20})
counts = (1, 2, 4)          # several recordings per scene, made while the other thread renders
seen = {}                   # (scene, spp) -> the first image: every later one must equal it
errors = []

def render_loop(name, sc, until):
    n = 0
    while time.perf_counter() < until:
        for spp in counts:
            try:
                img = np.array(draaw_mi.render(sc, version="v4", spp=spp, seed=1))
                if not np.array_equal(img, seen.setdefault((name, spp), img)):
                    errors.append(f"{name} at {spp} spp: another image")
            except Exception as e:
                errors.append(f"{name}: {e!r}"[:300])
            n += 1
    return n

# 1. two threads, two scenes, one (cached) V4 integrator
until = time.perf_counter() + SECONDS
worker = threading.Thread(target=render_loop, args=("a", a, until))
worker.start()
n_b = render_loop("b", b, until)
worker.join()
for (name, spp), img in seen.items():      # each image as this thread alone renders it
    sc = a if name == "a" else b
    if not np.array_equal(np.array(draaw_mi.render(sc, version="v4", spp=spp, seed=1)), img):
        errors.append(f"{name} at {spp} spp: not the image of a render alone")
seen.clear()                # (the preview below moves a's roughness)

# 2. a preview of one scene refining while the notebook renders the other
frames = []
pv = Preview(a, version="v4", max_depth=3, max_spp=10**6)
pv.on_frame(frames.append)
pv.on_error(lambda e: errors.append(f"preview: {e!r}"[:300]))
pv.start()
until = time.perf_counter() + SECONDS
rng = np.random.default_rng(5)
while time.perf_counter() < until:
    value = float(np.float32(rng.uniform(0.1, 0.5)))
    pv.wait(pv.update({"m.roughness": value}), spp=1, timeout=30)
    render_loop("b", b, time.perf_counter() + 0.2)
    held = float(np.array(a.params[a.key("m.roughness")]).ravel()[0])
    if held != value:      # (a replay of b's recording wrote a's old value back)
        errors.append(f"the preview set a's roughness to {value}, the scene holds {held}")

# 3. ... and while the notebook fits the other
ref = np.array(draaw_mi.render(b, version="v4", spp=4, seed=3))
draaw_mi.fit(b, ref, ["m.roughness"], version="v4", spp=2, iterations=8, progress=False)

# 4. ... and while it renders a batch of the other (frozen frames), which must equal the
# frames of the batch run again alone
import os, tomli_w
from draaw_mi import batch
from draaw_mi.io import read_exr
folder = sys.argv[2]
with open(os.path.join(folder, "b.toml"), "wb") as fh:
    tomli_w.dump(description(0.8, {"type": "point", "position": [0, 3, 2], "intensity": 20}), fh)
job = {"name": "orbit", "scene": os.path.join(folder, "b.toml"), "frames": 8, "spp": 2,
       "version": "v4", "camera": {"orbit": {"target": [0, 0, 0], "radius": 4.0, "height": 0.5}}}
def batch_frames(out):
    res = batch.run({"output": os.path.join(out, "{frame:04d}.exr"), "jobs": [job]}, out=folder,
                    progress=False)
    if res.failed:
        errors.append(f"batch {out}: {res.failed} frames failed")
    return [read_exr(os.path.join(folder, out, f"{i:04d}.exr")) for i in range(8)]
beside = batch_frames("beside")
pv.stop()
alone = batch_frames("alone")
if not all(np.array_equal(x, y) for x, y in zip(beside, alone)):
    errors.append("batch frames rendered beside the preview differ")
if pv.error is not None:
    errors.append(f"preview: {pv.error!r}"[:300])

print("renders", n_b, "frames", len(frames))
print("errors", len(errors), errors[:3])
'''


def test_renders_from_two_threads_neither_fail_nor_change_the_images(tmp_path):
    """Two threads rendering two scenes, each image equal to a render alone; a preview
    refining one scene while the notebook renders, fits, then renders a batch of the other."""
    root = Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run([sys.executable, "-c", CHILD, "2.0", str(tmp_path)], cwd=root, capture_output=True,
                             text=True, timeout=120)
    except subprocess.TimeoutExpired:        # Dr.Jit's abort hung once it had printed its IR
        pytest.fail("the child process hung (Dr.Jit aborted?)")
    assert out.returncode == 0, out.stderr[-1500:]
    lines = out.stdout.strip().splitlines()
    assert lines[-1] == "errors 0 []", lines[-1]
    renders, frames = (int(v) for v in lines[-2].split()[1::2])
    assert renders > 20 and frames > 5, lines[-2]   # both threads really rendered
