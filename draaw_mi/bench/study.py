"""What accuracy costs in time: the benchmark study behind ``draaw-mi bench``.

For each scene it renders a ground truth (Mitsuba's ``path`` with the scene's materials at high
spp, cached as EXR), then for every setting of a grid — version (V1..V4 and ``path`` as the
peer), spp (powers of two), ``max_depth``, adaptive subsampling on/off — it measures:

* **time**: median of ``repeats`` timed renders after a warm-up render; the warm-up's extra
  time is reported separately as ``compile_s`` (JIT compilation, or a disk-cache hit);
* **error** against the ground truth, averaged over the repeats (independent seeds): RMSE,
  relative MSE (``(x - gt)^2 / (gt^2 + 0.01)``) and mean CIEDE2000 of the sRGB-encoded images
  (colour-science);
* **bias**: the error that does not fall with spp, i.e. how far the image a version converges
  to is from the ground truth. Each version is rendered twice more at half the ground truth's
  spp (cached as the ground truth is) and :func:`~draaw_mi.bench.bias.converged_bias` takes
  both renders' noise and the ground truth's out; it is reported as an upper bound where it is
  within the estimate's noise. (Adaptive and denoised settings, which have no such
  reference, keep the estimate from their highest spp levels, :func:`estimate_bias`.) The
  spp levels of a quick study (1, 4, 16) cannot tell V1's bias from its noise: the old
  estimate gave "< 0.91" on the material spheres, where V1 converges 0.07 from ``path``.
* **spread and fireflies**: the lowest and highest RMSE of the repeats; where they differ by
  2x or more a setting is *firefly-dominated*: its error is a few samples thousands of times
  the pixel's value (V1/V2 light near-mirror Phong lobes by emitter sampling alone, without
  MIS), so over a few repeats it jumps, and can rise with spp while the expected MSE falls as
  1 / spp. (``tail_share``, the share of the squared error in the largest 0.5 % of the
  pixel values, is reported too: :func:`~draaw_mi.bench.bias.tail_share`.)

Results are written as JSON, CSV, a Markdown summary and plots (see :mod:`draaw_mi.bench.report`).
GO-Draaw's frame-time statistics along a camera path are in :func:`frame_times`.
"""
from __future__ import annotations

import hashlib
import json
import os
import platform
import time
import warnings
from dataclasses import asdict, dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import load_scene
from ..errors import DraawError
from ..integrators import SCENE_VERSION, resolve_version
from ..io import read_exr, write_exr
from ..progress import check_mode, closed_after, progress_bar
from ..rendering.renderer import render
from ..rendering.session import BLIND, session_of
from ..scene.camera import go_draaw_look_at, look_at_transform, scene_fov, sensor_keys, x_fov
from ..scene.camera_path import interpolate
from .bias import FIREFLY_SPREAD, converged_bias, estimate_bias, tail_share
from .code_digest import code_digest
from .metrics import errors
from .report import write_report

DEFAULT_VERSIONS = ("v1", "v2", "v3", "v4", "path")


@dataclass(frozen=True)
class Setting:
    version: str
    spp: int
    max_depth: int
    adaptive: int | None = None
    denoise: bool = False          # OIDN on the colour (albedo/normal guides): biased

    @property
    def label(self) -> str:
        return (f"{self.version}{'+adaptive' + str(self.adaptive) if self.adaptive else ''}"
                f"{'+oidn (biased)' if self.denoise else ''}")


def load_note() -> str:
    """How busy the machine was, for a benchmark's header: the 1-minute load average now (this
    job included) against the core count. Measured, not assumed: a report that says "shared
    with other jobs" when it was not misleads whoever compares its absolute times.

    >>> load_note().startswith("load average ")
    True
    """
    if not hasattr(os, "getloadavg"):                  # (not on Windows)
        return "load average unknown on this system"
    load, cores = os.getloadavg()[0], os.cpu_count() or 1
    state = "other jobs shared the cores" if load > cores + 0.5 else "no sign of other jobs"
    return f"load average {load:.1f} at the end, this job included, on {cores} cores ({state})"


def with_load_note(text: str) -> str:
    """``text`` with its ``LOAD_NOTE`` placeholder replaced by :func:`load_note`, read now: a
    benchmark's header is written before its runs, the load is measured after them.

    >>> with_load_note("Machine: LOAD_NOTE.").startswith("Machine: load average ")
    True
    """
    return text.replace("LOAD_NOTE", load_note(), 1)


# --------------------------------------------------------------------------- ground truth
def _scene_key(scene, spp: int, max_depth: int) -> str:
    h = hashlib.sha256()
    src = scene.source
    if src and os.path.isfile(src):
        with open(src, "rb") as f:
            h.update(f.read())
    elif scene.description is not None:
        h.update(json.dumps(scene.description, sort_keys=True, default=str).encode())
    for path in sorted(scene.info.get("files", [])):     # meshes, textures, includes it reads
        if os.path.isfile(path):                          # (a scene that reads none: key as before)
            with open(path, "rb") as f:
                h.update(path.encode() + b"\0" + hashlib.sha256(f.read()).digest())
    h.update(repr((scene.resolution, spp, max_depth)).encode())
    h.update(code_digest().encode())        # a fixed BSDF or integrator renders it anew
    version = reference_version(scene)
    if version != "path":            # (a path render of an SDF scene lacks its objects)
        h.update(version.encode())
    return h.hexdigest()[:16]


def ground_truth(scene, spp: int = 4096, max_depth: int | None = None, cache_dir: str | None = None,
                 progress: bool | str = False) -> np.ndarray:
    """The :func:`reference_version` render at high spp (Mitsuba's ``path`` unless the scene
    has media or SDF objects), cached as ``<cache_dir>/gt-<hash>.exr`` (atomic write)."""

    max_depth = scene.settings["max_depth"] if max_depth is None else max_depth
    path = None
    if cache_dir:
        name = os.path.splitext(os.path.basename(scene.source or "scene"))[0]
        path = os.path.join(cache_dir, f"gt-{name}-{_scene_key(scene, spp, max_depth)}.exr")
        if os.path.isfile(path):
            return read_exr(path)[..., :3]
    version = reference_version(scene)
    img = np.array(render(scene, version=version, spp=spp, seed=2 ** 31 - 1, max_depth=max_depth,
                          progress=progress, post=[]))[..., :3]
    if path:
        write_exr(path, img)
    return img


CONVERGED_SEEDS = (2 ** 31 - 3, 2 ** 31 - 5)      # the converged halves' seeds (not the gt's)


def converged_halves(scene, version: str, spp: int, max_depth: int, cache_dir: str | None = None,
                     progress: bool | str = False) -> tuple[np.ndarray, np.ndarray]:
    """Two independent renders of ``version`` at ``spp // 2`` each (at least 1): what the
    version converges to, with its noise measurable (:func:`~draaw_mi.bench.bias.converged_bias`);
    cached as ``<cache_dir>/conv-<name>-<version>-<hash>-<k>.exr``."""
    half = max(1, spp // 2)
    paths = [None, None]
    if cache_dir:
        name = os.path.splitext(os.path.basename(scene.source or "scene"))[0]
        key = _scene_key(scene, half, max_depth)
        paths = [os.path.join(cache_dir, f"conv-{name}-{version}-{key}-{k}.exr") for k in (0, 1)]
        if all(os.path.isfile(p) for p in paths):
            return tuple(read_exr(p)[..., :3] for p in paths)
    out = []
    for path, seed in zip(paths, CONVERGED_SEEDS):
        img = np.nan_to_num(np.array(render(scene, version=version, spp=half, seed=seed, max_depth=max_depth,
                                            progress=progress, post=[]))[..., :3])
        if path:
            write_exr(path, img)
        out.append(img)
    return tuple(out)


# --------------------------------------------------------------------------- measurement
def _timed_render(scene, s: Setting, seed: int) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    img = render(scene, version=s.version, spp=s.spp, seed=seed, max_depth=s.max_depth,
                 adaptive=s.adaptive, post=[], **({"denoise": True} if s.denoise else {}))
    dr.eval(img)
    dr.sync_thread()
    arr = np.array(img)
    return arr, time.perf_counter() - t0


def measure(scene, s: Setting, gt: np.ndarray, repeats: int = 3, seed: int = 1) -> tuple[dict, np.ndarray]:
    """Time and error of one setting (see the module docstring): (row, last image)."""
    return measure_group(scene, [s], gt, repeats, seed)[0]


# a render with inf pixels has an infinite error, without NumPy's overflow warnings: the row's
# "finite" column says why
@np.errstate(over="ignore", invalid="ignore")
def measure_group(scene, settings: list, gt: np.ndarray, repeats: int = 3,
                  seed: int = 1) -> list[tuple[dict, np.ndarray]]:
    """:func:`measure` for settings that are compared with each other (the versions at one
    spp): after a warm-up of each, their timed renders run round-robin, so a slower or busier
    stretch of the machine falls on all of them alike rather than on whichever ran then."""
    first = [_timed_render(scene, s, seed + 1000)[1] for s in settings]
    # a second warm-up where it is cheap: in a fresh process the second render of a setting
    # still runs 1.5-5x slower than later ones (and would land in the timed median)
    for s, t in zip(settings, first):
        if t < WARMUP_AGAIN_S:
            _timed_render(scene, s, seed + 1001)
    times, errs, imgs = ([[] for _ in settings] for _ in range(3))
    sq = [[] for _ in settings]                # each repeat's mean squared error
    tails = [[] for _ in settings]             # each repeat's tail_share
    finite = [True for _ in settings]          # of the raw renders (imgs are nan_to_num'd)
    for r in range(repeats):
        for i, s in enumerate(settings):
            img, t = _timed_render(scene, s, seed + r)
            times[i].append(t)
            errs[i].append(errors(img, gt))
            finite[i] = finite[i] and bool(np.isfinite(img[..., :3]).all())
            imgs[i].append(np.nan_to_num(img[..., :3]))
            sq[i].append(float(np.mean((imgs[i][-1] - gt) ** 2)))
            tails[i].append(tail_share(imgs[i][-1], gt))
    out = []
    for i, s in enumerate(settings):
        median = float(np.median(times[i]))
        stack = np.stack(imgs[i])
        # MSE of one render = bias^2 + variance; the variance is estimated from the repeats
        mse = float(np.mean((stack - gt) ** 2))
        var = float(np.mean(stack.var(axis=0, ddof=1))) if repeats > 1 else float("nan")
        row = asdict(s)
        row.update({"label": s.label, "time_s": median, "time_min_s": float(np.min(times[i])),
                    "compile_s": max(0.0, first[i] - median), "repeats": repeats,
                    "finite": finite[i], "mse": mse, "variance": var,
                    # standard error of the mse: the spread of the repeats' errors (a firefly
                    # in one repeat shows here)
                    "mse_se": float(np.std(sq[i], ddof=1) / np.sqrt(repeats)) if repeats > 1 else float("nan")})
        for k in errs[i][0]:
            row[k] = float(np.mean([e[k] for e in errs[i]]))
        # the repeats' spread, and whether a few fireflies make the error (see tail_share)
        row["rmse_min"] = float(min(e["rmse"] for e in errs[i]))
        row["rmse_max"] = float(max(e["rmse"] for e in errs[i]))
        row["tail_share"] = float(np.mean(tails[i]))
        # fireflies: the repeats' errors differ by FIREFLY_SPREAD or more (the renders of a
        # smooth-noise method differ by 20 % at most at 1 spp, 64x64; V1's by 10x)
        row["fireflies"] = bool(repeats > 1 and row["rmse_max"] >= FIREFLY_SPREAD * row["rmse_min"])
        out.append((row, imgs[i][-1]))
    return out


WARMUP_AGAIN_S = 0.5     # settings whose first render took less get a second warm-up
def reference_version(scene) -> str:
    """The ground truth's integrator: Mitsuba's ``path``, ``volpath`` for media, and V4 (the
    only unbiased one that traces them) for scenes with ``[[sdf]]`` objects."""
    holds = session_of(scene).holds()
    return "v4" if holds["sdf"] else "volpath" if holds["media"] else "path"


def scene_versions(scene, versions) -> list[str]:
    """``versions`` as they apply to ``scene``: with media ``path`` / ``prb`` become
    ``volpath`` (:func:`_media_versions`); with ``[[sdf]]`` objects Mitsuba's integrators,
    which cannot see them, are left out (with a warning), and so is ``scene`` (the scene's own
    integrator) for a scene that declares none."""
    holds = session_of(scene).holds()
    out = _media_versions(versions) if holds["media"] else list(versions)
    own = [v for v in out if resolve_version(v) == SCENE_VERSION]
    if own and not scene.info.get("integrator"):
        warnings.warn(f"{scene.source}: declares no integrator of its own for version "
                      f"{own[0]!r}; left out", RuntimeWarning, stacklevel=3)
        out = [v for v in out if v not in own]
    if holds["sdf"]:
        blind = [v for v in out if "sdf" in BLIND.get(resolve_version(v), ())]
        if blind:
            warnings.warn(f"{scene.source}: {', '.join(blind)} cannot see its [[sdf]] objects; left out",
                          RuntimeWarning, stacklevel=3)
        out = [v for v in out if v not in blind]
    return out


def _media_versions(versions) -> list[str]:
    """Versions for a scene with participating media: ``path``/``prb`` ignore media, so
    Mitsuba's ``volpath`` stands in for them (V1/V2 render GO-Draaw's single-scattering march,
    V3/V4 full volumetric transport)."""
    out = []
    for v in versions:
        v2 = {"path": "volpath", "prb": "volpath"}.get(v, v)
        if v2 not in out:
            out.append(v2)
    return out


def run_study(scenes, versions=DEFAULT_VERSIONS, spps=(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024),
              max_depths=None, adaptive=(None, 8), adaptive_spp=(1,), repeats: int = 3,
              resolution=None, gt_spp: int = 4096, out_dir: str = "out/bench", cache_dir: str | None = None,
              progress: bool | str = True, seed: int = 1, denoise_spp=(), converged: bool = True) -> dict:
    """Run the grid on every scene; write results into ``out_dir`` and return them.

    ``converged``: measure each version's bias against its own converged renders (two at
    ``gt_spp / 2`` each per version and depth, and the ground truth's integrator's, cached;
    the module docstring); False: from the highest spp levels studied, as before.

    ``denoise_spp``: also measure every version at these spp with OIDN denoising
    (``render(..., denoise=True)``; labelled ``+oidn (biased)``; needs ``pyoidn``).
    """
    check_mode(progress, "bench.run_study")

    os.makedirs(out_dir, exist_ok=True)
    cache_dir = cache_dir or os.path.join(out_dir, "cache")
    loaded = []
    for sc in scenes:
        s = load_scene(sc, **({"resolution": tuple(resolution)} if resolution else {}))
        loaded.append(s)
    plan = []
    for s in loaded:
        depths = max_depths or [s.settings["max_depth"]]
        holds = session_of(s).holds()
        blind = holds["media"] or holds["sdf"]        # adaptive subsampling cannot see them
        for d in depths:
            for v in scene_versions(s, versions):
                for spp in spps:
                    plan.append((s, Setting(v, spp, d, None)))
                for spp in denoise_spp:
                    plan.append((s, Setting(v, spp, d, None, True)))
                if adaptive and any(a for a in adaptive) and not blind:
                    for a in adaptive:
                        if a:
                            for spp in adaptive_spp:
                                plan.append((s, Setting(v, spp, d, a)))
    # the converged renders behind each version's bias: (scene, version, depth), plain settings
    conv_plan = []
    if converged:
        for s, setting in plan:
            key = (s, setting.version, setting.max_depth)
            if not setting.adaptive and not setting.denoise and key not in conv_plan:
                conv_plan.append(key)
        for s in loaded:          # the ground truth's integrator at its depth: the gt's noise
            key = (s, reference_version(s), ground_truth_depth(max_depths or [s.settings["max_depth"]]))
            if key not in conv_plan:
                conv_plan.append(key)
    with closed_after(progress_bar(len(plan) + len(loaded) + len(conv_plan), "bench", "setting", progress,
                                   where="bench.run_study")) as bar:
        rows, images, gts, gt_depths = [], {}, {}, {}
        for s in loaded:
            name = os.path.splitext(os.path.basename(s.source))[0]
            gt_depths[name] = d = ground_truth_depth(max_depths or [s.settings["max_depth"]])
            if bar is not None:
                bar.set_postfix_str(f"{name}: ground truth ({gt_spp} spp, max_depth {d})")
            gts[name] = ground_truth(s, gt_spp, max_depth=d, cache_dir=cache_dir)
            if bar is not None:
                bar.update(1)
        # the versions at one (scene, spp, depth, adaptive, denoise) are timed round-robin; the
        # rows keep the plan's order (version by version) for the report
        order = {(id(s), setting): i for i, (s, setting) in enumerate(plan)}
        groups: dict = {}
        for s, setting in plan:
            key = (id(s), setting.spp, setting.max_depth, setting.adaptive, setting.denoise)
            groups.setdefault(key, (s, []))[1].append(setting)
        for s, settings in groups.values():
            name = os.path.splitext(os.path.basename(s.source))[0]
            if bar is not None:
                first = settings[0]
                bar.set_postfix_str(f"{name}: {first.spp} spp depth {first.max_depth}, "
                                    f"{len(settings)} version(s)")
            for setting, (row, img) in zip(settings, measure_group(s, settings, gts[name], repeats, seed)):
                row["scene"] = name
                row["resolution"] = list(s.resolution)
                rows.append((order[(id(s), setting)], row))
                images[(name, setting)] = img
            if bar is not None:
                bar.update(len(settings))
        rows = [row for _, row in sorted(rows, key=lambda p: p[0])]
        refs = {os.path.splitext(os.path.basename(s.source))[0]: reference_version(s) for s in loaded}
        bias = estimate_bias(rows, gt_spp, refs)
        halves = {}
        for s, v, d in conv_plan:
            name = os.path.splitext(os.path.basename(s.source))[0]
            if bar is not None:
                bar.set_postfix_str(f"{name}: {v} converged ({gt_spp} spp, max_depth {d})")
            halves[(name, v, d)] = converged_halves(s, v, gt_spp, d, cache_dir=cache_dir)
            if bar is not None:
                bar.update(1)
        for (name, v, d), hv in halves.items():
            gt_halves = halves.get((name, refs[name], gt_depths[name]))
            bias[(name, v, d)] = converged_bias(hv, gts[name], gt_halves)
    for r in rows:
        r["bias_rmse"], r["bias_resolved"] = bias.get((r["scene"], r["label"], r["max_depth"]), (None, None))
        r["bias_method"] = ("converged" if (r["scene"], r["label"], r["max_depth"]) in halves
                            else "spp levels" if r["bias_rmse"] is not None else None)
    result = {"rows": rows, "ground_truth_spp": gt_spp, "ground_truth_depth": gt_depths, "repeats": repeats,
              "bias_from": "converged renders" if converged else "spp levels",
              "machine": _machine(), "load": load_note()}
    write_report(result, images, gts, out_dir)
    return result


def ground_truth_depth(depths) -> int:
    """The ground truth's ``max_depth`` for a study of ``depths``: unbounded (-1) if they hold
    it, else the deepest (a shallower one would show the depth gap as every deeper setting's
    error and bias; at a lower depth it is that depth's bias, which the study is to show).

    >>> ground_truth_depth([3, 12]), ground_truth_depth([6, -1, 2]), ground_truth_depth([6])
    (12, -1, 6)
    """
    return -1 if -1 in depths else max(depths)


def _machine() -> dict:

    return {"cpu_count": os.cpu_count(), "threads": dr.thread_count(), "platform": platform.platform(),
            "variant": mi.variant(), "mitsuba": mi.__version__, "drjit": dr.__version__}


# --------------------------------------------------------------------------- frame times
def frame_times(scene, keyframes, versions=DEFAULT_VERSIONS, frames: int = 60, spp: int = 1,
                fov: float | None = None, faithful: bool = False, error_frames: int = 3,
                gt_spp: int = 256, progress: bool | str = True) -> list[dict]:
    """GO-Draaw's frame-time statistics along a camera path, per version.

    The camera follows GO-Draaw's keyframes (position + angles) interpolated to ``frames``
    frames. Per version: mean, std, min, p10, median, p90, max frame time (seconds; each frame
    is a full render call, evaluated and synchronised) and the mean RMSE / CIEDE2000 against a
    ``path`` ground truth on ``error_frames`` evenly spaced frames.
    """
    check_mode(progress, "bench.frame_times")

    # (frames "seconds" at 1 fps: frames / 60 s at 60 fps truncates 123 * 60 / 60 to 122)
    path = interpolate(keyframes, duration=frames, fps=1, faithful=faithful)
    own_fov, fov_axis = scene_fov(scene)
    fov = own_fov if fov is None else fov
    params = scene.params
    key, x_fov_key = sensor_keys(scene)
    if key is None:
        raise DraawError("frame_times: the scene's sensor has no to_world parameter")
    if x_fov_key:    # (along the scene's fov_axis, as its own fov is)
        params[x_fov_key] = x_fov(fov, fov_axis, *scene.settings["resolution"])

    def set_camera(p):
        params[key] = look_at_transform(*go_draaw_look_at(p[:3], p[3], p[4], fov))
        params.update()

    check = set(np.linspace(0, len(path) - 1, error_frames).astype(int).tolist()) if error_frames else set()
    gts = {}
    for i in sorted(check):
        set_camera(path[i])
        gts[i] = np.array(render(scene, version=reference_version(scene), spp=gt_spp, seed=777,
                                 post=[]))[..., :3]
    if gts and not any(np.any(g != 0) for g in gts.values()):
        # (GO-Draaw's own path, in its units (x 300..900), over a scene of a few units: every
        # frame is empty, with an error of 0 and the times of empty renders)
        warnings.warn(f"frame_times: the ground truth is black in all {len(gts)} frames checked: the "
                      "camera path sees nothing of the scene (is it in the scene's units? GO-Draaw's "
                      "paths are in GO-Draaw's); the errors and times are of empty frames",
                      RuntimeWarning, stacklevel=2)
    out = []
    versions = scene_versions(scene, versions)
    with closed_after(progress_bar(len(versions) * len(path), "frame times", "frame", progress,
                                   where="bench.frame_times")) as bar:
        for v in versions:
            set_camera(path[0])
            render(scene, version=v, spp=spp, post=[])          # warm-up (compilation)
            times, errs = [], []
            for i, p in enumerate(path):
                set_camera(p)
                t0 = time.perf_counter()
                img = render(scene, version=v, spp=spp, seed=i, post=[])
                dr.eval(img)
                dr.sync_thread()
                times.append(time.perf_counter() - t0)
                if i in gts:
                    errs.append(errors(np.array(img), gts[i]))
                if bar is not None:
                    bar.update(1)
            t = np.array(times)
            row = {"version": v, "frames": len(t), "spp": spp, "mean_s": float(t.mean()),
                   "std_s": float(t.std(ddof=1)) if len(t) > 1 else 0.0, "min_s": float(t.min()),
                   "p10_s": float(np.quantile(t, 0.1)), "median_s": float(np.median(t)),
                   "p90_s": float(np.quantile(t, 0.9)), "max_s": float(t.max())}
            if errs:
                row["rmse"] = float(np.mean([e["rmse"] for e in errs]))
                row["ciede2000"] = float(np.mean([e["ciede2000"] for e in errs]))
            out.append(row)
    return out
