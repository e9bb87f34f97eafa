"""Frame planning: expand validated jobs into self-contained, hashed frame specs.

A frame spec is a plain dict (picklable, JSON-able) that holds everything a worker needs to
render one frame: scene file and its hash, effective render settings, the camera and the
parameter values of that frame, a deterministic seed and the output path. Its ``hash`` is the
job identity written into the EXR; a frame whose file carries the same hash is finished.

Planning loads every scene once (through a :class:`~draaw_mi.batch.frame.SceneCache`) to resolve
the scene's default settings and to check that every overridden parameter exists, so a bad
manifest fails before anything renders.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile

import drjit as dr
import numpy as np

from ..errors import DraawError, SceneError
from ..integrators import SCENE_VERSION, is_draaw, resolve_version
from ..post import display_encoded
from ..rendering.film_colour import scene_colour_names, sensor_index, sensor_spp
from ..rendering.session import session_of
from ..scene import value_like
from ..scene.camera import check_look_at, go_draaw_look_at, sensor_reach, x_fov
from ..scene.camera_path import interpolate
from ..scene.schema import Where, control_character
from ..scene.smoke_boxes import check_camera_outside_smoke
from .digests import file_hash, files_hash, versions  # noqa: F401 (re-exported)
from .frame import SceneCache
from .manifest import Manifest, format_output
from .sheet import sheet_path


def frame_seed(job_seed: int, frame: int) -> int:
    """A deterministic per-frame seed in [0, 2**31): the same frame always gets the same seed,
    and neighbouring frames get unrelated ones (no shared sample streams).

    >>> frame_seed(0, 3) == frame_seed(0, 3), frame_seed(0, 3) != frame_seed(0, 4)
    (True, True)
    """
    digest = hashlib.sha256(f"draaw-batch:{job_seed}:{frame}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def canonical_version(version: str) -> str:
    """One name per integrator for the frame hash (``V4``, ``draaw_v4``, ``optimised`` ->
    ``v4``): the pixels depend on the integrator, not on how the manifest spells it.

    >>> canonical_version("V4"), canonical_version("V2M"), canonical_version("path")
    ('v4', 'v3', 'path')
    """
    plugin = resolve_version(version)
    return plugin.removeprefix("draaw_")


def frame_hash(spec: dict) -> str:
    """Hash of everything that determines a frame's pixels (not its output path or time)."""
    keys = ("scene_hash", "resolution", "version", "spp", "sampler", "seed", "max_depth", "aovs", "post",
            "camera", "params", "half", "versions")
    if spec.get("files_hash"):     # (only then: frames of scenes that read no file keep their hash)
        keys += ("files_hash",)
    if spec.get("defines"):        # (likewise: jobs without an XML scene's defines)
        keys += ("defines",)
    if spec.get("sensor"):         # (likewise: jobs of the first sensor)
        keys += ("sensor",)
    if spec.get("scene_camera_mirror"):
        # (only then: a scene's own GO-Draaw camera with sin(phi) > 0 renders mirrored, so its
        # frames hashed without this key are stale; the others keep their hash)
        keys += ("scene_camera_mirror",)
    keys += tuple(k for k in CHANGED_KEYS if spec.get(k))     # (likewise: _changed_since_hashed)
    values = {k: spec.get(k) for k in keys}
    values["version"] = canonical_version(values["version"])
    text = json.dumps(values, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:32]


#: frame-hash keys of renders whose pixels changed since frames were hashed without them
CHANGED_KEYS = ("declared_integrator", "post_by_channel_names")


def _changed_since_hashed(scene, version: str, integrator, chain) -> dict:
    """The :data:`CHANGED_KEYS` of a job's frames: ``declared_integrator``, the settings of
    the Mitsuba integrator a scene declares, where a frame now renders with it (``path`` of
    ``rr_depth`` 2 had rendered with a default ``path``); ``post_by_channel_names`` where a
    post chain once took an AOV for alpha (an RGB film with one AOV channel) or alpha for an
    AOV (an RGBA film with AOVs). Empty for every other frame, whose hash stays."""
    out = {}
    if not is_draaw(version) and integrator is scene.mi_scene.integrator() \
            and resolve_version(version) != SCENE_VERSION:
        out["declared_integrator"] = str(integrator)
    if chain and is_draaw(version):
        colour, aov = len(scene_colour_names(scene)), len(integrator.aov_names())
        if (colour == 3 and aov == 1) or (colour == 4 and aov > 0):
            out["post_by_channel_names"] = True
    return out


# --------------------------------------------------------------------------- cameras
def _ease(rows: np.ndarray, frames: int) -> np.ndarray:
    """Smoothstep-eased piecewise-linear path through ``rows`` with ``frames`` samples (the
    non-faithful GO-Draaw interpolation of :func:`draaw_mi.scene.camera_path.interpolate`)."""
    n = len(rows)
    if n == 1 or frames == 1:
        return np.repeat(rows[:1], frames, axis=0)
    u = np.linspace(0.0, n - 1, frames)
    seg = np.minimum(u.astype(int), n - 2)
    t = u - seg
    s = t * t * (3 - 2 * t)
    return rows[seg] + (rows[seg + 1] - rows[seg]) * s[:, None]


def camera_frames(cam: dict, frames: int, scene_fov: float) -> list[dict]:
    """One ``{origin, target, up, fov}`` per frame for a validated camera table, with
    ``mirror: true`` where a GO-Draaw keyframe's view is mirrored (``sin φ > 0``, see
    :func:`~draaw_mi.scene.camera.go_draaw_look_at`; only there: the other frames keep
    their hashes)."""

    fov = float(cam.get("fov", scene_fov))
    out = []
    if cam["kind"] == "orbit":
        o = cam["orbit"]
        up = np.asarray(o["up"], float)
        up /= max(np.linalg.norm(up), 1e-12)
        e1 = np.cross([1.0, 0.0, 0.0], up)
        if np.linalg.norm(e1) < 1e-6:
            e1 = np.cross([0.0, 0.0, 1.0], up)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(up, e1)
        full = math.isclose(o["degrees"] % 360.0, 0.0, abs_tol=1e-9)
        steps = frames if full else max(frames - 1, 1)      # a full turn must not repeat frame 0
        target = np.asarray(o["target"], float)
        for i in range(frames):
            a = math.radians(o["start"] + o["degrees"] * i / steps)
            origin = target + up * o["height"] + o["radius"] * (math.cos(a) * e1 + math.sin(a) * e2)
            out.append((origin, target, up, False))
    elif cam["kind"] == "look_at":
        rows = _ease(np.asarray(cam["look_at"], float), frames)
        out = [(r[0:3], r[3:6], r[6:9], cam.get("mirror", False)) for r in rows]
        for i, (o, t, u, _) in enumerate(out):          # (the keys are checked; eased frames too)
            check_look_at(o, t, u, Where(f"camera look_at frame {i}"))
    else:
        keys = cam["keyframes"]
        if len(keys) == 1 or frames == 1:
            path = np.repeat(np.asarray(keys[:1], float), frames, axis=0)
        else:
            path = interpolate(keys, duration=1.0, fps=frames, faithful=cam["faithful"])
        for p in path:
            try:
                out.append(go_draaw_look_at(p[:3], p[3], p[4], fov))
            except ValueError:
                raise SceneError(f"camera keyframe {p.tolist()} gives a degenerate view") from None
    return [{"origin": [float(v) for v in o], "target": [float(v) for v in t], "up": [float(v) for v in u],
             "fov": fov, **({"mirror": True} if m else {})} for o, t, u, m in out]


def param_value(kind: str, data, frame: int, frames: int):
    """The value of an override at ``frame``: constant, linear from/to, or per-frame list."""
    if kind == "const":
        return data
    if kind == "values":
        return data[frame]
    a, b = data
    t = frame / (frames - 1) if frames > 1 else 0.0
    if isinstance(a, list):
        return [x + (y - x) * t for x, y in zip(a, b)]
    return a + (b - a) * t


def _draaw(version: str) -> bool:
    try:
        return is_draaw(version)
    except DraawError:
        return True                      # (an unknown version fails later, with its own message)


def same_file(path: str) -> str:
    """``path`` as plan() tells files apart: absolute, links followed, without case (x/0001.exr
    and x/0001.EXR are one file on macOS or Windows)."""
    return os.path.normcase(os.path.realpath(path)).casefold()


def file_identity(path: str):
    """``(device, inode)`` of the file at ``path`` (links followed), or ``None`` where there is
    none: two names are one file exactly when they give the same identity (``Env.exr`` and
    ``env.exr`` on macOS, not on Linux)."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def input_files(manifest: Manifest, cache) -> dict:
    """What a run reads, by :func:`file_identity` -> what it is: the manifest, each job's scene
    file and every file that scene reads (``scene.info["files"]``: meshes, textures,
    environment maps). No frame, preview, contact sheet or log may be one of them: the run
    would overwrite its own input (a frame written over the environment map it lit, rendered
    again from itself at every run; a log appended to the scene file). A name with no file
    behind it yet is none of them."""
    found = {}

    def add(path, what):
        ident = file_identity(path)
        if ident is not None:
            found.setdefault(ident, what)
    if not manifest.path.startswith("<"):
        add(manifest.path, "the manifest")
    for job in manifest.jobs:
        add(job.scene, f"the scene file of job {job.name!r}")
        try:
            entry = cache.get(job.scene, job.resolution, defines=job.defines)
        except DraawError as e:                    # (as plan() says it)
            raise SceneError(f"{manifest.path}: job {job.name!r}: {e}") from None
        for f in entry.scene.info.get("files", []):
            add(f, f"a file the scene of job {job.name!r} reads")
    return found


def check_file_name(where: str, path: str, what: str) -> None:
    """Refuse an output ``path`` with a name longer than its file system takes (255 bytes on
    Linux and macOS): the frame would render, then fail as it is written."""
    folder = os.path.dirname(path) or "."
    while not os.path.isdir(folder) and os.path.dirname(folder) != folder:
        folder = os.path.dirname(folder)
    try:
        longest = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        longest = 255
    for part in path.split(os.sep):
        if len(os.fsencode(part)) > longest:
            raise SceneError(f"{where}: output pattern gives {what} a name of {len(os.fsencode(part))} bytes "
                             f"({part[:24]}...); expected at most {longest}, the file system's limit")


# --------------------------------------------------------------------------- plan
def plan(manifest: Manifest, cache=None) -> list[dict]:
    """Every frame of every job as a spec dict, validated against the loaded scenes and the
    files the run reads (:func:`input_files`)."""
    cache = cache if cache is not None else SceneCache()
    vers = versions()
    specs, seen = [], {}
    where = manifest.path
    inputs = input_files(manifest, cache)
    for ji, job in enumerate(manifest.jobs):
        loc = f"{where}: job {job.name!r}"
        try:
            entry = cache.get(job.scene, job.resolution, defines=job.defines)
        except DraawError as e:
            raise SceneError(f"{loc}: {e}") from None
        scene = entry.scene
        s = scene.settings
        try:
            sensor = sensor_index(scene, job.sensor, loc)
        except DraawError as e:
            raise SceneError(str(e)) from None
        if sensor and job.resolution is not None:
            raise SceneError(f"{loc}: resolution sizes the scene's first film; sensor = {job.sensor!r} renders "
                             "another at its own size: drop resolution")
        version = job.version or s["version"]
        spp = job.spp or sensor_spp(scene, sensor)
        max_depth = s["max_depth"] if job.max_depth is None else job.max_depth
        aovs = list(s.get("aovs", [])) if job.aovs is None else job.aovs
        if job.aovs is None and aovs and not _draaw(version):
            aovs = []                    # the scene's AOVs come from v1..v4 (as render() does)
        encoded = display_encoded(s.get("post", []) if job.post is None else job.post)
        try:
            session = session_of(scene)
            integ = session.integrator(version, max_depth, s.get("hide_emitters", False), aovs)
            session.check_version_sees(version)
        except DraawError as e:
            raise SceneError(f"{loc}: {e}") from None
        changed = _changed_since_hashed(scene, version, integ, s.get("post", []) if job.post is None else job.post)
        keys = {}
        for name in job.params:
            try:
                keys[name] = scene.key(name)
            except DraawError as e:
                raise SceneError(f"{loc}: params: {e}") from None
            same = [n for n in keys if n != name and keys[n] == keys[name]]
            if same:      # (else the last one wins, silently)
                raise SceneError(f"{loc}: params: {name!r} and {same[0]!r} are the same parameter "
                                 f"{keys[name]!r}; keep one")
            if job.camera is not None and keys[name] in (entry.fov_key, entry.camera_key):
                # (else the camera table's view replaces the override, silently)
                raise SceneError(f"{loc}: params.{name}: the job's camera table sets the view and "
                                 "field of view; give camera.fov, or drop the camera table")
            _check_shape(loc, name, job.params[name], scene.all_params[keys[name]], keys[name])
        _check_values(loc, keys, job.params, job.frames, scene)
        if sensor and job.camera is not None:
            raise SceneError(f"{loc}: camera: a camera table moves the scene's first sensor; sensor = "
                             f"{job.sensor!r} renders another: drop one")
        cams = None
        if job.camera is not None:
            if entry.camera_key is None:
                raise SceneError(f"{loc}: camera: the scene's sensor has no to_world parameter")
            try:
                cams = camera_frames(job.camera, job.frames, entry.fov)
                volumes = scene.info.get("volumes", [])
                if volumes:
                    w, h = scene.resolution
                    for f, c in enumerate(cams):     # (at the frame's own field of view)
                        reach = sensor_reach(scene, x_fov(c["fov"], entry.fov_axis, w, h))
                        check_camera_outside_smoke(c["origin"], volumes, Where(f"frame {f}"), reach)
            except DraawError as e:
                raise SceneError(f"{loc}: camera: {e}") from None
        for f in range(job.frames):
            out = format_output(job.output, job, f, version, spp)
            if control_character(out) is not None:                  # ({frame:c} of a small number)
                raise SceneError(f"{where}: output pattern gives {out!r} for job {job.name!r} frame {f}, "
                                 "a name with a control character; expected printable file names")
            # a frame's files (its EXR, and its PNG with previews), told apart without case:
            # x/0001.exr and x/0001.EXR share a preview, and are one file on macOS or Windows
            files = [out] + ([os.path.splitext(out)[0] + ".png"] if job.previews else [])
            for path in files:
                check_file_name(where, path, f"job {job.name!r} frame {f}")
                if file_identity(path) in inputs:
                    raise SceneError(f"{where}: output pattern gives {path!r} for job {job.name!r} frame {f}, "
                                     f"which is {inputs[file_identity(path)]}; give the frames names of their own")
                if path.casefold() in seen:
                    raise SceneError(f"{where}: output pattern gives the same file {path!r} for "
                                     f"{seen[path.casefold()]} and job {job.name!r} frame {f}")
                seen[path.casefold()] = f"job {job.name!r} frame {f}"
            spec = {
                "job": job.name, "job_index": ji, "frame": f, "frames": job.frames,
                "scene": job.scene, "scene_hash": entry.hash, "files_hash": entry.files_hash,
                "defines": dict(job.defines), "sensor": sensor,
                "resolution": list(scene.resolution),
                "version": version, "spp": int(spp), "sampler": s.get("sampler"),
                # (a job without a seed takes its scene's, as render() does: two scenes
                # that differ only in render.seed give different frames)
                "seed": frame_seed(int(s.get("seed", 0)) if job.seed is None else job.seed, f),
                "max_depth": int(max_depth), "aovs": list(aovs), "post": job.post,
                "camera": cams[f] if cams else None,
                "scene_camera_mirror": not cams and bool(scene.info.get("camera", {}).get("mirror")),
                **changed,
                "params": {keys[n]: param_value(k, d, f, job.frames) for n, (k, d) in job.params.items()},
                "half": job.half, "preview": job.previews, "output": out, "versions": vers,
                "encoded": encoded,
                "freeze": job.freeze,
                # (not in the hash: a moved manifest's frames stay done; in the header, so
                # that another manifest's run does not silently replace them)
                "manifest": None if where.startswith("<") else os.path.abspath(where),
            }
            spec["hash"] = frame_hash(spec)
            specs.append(spec)
    if manifest.contact_sheet:
        for spec in (sp for sp in specs if sp["frame"] == 0):
            path = sheet_path(spec)
            check_file_name(where, path, f"the contact sheet of job {spec['job']!r}")
            if file_identity(path) in inputs:
                raise SceneError(f"{where}: job {spec['job']!r}'s contact sheet {path!r} is "
                                 f"{inputs[file_identity(path)]}; rename the job or change the output pattern")
            if path.casefold() in seen:
                raise SceneError(f"{where}: job {spec['job']!r}'s contact sheet {path!r} is the file of "
                                 f"{seen[path.casefold()]}; rename the job or change the output pattern")
            seen[path.casefold()] = f"job {spec['job']!r}'s contact sheet"
    return specs


def components(value) -> int:
    """Number of values a parameter holds: 3 for a Color3f, the width of a Float array."""
    if dr.is_array_v(value):
        return len(value) if dr.depth_v(value) > 1 else dr.width(value)
    return 1


def _check_shape(loc, name, spec, current, key):
    """An override's values fit the parameter: not a transform, not integers, as many
    components, convertible to its type (else the frames fail one by one at render time)."""

    kind_name = type(current).__name__
    if "Transform" in kind_name:
        raise SceneError(f"{loc}: params.{name}: transforms cannot be overridden; use [camera] for the "
                         "sensor")
    if dr.is_integral_v(current) or dr.is_mask_v(current):
        hint = "; a job's resolution sets the film size" if key.endswith(("film.size", "crop_size")) else ""
        raise SceneError(f"{loc}: params.{name}: {key} holds integers ({kind_name}); batch overrides "
                         f"set number parameters{hint}")
    kind, data = spec
    samples = data if kind in ("values", "linear") else [data]
    # (a texture takes one number or one per channel: a constant map of its shape)
    want = current.shape[-1] if dr.is_tensor_v(current) else components(current)
    for v in samples:
        size = len(v) if isinstance(v, list) else 1
        if size != want and size != 1:
            raise SceneError(f"{loc}: params.{name}: value {v!r} has {size} components; the parameter "
                             f"has {want}")
        try:
            value_like(current, v, key)
        except DraawError as e:
            raise SceneError(f"{loc}: params.{name}: {e}") from None


def _check_values(loc, keys: dict, specs: dict, frames: int, scene) -> None:
    """Every frame's value of an override within the parameter's range (roughness in [0, 1],
    colours >= 0, finite: :func:`draaw_mi.materials.check_value`; an SDF object's radius > 0,
    a round box's radius within its size, ...: :meth:`SDFScene.check
    <draaw_mi.sdf.scene.SDFScene.check>`), before anything renders (an out-of-range
    value would render as the clamped one, with exit status 0). A frame's values are checked
    together, on the scene as loaded (each frame starts from it)."""
    for f in range(frames):
        values = {}
        for name, (kind, data) in specs.items():
            v = param_value(kind, data, f, frames)
            if isinstance(v, list) and len(v) == 1:
                v = v[0]
            if not isinstance(v, list) or len(v) == 3:
                values[f"params.{name}"] = (keys[name], v)
        try:
            scene.check_values(f"frame {f}", values)
        except DraawError as e:
            raise SceneError(f"{loc}: {e}") from None


def check_writable(folders, where: str) -> None:
    """Every output folder exists and is writable, or can be created (checked before rendering)."""
    for folder in folders:
        probe = folder
        while not os.path.exists(probe):
            parent = os.path.dirname(probe)
            if parent == probe:
                break
            probe = parent
        if not os.path.isdir(probe):
            raise SceneError(f"{where}: output folder {folder!r} cannot be created ({probe!r} is a file)")
        if not os.access(probe, os.W_OK | os.X_OK):
            raise SceneError(f"{where}: output folder {folder!r} is not writable (no write permission "
                             f"on {probe!r})")


def prepare_outputs(folders, where: str) -> None:
    """Create the output folders and write and delete a probe file in each: the real test of
    "writable" (permission bits do not tell for root, read-only mounts or /proc). Called by
    ``run`` before anything renders; raises a one-line SceneError."""
    for folder in folders:
        try:
            os.makedirs(folder, exist_ok=True)
            fd, probe = tempfile.mkstemp(prefix=".draaw-probe-", dir=folder)
            os.close(fd)
            os.unlink(probe)
        except OSError as e:
            raise SceneError(f"{where}: output folder {folder!r} cannot be written "
                             f"({e.strerror or e})") from None
