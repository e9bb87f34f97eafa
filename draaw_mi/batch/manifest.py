"""Batch manifests: read a TOML/JSON manifest and validate it into :class:`Job` objects.

A manifest lists jobs; a job is a scene rendered along a camera path with parameter overrides
at some version / spp / AOVs / post chain. ``version``, ``spp`` and ``scene`` may be lists:
the job then expands into one job per combination (named ``job-v4-16`` and so on)::

    output = "out/{job}/{frame:04d}.exr"     # pattern relative to --out DIR (or the current
                                             # folder), inside it; fields: job scene version spp frame
    half = false                             # float16 EXR channels instead of float32
    previews = false                         # also an sRGB PNG beside every EXR
    contact_sheet = false                    # one PNG with every frame of a job, per job
    log = "render-log.jsonl"                 # a file (no fields), relative like output; default:
                                             # <manifest>.batch.jsonl in the output pattern's
                                             # fixed folder (out/ here)
    # a job's freeze = false re-traces every frame instead of replaying a dr.freeze recording

    [defaults]                               # any job key, applied where a job does not set it
    spp = 16

    [[jobs]]
    name = "turntable"
    scene = "material_spheres.toml"          # relative to the manifest's folder
    frames = 24
    version = "v4"                           # or ["v1", "v4"]
    resolution = [256, 256]
    aovs = ["depth", "normal"]
    camera = { orbit = { target = [0, 0.1, 0], radius = 9.3, height = 2.2, degrees = 360 } }
    params = { "r0m0.roughness" = { from = 0.05, to = 0.95 } }
    # a Mitsuba XML scene's $name parameters (its <default>s), as draaw-mi render -D sets them:
    # defines = { max_depth = 8, albedo = "0.2, 0.5, 0.8" }
    # sensor = "top"                         # another of the scene's sensors (index or id)

Camera tables (one of): ``orbit``; ``keyframes`` (GO-Draaw ``[x, y, z, theta, phi]`` rows,
interpolated as in :mod:`draaw_mi.scene.camera_path`, ``faithful`` for GO-Draaw's exact quirks);
``file`` (a GO-Draaw ``camera_positions.json``); ``look_at`` (a list of
``{origin, target, up}`` keyframes, eased like the GO-Draaw path; ``mirror = true`` in every
keyframe for a mirrored view, as a scene's ``[camera]``). ``fov`` sets the field of
view. Parameter values: a number or list (every frame), ``{from, to}`` (linear over the
frames) or ``{values = [...]}`` (one per frame).

Every file of a run lies under the output folder: an absolute or climbing (``..``) output
pattern or log is refused, unless ``allow_outside_out`` (:mod:`~draaw_mi.batch.confine`).

Every error is one line naming the manifest, the field, the bad value and what was expected.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import string as _string
from dataclasses import dataclass, field

from ..errors import DraawError, ParameterError, SceneError, suggest
from ..integrators import resolve_version
from ..post import load_chain
from ..scene.camera import check_look_at
from ..scene.camera_path import as_keyframes
from ..scene.schema import Where, boolean, check_keys, number, read_document, resolution, string, vector
from ..scene.xml_film import check_defines
from .confine import check_relative

TOP_KEYS = ("output", "half", "previews", "contact_sheet", "log", "defaults", "jobs")
JOB_KEYS = ("name", "scene", "frames", "version", "spp", "seed", "max_depth", "resolution", "aovs",
            "post", "camera", "params", "output", "half", "previews", "freeze", "defines", "sensor")
CAMERA_KEYS = ("orbit", "keyframes", "file", "look_at", "faithful", "fov")
ORBIT_KEYS = ("target", "radius", "height", "degrees", "start", "up")
LOOK_AT_KEYS = ("origin", "target", "up", "mirror")
PATTERN_FIELDS = ("job", "scene", "version", "spp", "frame")
DEFAULT_OUTPUT = "{job}/{frame:04d}.exr"
EXPANDING = ("scene", "version", "spp")


@dataclass
class Job:
    """One validated job: a scene rendered over ``frames`` frames with fixed settings."""
    name: str
    scene: str                    # absolute path
    frames: int
    output: str                   # absolute pattern
    version: str | None = None
    spp: int | None = None
    seed: int | None = None       # None: the scene's render.seed
    max_depth: int | None = None
    resolution: tuple | None = None
    aovs: list | None = None
    post: list | None = None
    camera: dict | None = None    # validated camera table (see module docstring)
    params: dict = field(default_factory=dict)   # name -> ("const"|"linear"|"values", data)
    half: bool = False
    previews: bool = False
    freeze: bool = True           # replay a frozen render after the first frame (dr.freeze)
    defines: dict = field(default_factory=dict)  # an XML scene's $name values, as strings
    sensor: int | str = 0         # the scene's sensor that renders (an index or an id)


@dataclass
class Manifest:
    """A validated manifest: its jobs plus batch-wide options."""
    path: str
    jobs: list
    contact_sheet: bool = False
    log: str | None = None
    root: str | None = None       # the output folder every file must lie under (None: anywhere)


def read_manifest_file(path: str) -> dict:
    """Parse a TOML or JSON manifest into a dict (errors name the file and line)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        raise SceneError(f"{path}: is a folder; expected a manifest file (.toml or .json)")
    if not os.path.isfile(path):
        raise SceneError(f"{path}: manifest does not exist")
    if not path.lower().endswith((".toml", ".json")):
        raise SceneError(f"{path}: unknown manifest format; expected .toml or .json")
    return read_document(path, "manifest")


def parse_manifest(source, out_dir: str | None = None, allow_outside_out: bool = False) -> Manifest:
    """Validate a manifest (file name or dict) into a :class:`Manifest`.

    Relative scene and camera files resolve against the manifest's folder; output patterns and
    the log against ``out_dir`` when given, else against the current folder, and they must lie
    under it (:mod:`~draaw_mi.batch.confine`) unless ``allow_outside_out``.
    """
    if not isinstance(source, (dict, str, os.PathLike)) or isinstance(source, bytes):
        raise ParameterError(f"batch: manifest={source!r}; expected a manifest file's path or a dict")
    if out_dir is not None and (not isinstance(out_dir, (str, os.PathLike)) or not os.fspath(out_dir)):
        raise ParameterError(f"batch: out={out_dir!r}; expected an output folder's path (leave it out "
                             "for the current folder)")
    if isinstance(source, dict):
        doc, name, base = source, "<manifest>", os.getcwd()
    else:
        name = os.fspath(source)
        doc, base = read_manifest_file(name), os.path.dirname(os.path.abspath(name))
    where = Where(name)
    check_keys(doc, TOP_KEYS, where, required=("jobs",))
    out_base = os.path.abspath(out_dir) if out_dir is not None else os.getcwd()
    confined = not allow_outside_out
    pattern = doc.get("output", DEFAULT_OUTPUT)
    half = boolean(doc.get("half", False), where / "half")
    previews = boolean(doc.get("previews", False), where / "previews")
    sheet = boolean(doc.get("contact_sheet", False), where / "contact_sheet")
    log = doc.get("log")
    if log is not None:
        log = string(log, where / "log")
        if "{" in log or "}" in log or not log.strip() or log.endswith(("/", os.sep)):
            raise (where / "log").error(f"{log!r} must name one file (no {{fields}}: one log serves "
                                        "every job)")
        if confined:
            check_relative(log, where / "log", "the log")
        log = os.path.join(out_base, log)
    defaults = doc.get("defaults", {})
    check_keys(defaults, [k for k in JOB_KEYS if k != "name"], where / "defaults")
    jobs_doc = doc["jobs"]
    if not isinstance(jobs_doc, list) or not jobs_doc:
        raise (where / "jobs").error("expected a non-empty list of job tables ([[jobs]])")
    jobs, names = [], set()
    for i, jd in enumerate(jobs_doc):
        wj = where / "jobs" / i
        check_keys(jd, JOB_KEYS, wj)
        merged = {**{"output": pattern, "half": half, "previews": previews}, **defaults, **jd}
        for job in _expand(merged, wj, base, out_base, i, confined):
            if job.name in names:
                raise (wj / "name").error(f"{job.name!r} is used by two jobs; job names must be unique")
            names.add(job.name)
            jobs.append(job)
    return Manifest(name, jobs, sheet, log, out_base if confined else None)


def _expand(jd: dict, where: Where, base: str, out_base: str, index: int, confined: bool):
    name = jd.get("name", f"job{index}")
    name = string(name, where / "name")
    if not name or any(c in name for c in "/\\") or name.startswith("."):
        raise (where / "name").error(f"{name!r} is not a usable job name (no slashes, not empty)")
    if "scene" not in jd:
        raise where.error("missing required key 'scene'")
    axes = {k: (jd[k] if isinstance(jd.get(k), list) else [jd.get(k)]) for k in EXPANDING}
    for k in EXPANDING:
        if isinstance(jd.get(k), list) and not jd[k]:
            raise (where / k).error("is an empty list")
    combos = list(itertools.product(*(axes[k] for k in EXPANDING)))
    for combo in combos:
        vals = dict(zip(EXPANDING, combo))
        suffix = "".join(f"-{_tag(k, vals[k])}" for k in EXPANDING if isinstance(jd.get(k), list))
        yield _job(dict(jd, **vals), where, base, out_base, name + suffix, confined)


def _tag(key, value):
    if key == "scene":
        return os.path.splitext(os.path.basename(str(value)))[0]
    return str(value)


def _job(jd: dict, where: Where, base: str, out_base: str, name: str, confined: bool) -> Job:
    scene = string(jd["scene"], where / "scene")
    scene = scene if os.path.isabs(scene) else os.path.normpath(os.path.join(base, scene))
    if os.path.isdir(scene):
        raise (where / "scene").error(f"{scene!r} is a folder; expected a scene file")
    if not os.path.isfile(scene):
        raise (where / "scene").error(f"scene file {scene!r} does not exist")
    job = Job(name=name, scene=scene, frames=1, output="")
    if "defines" in jd:
        job.defines = _defines(jd["defines"], where / "defines", scene)
    if "sensor" in jd:
        sensor = jd["sensor"]
        if isinstance(sensor, bool) or not (isinstance(sensor, int) and sensor >= 0
                                            or isinstance(sensor, str) and sensor.strip()):
            raise (where / "sensor").error(f"{sensor!r}; expected a sensor's index (0 the first) or its id")
        job.sensor = sensor
    if jd.get("version") is not None:
        job.version = string(jd["version"], where / "version")
        try:
            resolve_version(job.version)
        except Exception as e:  # noqa: BLE001 - resolve_version raises a DraawError with the list
            raise (where / "version").error(str(e)) from None
    if jd.get("spp") is not None:
        job.spp = int(number(jd["spp"], where / "spp", lo=1, hi=2 ** 24, integer=True))
    if "seed" in jd:
        job.seed = int(number(jd["seed"], where / "seed", lo=0, hi=2 ** 32 - 1, integer=True))
    if "max_depth" in jd:
        job.max_depth = int(number(jd["max_depth"], where / "max_depth", lo=-1, hi=1024, integer=True))
    if "resolution" in jd:
        job.resolution = resolution(jd["resolution"], where / "resolution")
    if "aovs" in jd:
        aovs = jd["aovs"]
        if not isinstance(aovs, list) or not all(isinstance(a, str) and a for a in aovs):
            raise (where / "aovs").error(f"{aovs!r} is not a list of AOV names")
        twice = sorted({a for a in aovs if aovs.count(a) > 1})
        if twice:                    # (a frame would hold it once: the list said otherwise)
            raise (where / "aovs").error(f"{aovs!r} names {', '.join(map(repr, twice))} twice; "
                                         "expected each AOV once")
        job.aovs = list(aovs)
    if "post" in jd:
        job.post = _check_post(jd["post"], where / "post")
    job.half = boolean(jd.get("half", False), where / "half")
    job.previews = boolean(jd.get("previews", False), where / "previews")
    job.freeze = boolean(jd.get("freeze", True), where / "freeze")
    if "camera" in jd:
        job.camera = _camera(jd["camera"], where / "camera", base)
    job.params = _params(jd.get("params", {}), where / "params")
    job.frames = _frames(jd, job, where)
    job.output = _pattern(jd.get("output", DEFAULT_OUTPUT), where / "output", out_base, job, confined)
    return job


def _defines(defines, where: Where, scene: str) -> dict:
    """A job's ``defines``: the ``$name`` values of a Mitsuba XML scene (as ``load_scene``'s
    ``defines`` takes them; only an XML scene has such parameters)."""
    if not scene.lower().endswith(".xml"):
        raise where.error(f"sets $name parameters of a Mitsuba XML scene; {os.path.basename(scene)!r} "
                          "is not one (give the values through params)")
    if not isinstance(defines, dict):
        raise where.error(f"{defines!r}; expected a table of $name values, e.g. {{ res = 64 }}")
    try:
        return check_defines(defines, "")
    except DraawError as e:
        raise where.error(str(e).removeprefix(": ")) from None


def _check_post(chain, where: Where) -> list:
    """Validate a post chain as ``draaw-mi render --post`` does; keep its canonical list form."""
    if not isinstance(chain, list):
        raise where.error(f"{chain!r} is not a list of filter tables")
    try:
        return load_chain(chain).to_list()
    except Exception as e:  # noqa: BLE001 - ParameterError naming the entry
        raise where.error(str(e)) from None


def _camera(cam, where: Where, base: str) -> dict:
    check_keys(cam, CAMERA_KEYS, where)
    kinds = [k for k in ("orbit", "keyframes", "file", "look_at") if k in cam]
    if len(kinds) != 1:
        raise where.error("needs exactly one of orbit, keyframes, file, look_at"
                          + (f" (got {', '.join(kinds)})" if kinds else ""))
    kind = kinds[0]
    out = {"kind": kind, "faithful": boolean(cam.get("faithful", False), where / "faithful")}
    if "fov" in cam:
        out["fov"] = number(cam["fov"], where / "fov", lo=0.1, hi=179.0)
    if kind == "orbit":
        o = cam["orbit"]
        wo = where / "orbit"
        check_keys(o, ORBIT_KEYS, wo, required=("radius",))
        out["orbit"] = {"target": vector(o.get("target", [0, 0, 0]), wo / "target"),
                        "radius": number(o["radius"], wo / "radius", lo=0.0, lo_open=True),
                        "height": number(o.get("height", 0.0), wo / "height"),
                        "degrees": number(o.get("degrees", 360.0), wo / "degrees"),
                        "start": number(o.get("start", 0.0), wo / "start"),
                        "up": vector(o.get("up", [0, 1, 0]), wo / "up")}
        if math.hypot(*out["orbit"]["up"]) < 1e-9:      # (else every frame is black, exit 0)
            raise (wo / "up").error(f"{out['orbit']['up']} has no direction; expected the orbit's axis, "
                                    "such as [0, 1, 0]")
    elif kind == "look_at":
        keys = cam["look_at"]
        if not isinstance(keys, list) or not keys:
            raise (where / "look_at").error("expected a non-empty list of {origin, target, up} tables")
        rows = []
        for i, k in enumerate(keys):
            wk = where / "look_at" / i
            check_keys(k, LOOK_AT_KEYS, wk, required=("origin", "target"))
            row = (vector(k["origin"], wk / "origin") + vector(k["target"], wk / "target")
                   + vector(k.get("up", [0, 1, 0]), wk / "up"))
            check_look_at(row[0:3], row[3:6], row[6:9], wk)   # (a camera at its target: a flat frame)
            rows.append(row)
            # a scene file's look-at camera takes it (the tuner saves a mirrored GO-Draaw
            # camera so); frames eased between a mirrored and a plain view are no camera
            mirror = boolean(k.get("mirror", False), wk / "mirror")
            if i and mirror != out["mirror"]:
                raise (wk / "mirror").error(f"{mirror}, keyframe 0 says {out['mirror']}: a path's "
                                            "keyframes are all mirrored or none")
            out["mirror"] = mirror
        out["look_at"] = rows
    else:
        if kind == "file":
            path = string(cam["file"], where / "file")
            path = path if os.path.isabs(path) else os.path.join(base, path)
            try:
                with open(path) as fh:
                    keys = json.load(fh)
            except OSError as e:
                raise (where / "file").error(f"cannot read {path!r} ({e.strerror})") from None
            except json.JSONDecodeError as e:
                raise (where / "file").error(f"{path!r} is not JSON ({e.msg} at line {e.lineno})") from None
        else:
            keys = cam["keyframes"]
        try:
            out["keyframes"] = as_keyframes(keys if isinstance(keys, list) else [keys]).tolist()
        except Exception as e:  # noqa: BLE001 - ParameterError with the keyframe index
            raise (where / kind).error(str(e)) from None
    return out


def _params(params, where: Where) -> dict:
    if not isinstance(params, dict):
        raise where.error(f"expected a table of parameter overrides, got {params!r}")
    out = {}
    for name, spec in params.items():
        wp = where / name
        if isinstance(spec, dict):
            if "values" in spec:
                check_keys(spec, ("values",), wp)
                vals = spec["values"]
                if not isinstance(vals, list) or not vals:
                    raise (wp / "values").error("expected a non-empty list, one value per frame")
                out[name] = ("values", [_value(v, wp / "values" / i) for i, v in enumerate(vals)])
            else:
                check_keys(spec, ("from", "to"), wp, required=("from", "to"))
                a, b = _value(spec["from"], wp / "from"), _value(spec["to"], wp / "to")
                if (isinstance(a, list) != isinstance(b, list)) or (isinstance(a, list) and len(a) != len(b)):
                    raise wp.error("'from' and 'to' must have the same shape")
                out[name] = ("linear", (a, b))
        else:
            out[name] = ("const", _value(spec, wp))
    return out


def _value(v, where: Where):
    if isinstance(v, list):
        if not v:
            raise where.error("is an empty list")
        return [number(x, where / i) for i, x in enumerate(v)]
    return number(v, where)


def _frames(jd: dict, job: Job, where: Where) -> int:
    n_values = {name: len(d) for name, (kind, d) in job.params.items() if kind == "values"}
    if "frames" in jd:
        frames = int(number(jd["frames"], where / "frames", lo=1, hi=10 ** 6, integer=True))
    elif n_values:
        frames = next(iter(n_values.values()))
    elif job.camera and job.camera["kind"] in ("keyframes", "file", "look_at"):
        frames = len(job.camera.get("keyframes") or job.camera.get("look_at"))
    else:
        frames = 1
    for name, n in n_values.items():
        if n != frames:
            raise (where / "params" / name / "values").error(f"has {n} values for {frames} frames")
    cam = job.camera
    if cam and cam["kind"] in ("keyframes", "file") and cam["faithful"] and frames < 2:
        raise (where / "frames").error("GO-Draaw's faithful interpolation needs at least 2 frames")
    return frames


def _pattern(pattern, where: Where, out_base: str, job: Job, confined: bool) -> str:
    pattern = string(pattern, where)
    if not pattern.lower().endswith(".exr"):
        raise where.error(f"{pattern!r} must end with .exr")
    if confined:
        check_relative(pattern, where, "frames")
    try:
        fields = [f for _, f, _, _ in _string.Formatter().parse(pattern) if f is not None]
    except ValueError as e:
        raise where.error(f"{pattern!r} is not a valid pattern ({e})") from None
    for f in fields:
        base_name = f.split(".")[0].split("[")[0]
        if base_name not in PATTERN_FIELDS:
            raise where.error(f"{pattern!r} uses unknown field {{{f}}}{suggest(base_name, PATTERN_FIELDS)}")
        if f != base_name:      # {job.upper} would name a folder after a method's address
            raise where.error(f"{pattern!r}: field {{{f}}} must be a bare name ({{{base_name}}}, "
                              "with an optional format such as {frame:04d})")
    if job.frames > 1 and "frame" not in fields:
        raise where.error(f"{pattern!r} has no {{frame}} field, so {job.frames} frames would overwrite "
                          "one file")
    try:         # (the effective version and spp come with planning; stand-ins of their types)
        format_output(pattern, job, 0, version=job.version or "v4", spp=job.spp or 1)
    except (ValueError, KeyError, IndexError, TypeError) as e:
        raise where.error(f"{pattern!r} cannot be formatted ({e})") from None
    if os.path.isabs(pattern):
        return pattern
    # the folder as it is written: braces in it are text, not fields (else an --out of 'out{x}'
    # raises KeyError, and '{job}dir' puts every job in a folder of its own)
    return os.path.join(out_base.replace("{", "{{").replace("}", "}}"), pattern)


def format_output(pattern: str, job: Job, frame: int, version: str, spp: int) -> str:
    """The output file of ``frame`` of ``job`` (pattern fields: job scene version spp frame);
    ``version`` and ``spp``: the frame's effective ones (the scene's own where the job sets
    none)."""
    return os.path.normpath(pattern.format(
        job=job.name, scene=os.path.splitext(os.path.basename(job.scene))[0],
        version=version, spp=int(spp), frame=frame))


def fixed_folder(pattern: str) -> str:
    """The folder of an (absolute) output pattern before its first field: where the frames of
    every job with that pattern live, whatever the jobs are called.

    >>> fixed_folder("/r/out/{job}/{frame:04d}.exr"), fixed_folder("/r/out/shot_{job}.exr")
    ('/r/out', '/r/out')
    >>> fixed_folder("/r/out{{v2}}/{job}/{frame}.exr")       # braces written as text
    '/r/out{v2}'
    """
    literal = []
    for text, field_name, _, _ in _string.Formatter().parse(pattern):
        literal.append(text)                 # ('{{' comes back as '{')
        if field_name is not None:
            break
    return os.path.normpath(os.path.dirname("".join(literal)))
