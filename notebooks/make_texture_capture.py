"""Write notebooks/texture_capture.ipynb (no outputs): python notebooks/make_texture_capture.py

CI executes it with DRAAW_MI_NOTEBOOK_SMALL=1 (24x24 images, 8x8 maps, few iterations;
tests/test_notebooks.py).
"""
from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _nbgen  # noqa: E402  (notebooks/_nbgen.py, beside this script)

CELLS = [
    ("md", """# Texture capture: base colour, roughness and metallic maps from photos

**Expected runtime**: about 3 minutes on two cores (the full configuration: 8 captures at
128x128, 64x64 maps, 800 iterations); 15 s with `DRAAW_MI_NOTEBOOK_SMALL=1` (what CI runs).

A real object is not one roughness. This notebook makes a synthetic *capture set* of a
sphere whose material varies over its surface, then recovers its **maps** with
`draaw_mi.fit`:

1. ground-truth maps (colour blobs, a smooth roughness, sharp metallic patches);
2. captures: each photo from its own camera *and* under its own lamp (plus an environment):
   a photo under a second light constrains roughness and metallic more than a second view;
3. the fit: maps as a multi-scale pyramid kept in range (`maps="pyramid"`, the default),
   two captures per iteration (`batch=2`);
4. the maps beside the truth, their errors, and the object relit under a light no capture had;
5. the maps written as EXR and PNG.

How well this works today, against the texel-by-texel fit, is measured in
`benchmarks/results/svbrdf_fit.md`."""),
    ("code", """import os
import time

import matplotlib.pyplot as plt
import numpy as np

import draaw_mi
from draaw_mi.fitting.captures import render_capture

SMALL = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL") == "1"
RES = 24 if SMALL else 128            # image size (square)
N = 8 if SMALL else 64                # texels per side of each map
CAPTURES = 4 if SMALL else 8
ITERATIONS = 60 if SMALL else 800
REF_SPP = 128 if SMALL else 512
# this notebook's files: out/texture_capture beside it (DRAAW_MI_NOTEBOOK_OUT names another folder)
OUT = os.path.join(os.environ.get("DRAAW_MI_NOTEBOOK_OUT", "out"), "texture_capture")
os.makedirs(OUT, exist_ok=True)
print(f"{RES}x{RES} images, {N}x{N} maps, {CAPTURES} captures, {ITERATIONS} iterations; files in {OUT}")"""),
    ("md", """## Ground truth

Maps live in the sphere's UV space (u around the pole axis, v from pole to pole)."""),
    ("code", """rng = np.random.default_rng(1)
v, u = np.meshgrid((np.arange(N) + .5) / N, (np.arange(N) + .5) / N, indexing="ij")

def blobs(k, s):
    f = np.zeros((N, N))
    for _ in range(k):
        cu, cv, a = rng.random(), rng.uniform(.2, .8), rng.uniform(-1, 1)
        du = np.minimum(abs(u - cu), 1 - abs(u - cu))
        f += a * np.exp(-(du ** 2 + (v - cv) ** 2) / (2 * s * s))
    return (f - f.min()) / (np.ptp(f) + 1e-9)

TRUTH = {"obj.base_color": np.stack([0.1 + 0.8 * blobs(4, .12) for _ in range(3)], -1).astype(np.float32),
         "obj.roughness": (0.15 + 0.65 * blobs(5, .15))[..., None].astype(np.float32),
         "obj.metallic": (blobs(6, .08) > 0.55)[..., None].astype(np.float32)}
fig, axes = plt.subplots(1, 3, figsize=(9, 3))
for a, (name, m) in zip(axes, TRUTH.items()):
    a.imshow(np.clip(m, 0, 1) if m.shape[2] == 3 else m[..., 0], vmin=0, vmax=1)
    a.set_title(name)
    a.axis("off")"""),
    ("md", """## Captures

An environment map (sky, ground, a sun, two coloured lamps) lights every photo; each photo
also has its own point lamp `L{i}` and its own camera. A capture says which lights are on
(`"lights": {"L0": 1, "L1": 0, ...}`, factors on the scene's light intensities)."""),
    ("code", """def environment(path, w=64, h=32):
    th, ph = np.meshgrid((np.arange(h) + .5) / h * np.pi, (np.arange(w) + .5) / w * 2 * np.pi, indexing="ij")
    up = np.cos(th)
    env = np.stack([0.5 + 0.3 * up, 0.6 + 0.3 * up, 0.9 + 0.2 * up], -1) * (up > 0)[..., None]
    env += np.array([0.25, 0.2, 0.12]) * ((up <= 0) * (0.6 + 0.4 * (np.sin(6 * ph) > 0)))[..., None]
    for t0, p0, s, c in ((0.6, 1.0, 0.1, [30, 28, 22]), (1.3, 3.5, 0.25, [0.2, 1.5, 0.3]), (1.2, 5.0, 0.2, [1.8, 0.4, 0.3])):
        d2 = (th - t0) ** 2 + (np.minimum(abs(ph - p0), 2 * np.pi - abs(ph - p0)) * np.sin(t0)) ** 2
        env += np.array(c) * np.exp(-d2 / (2 * s * s))[..., None]
    draaw_mi.write_exr(path, env.astype(np.float32))
    return path

ENV = environment(os.path.join(OUT, "env.exr"))

def lamp(j, k=CAPTURES):
    b = 2 * np.pi * j / k + (0.9 if j % 2 else -0.9)
    return [4 * np.cos(b), 4 * np.sin(b), 2.0 if j % 3 else -1.0]

def sphere_scene(maps):
    return draaw_mi.load_scene({
        "render": {"resolution": [RES, RES], "spp": 16, "max_depth": 2, "filter": "gaussian"},
        "camera": {"origin": [3.2, 0, 0.5], "target": [0, 0, 0], "up": [0, 0, 1], "fov": 40},
        "materials": {"obj": {"base_color": maps["obj.base_color"].tolist(),
                              "roughness": maps["obj.roughness"][..., 0].tolist(),
                              "metallic": maps["obj.metallic"][..., 0].tolist()}},
        "shapes": [{"type": "sphere", "radius": 1.0, "name": "ball", "material": "obj"}],
        "lights": [{"type": "point", "name": f"L{j}", "position": lamp(j), "intensity": 20.0}
                   for j in range(CAPTURES + 1)] + [{"type": "envmap", "name": "env", "file": ENV}]})

def capture(i):
    a = 2 * np.pi * i / CAPTURES + (np.pi / CAPTURES if i == CAPTURES else 0.0)
    return {"camera": {"origin": [3.2 * np.cos(a), 3.2 * np.sin(a), 1.2 if i % 2 else -0.4],
                       "target": [0, 0, 0], "up": [0, 0, 1], "fov": 40},
            "lights": {f"L{j}": float(j == i) for j in range(CAPTURES + 1)}}

captures = [capture(i) for i in range(CAPTURES)]
truth_scene = sphere_scene(TRUTH)
t = time.perf_counter()
photos = [render_capture(truth_scene, c, spp=REF_SPP, version="path", seed=100 + i) for i, c in enumerate(captures)]
print(f"{len(photos)} photos rendered in {time.perf_counter() - t:.1f} s")
fig, axes = plt.subplots(1, len(photos), figsize=(2.2 * len(photos), 2.4))
for i, (a, p) in enumerate(zip(axes, photos)):
    a.imshow(np.clip(p, 0, 1) ** (1 / 2.2))
    a.set_title(f"capture {i}", fontsize=9)
    a.axis("off")"""),
    ("md", """## Fit

From maps of 0.5 everywhere. Each iteration renders two captures (`batch=2`) with
`draaw_v4` and path-replay gradients; the progress bar shows the loss as a PSNR."""),
    ("code", """grey = {"obj.base_color": np.full((N, N, 3), 0.5, np.float32), "obj.roughness": np.full((N, N, 1), 0.5, np.float32),
        "obj.metallic": np.full((N, N, 1), 0.5, np.float32)}
scene = sphere_scene(grey)
result = draaw_mi.fit(scene, photos, list(TRUTH), captures=captures, iterations=ITERATIONS, batch=2,
                      spp=16, progress=not SMALL)
errors = draaw_mi.fitting.map_outputs.map_errors(result.values, TRUTH, result.observed)
start = draaw_mi.fitting.map_outputs.map_errors(grey, TRUTH, result.observed)
print(f"fit: {result.seconds:.1f} s, {result.observed['obj.base_color'].mean():.0%} of the texels observed")
for name, e in errors.items():
    print(f"{name:16s} MAE {e['mae']:.3f} (start {start[name]['mae']:.3f})   PSNR {e['psnr']:.1f} dB")
print("captures not explained:", [i for i, c in enumerate(result.captures) if not c["explained"]] or "none")"""),
    ("md", """## The maps, the truth and the error

Texels no capture saw (near the poles) are blank in the error maps; the fit filled them from
their neighbours."""),
    ("code", """result.plot_maps(TRUTH);"""),
    ("md", """## Relit under a new light

A camera between two captures and the lamp `L{CAPTURES}`, which no capture switched on:
the fitted maps against the truth, rendered alike."""),
    ("code", """held_out = capture(CAPTURES)
relit = render_capture(scene, held_out, spp=256, version="path", seed=7)
reference = render_capture(truth_scene, held_out, spp=256, version="path", seed=7)
psnr = -10 * np.log10(np.mean((np.clip(relit, 0, 1) - np.clip(reference, 0, 1)) ** 2))
fig, axes = plt.subplots(1, 3, figsize=(9, 3.2))
for a, img, title in zip(axes, (reference, relit, np.abs(relit - reference)),
                         ("truth, new light", "fitted maps, new light", "|difference|")):
    a.imshow(np.clip(img, 0, 1) ** (1 / 2.2))
    a.set_title(title, fontsize=9)
    a.axis("off")
print(f"relit PSNR {psnr:.1f} dB")"""),
    ("md", """## When the metallic map is wrong: two starts

A metallic map is 0 or 1 almost everywhere, and its fit can stop in a local minimum: from
metallic 0.5 a dark dielectric may turn metal (the fastest way to darken a texel), from 0 part
of a real metal patch may stay dielectric. `draaw_mi.fitting.fit_two_starts` fits from both,
keeps each region where they disagree from the fit whose renders match the captures better,
and refines, for about three times this fit's time:

```python
scene = sphere_scene(grey)       # (the fit above left its maps in the scene)
res = draaw_mi.fitting.fit_two_starts(scene, photos, list(TRUTH), captures=captures,
                                      iterations=ITERATIONS, batch=2, spp=16)
res.stages    # each stage's captures error
```

`benchmarks/results/svbrdf_fit.md` measures it on a sphere, a monkey and a tile."""),
    ("md", """## Files to take elsewhere

`result.save_maps(folder)` writes each map as a linear EXR, an 8-bit and a 16-bit PNG (colour
maps sRGB-encoded). For a scene described in a TOML file, `result.save("fitted.toml", scene)`
writes the scene with the maps as EXR textures beside it; the command line does both:
`draaw-mi fit SCENE --captures captures.json --param obj.base_color ... -o fitted.toml --maps maps/`."""),
    ("code", """for path in result.save_maps(os.path.join(OUT, "maps")):
    print(os.path.relpath(path, OUT))"""),
]


def build():
    return _nbgen.build(CELLS)


if __name__ == "__main__":
    _nbgen.write(CELLS, "texture_capture")
