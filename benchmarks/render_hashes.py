"""Bit-identity of a refactor: SHA-256 of the sample scenes' renders (V1-V4 and ``path``, 32 spp
at their own size, 8 spp at 48x32: traced and replayed passes), a denoised and an adaptive
render, a fit of ``scenes/fit_sphere.toml`` and every frame of ``scenes/batch_example.toml``.
Run it from the repository root before and after a change that must not change any pixel,
and compare the files::

    .venv/bin/python benchmarks/render_hashes.py before.json          # about a minute
    .venv/bin/python benchmarks/render_hashes.py after.json
    .venv/bin/python benchmarks/render_hashes.py --compare before.json after.json

``benchmarks/results/render_hashes.json`` holds the hashes of session 46's refactor (the same
before and after it). A second argument (render, denoise, fit, batch) runs one part only.
"""
import glob
import hashlib
import json
import os
import sys
import tempfile
import warnings

USAGE = ("usage: render_hashes.py OUT.json [all|render|denoise|fit|batch]   (hashes of the renders, written to OUT.json)\n"
         "       render_hashes.py --compare A.json B.json")
if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help") or (sys.argv[1].startswith("-") and sys.argv[1] != "--compare"):
    # (without OUT.json it rendered everything, then failed; --help was taken for a file name)
    print(USAGE, file=sys.stderr if len(sys.argv) < 2 else sys.stdout)
    sys.exit(2 if len(sys.argv) < 2 else 0)
if sys.argv[1] == "--compare" and len(sys.argv) != 4:
    sys.exit(USAGE)
if len(sys.argv) == 4 and sys.argv[1] == "--compare":
    a, b = (json.load(open(p)) for p in sys.argv[2:])
    differ = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    print(f"{len(a)} and {len(b)} hashes; {len(differ)} differ" + "".join(f"\n  {k}" for k in differ))
    sys.exit(1 if differ else 0)

import numpy as np  # noqa: E402
warnings.simplefilter("ignore")
import drjit as dr  # noqa: E402

import draaw_mi  # noqa: E402
dr.set_thread_count(2)
out = {}
def h(a):
    return hashlib.sha256(np.ascontiguousarray(np.asarray(a, dtype=np.float32)).tobytes()).hexdigest()[:16]
what = sys.argv[2] if len(sys.argv) > 2 else "all"
if what in ("all", "render"):
    for path in sorted(glob.glob("scenes/*.toml")):
        if "batch" in path: continue
        scene = draaw_mi.load_scene(path)
        for v in ("v1", "v2", "v3", "v4", "path"):
            for spp, res in ((32, None), (8, (48, 32))):
                k = f"{os.path.basename(path)}:{v}:{spp}:{res}"
                try:
                    img = draaw_mi.render(scene, version=v, spp=spp, seed=3, resolution=res)
                    out[k] = h(img)
                except draaw_mi.DraawError as e:
                    out[k] = "error: " + str(e)[:80]
                print(k, out[k], flush=True)
        del scene
if what in ("all", "denoise"):
    img = draaw_mi.render("scenes/cornell.toml", spp=8, seed=2, resolution=(64, 64), denoise=True)
    out["denoise"] = h(img); print("denoise", out["denoise"])
    img = draaw_mi.render("scenes/cornell.toml", version="v4", spp=64, seed=2, resolution=(64, 64), adaptive=8)
    out["adaptive"] = h(img); print("adaptive", out["adaptive"])
if what in ("all", "fit"):
    truth = draaw_mi.load_scene("scenes/fit_sphere.toml", resolution=(48, 48))
    p = truth.params
    p[truth.key("target.roughness")] = 0.25; p[truth.key("target.metallic")] = 0.8; p.update()
    ref = draaw_mi.render(truth, spp=64, seed=9)
    res = draaw_mi.fit("scenes/fit_sphere.toml", [ref], params=["target.roughness", "target.metallic"],
                       iterations=12, progress=False, resolution=(48, 48))
    out["fit"] = hashlib.sha256(repr((res.values, [float(x) for x in res.losses])).encode()).hexdigest()[:16]
    print("fit", out["fit"], res.values)
if what in ("all", "batch"):
    d = tempfile.mkdtemp()
    r = draaw_mi.batch.run("scenes/batch_example.toml", out=d, progress=False)
    for f in sorted(glob.glob(d + "/**/*.exr", recursive=True)):
        img = draaw_mi.read_exr(f)
        arr = img[0] if isinstance(img, tuple) else img
        out["batch:" + os.path.relpath(f, d)] = h(arr)
    print("batch frames", len([k for k in out if k.startswith("batch")]))
json.dump(out, open(sys.argv[1], "w"), indent=1, sort_keys=True)
print(f"{len(out)} hashes written to {sys.argv[1]}")
