"""Write notebooks/voxels_smoke.ipynb (no outputs): python notebooks/make_voxels_smoke.py

CI executes it with DRAAW_MI_NOTEBOOK_SMALL=1 (48x36, few spp; tests/test_notebooks.py), and
checks the picked cells, draaw_v4 against volpath and the AD-vs-FD albedo gradient it prints.
"""
from __future__ import annotations

import os

import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _nbgen  # noqa: E402  (notebooks/_nbgen.py, beside this script)


CELLS = [
    ("md", """# Voxels and smoke

`draaw_mi.media.VoxelGrid` holds occupancy, solid colour, smoke colour and density on a regular
grid, with GO-Draaw's editing tools (quirks fixed) and exact picking. In a scene, `[[volumes]]`
entries render a grid as solid voxels (one mesh of exterior faces) or as smoke (Mitsuba's own
`heterogeneous` medium), so `draaw_v4` and Mitsuba's `volpath` render the same scene, and the
medium's albedo and density are ordinary `mi.traverse` parameters.

Set `DRAAW_MI_NOTEBOOK_SMALL=1` to run a tiny version (48x36) - CI does."""),
    ("code", """import os
import time

import numpy as np
import matplotlib.pyplot as plt
import drjit as dr
import mitsuba as mi

import draaw_mi
from draaw_mi.media import VoxelGrid

SMALL = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL") == "1"
RES = (48, 36) if SMALL else (320, 240)
SPP = 8 if SMALL else 64
VOX = 24 if SMALL else 64                       # voxelisation resolution
ROOT = os.path.abspath(os.path.join(os.getcwd(), "..")) if os.path.basename(os.getcwd()) == "notebooks" else os.getcwd()
# this notebook's files: out/voxels_smoke beside it (DRAAW_MI_NOTEBOOK_OUT names another folder)
TMP = os.path.join(os.environ.get("DRAAW_MI_NOTEBOOK_OUT", "out"), "voxels_smoke")
os.makedirs(TMP, exist_ok=True)
print(f"{RES[0]}x{RES[1]}, {SPP} spp per seed, voxels {VOX}^3")"""),
    ("md", """## Editing and picking

Cells are addressed by index `(ix, iy, iz)` or by a ray `(origin, direction)`, which hits the
first occupied cell exactly (a DDA through every crossed cell; GO-Draaw's 64 fixed steps could
skip thin features). `add` is GO-Draaw's 3x3x3 brush, clipped at the grid's faces."""),
    ("code", """g = VoxelGrid.empty((8, 8, 8), (-1, -1, -1), (1, 1, 1))
g.add((5, 4, 4), color=(0.9, 0.5, 0.1))            # 3x3x3: x in 4..6, y and z in 3..5
g.draw((2, 4, 4), color=(0.1, 0.3, 0.9))           # a single voxel in front of the block
ray = ((-3.0, 0.125, 0.125), (1.0, 0.0, 0.0))      # along +x through the centres of row (:, 4, 4)
print("pick along +x:", g.pick(*ray))
print("erased:", g.erase(ray), "-> pick along +x:", g.pick(*ray))
print("voxels:", int(g.occupied.sum()), "- repainted:", g.paint((0.8, 0.8, 0.8), randomness=0.2))

# picking under a pixel of a Mitsuba camera looking down -z through the same row
sensor = mi.load_dict({"type": "perspective", "fov": 30,
                       "to_world": mi.ScalarTransform4f().look_at([0.125, 0.125, 5.0], [0.125, 0.125, 0.0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 33, "height": 33}})
print("pick under the centre pixel:", g.pick_pixel(sensor, 16, 16))"""),
    ("md", """## Voxelise a mesh

GO-Draaw's `monkey.obj` if its data is next to the project (`../shared/data/go-draaw`),
otherwise a torus made by trimesh. `fill="surface"` keeps a shell, `"solid"` fills the inside."""),
    ("code", """monkey_obj = os.path.join(ROOT, "..", "shared", "data", "go-draaw", "monkey.obj")
if os.path.isfile(monkey_obj):
    mesh, label = monkey_obj, "GO-Draaw's monkey"
else:
    import trimesh
    mesh, label = trimesh.creation.torus(1.0, 0.4), "a trimesh torus"
t0 = time.perf_counter()
vox = VoxelGrid.from_mesh(mesh, VOX, fill="surface", seed=1)
print(f"{label}: {int(vox.occupied.sum())} surface voxels of {VOX}^3 in {time.perf_counter() - t0:.2f} s")
vox.paint((0.75, 0.35, 0.15), randomness=0.3)      # noisy terracotta
smoke = vox.copy()
smoke.paint((0.9, 0.9, 0.95), randomness=0.1)   # to_smoke takes the voxel colours
smoke.to_smoke(density=1.0)                          # voxels -> smoke cells (per-cell density)
vox.save(os.path.join(TMP, "solid.npz"))
smoke.save(os.path.join(TMP, "smoke.npz"))

ext = vox.bbox_max - vox.bbox_min                    # keep the mesh's proportions, 1.3 high
size = ext * 1.3 / ext[1]
def bounds(x):
    return [[x - size[0] / 2, 0.0, -size[2] / 2], [x + size[0] / 2, size[1], size[2] / 2]]"""),
    ("md", """## Solid and smoke: `draaw_v4` vs Mitsuba's `volpath`

The same voxels twice: solid on the left (the `draaw` material reads the voxel colours), smoke
on the right. Both integrators have the same expectation, so the image means agree within the
seed-to-seed noise."""),
    ("code", """desc = {
    "render": {"resolution": list(RES), "spp": SPP, "max_depth": 8, "filter": "box"},
    "camera": {"origin": [0.0, 1.8, 6.5], "target": [0.0, 0.7, 0.0], "fov": 40},
    "materials": {"floor": {"base_color": [0.6, 0.6, 0.6], "roughness": 0.8},
                  "voxel": {"roughness": 0.55, "specular": 0.5}},
    "shapes": [{"type": "rectangle", "name": "ground", "material": "floor", "scale": 6.0,
                "rotate": {"axis": [1, 0, 0], "angle": -90}}],
    "volumes": [{"name": "solid", "mode": "solid", "file": os.path.join(TMP, "solid.npz"),
                 "bounds": bounds(-1.0), "material": "voxel"},
                {"name": "smoke", "mode": "smoke", "file": os.path.join(TMP, "smoke.npz"),
                 "bounds": bounds(1.0), "density_scale": 30.0, "g": 0.3}],
    "lights": [{"type": "area", "shape": "rectangle", "position": [1.5, 4.0, 2.5], "target": [0, 0.5, 0],
                "size": 1.5, "intensity": 12.0, "color": [1.0, 0.85, 0.6]},
               {"type": "constant", "intensity": 0.25}],
}
scene = draaw_mi.load_scene(desc)
seeds = range(4)
images, means, ses = {}, {}, {}
for version in ("v4", "volpath"):
    t0 = time.perf_counter()
    imgs = np.array([np.array(draaw_mi.render(scene, version=version, seed=s, post=[]))[..., :3] for s in seeds])
    images[version], means[version] = imgs.mean(axis=0), imgs.mean()
    # the seeds are independent renders (a pixel's R, G and B come from the same paths, so
    # per-pixel variances may not be pooled as independent): the spread of the per-seed means
    ses[version] = imgs.mean(axis=(1, 2, 3)).std(ddof=1) / np.sqrt(len(seeds))
    print(f"{version:8s} image mean {means[version]:.5f} +- {ses[version]:.5f} "
          f"({len(seeds)} seeds x {SPP} spp, {time.perf_counter() - t0:.1f} s)")
z = (means["v4"] - means["volpath"]) / np.hypot(ses["v4"], ses["volpath"])
print(f"v4 - volpath: z = {z:+.2f}")
fig, axes = plt.subplots(1, 2, figsize=(10, 4))
for ax, (version, img) in zip(axes, images.items()):
    ax.imshow(np.clip(img, 0, 1) ** (1 / 2.2), interpolation="nearest")
    ax.set_title(f"{version}, {len(seeds) * SPP} spp")
    ax.axis("off")"""),
    ("md", """## Albedo gradients and a gradient step

The smoke's albedo grid is `smoke.interior_medium.albedo.data` in `mi.traverse`; `draaw_v4`
differentiates through it by path replay. First the derivative of the mean image along "all
cells brighter" against central differences (a linear loss, so both estimate the same
quantity; the adjoint pass uses its own random numbers, hence the independent errors). The
errors are the spread over seeds, so the check renders a smaller image with many seeds
(80x60, 64 seeds): an error estimated from a handful of seeds can be off by a factor of two
or more. Measured so, AD and FD agree within about two standard errors, some 0.5 % of the
gradient. Then a squared error against a target rendered with half the albedo, and one
gradient step that lowers it."""),
    ("code", """# a smaller image, many seeds: the standard errors below are the spread over seeds
GRES, GSPP, NSEEDS = ((32, 24), 8, 12) if SMALL else ((80, 60), 16, 64)
gscene = draaw_mi.load_scene({**desc, "render": {**desc["render"], "resolution": list(GRES), "spp": GSPP}})
params = mi.traverse(gscene.mi_scene)
key = "smoke.interior_medium.albedo.data"
a0 = mi.TensorXf(params[key])
seeds, h = range(NSEEDS), 0.02
# the cells whose albedo +- h stays in [0, 1] (the smoke is painted up to 0.99998)
inner = (np.array(a0) >= h) & (np.array(a0) <= 1 - h)
print(f"gradients at {GRES[0]}x{GRES[1]}, {GSPP} spp per seed, {NSEEDS} seeds")

def set_albedo(value):
    params[key] = mi.TensorXf(value); params.update()

def render_v4(seed, grad=False):
    return draaw_mi.render(gscene, version="v4", seed=seed, params=params if grad else None, post=[])

def image_mean(image):
    return dr.mean(image[..., :3], axis=None)

# primal renders first, then the adjoint ones (each kind of kernel is compiled once)
set_albedo(a0 * 0.5)
target = sum(render_v4(100 + s)[..., :3] for s in range(8)) / 8

def loss(image):
    return dr.mean(dr.square(image[..., :3] - target), axis=None)

fd = []
for seed in seeds:
    vals = []
    for sgn in (1.0, -1.0):
        set_albedo(np.array(a0) + sgn * h * inner)
        vals.append(image_mean(render_v4(seed)).item())
    fd.append((vals[0] - vals[1]) / (2 * h))
set_albedo(a0)
loss_before = np.mean([loss(render_v4(50 + s)).item() for s in range(2)])

def gradient(objective, seed):
    dr.enable_grad(params[key]); params.update()
    dr.backward(objective(render_v4(seed, grad=True)))
    g = dr.grad(params[key])
    dr.disable_grad(params[key])
    return np.array(g)

ad = [gradient(image_mean, seed)[inner].sum() for seed in seeds]
ad, fd = np.array(ad), np.array(fd)
se = lambda a: a.std(ddof=1) / np.sqrt(len(a))
print(f"d mean(image) / d albedo (cells within [h, 1 - h]): AD {ad.mean():+.5f} +- {se(ad):.5f}   FD {fd.mean():+.5f} +- {se(fd):.5f}   "
      f"AD-FD {np.mean(ad - fd):+.5f} +- {np.hypot(se(ad), se(fd)):.5f}")

g = gradient(loss, 7)
step = np.clip(np.array(a0) - 0.4 * g / np.abs(g).max(), 0.0, 1.0)   # the largest change is 0.4
set_albedo(step)
loss_after = np.mean([loss(render_v4(50 + s)).item() for s in range(2)])
set_albedo(a0)
inside = np.array(a0) > 0
print(f"one step: loss {loss_before:.6f} -> {loss_after:.6f}; mean smoke albedo {np.array(a0)[inside].mean():.3f} "
      f"-> {step[inside].mean():.3f}")"""),
]


def build():
    return _nbgen.build(CELLS)


if __name__ == "__main__":
    _nbgen.write(CELLS, "voxels_smoke")
