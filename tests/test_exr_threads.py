"""Scenes that read EXR files load with 1 Dr.Jit thread (``draaw_mi.guard.exr_reading_threads``).

Mitsuba 3.9.1 decodes EXR files on Dr.Jit's thread pool and waits for ever with fewer than
2 threads: ``draaw-mi render --threads 1`` of a scene with an EXR roughness map hung, as did
Dask workers on two cores (one thread each). The scenarios run in a child process under a
timeout, since the failure is a hang.
"""
from __future__ import annotations

import subprocess
import sys

CHILD = r'''
import os, sys
import numpy as np, drjit as dr, mitsuba as mi
import draaw_mi
d = sys.argv[1]
draaw_mi.write_exr(os.path.join(d, "rough.exr"), np.full((4, 4, 1), 0.4, np.float32))
draaw_mi.write_exr(os.path.join(d, "sky.exr"), np.full((8, 16, 3), 0.5, np.float32))
dr.set_thread_count(1)
scene = draaw_mi.load_scene({
    "render": {"resolution": [8, 8], "spp": 2},
    "materials": {"m": {"base_color": [0.5, 0.5, 0.5], "roughness": os.path.join(d, "rough.exr")}},
    "shapes": [{"type": "sphere", "material": "m"}],
    "lights": [{"type": "envmap", "file": os.path.join(d, "sky.exr")}],
    "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
img = np.asarray(draaw_mi.render(scene))
with open(os.path.join(d, "s.xml"), "w") as f:
    f.write('<scene version="3.0.0"><shape type="sphere"><bsdf type="diffuse">'
            '<texture type="bitmap" name="reflectance"><string name="filename" value="rough.exr"/>'
            '</texture></bsdf></shape><emitter type="constant"/>'
            '<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>'
            '<integer name="height" value="8"/></film></sensor></scene>')
xml = draaw_mi.load_scene(os.path.join(d, "s.xml"))
print("loaded", dr.thread_count(), float(np.mean(img)) > 0, len(xml.mi_scene.shapes()))
'''


def test_scenes_with_exr_files_load_and_render_with_one_thread(tmp_path):
    out = subprocess.run([sys.executable, "-c", CHILD, str(tmp_path)], capture_output=True,
                         text=True, timeout=90)
    assert out.returncode == 0, out.stderr[-2000:]
    # the count set before the load is back after it (the renders ran with 1 thread)
    assert out.stdout.split() == ["loaded", "1", "True", "1"], out.stdout
