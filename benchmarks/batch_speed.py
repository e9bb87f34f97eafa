"""Batch speed: a 24-frame camera path at 256², draaw-mi's in-process batch executor versus
calling Mitsuba's own ``mitsuba`` command once per frame on the same scene exported as XML.

The ``mitsuba`` executable cannot load draaw-mi's Python plugins, so the exported XML uses
Mitsuba's C++ equivalents: ``principled`` (base_color, roughness, metallic, specular; wrapped in
``twosided`` like the ``draaw`` BSDF) and the ``path`` integrator with the same max_depth. Three
contenders, each timed as a whole command (process start-up included, as a user runs them):

* ``cli``      — ``mitsuba -m llvm_ad_rgb -o frame.exr frame_NN.xml`` for each of the 24 frames;
* ``cli-exe``  — the same with the C++ executable that the ``mitsuba`` console script (a Python
  wrapper that imports mitsuba, then starts it) runs: the per-process cost without Python;
* ``batch-xml`` — ``draaw-mi batch`` on a manifest whose scene is the same XML (C++ ``path`` +
  ``principled``, camera set per frame through ``mi.traverse``): same renderer, only the
  executor differs;
* ``batch-v4``  — ``draaw-mi batch`` on the TOML scene with draaw-mi's ``v4`` integrator and
  the Python ``draaw`` BSDF (the project's own renderer).

Runs are interleaved (cli, batch-xml, batch-v4, cli, ...) and reported as medians per frame.
Usage: ``python benchmarks/batch_speed.py [--spp 4 16] [--repeats 3] [--out results/batch_speed.md]``
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from draaw_mi.bench.study import load_note  # noqa: E402
from draaw_mi.io import write_text  # noqa: E402
BIN = os.path.dirname(sys.executable)
FRAMES, RES = 24, 256


def _exe() -> str:
    import mitsuba
    return os.path.join(os.path.dirname(mitsuba.__file__), "mitsuba")
ORBIT = {"target": [0.0, 0.1, -0.9], "radius": 11.5, "height": 2.4, "degrees": 360}

PLUGIN_TAGS = {
    "bsdf": {"draaw", "diffuse", "principled", "twosided", "conductor", "roughconductor", "dielectric"},
    "shape": {"sphere", "rectangle", "disk", "cube", "cylinder", "ply", "obj"},
    "emitter": {"area", "constant", "point", "spot", "envmap", "directional"},
    "sensor": {"perspective"}, "sampler": {"independent"}, "film": {"hdrfilm"},
    "rfilter": {"box", "gaussian", "tent"}, "texture": {"bitmap"}, "integrator": {"path"},
}


def _tag(plugin_type: str) -> str:
    for tag, types in PLUGIN_TAGS.items():
        if plugin_type in types:
            return tag
    raise ValueError(f"no XML tag known for plugin type {plugin_type!r}")


def _fmt(v) -> str:
    return ", ".join(repr(float(x)) for x in v)


def _xml(name, value, indent) -> list[str]:
    """XML lines for one property ``name = value`` of a Mitsuba scene dict."""
    import mitsuba as mi

    pad = " " * indent
    attr = f' name="{name}"' if name else ""
    if isinstance(value, dict):
        t = value["type"]
        if t == "rgb":
            return [f'{pad}<rgb{attr} value="{_fmt(value["value"])}"/>']
        if t == "ref":
            return [f'{pad}<ref{attr} id="{value["id"]}"/>']
        if t == "draaw":                       # the Python BSDF -> Mitsuba's principled, two-sided
            inner = {"type": "principled"}
            inner.update({k: value[k] for k in ("base_color", "roughness", "metallic", "specular") if k in value})
            return _xml(name, {"type": "twosided", "bsdf": inner}, indent)
        ident = f' id="{value["id"]}"' if "id" in value else ""    # (a TOML light's black surface)
        lines = [f'{pad}<{_tag(t)} type="{t}"{ident}{attr}>']
        for k, v in value.items():
            if k not in ("type", "id"):
                lines += _xml(k if not (t == "twosided" and k == "bsdf") else "", v, indent + 4)
        return lines + [f"{pad}</{_tag(t)}>"]
    if isinstance(value, bool):
        return [f'{pad}<boolean{attr} value="{str(value).lower()}"/>']
    if isinstance(value, int):
        return [f'{pad}<integer{attr} value="{value}"/>']
    if isinstance(value, float):
        return [f'{pad}<float{attr} value="{value!r}"/>']
    if isinstance(value, str):
        return [f'{pad}<string{attr} value="{value}"/>']
    if isinstance(value, (list, tuple)) and len(value) == 3:
        return [f'{pad}<point{attr} value="{_fmt(value)}"/>']
    if isinstance(value, mi.ScalarTransform4f):
        m = np.array(value.matrix).reshape(4, 4)
        return [f'{pad}<transform{attr}>', f'{pad}    <matrix value="{" ".join(repr(float(x)) for x in m.ravel())}"/>',
                f"{pad}</transform>"]
    raise ValueError(f"cannot write {name}={value!r} as XML")


def scene_xml(mi_dict: dict, spp: int, max_depth: int, camera=None) -> str:
    """Mitsuba 3 XML for a scene dict, with a ``path`` integrator and, optionally, a look-at camera."""
    import mitsuba as mi

    d = dict(mi_dict)
    sensor = dict(d.pop("sensor"))
    sensor["sampler"] = {"type": "independent", "sample_count": spp}
    if camera is not None:
        sensor["to_world"] = mi.ScalarTransform4f().look_at(origin=camera["origin"], target=camera["target"],
                                                             up=camera["up"])
    lines = ['<scene version="3.0.0">',     '    <integrator type="path" id="integrator">',
             f'        <integer name="max_depth" value="{max_depth}"/>', "    </integrator>"]
    for k, v in d.items():
        if k == "type" or k == "integrator":
            continue
        block = _xml("", v, 4)
        block[0] = block[0].replace(f' type="{v["type"]}"', f' type="{v["type"]}" id="{k}"', 1)\
            if not block[0].lstrip().startswith("<bsdf type=\"twosided\"") else\
            block[0].replace('type="twosided"', f'type="twosided" id="{k}"', 1)
        lines += block
    s = _xml("", sensor, 4)
    s[0] = s[0].replace('type="perspective"', 'type="perspective" id="sensor"', 1)
    return "\n".join(lines + s + ["</scene>", ""])


def kernel_seconds(xml_paths) -> float:
    """Mean summed JIT kernel time (s) per frame of ``mi.render`` of each frame's XML scene
    in this process (one render each, after a warm-up render of the first): the render work
    that every contender does, and so the floor of any executor's time per frame."""
    import drjit as dr
    import mitsuba as mi

    was = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        times = []
        for i, path in enumerate(xml_paths):
            scene = mi.load_file(path)
            if i == 0:
                dr.eval(mi.render(scene, seed=999))
                dr.sync_thread()
            dr.kernel_history_clear()
            dr.eval(mi.render(scene, seed=i))
            dr.sync_thread()
            times.append(sum(k.get("execution_time", 0.0) for k in dr.kernel_history()
                             if k["type"] == dr.KernelType.JIT) / 1000.0)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, was)
    return statistics.mean(times)


def _run(cmd) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:3])} ...: exit {r.returncode}: {r.stderr.decode()[-400:]}")
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "batch_speed.md"))
    args = ap.parse_args()

    import drjit as dr
    import mitsuba as mi
    import tomli_w

    import draaw_mi
    from draaw_mi.batch.manifest import parse_manifest
    from draaw_mi.batch.planner import camera_frames

    global EXE
    EXE = _exe()
    work = tempfile.mkdtemp(prefix="draaw-batch-speed-")
    scene_file = os.path.join(ROOT, "scenes", "material_spheres.toml")
    scene = draaw_mi.load_scene(scene_file, resolution=(RES, RES))
    max_depth = scene.settings["max_depth"]
    job = {"name": "path", "scene": scene_file, "frames": FRAMES, "camera": {"orbit": ORBIT}}
    cams = camera_frames(parse_manifest({"jobs": [job]}).jobs[0].camera, FRAMES, 34.0)
    rows = {}
    for spp in args.spp:
        xmls = []
        for i, cam in enumerate(cams):
            p = os.path.join(work, f"spp{spp}_frame{i:02d}.xml")
            with open(p, "w") as fh:
                fh.write(scene_xml(scene.mi_dict, spp, max_depth, cam))
            xmls.append(p)
        base_xml = os.path.join(work, f"spp{spp}_base.xml")
        with open(base_xml, "w") as fh:
            fh.write(scene_xml(scene.mi_dict, spp, max_depth))
        manifests = {}
        for name, sc, version in (("batch-xml", base_xml, "path"), ("batch-v4", scene_file, "v4")):
            doc = {"output": "{job}/{frame:04d}.exr",
                   "jobs": [{"name": "orbit", "scene": sc, "frames": FRAMES, "spp": spp, "version": version,
                             "resolution": [RES, RES], "max_depth": max_depth, "camera": {"orbit": ORBIT}}]}
            manifests[name] = os.path.join(work, f"spp{spp}_{name}.toml")
            with open(manifests[name], "wb") as fh:
                tomli_w.dump(doc, fh)

        def cli(rep):
            out = os.path.join(work, f"cli{spp}_{rep}")
            os.makedirs(out)
            t = 0.0
            for i, x in enumerate(xmls):
                t += _run([os.path.join(BIN, "mitsuba"), "-m", "llvm_ad_rgb", "-o",
                           os.path.join(out, f"{i:04d}.exr"), x])
            return t

        def batch(name):
            def go(rep):
                out = os.path.join(work, f"{name}{spp}_{rep}")
                return _run([os.path.join(BIN, "draaw-mi"), "batch", manifests[name], "--out", out, "--no-progress"])
            return go

        def cli_exe(rep):                                   # the C++ binary the console script runs
            out = os.path.join(work, f"exe{spp}_{rep}")
            os.makedirs(out)
            return sum(_run([EXE, "-m", "llvm_ad_rgb", "-o", os.path.join(out, f"{i:04d}.exr"), x])
                       for i, x in enumerate(xmls))

        contenders = {"cli": cli, "cli-exe": cli_exe, "batch-xml": batch("batch-xml"), "batch-v4": batch("batch-v4")}
        for f in contenders.values():                       # warm-up: kernels into ~/.drjit
            f("warm")
        times = {k: [] for k in contenders}
        for rep in range(args.repeats):
            for k, f in contenders.items():
                times[k].append(f(rep) / FRAMES)
                print(f"spp {spp} rep {rep} {k}: {times[k][-1]:.3f} s/frame", flush=True)
        # sanity: the XML scene really is the same view (cli frame vs batch-xml frame, same spp)
        a = draaw_mi.read_exr(os.path.join(work, f"cli{spp}_0", "0005.exr"))[..., :3]
        b = draaw_mi.read_exr(os.path.join(work, f"batch-xml{spp}_0", "orbit", "0005.exr"))[..., :3]
        rows[spp] = {k: statistics.median(v) for k, v in times.items()}
        rows[spp]["all"] = times
        rows[spp]["mean_cli"], rows[spp]["mean_xml"] = float(a.mean()), float(b.mean())
        rows[spp]["kernel"] = kernel_seconds(xmls)
    shutil.rmtree(work, ignore_errors=True)

    lines = ["# Batch speed: in-process batch executor vs one `mitsuba` command per frame", "",
             f"24-frame orbit of `scenes/material_spheres.toml` at {RES}x{RES}, max_depth {max_depth}, box filter, "
             f"{dr.thread_count()} Dr.Jit threads, Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}, "
             f"variant llvm_ad_rgb. Wall-clock per frame of the whole command (process start-up included), "
             f"median of {args.repeats} interleaved repeats after one warm-up run each (kernels on disk). "
             f"Machine: {load_note()}; compare ratios, not absolute times.", "",
             "* `cli`: `mitsuba -m llvm_ad_rgb -o NNNN.exr frame_NN.xml`, one process per frame; the XML is "
             "the scene exported with Mitsuba's C++ `principled` BSDF (in `twosided`) for the Python `draaw` "
             "BSDF and the C++ `path` integrator (the `mitsuba` executable cannot load Python plugins).",
             "* `cli-exe`: the same with the C++ executable `site-packages/mitsuba/mitsuba` that the `mitsuba` "
             "console script (a Python wrapper: it imports mitsuba, then starts that executable) runs.",
             "* `batch-xml`: `draaw-mi batch` on the same XML scene, version `path` (same renderer and BSDF as "
             "`cli`; only the executor differs).",
             "* `batch-v4`: `draaw-mi batch` on the TOML scene with draaw-mi's `v4` integrator and `draaw` BSDF.",
             "* `kernel`: the render kernel alone, in this process after the runs: `mi.render` of each frame's XML "
             "scene, one render each, summed `dr.kernel_history` execution times, mean per frame. Every contender "
             "runs this work, so `cli / kernel` bounds what any executor can reach against the `mitsuba` command.",
             "", "| spp | cli s/frame | cli-exe s/frame | batch-xml s/frame | batch-v4 s/frame | kernel s/frame "
             "| cli / batch-xml | cli-exe / batch-xml | cli / batch-v4 | cli / kernel (bound) "
             "| mean pixel cli vs batch-xml (frame 5) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for spp, r in rows.items():
        lines.append(f"| {spp} | {r['cli']:.3f} | {r['cli-exe']:.3f} | {r['batch-xml']:.3f} | {r['batch-v4']:.3f} | "
                     f"{r['kernel']:.3f} | {r['cli'] / r['batch-xml']:.2f}x | {r['cli-exe'] / r['batch-xml']:.2f}x | "
                     f"{r['cli'] / r['batch-v4']:.2f}x | {r['cli'] / r['kernel']:.2f}x | "
                     f"{r['mean_cli']:.4f} vs {r['mean_xml']:.4f} |")
    lines += ["", "Raw per-frame times (s), in run order:", ""]
    for spp, r in rows.items():
        for k, v in r["all"].items():
            lines.append(f"* spp {spp}, {k}: " + ", ".join(f"{x:.3f}" for x in v))
    lines += ["", f"Command: `{' '.join(['python', 'benchmarks/batch_speed.py'] + sys.argv[1:])}`", ""]
    write_text(args.out, "\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
