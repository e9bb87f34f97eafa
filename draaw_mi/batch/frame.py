"""Rendering one frame spec: a per-process scene cache, parameter updates, the NaN guard.

:func:`render_frame` is a pure function of its spec: every parameter a previous frame changed
is put back to the scene's loaded value unless this frame sets it, and the seed is part of the
spec, so a frame renders to the same bits in any process, after any other frame (box filter).
Both executors call it; the Dask executor keeps one :class:`SceneCache` per worker process.
"""
from __future__ import annotations

import hashlib
import os
import re
import threading
import time
import warnings

import drjit as dr
import numpy as np

from ..errors import DraawError, NonFiniteWarning, RenderError
from ..guard import in_foreground
from ..limits import HALF_MAX
from ..rendering.film_colour import check_film_colour, scene_colour_names
from ..rendering.renderer import MAX_PASS_SPP, render
from ..rendering.session import apply_post, holding, non_finite_count, session_of
from ..scene import load_scene, value_like
from ..scene.camera import look_at_transform, scene_fov, sensor_keys, x_fov
from .confine import check_inside
from .digests import file_hash, files_hash
from .exr import metadata, write_frame, write_preview


class CachedScene:
    """A loaded scene, its file hash, the hash of the files it reads (textures, meshes, ...:
    :func:`~draaw_mi.batch.planner.files_hash`) and the original values of everything frames
    override."""

    def __init__(self, scene, digest: str):
        self.scene, self.hash = scene, digest
        self.files_hash = files_hash(scene.info.get("files"))
        params = scene.params
        self.camera_key, self.fov_key = sensor_keys(scene)
        # a camera table's fov is measured as the scene's is, along its fov_axis (an XML
        # scene's: its sensor's x_fov); a y-axis fov written into x_fov would zoom in 1.9x
        self.fov, self.fov_axis = scene_fov(scene)
        # copies: params[key] is the scene's own value, which the next update changes in place
        self.originals: dict = {}
        if self.camera_key:
            self.originals[self.camera_key] = _snapshot(params[self.camera_key])
        if self.fov_key:
            self.originals[self.fov_key] = _snapshot(params[self.fov_key])
        self.prepared: set = set()
        self.params_moved = False        # the last apply() left an override in the scene

    def render(self, spec: dict):
        """Render the frame: one pass through the scene's render session, replayed from a
        ``dr.freeze`` recording from the second frame on, when the samples fit in one pass (the
        trace costs more than the kernel at low spp); otherwise through
        :func:`draaw_mi.render`. Same bits either way: the pass is render()'s one-pass render
        with its seed. Returns ``(image, info)``, ``info`` with render()'s ``channels``,
        ``non_finite`` and ``post``."""
        s = self.scene.settings
        spp = spec["spp"]
        session = session_of(self.scene)
        integrator = session.integrator(spec["version"], spec["max_depth"], s.get("hide_emitters", False),
                                        spec["aovs"])               # the one render() uses too
        self._prepare(integrator, spec)
        if (not spec.get("freeze", True) or spp > MAX_PASS_SPP or not session.freezes(spp, True)
                or session.sample_passes(spp, MAX_PASS_SPP) != [spp] or spec.get("sensor")):
            with warnings.catch_warnings():      # (the NaN guard below says it, failing the frame)
                warnings.simplefilter("ignore", NonFiniteWarning)
                return render(self.scene, version=spec["version"], spp=spp, seed=spec["seed"],
                              max_depth=spec["max_depth"], aovs=spec["aovs"], post=spec["post"],
                              return_info=True, sensor=spec.get("sensor", 0))
        # the film's colour checked and named as render() does it
        chain = s.get("post", []) if spec["post"] is None else spec["post"]
        if chain:
            check_film_colour(self.scene, "a post chain")
        colour = scene_colour_names(self.scene)
        image = session.render_pass(integrator, spp, spec["seed"], freeze=True)
        bad = 0
        if chain:                             # counted before the chain: it reads NaN/inf as 0
            bad = non_finite_count(image)
            image = apply_post(image, chain, colour + list(integrator.aov_names()))
        return image, {"channels": colour + list(integrator.aov_names()), "non_finite": bad, "post": chain}

    def _prepare(self, integrator, spec: dict) -> None:
        """Let ``integrator`` learn what it learns from the scene (V4's light pilot) with the
        scene as loaded, not as this frame moved it: whichever frame a run starts with (a
        resumed run starts mid-job), the frames then render the same bits."""
        prepare = getattr(integrator, "prepare_selection", None)
        if prepare is None or id(integrator) in self.prepared:
            return
        params = self.scene.all_params          # (SDF objects' parameters too)
        for key, original in self.originals.items():
            params[key] = original
        params.update()
        if self.params_moved:                      # the lights as loaded, not as last moved
            session_of(self.scene).scene_changed()
            self.params_moved = False
        prepare(self.scene.mi_scene)
        self.prepared.add(id(integrator))
        self.apply(spec)

    def apply(self, spec: dict) -> None:
        """Set this frame's camera and overrides; restore everything else a frame changed."""
        params = self.scene.all_params          # (SDF objects' parameters too)
        wanted = {}
        for key, value in spec["params"].items():
            if key not in self.originals:
                self.originals[key] = _snapshot(params[key])
            wanted[key] = value_like(self.originals[key], value, key)
        cam = spec.get("camera")
        if cam is not None:
            wanted[self.camera_key] = look_at_transform(cam["origin"], cam["target"], cam["up"],
                                                        cam.get("mirror", False))
            if self.fov_key:
                w, h = self.scene.settings["resolution"]
                wanted[self.fov_key] = type(self.originals[self.fov_key])(x_fov(cam["fov"], self.fov_axis, w, h))
        for key, original in self.originals.items():
            params[key] = wanted.get(key, original)
        params.update()
        # also when this frame only puts overrides back: else a job without overrides after
        # one that dimmed a light keeps V4's power table of that light's last value (frames up
        # to 1.4 off the same job rendered alone)
        if spec["params"] or self.params_moved:
            session_of(self.scene).scene_changed()       # e.g. V4's light powers
        self.params_moved = bool(spec["params"])


def _snapshot(value):
    """A copy of a scene parameter's current value (Dr.Jit values are copied by their type)."""
    try:
        return type(value)(value)
    except Exception:  # noqa: BLE001 - a Python value: immutable already
        return value


_ANY = object()          # SceneCache.get: any hash of the scene's files will do


class SceneCache:
    """Scenes loaded once per process, keyed by (file, resolution, an XML scene's defines);
    reloaded if the file changes."""
    def __init__(self):
        self._scenes: dict = {}
        self._guard = threading.Lock()

    def get(self, path: str, resolution=None, digest: str | None = None, files=_ANY,
            defines: dict | None = None) -> CachedScene:
        """The scene of ``path`` at ``resolution``; ``digest`` / ``files``: the hashes of the
        scene file and of the files it reads that the caller planned with (a cached scene
        whose files changed since it was loaded is loaded again: a long-lived Dask worker)."""

        where = os.path.abspath(path)
        named = tuple(sorted((defines or {}).items()))
        key = (where, tuple(resolution) if resolution else None, named)
        with self._guard:
            entry = self._scenes.get(key)
            if entry is not None and (digest is None or entry.hash == digest)\
                    and (files is _ANY or entry.files_hash == files):
                return entry
            current = file_hash(path)
            if digest is not None and current != digest:
                raise RenderError(f"{path}: scene file changed since the batch was planned (sha256 "
                                  f"{current[:12]}, planned {digest[:12]}); re-run the batch")
            if entry is not None:          # free the old scene first: a live twin changes kernels
                for k in [k for k, e in self._scenes.items() if e is entry]:
                    del self._scenes[k]
                entry = None
            scene = load_scene(path, **({"resolution": tuple(resolution)} if resolution else {}),
                               **({"defines": dict(defines)} if defines else {}))
            entry = self._scenes[key] = CachedScene(scene, current)
            # the same scene under the resolution it has: planning asks without one (the
            # scene's own), frames ask with the spec's; a second copy would take a second load
            # and its memory (and, live beside the first, other kernels)
            self._scenes.setdefault((where, tuple(scene.resolution), named), entry)
            return entry


def render_frame(spec: dict, cache: SceneCache, track_kernels: bool = False) -> dict:
    """Render one frame spec to its EXR (and PNG preview); return a result record.

    Raises :class:`~draaw_mi.errors.DraawError` (bad override value, non-finite pixels, I/O)
    for a frame that cannot be finished; the file is then not written.
    """
    t0 = time.perf_counter()
    entry = cache.get(spec["scene"], spec["resolution"], spec["scene_hash"], spec.get("files_hash"),
                      spec.get("defines"))
    if entry.files_hash != spec.get("files_hash"):
        raise RenderError(f"{spec['scene']}: a file the scene reads (texture, mesh, ...) changed since "
                          "the batch was planned; re-run the batch")
    with holding(entry.scene):                  # (the frame's parameter updates too)
        entry.apply(spec)
        if track_kernels:
            dr.kernel_history()                     # clears the history
        image, info = entry.render(spec)
        channels = info["channels"]
        arr = np.array(image, dtype=np.float32)
        kernels = []
        if track_kernels:
            kernels = sorted({kernel_signature(k) for k in dr.kernel_history()
                              if k["type"] == dr.KernelType.JIT})
    bad = max(info["non_finite"], int(np.count_nonzero(~np.isfinite(arr))))
    if bad:
        raise RenderError(f"job {spec['job']!r} frame {spec['frame']}: {bad} non-finite pixel values "
                          "(NaN guard); frame not written")
    if spec["half"]:            # (values beyond half's range would be stored as inf: the same guard)
        over = int(np.count_nonzero(np.abs(arr) > HALF_MAX))
        if over:
            raise RenderError(f"job {spec['job']!r} frame {spec['frame']}: {over} pixel values beyond "
                              f"half's range (+-{HALF_MAX:g}, the largest {float(np.abs(arr).max()):.4g}) would "
                              "be stored as inf (NaN guard); frame not written: set half = false, or "
                              "darken the scene")
    seconds = time.perf_counter() - t0
    # still under the output folder: a symbolic link made there since planning is not followed
    check_inside(spec["output"], spec.get("root"), f"job {spec['job']!r} frame {spec['frame']}", "its EXR")
    write_frame(spec["output"], arr, channels, metadata(spec, seconds, post=info["post"]), half=spec["half"])
    # after its EXR: a PNG is never there without its frame; an EXR whose preview a kill
    # prevented reads as "no-preview", and the next run writes the PNG from it
    if spec.get("preview"):
        write_preview(spec, arr, channels)
    return {"job": spec["job"], "frame": spec["frame"], "output": spec["output"], "seconds": seconds,
            "channels": channels, "kernels": kernels, "pid": os.getpid(), "threads": dr.thread_count()}


_ALIGNMENT = re.compile(r"\balign \d+|drjit_[0-9a-f]{32}")
_SIGNATURES: dict = {}          # kernel hash -> signature (one hash is one code)


def kernel_signature(entry: dict) -> str:
    """What a kernel computes, from its ``dr.kernel_history()`` entry: the hash of its code
    with the load alignments and its own name left out. Dr.Jit specialises a kernel to the
    alignment of the buffers it is given, so a small kernel outside the recorded render (an
    8-wide camera update) gets a new hash on frames whose buffers the PNG previews moved; by
    hash alone, a batch would warn of recompiles that compute the same thing."""
    key = str(entry["hash"])
    sig = _SIGNATURES.get(key)          # (a replayed frame's kernels: found, not read again)
    if sig is None:
        ir = entry.get("ir")
        text = ir.getvalue() if hasattr(ir, "getvalue") else ir
        sig = hashlib.sha256(_ALIGNMENT.sub("", text).encode()).hexdigest()[:32] if text else key
        if len(_SIGNATURES) > 4096:
            _SIGNATURES.clear()
        _SIGNATURES[key] = sig
    return sig


@in_foreground
def safe_render_frame(spec: dict, cache: SceneCache, track_kernels: bool = False) -> dict:
    """:func:`render_frame` that reports a failure as ``{"error": ...}`` instead of raising
    (any exception: a failing frame must not stop the batch)."""
    try:
        return render_frame(spec, cache, track_kernels)
    except DraawError as e:
        msg = str(e)
    except Exception as e:  # noqa: BLE001 - Mitsuba/Dr.Jit errors are RuntimeErrors
        msg = f"{type(e).__name__}: {str(e).strip().splitlines()[-1] if str(e).strip() else ''}"
    return {"job": spec["job"], "frame": spec["frame"], "output": spec["output"], "error": msg,
            "pid": os.getpid()}
