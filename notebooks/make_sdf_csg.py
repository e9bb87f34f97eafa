"""Write notebooks/sdf_csg.ipynb (no outputs): python notebooks/make_sdf_csg.py

CI executes it with DRAAW_MI_NOTEBOOK_SMALL=1 (48x36, few spp; tests/test_notebooks.py), and
checks the distances, the whole-image AD-vs-FD radius gradient, the shape fit and the tracer
figures it prints.
"""
from __future__ import annotations

import os

import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _nbgen  # noqa: E402  (notebooks/_nbgen.py, beside this script)


CELLS = [
    ("md", """# Signed distance fields: a CSG tree in Python

`draaw_mi.sdf` builds shapes from primitives and operators (GO-Draaw's ray-marched spheres, in
3D, bugs fixed). The tree is ordinary Python; `to_entries` turns it into `[[sdf]]` tables, so
the sphere tracer inside `draaw_v1`..`v4` renders it with meshes, shadows and the `draaw`
material, and `draaw_mi.sdf.parameters` makes its radii, centres and blend radii
differentiable.

Set `DRAAW_MI_NOTEBOOK_SMALL=1` to run a tiny version (48x36) - CI does."""),
    ("code", """import os
import time

import numpy as np
import matplotlib.pyplot as plt
import drjit as dr
import mitsuba as mi

import draaw_mi
from draaw_mi.sdf import Box, RoundBox, Sphere, smooth_subtraction, smooth_union
from draaw_mi.sdf.export import to_entries
from draaw_mi.bench.sdf_study import camera_march

SMALL = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL") == "1"
RES = (48, 36) if SMALL else (320, 240)
SPP = 16 if SMALL else 64
print(f"{RES[0]}x{RES[1]}, {SPP} spp")"""),
    ("md", """## Build the tree

A red ball smoothly merged (`k` = blend radius) into a blue rounded block, with a bite taken
out by a smooth subtraction. Operators blend the materials with the same weight as the
distances."""),
    ("code", """ball = Sphere((-0.35, 0.75, 0.0), 0.55, name="ball", material="red")
block = RoundBox((0.35, 0.45, 0.0), (0.8, 0.9, 0.8), 0.06, name="block", material="blue")
blob = smooth_union(ball, block, k=0.3, name="blob")
bite = Sphere((0.65, 0.95, 0.45), 0.35, name="bite", material="gold")
tree = smooth_subtraction(blob, bite, k=0.05, name="carved")
for node in tree.nodes():
    print(node.describe())

# exact where the operands are further apart than k: at the ball's centre d = -radius
d = tree.distance(mi.Point3f([-0.35, 2.0], [0.75, 0.75], [0.0, 0.0]))
print(f"distance at the ball's centre {d[0]:+.4f}, at (2, 0.75, 0) {d[1]:+.4f}")"""),
    ("md", """## Distance slices

`tree.distance` evaluates any batch of points (a `mi.Point3f`); here the plane z = 0 and the
plane y = 0.75, with the zero level set (the surface) in black."""),
    ("code", """n = 96 if SMALL else 256
xs = np.linspace(-1.5, 1.5, n)
fig, axes = plt.subplots(1, 2, figsize=(9, 4))
for ax, (title, plane) in zip(axes, [("z = 0", "xy"), ("y = 0.75", "xz")]):
    u, v = np.meshgrid(xs, xs + (0.5 if plane == "xy" else 0.0))
    zero = np.zeros_like(u)
    p = (u, v, zero) if plane == "xy" else (u, np.full_like(u, 0.75), v)
    dist = np.array(tree.distance(mi.Point3f(*(c.ravel().astype(np.float32) for c in p)))).reshape(u.shape)
    im = ax.imshow(dist, origin="lower", extent=(xs[0], xs[-1], v[0, 0], v[-1, 0]), cmap="RdBu", vmin=-1, vmax=1)
    ax.contour(u, v, dist, levels=[0.0], colors="k")
    ax.set_title(f"signed distance, {title}")
    ax.set_xlabel("x"); ax.set_ylabel(plane[1])
fig.colorbar(im, ax=axes, shrink=0.8)"""),
    ("md", """## Render it

The tree goes into a scene description next to a mesh floor; SDFs and meshes are depth-tested
against each other and shadow each other."""),
    ("code", """desc = {
    "render": {"resolution": list(RES), "spp": SPP, "max_depth": 4, "filter": "box"},
    "camera": {"origin": [0.0, 1.6, 4.2], "target": [0.0, 0.6, 0.0], "fov": 40},
    "materials": {"red": {"base_color": [0.85, 0.12, 0.08], "roughness": 0.35},
                  "blue": {"base_color": [0.1, 0.2, 0.85], "roughness": 0.5},
                  "gold": {"base_color": [1.0, 0.78, 0.34], "roughness": 0.4, "metallic": 1.0},
                  "ground": {"base_color": [0.6, 0.6, 0.6], "roughness": 0.8}},
    "shapes": [{"type": "rectangle", "name": "floor", "material": "ground", "scale": 4.0,
                "rotate": {"axis": [1, 0, 0], "angle": -90}}],
    "lights": [{"type": "point", "position": [2.0, 4.0, 3.0], "intensity": 40.0},
               {"type": "constant", "intensity": 0.3}],
    "sdf": to_entries(tree),
}
scene = draaw_mi.load_scene(desc)
t0 = time.perf_counter()
img = np.array(draaw_mi.render(scene, version="v4", seed=1))
print(f"draaw_v4, {SPP} spp: {time.perf_counter() - t0:.1f} s")
plt.figure(figsize=(5, 4))
plt.imshow(np.clip(img[..., :3], 0, 1) ** (1 / 2.2), interpolation="nearest")
plt.axis("off")"""),
    ("md", """## Shape gradients against finite differences

`draaw_mi.sdf.parameters(scene)` is `mi.traverse` plus `sdf.NODE.PARAM` keys. A shape parameter
changes the image in two ways: the surface points the pixels see move and turn (the
*interior* term, from re-attaching each hit point to the SDF), and the outlines and shadow
edges slide across pixels and light samples (the *boundary* terms, estimated in a band one
pixel wide around every outline the sphere tracer passes, `draaw_mi.sdf.silhouette`). Both
are on by default (`sdf_silhouettes`), so the derivative of the **whole image's** mean follows
central differences (the same seeds for both: common random numbers) to a few per cent: below,
AD reads 3 % above FD, 2.8 standard errors of their difference, the band's own small bias (the
SDF guide's tests allow 4).

The light is not at the camera: there its shadow edges would lie on the outlines, which the
one-sided band counts twice (−0.020 of 0.144 on this tree).

An earlier version of this notebook compared the gradient on interior pixels only and printed
AD − FD = +0.0226 ± 0.0006 at 320x240. That gap was the finite difference's: with a step of
0.01 the outline moves by about one pixel at that size and sweeps into the mask, which was
eroded by only one pixel (+0.0230 ± 0.0008 at h = 0.01, +0.0034 ± 0.0040 at h = 0.002, and
none at 160x120, where the step is half a pixel)."""),
    ("code", """grad_desc = dict(desc, lights=[{"type": "point", "position": [2.0, 4.0, 3.0], "intensity": 30.0}],
                 render=dict(desc["render"], max_depth=2))
gscene = draaw_mi.load_scene(grad_desc)

def loss(image):
    return dr.mean(image[..., :3], axis=None)

params = draaw_mi.sdf.parameters(gscene)
key, h = "sdf.ball.radius", 0.01
r0 = float(params[key][0])
ad, fd = [], []
for seed in range(8 if SMALL else 4):
    dr.enable_grad(params[key])
    dr.backward(loss(draaw_mi.render(gscene, version="v4", spp=SPP, seed=seed, params=params, post=[])))
    ad.append(float(dr.grad(params[key])[0]))
    dr.disable_grad(params[key])
    vals = []
    for r in (r0 + h, r0 - h):
        params[key] = r
        vals.append(loss(draaw_mi.render(gscene, version="v4", spp=SPP, seed=seed, post=[])).item())
    params[key] = r0
    fd.append((vals[0] - vals[1]) / (2 * h))
ad, fd = np.array(ad), np.array(fd)
se = lambda a: a.std(ddof=1) / np.sqrt(len(a))
print(f"d mean(image) / d radius (whole image): AD {ad.mean():+.5f} +- {se(ad):.5f}   FD {fd.mean():+.5f} +- {se(fd):.5f}")

# where the gradient lives: forward mode gives the derivative image
dr.enable_grad(params[key])
img = draaw_mi.render(gscene, version="v4", spp=4 * SPP, seed=99, params=params, post=[])
dr.set_grad(params[key], 1.0)
dr.forward_to(img)
dimg = np.array(dr.grad(img))[..., :3].mean(-1)
dr.disable_grad(params[key])
v = np.percentile(np.abs(dimg), 99)
plt.figure(figsize=(5, 4))
plt.imshow(dimg, cmap="RdBu_r", vmin=-v, vmax=v)
plt.colorbar(label="d pixel / d radius")
plt.title("outline, shadow edge and shading")
plt.axis("off")"""),
    ("md", """## Fitting a shape to two views

A ball smoothly merged into a slab, seen from two cameras. Starting from radius 0.42 (truth
0.55: 24 % small), blend radius k 0.18 (truth 0.25: 28 % small) and centre x -0.05 (truth
0.12: 0.17 off, on the other side of the slab's middle), `draaw_mi.fit` moves the outline onto
the references'. Without the boundary terms the same fit runs away (`benchmarks/sdf_fit.py`: radius 0.55 → 1.23)."""),
    ("code", """FIT_RES = 32 if SMALL else 96
views = [{"origin": [0.0, 1.3, 4.2], "target": [0.0, 0.5, 0.0], "fov": 36},
         {"origin": [3.0, 1.8, 2.8], "target": [0.0, 0.5, 0.0], "fov": 36}]
def ball_on_slab(x, radius, k):
    return smooth_union(Sphere((x, 0.75, 0.0), radius, name="ball", material="red"),
                        Box((0.0, 0.2, 0.0), (1.8, 0.3, 1.0), name="slab", material="red"), k=k, name="blob")

def fit_desc(camera, tree):
    return {"render": {"resolution": [FIT_RES, FIT_RES], "spp": 16, "max_depth": 3, "filter": "box"},
            "camera": camera, "materials": {k: desc["materials"][k] for k in ("red", "ground")},
            "shapes": desc["shapes"] + [{"type": "rectangle", "name": "backdrop", "material": "ground",
                                         "scale": 6.0, "translate": [0.0, 0.0, -1.6]}],
            "lights": [{"type": "point", "position": [1.5, 3.5, 3.0], "intensity": 25.0},
                       {"type": "constant", "intensity": 0.35}],
            "sdf": to_entries(tree)}
truth_tree = ball_on_slab(0.12, 0.55, 0.25)
refs = [np.array(draaw_mi.render(draaw_mi.load_scene(fit_desc(v, truth_tree)), version="v4", spp=64 if SMALL else 512,
                                 seed=7, post=[]))[..., :3] for v in views]
start = {"sdf.ball.radius": 0.42, "sdf.ball.center": [-0.05, 0.75, 0.0], "sdf.blob.k": 0.18}
fscene = draaw_mi.load_scene(fit_desc(views[0], truth_tree))
t0 = time.perf_counter()
res = draaw_mi.fit(fscene, refs, params=list(start), views=views, init=start, version="v4", spp=16,
                   iterations=40 if SMALL else 80, lr=0.02, post=[], progress=False, average_last=0.2)
print(f"fit: {res.iterations} iterations, {time.perf_counter() - t0:.0f} s")
truth = {"sdf.ball.radius": 0.55, "sdf.ball.center": [0.12, 0.75, 0.0], "sdf.blob.k": 0.25}
for k, t in truth.items():
    print(f"{k:18s} start {np.round(start[k], 3)}  fitted {np.round(res.values[k], 3)}  truth {np.round(t, 3)}")

first = np.array(draaw_mi.render(draaw_mi.load_scene(fit_desc(views[0], ball_on_slab(-0.05, 0.42, 0.18))),
                                 version="v4", spp=32, seed=1, post=[]))[..., :3]
fig, axes = plt.subplots(1, 4, figsize=(13, 3.2))
for ax, (title, im) in zip(axes[:3], [("start", first), ("fitted", res.image[..., :3]), ("reference", refs[0])]):
    ax.imshow(np.clip(im, 0, 1) ** (1 / 2.2)); ax.set_title(title); ax.axis("off")
r_hist = [h["values"]["sdf.ball.radius"] for h in res.history]
k_hist = [h["values"]["sdf.blob.k"] for h in res.history]
axes[3].plot(r_hist, label="radius"); axes[3].plot(k_hist, label="k")
axes[3].axhline(0.55, ls=":", c="C0"); axes[3].axhline(0.25, ls=":", c="C1")
axes[3].set_xlabel("iteration"); axes[3].legend()"""),
    ("md", """## What the tracer's knobs cost

`sdf_epsilon` (relative hit tolerance), `sdf_max_steps` (a ray that has not converged by then is
a miss) and `sdf_relaxation` (over-relaxed sphere tracing with Keinert et al.'s fallback) are
integrator options. For each setting: the march steps per camera ray, the share of rays that
hit with a strict tracer but miss with this one, and the render time (after a warm-up render
that compiles). `draaw-mi bench` runs the full study (`benchmarks/results/sdf_study_sdf_csg.md`)."""),
    ("code", """strict = {"sdf_epsilon": 1e-6, "sdf_max_steps": 4096, "sdf_relaxation": 1.0}
settings = [{"sdf_epsilon": 1e-5, "sdf_max_steps": 256, "sdf_relaxation": 1.0},
            {"sdf_epsilon": 1e-5, "sdf_max_steps": 256, "sdf_relaxation": 1.6},
            {"sdf_epsilon": 1e-5, "sdf_max_steps": 8, "sdf_relaxation": 1.0},
            {"sdf_epsilon": 5e-5, "sdf_max_steps": 256, "sdf_relaxation": 1.0}]
ref_hit = camera_march(scene, strict)[0]
for s in settings:
    hit, steps = camera_march(scene, s)
    draaw_mi.render(scene, version="v4", spp=4, seed=0, integrator_options=s)          # compile
    t0 = time.perf_counter()
    dr.eval(draaw_mi.render(scene, version="v4", spp=4, seed=0, integrator_options=s)); dr.sync_thread()
    ms = (time.perf_counter() - t0) * 1e3
    print(f"eps={s['sdf_epsilon']:g} steps={s['sdf_max_steps']} relax={s['sdf_relaxation']:g}: "
          f"mean steps {steps[ref_hit].mean():.1f}, false misses {np.sum(ref_hit & ~hit) / ref_hit.sum():.4f}, {ms:.0f} ms")"""),
]


def build():
    return _nbgen.build(CELLS)


if __name__ == "__main__":
    _nbgen.write(CELLS, "sdf_csg")
