"""A running preview survives what a notebook's main thread does beside it: scenes loaded again
(a re-run cell rebinds ``scene``, freeing the old one) and fits of other scenes that are then
let go, renders and fits of a scene kept. In subprocesses: the failures these catch were
segmentation faults (exit -11)."""
from __future__ import annotations

import subprocess
import sys

from conftest import ROOT

#: a Preview refines; the main thread re-runs "scene = load_scene(...); render(scene)"
RELOADED_BESIDE = """
import faulthandler; faulthandler.enable()
import draaw_mi
from draaw_mi.rendering.preview import Preview
S = "scenes/material_spheres.toml"
a = draaw_mi.load_scene(S, resolution=[16, 16])
pa = Preview(a, max_depth=3, max_spp=10**9); pa.start(); pa.wait(spp=1)
for n in range(60):
    scene = draaw_mi.load_scene(S, resolution=[16, 16])   # (the previous one is freed here)
    img = draaw_mi.render(scene, spp=1, max_depth=2)
print("cells", n + 1, "error", repr(pa.error), "refined", pa.spp > 1, flush=True)
pa.stop()
"""

#: (the scripts below) a tiny scene of one material "m" at roughness ``rough``
TINY_SCENE = """
import draaw_mi
def mk(rough):
    return draaw_mi.load_scene({"render": {"resolution": [16, 16], "filter": "box"},
        "materials": {"m": {"roughness": rough}}, "shapes": [{"type": "sphere", "material": "m"}],
        "lights": [{"type": "constant"}], "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
"""

#: a Preview refines while another thread changes its roughness; the main thread loads a
#: scene and lets it go, then loads one, fits it and lets it go, three times
FITTED_BESIDE = TINY_SCENE + """
import faulthandler, gc, threading, time; faulthandler.enable()
import numpy as np
import draaw_mi
from draaw_mi.guard import RENDER_GUARD
from draaw_mi.rendering.preview import Preview
pa = Preview(mk(0.5), version="v4", max_depth=3, max_spp=10**9); pa.start(); pa.wait(spp=1)
stop = False
def slider():
    i = 0
    while not stop:
        i += 1; pa.update({"m.roughness": 0.1 + (i % 8) * 0.1}); time.sleep(0.005)
th = threading.Thread(target=slider); th.start()
ref = np.zeros((16, 16, 3), np.float32)
for k in range(3):
    with RENDER_GUARD:
        t = mk(0.3)
        del t
        gc.collect()
    time.sleep(0.3)
    b = mk(0.7)
    draaw_mi.fit(b, ref, ["m.roughness"], version="v4", spp=2, iterations=2, progress=False, max_depth=3)
    time.sleep(0.3)
    with RENDER_GUARD:            # (as the Jupyter guide advised: no free beside a frame)
        del b
        gc.collect()
    time.sleep(0.3)
stop = True; th.join()
print("fits", k + 1, "error", repr(pa.error), flush=True)
pa.stop()
"""


#: a Preview refines; the main thread reads another scene's parameters, then renders and fits
#: that scene (kept: no scene made or freed) for 8 seconds
KEPT_BESIDE = TINY_SCENE + """
import faulthandler, time; faulthandler.enable()
import numpy as np
import draaw_mi
from draaw_mi.rendering.preview import Preview
a, b = mk(0.5), mk(0.7)
pa = Preview(a, version="v4", max_depth=3, max_spp=10**9); pa.start(); pa.wait(spp=1)
key = b.key("m.roughness")                     # (b's parameters traversed beside the preview)
ref = np.zeros((16, 16, 3), np.float32)
t0, n = time.time(), 0
while time.time() - t0 < 8:
    draaw_mi.render(b, spp=2, version="v4", max_depth=3)
    draaw_mi.fit(b, ref, [key], version="v4", spp=2, iterations=2, progress=False, max_depth=3)
    n += 1
print("rounds", n > 10, "error", repr(pa.error), "refined", pa.spp > 1, flush=True)
pa.stop()
"""


def _run(script: str) -> str:
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"exit {out.returncode}: {out.stderr[-3000:]}"
    return out.stdout


def test_scenes_loaded_again_beside_a_preview():
    """A scene freed on the main thread while the preview's worker records or replays took its
    objects out of Dr.Jit's registry under the worker (a segfault within 10 cells, 4 runs of 4):
    a scene is let go under the render guard, and a recording made before is not replayed."""
    assert _run(RELOADED_BESIDE).strip().endswith("cells 60 error None refined True")


def test_scenes_fitted_and_let_go_beside_a_preview():
    """A fit of another scene, let go, and the next scene's fit, beside a refining preview:
    the preview replayed a recording whose registry had changed (a segfault in the first or
    second round, 2 runs of 2); it traces from then on instead."""
    assert _run(FITTED_BESIDE).strip().endswith("fits 3 error None")


def test_renders_and_fits_of_a_kept_scene_beside_a_preview():
    """Renders and fits of another scene, kept alive, beside a refining preview: the preview's
    replays after them segfaulted (15-20 s of renders or fits: 2-3 runs in 4); its frames are
    traced from the first such call on (guard.background_replay), and the first traversal of a
    scene's parameters takes the guard."""
    assert _run(KEPT_BESIDE).strip().endswith("rounds True error None refined True")
