"""Write notebooks/material_tuning.ipynb (no outputs): python notebooks/make_material_tuning.py

CI executes it with DRAAW_MI_NOTEBOOK_SMALL=1 (48x48, small budgets; tests/test_notebooks_jupyter.py);
the slow browser test opens it in JupyterLab and moves a slider.
"""
from __future__ import annotations

import os

import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _nbgen  # noqa: E402  (notebooks/_nbgen.py, beside this script)


CELLS = [
    ("md", """# Material tuning with a live, progressive preview

`draaw_mi.widgets.MaterialTuner` is GO-Draaw's web front end in Jupyter: sliders and colour
pickers for every `draaw` material parameter, textures and normal maps, render options, light,
camera orbit, the post chain, an error view against a reference, saving to TOML and a Python
snippet. A worker thread renders 1-spp frames and refines them by a running mean while you
pause; moving a slider writes Dr.Jit parameter values, so no kernel is recompiled. Drag on
the image to orbit the camera, scroll to move nearer or farther, double-click to go back.

Set `DRAAW_MI_NOTEBOOK_SMALL=1` to run a tiny version (48x48) - CI does."""),
    ("code", """import os
import time

import numpy as np
import matplotlib.pyplot as plt

import draaw_mi
from draaw_mi.widgets import MaterialTuner

SMALL = os.environ.get("DRAAW_MI_NOTEBOOK_SMALL") == "1"
RES = 48 if SMALL else 256                 # preview size (square)
BUDGET = 16 if SMALL else 256              # refinement budget, samples per pixel
ROOT = os.path.abspath(os.path.join(os.getcwd(), "..")) if os.path.basename(os.getcwd()) == "notebooks" else os.getcwd()
# this notebook's files: out/material_tuning beside it (DRAAW_MI_NOTEBOOK_OUT names another folder)
OUT = os.path.join(os.environ.get("DRAAW_MI_NOTEBOOK_OUT", "out"), "material_tuning")
scene = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "cornell.toml"), resolution=(RES, RES))
print(f"{RES}x{RES} preview, budget {BUDGET} spp; materials:", ", ".join(scene.info["materials"]))"""),
    ("md", """## The panel

Drag a slider: the first frame after a change is rendered at half resolution (sent as JPEG),
then full-resolution frames accumulate; after half a second at rest frames are sent as PNG.
*Render* switches version, depth, budget, resolution and OIDN denoising (biased), *Camera*
orbits, *Post* edits the shader chain, *Save* writes a TOML scene and shows a Python snippet."""),
    ("code", """tuner = MaterialTuner(scene, max_spp=BUDGET, save_path=os.path.join(OUT, "cornell_tuned.toml"))
tuner"""),
    ("md", """## Driving the panel from Python

Every control is an ipywidget: setting its value is exactly what dragging it does."""),
    ("code", """tuner.controls["metal"]["roughness"].value = 0.1
tuner.controls["metal"]["base_color_text"].value = "0.9, 0.45, 0.3"
frame = tuner.preview.wait(tuner.preview.generation, spp=4, timeout=120)
print(f"frame with the new values: {frame.spp} spp, {frame.render_s * 1e3:.0f} ms per 1-spp frame")"""),
    ("md", """## How quickly does a change show?

Time from a slider change to the next published frame (the worker may be busy with a frame
when the change arrives; see `benchmarks/results/preview_latency.md` for the measured study)."""),
    ("code", """latencies = []
for i in range(5 if SMALL else 20):
    time.sleep(0.05)
    t0 = time.perf_counter()
    tuner.controls["plastic"]["roughness"].value = 0.1 + 0.04 * i
    f = tuner.preview.wait(tuner.preview.generation, timeout=60)
    latencies.append(f.t_ready - t0)
print(f"change -> new frame: median {np.median(latencies) * 1e3:.0f} ms over {len(latencies)} changes")"""),
    ("md", """## Raw running mean vs OIDN denoising

The denoiser (`draaw_mi.denoise`, Intel Open Image Denoise on the CPU, guided by the albedo and
normal AOVs) is biased but removes most of the noise of a low sample count."""),
    ("code", """from draaw_mi.rendering.denoiser import available as denoiser_available

raw = np.array(draaw_mi.render(tuner.scene, spp=4, seed=3))
images = [("4 spp", raw)]
if denoiser_available():                     # pip install 'draaw-mi[denoise]' 
    images.append(("4 spp + OIDN (biased)", np.array(draaw_mi.render(tuner.scene, spp=4, seed=3, denoise=True))))
REF_SPP = 16 if SMALL else 64
images.append((f"{REF_SPP} spp", np.array(draaw_mi.render(tuner.scene, spp=REF_SPP, seed=4))))
fig, axes = plt.subplots(1, len(images), figsize=(4 * len(images), 4))
for ax, (title, img) in zip(axes, images):
    ax.imshow(np.clip(img[..., :3], 0, 1) ** (1 / 2.2), interpolation="nearest")
    ax.set_title(title)
    ax.axis("off")
plt.tight_layout()"""),
    ("md", "## Save the tuned scene and get the Python code"),
    ("code", """path = tuner.save(os.path.join(OUT, "cornell_tuned.toml"))
again = draaw_mi.load_scene(path)
print("saved", path, "- metal roughness in the file:", float(again.params[again.key("metal.roughness")][0]))
print(tuner.snippet())"""),
    ("md", """The worker keeps running while the notebook is open; `tuner.close()` stops it."""),
]


def build():
    return _nbgen.build(CELLS)


if __name__ == "__main__":
    _nbgen.write(CELLS, "material_tuning")
