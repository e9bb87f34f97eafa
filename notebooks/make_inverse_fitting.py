"""Write notebooks/inverse_fitting.ipynb (no outputs): python notebooks/make_inverse_fitting.py

The notebook is generated so that its source stays reviewable as Python; CI executes it with
DRAAW_MI_NOTEBOOK_SMALL=1 (32x32, few iterations; tests/test_notebooks.py).
"""
from __future__ import annotations

import os

import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _nbgen  # noqa: E402  (notebooks/_nbgen.py, beside this script)


CELLS = [
    ("md", """# Inverse fitting: roughness and metallic from a reference image

This notebook recovers the **roughness** and **metallic** of the two sphere materials of
`scenes/fit_two_spheres.toml` from a reference render, with `draaw_mi.fit`:

1. render a reference with known ground truth (Mitsuba's own `path` integrator, many samples),
2. reset the materials to a neutral start (roughness 0.5, metallic 0.5),
3. fit all four parameters jointly with the differentiable `draaw_v4` integrator
   (path replay backpropagation, Adam),
4. compare reference, start and fit side by side and plot the convergence.

The scene is built for identifiability: saturated base colours (so both the 4 % dielectric
specular and the metal tint show), a large softbox, a rim strip and a thin back light that the
flat tiles reflect (small roughnesses). See the comments in the scene file.

Set `DRAAW_MI_NOTEBOOK_SMALL=1` to run a tiny version (32x32, few iterations) - CI does."""),
    ("code", """import os
import time

import numpy as np
import matplotlib.pyplot as plt

import draaw_mi

SMALL = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL") == "1"
RES = 32 if SMALL else 128            # image size (square)
ITERATIONS = 80 if SMALL else 150     # Adam iterations
SPP = 16                              # samples per pixel per iteration
REF_SPP = 256 if SMALL else 4096      # reference quality
ROOT = os.path.abspath(os.path.join(os.getcwd(), "..")) if os.path.basename(os.getcwd()) == "notebooks" else os.getcwd()
scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "fit_two_spheres.toml"), resolution=(RES, RES))
print(f"{RES}x{RES}, {ITERATIONS} iterations, {SPP} spp per iteration; materials:", scene.summary()["materials"])"""),
    ("md", """## Ground truth and reference

`scene.params` is Mitsuba's `mi.traverse` of the scene; `scene.key("left.roughness")` names the
entry (`left.roughness.value`). The reference is rendered with Mitsuba's `path` integrator,
which the fit does not use, so the fit also checks that `draaw_v4` and `path` agree."""),
    ("code", """PARAMS = ["left.roughness", "left.metallic", "right.roughness", "right.metallic"]
TRUTH = {"left.roughness": 0.2, "left.metallic": 0.9, "right.roughness": 0.6, "right.metallic": 0.1}
START = {name: 0.5 for name in PARAMS}

def set_values(values):
    p = scene.params
    for name, value in values.items():
        p[scene.key(name)] = value
    p.update()

set_values(TRUTH)
reference = np.array(draaw_mi.render(scene, version="path", spp=REF_SPP, seed=2024))
set_values(START)
start_image = np.array(draaw_mi.render(scene, version="v4", spp=REF_SPP, seed=7))
reference.shape, float(reference.mean())"""),
    ("md", """## Fit

`draaw_mi.fit` renders the scene with `draaw_v4` (`spp` samples per iteration, a fresh seed
each time), compares with the reference (L2), back-propagates with path replay and takes an
Adam step. Roughness is optimised in log space (small roughnesses resolve as finely as large
ones), metallic linearly with projection onto [0, 1]; the result is the mean of the last quarter
of the iterates. The scene keeps the fitted values afterwards."""),
    ("code", """t0 = time.perf_counter()
result = draaw_mi.fit(scene, reference, PARAMS, version="v4", spp=SPP, iterations=ITERATIONS,
                      init=START, seed=1, progress=False)
print(f"{result.iterations} iterations in {time.perf_counter() - t0:.1f} s; "
      f"kernels compiled after the first two iterations: {result.kernel_compiles}")
for name in PARAMS:
    print(f"{name:16s} truth {TRUTH[name]:.3f}  fit {result.values[name]:.4f}  "
          f"error {result.values[name] - TRUTH[name]:+.4f}")
assert np.isfinite(result.losses).all()"""),
    ("md", "## Reference, start and fit side by side"),
    ("code", """fitted_image = np.array(draaw_mi.render(scene, version="v4", spp=REF_SPP, seed=11))

def show(ax, img, title):
    ax.imshow(np.clip(img, 0, 1) ** (1 / 2.2), interpolation="nearest")   # display gamma only
    ax.set_title(title)
    ax.axis("off")

fig, axes = plt.subplots(1, 4, figsize=(15, 4))
show(axes[0], reference, "reference (truth)")
show(axes[1], start_image, "start (0.5, 0.5)")
show(axes[2], fitted_image, "fit")
axes[3].imshow(np.abs(fitted_image - reference).mean(axis=2), cmap="magma", interpolation="nearest")
axes[3].set_title("|fit - reference|")
axes[3].axis("off")
plt.tight_layout()"""),
    ("md", "## Convergence"),
    ("code", """fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4))
a.semilogy(result.losses)
a.set_xlabel("iteration")
a.set_ylabel("L2 loss (noisy: 16 spp per iteration)")
for name in PARAMS:
    line, = b.plot([h["values"][name] for h in result.history], label=name)
    b.axhline(TRUTH[name], color=line.get_color(), ls=":", lw=1)
b.set_xlabel("iteration")
b.set_ylabel("value (dotted: truth)")
b.legend(fontsize=8)
plt.tight_layout()"""),
    ("md", """`result.plot("fit.png")` draws the same two panels; the CLI does it with
`draaw-mi fit SCENE --reference ref.exr --param left.roughness ... --plot fit.png`.

Accuracy over a grid of truths, hard cases (near mirror, metallic exactly 0 or 1, noisy and
differently exposed references, two views, a post chain in the loss): see
`benchmarks/fit_accuracy.md` and `benchmarks/fit_cases.md`."""),
]


def build():
    return _nbgen.build(CELLS)


if __name__ == "__main__":
    _nbgen.write(CELLS, "inverse_fitting")
