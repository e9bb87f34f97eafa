"""Loading scenes: :func:`load_scene` from TOML / JSON / dict descriptions, Mitsuba XML,
Mitsuba dicts and ``mi.Scene`` objects, and bare mesh files.

Example::

    >>> import draaw_mi
    >>> scene = draaw_mi.load_scene("scenes/cornell.toml", resolution=(32, 24), spp=4)
    >>> scene.resolution, scene.settings["spp"]
    ((32, 24), 4)
"""
from __future__ import annotations

import copy
import os
import re
import shutil
import tempfile
import warnings
import weakref

try:
    import fcntl                 # (POSIX: scratch folders' owner locks)
except ImportError:              # pragma: no cover - Windows
    fcntl = None

import mitsuba as mi
import numpy as np

from ..errors import DraawError, SceneError, raise_if_interrupted, suggest, user_stacklevel
from ..guard import RENDER_GUARD, in_foreground
from ..integrators import SCENE_VERSION, resolve_version
from ..sdf.scene import find as find_sdf
from .camera import auto_camera, clipped_away, filter_plugin, sampler_plugin
from .description import DEFAULT_SETTINGS, FILTERS, SAMPLERS, TOP_KEYS, aov_list, build_mitsuba_dict
from .draaw_scene import DraawScene
from .light_dicts import auto_light
from .meshes import MESH_SUFFIXES, bounds, load_mesh_parts
from .mitsuba_load import load_dict_or_error, load_mitsuba_file, mitsuba_error_message
from .mitsuba_xml import integrator_name, shape_names, xml_references
from .schema import Where, boolean, number, read_document, resolution, string
from .sdf_dicts import refuse_textured_materials
from .xml_film import check_defines, declared_defaults

SCENE_SUFFIXES = (".toml", ".json", ".xml") + MESH_SUFFIXES


def _bare_mesh_description(path: str) -> dict:
    """A description for a mesh file alone: camera and lights placed from its bounds."""
    with warnings.catch_warnings():            # (the scene's own load of the file says them)
        warnings.simplefilter("ignore", RuntimeWarning)
        parts = load_mesh_parts(path, Where(path))
    lo, hi = bounds(parts)
    camera = auto_camera(lo, hi)
    return {"shapes": [{"type": "mesh", "file": os.path.abspath(path)}], "camera": camera,
            "lights": auto_light(lo, hi, camera["origin"])}


@in_foreground
def load_scene(source, defines: dict | None = None, **overrides) -> DraawScene:
    """Load a scene from a TOML/JSON/XML/mesh file, a description dict, a Mitsuba scene dict
    (``{"type": "scene", ...}``) or an ``mi.Scene``.

    ``overrides`` replace render settings: ``resolution=(W, H)``, ``spp``, ``max_depth``,
    ``version``, ``seed``, ``hide_emitters``, ``aovs``, ``filter``, ``sampler`` (the last two
    for descriptions only). A loaded :class:`DraawScene` takes ``resolution=`` alone (a copy at
    that size). ``defines``: values
    of a Mitsuba XML file's ``$name`` parameters (its ``<default>`` values), e.g.
    ``{"res": 64, "spp": 16}`` (``draaw-mi render -D res=64``). An XML scene's
    ``resolution=`` sizes its first sensor's film. Errors are :class:`SceneError` naming the
    file and field.

    Example::

        >>> import draaw_mi
        >>> scene = draaw_mi.load_scene("scenes/cornell.toml", resolution=(32, 24), spp=4)
        >>> scene.resolution, scene.settings["spp"], scene.key("metal.roughness")
        ((32, 24), 4, 'metal.roughness.value')
    """
    with RENDER_GUARD:       # (plugins made while another thread replays a recording break it)
        return _load_scene(source, defines, **overrides)


def _load_scene(source, defines, **overrides) -> DraawScene:

    bad = set(overrides) - set(DEFAULT_SETTINGS)
    if bad:
        name = sorted(bad)[0]
        raise SceneError(f"load_scene: unknown setting {name!r}{suggest(name, DEFAULT_SETTINGS)}")
    is_xml = isinstance(source, (str, os.PathLike)) and os.fspath(source).lower().endswith(".xml")
    if defines is not None and not is_xml:
        name = os.fspath(source) if isinstance(source, (str, os.PathLike)) else type(source).__name__
        raise SceneError(f"{name}: defines={defines!r} set the $name parameters of a Mitsuba XML "
                         "file; this is not one (give a TOML scene's values in the file, or as "
                         "overrides such as resolution=, spp=)")
    if isinstance(source, DraawScene):
        overrides = {k: v for k, v in overrides.items() if v is not None}    # (None: the scene's)
        if not overrides:
            return source
        if set(overrides) == {"resolution"}:
            return source.with_resolution(*resolution(overrides["resolution"],
                                                      Where("load_scene") / "resolution"))
        # (they were dropped without a word: the scene came back as it was)
        raise SceneError(f"load_scene: a loaded DraawScene takes resolution= only, not "
                         f"{', '.join(sorted(set(overrides) - {'resolution'}))}; give them to "
                         "render (render(scene, spp=..., version=...)), or load the file again with them")
    if isinstance(source, mi.Scene):
        if overrides:
            return _from_mitsuba_scene(source, "<mi.Scene>", overrides)
        return _wrapped(source)
    if isinstance(source, dict):
        if source.get("type") == "scene":
            # (whatever key holds its integrator: Mitsuba's own dicts say "integrator", and
            # {"my_integrator": {"type": "direct"}} declares one as well)
            return _from_mitsuba_scene(load_dict_or_error(source, "<dict>"), "<dict>", overrides, source)
        refuse_manifest(source, "<dict>")
        return from_description(source, "<dict>", os.getcwd(), overrides)
    if not isinstance(source, (str, os.PathLike)):
        raise SceneError(f"load_scene: expected a file name, dict or mi.Scene, got {type(source).__name__}")
    path = os.fspath(source)
    if not os.path.exists(path):
        raise SceneError(f"{path}: scene file does not exist")
    if os.path.isdir(path):
        raise SceneError(f"{path}: is a folder, not a scene file")
    lower = path.lower()
    if not lower.endswith(SCENE_SUFFIXES):
        raise SceneError(f"{path}: unknown scene format; expected one of {', '.join(SCENE_SUFFIXES)}")
    if lower.endswith(".xml"):
        return _from_xml(path, check_defines(defines, path), overrides)
    if lower.endswith((".toml", ".json")):
        desc = read_document(path, "scene file")
        refuse_manifest(desc, path)
    else:
        desc = _bare_mesh_description(path)
    return from_description(desc, path, os.path.dirname(os.path.abspath(path)), overrides)


def _from_xml(path: str, defines: dict, overrides: dict) -> DraawScene:
    """A Mitsuba XML file with ``defines`` for its ``$name`` parameters, its film sized by a
    ``resolution`` override (reloads at another size keep both: ``info["xml"]``)."""
    size = _checked(overrides, path).get("resolution")
    scene = load_xml(path, defines, size)
    files, named = xml_references(path, defines)      # (includes followed, comments ignored)
    return _from_mitsuba_scene(scene, path, overrides, named_integrator=named, files=files,
                               xml={"path": os.path.abspath(path), "defines": defines})


def load_xml(path: str, defines: dict, size=None):
    """:func:`~draaw_mi.scene.mitsuba_load.load_mitsuba_file`, its errors as one
    :class:`SceneError` line naming the file (and the defaults it declares, for a bad define)."""
    try:
        return load_mitsuba_file(path, defines, size)
    except SceneError:
        raise
    except Exception as e:  # noqa: BLE001 - Mitsuba reports everything as RuntimeError
        raise_if_interrupted(e)                  # (Ctrl-C in a draaw plugin's constructor)
        message = mitsuba_error_message(e)
        if defines and "its includes use no $" in message:
            message += f"; its <default>s: {', '.join(declared_defaults(path)) or 'none'}"
        raise SceneError(f"{path}: {message}") from None


def refuse_manifest(desc, source: str) -> None:
    """A :class:`SceneError` when the document ``desc`` is a batch manifest (it has
    ``[[jobs]]`` and none of a scene's tables), not a scene."""
    if isinstance(desc, dict) and "jobs" in desc and not set(desc) & set(TOP_KEYS):
        run = f"draaw-mi batch {source}" if source != "<dict>" else "draaw_mi.batch.run(...)"
        raise SceneError(f"{source} is a batch manifest (it has [[jobs]]), not a scene; render it "
                         f"with `{run}`")


# The DraawScene of each recent bare mi.Scene (render(mi_scene) wraps it on every call, and the
# renderer keeps its recordings per DraawScene: a new wrapper would record anew, 5x slower than a
# replay). Holding the mi.Scene keeps its id from being reused; the oldest is let go.
_WRAPPED: dict = {}
WRAPPED_KEPT = 4


def wrap(mi_scene) -> DraawScene:
    """A :class:`DraawScene` of the ``mi.Scene`` ``mi_scene``, made anew and kept by nobody
    (:func:`load_scene` of an ``mi.Scene`` keeps its recent wrappers, and with them their
    scenes, so that repeated renders replay their recordings). For code that renders a
    Mitsuba scene it owns, once (a benchmark's timed render)."""
    return _from_mitsuba_scene(mi_scene, "<mi.Scene>", {})


def release_wrapped() -> None:
    """Let go of the wrappers :func:`load_scene` keeps for the last bare ``mi.Scene`` objects it
    was given, and with them of those scenes: each live scene's draaw materials take part in
    every later kernel's BSDF calls."""
    _WRAPPED.clear()


def _wrapped(mi_scene) -> DraawScene:
    key = id(mi_scene)
    entry = _WRAPPED.pop(key, None)
    if entry is None:             # (an entry holds its scene: its id is not reused meanwhile)
        entry = (mi_scene, wrap(mi_scene))
    _WRAPPED[key] = entry                       # (most recent last)
    while len(_WRAPPED) > WRAPPED_KEPT:
        _WRAPPED.pop(next(iter(_WRAPPED)))
    return entry[1]


#: the file a scratch folder's process holds locked (``flock``) for as long as the folder is
#: its: the kernel lets go of the lock when the process ends, however it ends
OWNER_FILE = ".owner"


def _hold(folder: str) -> int | None:
    """Lock ``folder``'s owner file for this process (made under another name and renamed once
    locked, so a sweep never finds it unlocked); the descriptor, or None where locks fail."""
    if fcntl is None:
        return None
    tmp = os.path.join(folder, OWNER_FILE + ".new")
    try:
        fd = os.open(tmp, os.O_CREAT | os.O_RDWR, 0o600)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.replace(tmp, os.path.join(folder, OWNER_FILE))
    except OSError:
        os.close(fd)
        return None
    return fd


def _remove_folder(path: str, fd: int | None) -> None:
    shutil.rmtree(path, ignore_errors=True)
    if fd is not None:
        os.close(fd)                                   # (the lock goes with it)


def sweep_scratch_folders(folder: str, prefix: str = "draaw-mi-") -> list[str]:
    """Remove the scratch folders (:class:`ScratchFolder`) that killed processes left in
    ``folder`` (a process killed by ``kill -9`` or SIGTERM runs no finaliser): this user's
    ``<prefix>*`` folders whose owner file no process holds locked (a lock, unlike a process
    id, is not fooled by another machine's or container's processes sharing the folder).
    Returns the removed paths; called once per process and temporary folder, by the first
    scratch folder made there.

    >>> import tempfile
    >>> root = tempfile.mkdtemp()
    >>> left = os.path.join(root, "draaw-mi-1-x"); os.mkdir(left)
    >>> open(os.path.join(left, OWNER_FILE), "w").close()            # its process has gone
    >>> held = os.path.join(root, "draaw-mi-2-y"); os.mkdir(held); fd = _hold(held)
    >>> [os.path.basename(p) for p in sweep_scratch_folders(root)]
    ['draaw-mi-1-x']
    >>> sorted(os.listdir(root))
    ['draaw-mi-2-y']
    >>> _remove_folder(held, fd); shutil.rmtree(root)
    """
    removed: list[str] = []
    if fcntl is None:
        return removed
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        if not entry.name.startswith(prefix):
            continue
        try:
            if not entry.is_dir(follow_symlinks=False) or entry.stat().st_uid != os.getuid():
                continue
            fd = os.open(os.path.join(entry.path, OWNER_FILE), os.O_RDWR)
        except OSError:
            continue                                   # (no owner file: not ours to judge)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)                               # held: its process runs
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        os.close(fd)
        removed.append(entry.path)
    return removed


class ScratchFolder:
    """The folder a scene's generated files go to (meshes, textures its description makes),
    removed once no scene holds it: the scenes derived from a scene (``with_resolution``,
    edits) load those files again and share it. Unlike :class:`tempfile.TemporaryDirectory`,
    whose finaliser warns (``ResourceWarning: Implicitly cleaning up``) when it is collected
    uncleaned, collection is how this one is meant to go; it also goes at exit. Its process
    holds its owner file locked, so a later process removes it if this one is killed
    (:func:`sweep_scratch_folders`).

    >>> folder = ScratchFolder()
    >>> path = folder.name
    >>> os.path.isdir(path)
    True
    >>> del folder
    >>> import gc; _ = gc.collect(); os.path.exists(path)
    False
    """
    __slots__ = ("name", "_remove", "__weakref__")
    _swept: set = set()            # temporary folders already swept by this process

    def __init__(self, prefix: str = "draaw-mi-"):
        folder = tempfile.gettempdir()
        if folder not in ScratchFolder._swept:
            ScratchFolder._swept.add(folder)
            sweep_scratch_folders(folder, prefix)
        self.name = tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-")
        self._remove = weakref.finalize(self, _remove_folder, self.name, _hold(self.name))

    def cleanup(self) -> None:
        """Remove the folder now."""
        self._remove()


def from_description(desc: dict, source: str, base_dir: str, overrides: dict) -> DraawScene:
    tmp = ScratchFolder()
    mi_dict, settings, info = build_mitsuba_dict(desc, source, base_dir, tmp.name, _checked(overrides, source))
    scene = load_dict_or_error(mi_dict, source)
    sensor = mi_dict["sensor"]
    clipped = clipped_away(info["camera"]["origin"], sensor["near_clip"], sensor["far_clip"],
                           _visible_boxes(scene, info.get("sdf")))
    if clipped:
        warnings.warn(f"{source}: camera: {clipped}; the image shows none of it", RuntimeWarning,
                      stacklevel=user_stacklevel())
    if info.get("sdf") is not None:
        refuse_textured_materials(scene, info["sdf"], source)
    try:
        description = copy.deepcopy(desc)      # (kept for writing the scene back: a fit's save)
    except Exception as e:  # noqa: BLE001 - a value's own __deepcopy__ / pickling: any kind
        raise SceneError(f"{source}: the scene holds a value that cannot be copied ({e}); give numbers, "
                         "lists, numpy arrays and file names") from None
    return DraawScene(scene, settings, source, info, mi_dict, tmp, description=description)


def _visible_boxes(scene, sdf) -> list:
    """The boxes (pairs of corners) of what ``scene`` draws: its shapes' but for the SDF
    objects' hidden proxies (a point at the SDF box's centre), and the SDF objects' own."""
    skip = set(sdf.proxy_ids) if sdf is not None else set()
    boxes = [(sh.bbox().min, sh.bbox().max) for sh in scene.shapes() if sh.id() not in skip]
    return boxes + [(b.min, b.max) for b in (sdf.bboxes() if sdf is not None else [])]


#: the smallest value of each integer override of :func:`load_scene` (the CLI names its flags
#: with them)
OVERRIDE_MINIMA = {"spp": 1, "max_depth": -1, "seed": 0}
#: and the largest (Mitsuba's samplers count samples, and take seeds, in 32 bits)
OVERRIDE_MAXIMA = {"spp": 2 ** 32 - 1, "seed": 2 ** 32 - 1}


def _checked(overrides: dict, source: str) -> dict:
    where = Where(source) / "override"
    out = dict(overrides)
    if out.get("resolution") is not None:
        out["resolution"] = resolution(out["resolution"], where / "resolution")
    for key, lo in OVERRIDE_MINIMA.items():
        if out.get(key) is not None:
            out[key] = number(out[key], where / key, lo=lo, hi=OVERRIDE_MAXIMA.get(key), integer=True)
    if out.get("sampler") is not None:
        out["sampler"] = string(out["sampler"], where / "sampler", SAMPLERS)
    if out.get("filter") is not None:
        out["filter"] = string(out["filter"], where / "filter", FILTERS)
    if out.get("hide_emitters") is not None:
        out["hide_emitters"] = boolean(out["hide_emitters"], where / "hide_emitters")
    if out.get("aovs") is not None:          # ("depth" is one name, not its letters)
        aovs = out["aovs"]
        out["aovs"] = aov_list([aovs] if isinstance(aovs, str) else
                               [str(a) if isinstance(a, np.str_) else a for a in aovs]
                               if isinstance(aovs, (tuple, np.ndarray)) else aovs, where / "aovs")
    if out.get("version") is not None:       # (refused now, not at the first render)
        try:
            resolve_version(out["version"])
        except DraawError as e:
            raise (where / "version").error(str(e)) from None
    return out


# Mitsuba integrator classes (their to_string() names) -> the render version that is them
_INTEGRATOR_VERSIONS = {"PathIntegrator": "path", "PRBIntegrator": "prb",
                        "VolumetricSimplePathIntegrator": "volpath", "PRBVolpathIntegrator": "prbvolpath",
                        **{f"DraawV{i}Integrator": f"draaw_v{i}" for i in range(1, 5)}}


def integrator_version(integrator) -> str | None:
    """The render version the Mitsuba integrator object is (``path``, ``prb``, ``volpath``,
    ``prbvolpath``, ``draaw_v1`` .. ``draaw_v4``); ``None`` for another (``direct``, ``aov``, ...)."""
    return _INTEGRATOR_VERSIONS.get(str(integrator).split("[", 1)[0].strip())


def integrator_depth(integrator) -> int | None:
    """The ``max_depth`` of a Mitsuba integrator object (-1: unlimited), ``None`` where it has
    none. C++ integrators expose it only through to_string(), -1 printed unsigned."""
    m = re.search(r"max_depth\s*=\s*(-?\d+)", str(integrator))
    if m is None:
        return None
    depth = int(m.group(1))
    return depth - 2 ** 32 if depth >= 2 ** 31 else depth


def _from_mitsuba_scene(scene, source: str, overrides: dict, mi_dict: dict | None = None,
                        named_integrator: bool = True, files: list | None = None,
                        xml: dict | None = None) -> DraawScene:
    """The integrator an XML file, a dict or an ``mi.Scene`` declares (Mitsuba 3.9 gives a
    scene that declares none no integrator: ``scene.integrator()`` is ``None``; an XML file's
    ``named_integrator`` says whether it or an include names one) becomes the scene's render
    version: the version that is it (``path``, ``prb``, ``draaw_v4``, ...) or, for another of
    Mitsuba's (``direct``, ``aov``, ...), ``"scene"``: the scene's own integrator object, with
    the file's settings. A scene without one renders with draaw-mi's default. ``files``: the
    files the scene reads besides its own
    (``info["files"]``); ``xml``: the XML file and defines it was loaded from
    (``info["xml"]``, for reloads at another size)."""
    sensors = scene.sensors()
    if not sensors:
        raise SceneError(f"{source}: the scene has no sensor (camera)")
    settings = dict(DEFAULT_SETTINGS)
    size = sensors[0].film().crop_size()          # (what renders: the crop window)
    settings["resolution"] = (int(size[0]), int(size[1]))
    settings["spp"] = int(sensors[0].sampler().sample_count())
    settings["sampler"] = sampler_plugin(sensors[0].sampler())
    # (the film's own: an XML film with Mitsuba's default gaussian is no box filter, neither in
    # 'info' nor in fit's extra views)
    settings["filter"] = filter_plugin(sensors[0].film().rfilter())
    integ = scene.integrator()
    if integ is not None:
        if integrator_depth(integ) is not None:
            settings["max_depth"] = integrator_depth(integ)
        # (the file's hide_emitters is kept: the sky it hides would render, mean 0.95 for 0.05)
        settings["hide_emitters"] = bool(getattr(integ, "hide_emitters", False))
        if named_integrator:
            # (not one of the versions: the scene's own, as Mitsuba would render it; a version
            # given to render() or --version replaces it)
            settings["version"] = integrator_version(integ) or SCENE_VERSION
    settings["post"] = []
    checked = _checked(overrides, source)
    if checked.get("sampler") not in (None, settings["sampler"]):
        raise SceneError(f"{source}: sampler={checked['sampler']!r} cannot override the sampler of a "
                         f"Mitsuba scene ({settings['sampler']!r}); set it in the scene itself")
    if checked.get("filter") not in (None, settings["filter"]):
        raise SceneError(f"{source}: filter={checked['filter']!r} cannot override the filter of a "
                         f"Mitsuba scene ({settings['filter']!r}); set it in the scene's film")
    settings.update({k: v for k, v in checked.items() if v is not None})
    info = {"materials": [], "files": list(files or []),
            "shapes": shape_names(scene, xml["path"] if xml else None)}
    if xml is not None:
        info["xml"] = xml
    if integ is not None and named_integrator:
        info["integrator"] = integrator_name(integ)
    # (the mi_scene of a loaded SDF scene: held while wrapped; a SceneError when that scene was
    # let go. load_scene(mi.Scene) is how draaw_mi.render takes one)
    sdf = find_sdf(scene, who="draaw_mi.render / load_scene of an mi.Scene")
    if sdf is not None:
        info["sdf"] = sdf
    d = DraawScene(scene, settings, source, info, mi_dict)
    # (the checked value: the command line's "32x32" would go in as a string, and a traceback out)
    if checked.get("resolution") and tuple(checked["resolution"]) != d.resolution:
        d = d.with_resolution(*checked["resolution"])
    return d

