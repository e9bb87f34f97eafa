"""Scenes: load TOML / JSON / dict descriptions, Mitsuba XML and bare mesh files.

>>> import draaw_mi
>>> scene = draaw_mi.load_scene({
...     "render": {"resolution": [32, 24], "spp": 4},
...     "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
...     "materials": {"gold": {"base_color": [1.0, 0.78, 0.34], "metallic": 1.0, "roughness": 0.3}},
...     "shapes": [{"type": "sphere", "material": "gold"}],
...     "lights": [{"type": "point", "position": [2, 3, 4], "intensity": 30}],
... })
>>> scene.resolution
(32, 24)
>>> "gold.roughness.value" in scene.params
True
"""
from __future__ import annotations

import os
import re
import tempfile
from dataclasses import dataclass, field
from typing import Any


from ..errors import ParameterError, SceneError, suggest
from .camera import filter_plugin, sampler_plugin
from .description import DEFAULT_SETTINGS, build_mitsuba_dict
from .light_dicts import auto_light
from .meshes import MESH_SUFFIXES, bounds, load_mesh_parts
from .mitsuba_load import load_dict_or_error, load_mitsuba_file, mitsuba_error_message
from .schema import Where
from .values import check_like, value_like

SCENE_SUFFIXES = (".toml", ".json", ".xml") + MESH_SUFFIXES


@dataclass(eq=False)
class DraawScene:
    """A loaded scene: the Mitsuba scene plus draaw-mi's render settings and names.

    Attributes: ``mi_scene`` (mi.Scene), ``settings`` (resolution, spp, max_depth, version, seed,
    filter, hide_emitters, aovs, post), ``source`` (file name or ``<dict>``), ``info`` (material,
    shape and light names, camera).
    """

    mi_scene: Any
    settings: dict
    source: str
    info: dict = field(default_factory=dict)
    mi_dict: dict | None = None
    _tmp: Any = None
    description: dict | None = None
    _params: Any = None
    _all_params: Any = None

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) of the film."""
        size = self.mi_scene.sensors()[0].film().size()
        return int(size[0]), int(size[1])

    @property
    def params(self):
        """``mi.traverse`` of the scene (cached; call ``.update()`` after changing values)."""
        if self._params is None:
            import mitsuba as mi
            self._params = mi.traverse(self.mi_scene)
        return self._params

    @property
    def all_params(self):
        """:attr:`params` plus the parameters of the scene's ``[[sdf]]`` objects as
        ``"sdf.NODE.PARAM"`` (a :class:`draaw_mi.sdf.SDFParameters` over the same
        ``mi.traverse``); :attr:`params` itself when the scene has none. Batch overrides, the
        fit and the preview read and write parameters through it.

        >>> # scene.all_params["sdf.red_ball.radius"] = 0.6; scene.all_params.update()
        """
        if self.sdf is None:
            return self.params
        if self._all_params is None:
            from ..sdf.params import SDFParameters
            self._all_params = SDFParameters(self, base=self.params)
        return self._all_params

    def sdf_param(self, key: str) -> str | None:
        """``"NODE.PARAM"`` when ``key`` is one of the scene's ``"sdf.NODE.PARAM"`` keys,
        else ``None``."""
        return None if self.sdf is None else self.all_params.sdf_name(key)

    def check_value(self, who: str, name: str, key: str, value) -> None:
        """Raise :class:`~draaw_mi.errors.ParameterError` (naming ``who``) if ``value`` is
        not one parameter ``key`` (of :attr:`all_params`; ``name`` as the user wrote it) takes:
        an SDF object's range (radius > 0, ...), else the materials' ranges
        (:func:`draaw_mi.materials.check_value`). Nothing changes."""
        self.check_values(who, {name: (key, value)})

    def check_values(self, who: str, values: dict) -> None:
        """:meth:`check_value` of ``{name: (key, value)}`` set together: the SDF values are
        checked with each other (a round box's new size with its new radius), on top of the
        scene's current values."""
        from ..materials import check_value
        sdf, names = {}, []
        for name, (key, value) in values.items():
            node_param = self.sdf_param(key)
            if node_param is not None:
                sdf[node_param] = value
                names.append(name)
            else:
                check_value(who, name, key, value)
        if sdf:
            try:
                self.sdf.check_many(sdf)
            except ParameterError as e:
                raise ParameterError(f"{who}: {', '.join(names)}: {e}") from None

    def key(self, name: str) -> str:
        """Resolve ``material.parameter`` (or a full traverse key, or an SDF object's
        ``sdf.NODE.PARAM``) to a key of :attr:`all_params`.

        >>> # scene.key("gold.roughness") -> "gold.roughness.value"
        """
        keys = list(self.all_params.keys())
        for cand in (name, f"{name}.value", f"{name}.data"):
            if cand in keys:
                return cand
        # the names people write: material.parameter (not Mitsuba's .value / .data keys)
        short = sorted({k.removesuffix(".value").removesuffix(".data") for k in keys})
        ending = [k for k in short if k.endswith("." + name)]
        if ending:                 # a bare parameter name ("roughness"): the materials that have it
            shown = ", ".join(repr(k) for k in ending[:6]) + (", ..." if len(ending) > 6 else "")
            raise SceneError(f"{self.source}: no parameter {name!r}; name the material too: {shown}")
        hint = suggest(name, short)
        if "; did you mean" not in hint:
            hint = suggest(name, keys)
        if hint.startswith("; valid:") and len(short) > 12:
            hint = "; `draaw-mi info` lists the scene's materials"
        raise SceneError(f"{self.source}: no parameter {name!r}{hint}")

    def with_resolution(self, width: int, height: int) -> "DraawScene":
        """The same scene with another film size. It reloads the Mitsuba scene and carries the
        current parameter values over (:func:`~draaw_mi.scene.carry.carry_values`): edits
        made through :attr:`params` stay; the copy has its own ``mi.traverse``."""
        if (width, height) == self.resolution:
            return self
        if self.mi_dict is None:
            raise SceneError(f"{self.source}: cannot change the resolution of a scene loaded from "
                             "XML or given as mi.Scene; edit its film instead")
        d = dict(self.mi_dict)
        sensor = dict(d["sensor"])
        sensor["film"] = dict(sensor["film"], width=int(width), height=int(height))
        d["sensor"] = sensor
        settings = dict(self.settings, resolution=(int(width), int(height)))
        scaled = DraawScene(load_dict_or_error(d, self.source), settings, self.source, self.info, d, self._tmp,
                          self.description)
        from .carry import carry_values
        carry_values(self, scaled)
        return scaled

    def updated_description(self, values: dict, dest: str | None = None) -> dict:
        """The scene description with ``{"material.parameter": value}`` written into its
        ``[materials]`` tables, a light's radiance into its ``[[lights]]`` table
        (:mod:`~draaw_mi.scene.light_values`) and ``{"sdf.NODE.PARAM": value}`` into its ``[[sdf]]`` tables
        (for saving fitted scenes). ``dest``: the file it will be
        written to; file names relative to the scene's folder are rewritten relative to
        ``dest``'s folder (written elsewhere, the scene lost its meshes and textures)."""
        import copy
        if self.description is None:
            raise SceneError(f"{self.source}: only TOML/JSON/dict scenes can be written back")
        desc = copy.deepcopy(self.description)
        if dest is not None:
            desc = _rebased(desc, self.info.get("relative_files", {}), os.path.dirname(os.path.abspath(dest)))
        mats = desc.setdefault("materials", {})
        from ..sdf.params import PREFIX
        for name, value in values.items():
            # (every sdf.* name goes to the [[sdf]] tables, which say why one cannot be written)
            if self.sdf is not None and name.startswith(PREFIX) and name not in self.params:
                from ..sdf.scene import write_back
                try:
                    write_back(desc.get("sdf"), name[len(PREFIX):], value)
                except ValueError as e:
                    raise SceneError(f"{self.source}: cannot write {name!r} back: {e}") from None
                continue
            from .light_values import RGB_PARAMS, SCALAR_PARAMS, light_names, write_light
            if write_light(desc, name, value):        # a light's intensity and colour
                continue
            mat, _, param = name.partition(".")
            if mat in light_names(desc):
                raise SceneError(f"{self.source}: cannot write {name!r} back: of a light, only "
                                 f"{', '.join(RGB_PARAMS + SCALAR_PARAMS)} can be written")
            param = param.removesuffix(".value").removesuffix(".data")
            if mat not in mats or not param or "." in param:
                raise SceneError(f"{self.source}: cannot write {name!r} back: no material or light "
                                 f"{mat!r} in the file (parameters of [materials], [[lights]], emitting "
                                 "[[shapes]] and [[sdf]] can be written)")
            mats[mat][param] = value
        return desc

    @property
    def sdf(self):
        """The scene's :class:`draaw_mi.sdf.scene.SDFScene` (``[[sdf]]`` entries), or ``None``."""
        return self.info.get("sdf")

    def features(self) -> dict:
        """Which effects the scene calls for (emitter kinds, textures, ...); ``aovs`` also
        where the scene's ``[render]`` table asks for them (render gives them to the
        integrator: the loaded scene's own integrator has none, and info said "off")."""
        from ..integrators.features import detect_features
        f = detect_features(self.mi_scene)
        f["aovs"] = f["aovs"] or bool(self.settings.get("aovs"))
        return f

    def summary(self) -> dict:
        """Everything ``draaw-mi info SCENE`` prints."""
        s = self.mi_scene
        return {
            "source": self.source,
            "resolution": list(self.resolution),
            # the description's names (Mitsuba merges meshes into one unnamed shape)
            "shapes": self.info.get("shapes") or [sh.id() or "unnamed" for sh in s.shapes()
                                                  if not sh.id().startswith("__sdf_")],
            "lights": self.info.get("lights") or [em.id() or str(em).split("[", 1)[0] for em in s.emitters()],
            "materials": self.info.get("materials", []),
            "settings": {k: v for k, v in self.settings.items() if k != "post"},
            "post": [p.get("type") if isinstance(p, dict) else p for p in self.settings.get("post", [])],
            "features": self.features(),
            "volumes": self.info.get("volumes", []),
            **({"sdf": self.sdf.describe()} if self.sdf is not None else {}),
        }


def _read_text_description(path: str) -> dict:
    from .schema import read_document
    return read_document(path, "scene file")


def _bare_mesh_description(path: str) -> dict:
    """A description for a mesh file alone: camera and lights placed from its bounds."""
    from .camera import auto_camera

    parts = load_mesh_parts(path, Where(path))
    lo, hi = bounds(parts)
    camera = auto_camera(lo, hi)
    return {"shapes": [{"type": "mesh", "file": os.path.abspath(path)}], "camera": camera,
            "lights": auto_light(lo, hi, camera["origin"])}


# description fields that name things, never files
_NAME_FIELDS = frozenset({"name", "material", "type", "shape", "mode", "children", "version"})


def _rebased(node, files: dict, folder: str):
    """``node`` (a description) with every string that is one of ``files``' relative names
    replaced by the name of that file relative to ``folder`` (the names the loader resolved
    against the scene's folder: only those, and not in fields that name things, so a shape
    whose material is called like a texture file keeps it)."""
    if isinstance(node, dict):
        return {k: v if k in _NAME_FIELDS else _rebased(v, files, folder) for k, v in node.items()}
    if isinstance(node, list):
        return [_rebased(v, files, folder) for v in node]
    if isinstance(node, str) and node in files:
        return os.path.relpath(files[node], folder)
    return node


def load_scene(source, **overrides) -> DraawScene:
    """Load a scene from a TOML/JSON/XML/mesh file, a description dict, a Mitsuba scene dict
    (``{"type": "scene", ...}``) or an ``mi.Scene``.

    ``overrides`` replace render settings: ``resolution=(W, H)``, ``spp``, ``max_depth``,
    ``version``, ``seed``, ``filter``, ``sampler`` (descriptions only). Errors are
    :class:`SceneError` naming the file and field.

    Example::

        >>> import draaw_mi
        >>> scene = draaw_mi.load_scene("scenes/cornell.toml", resolution=(32, 24), spp=4)
        >>> scene.resolution, scene.settings["spp"], scene.key("metal.roughness")
        ((32, 24), 4, 'metal.roughness.value')
    """
    from ..guard import RENDER_GUARD
    with RENDER_GUARD:       # (plugins made while another thread replayed a recording broke it)
        return _load_scene(source, **overrides)


def _load_scene(source, **overrides) -> DraawScene:
    import mitsuba as mi

    bad = set(overrides) - set(DEFAULT_SETTINGS)
    if bad:
        name = sorted(bad)[0]
        raise SceneError(f"load_scene: unknown setting {name!r}{suggest(name, DEFAULT_SETTINGS)}")
    if isinstance(source, DraawScene):
        return source
    if isinstance(source, mi.Scene):
        if overrides:
            return _from_mitsuba_scene(source, "<mi.Scene>", overrides)
        return _wrapped(source)
    if isinstance(source, dict):
        if source.get("type") == "scene":
            return _from_mitsuba_scene(load_dict_or_error(source, "<dict>"), "<dict>", overrides, source,
                                       named_integrator="integrator" in source)
        return _from_description(source, "<dict>", os.getcwd(), overrides)
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
        try:
            scene = load_mitsuba_file(path)
        except Exception as e:  # noqa: BLE001
            raise SceneError(f"{path}: {mitsuba_error_message(e)}") from None
        from .mitsuba_xml import xml_references
        files, named = xml_references(path)      # (includes followed, comments ignored)
        return _from_mitsuba_scene(scene, path, overrides, named_integrator=named, files=files)
    if lower.endswith((".toml", ".json")):
        desc = _read_text_description(path)
    else:
        desc = _bare_mesh_description(path)
    return _from_description(desc, path, os.path.dirname(os.path.abspath(path)), overrides)


# The DraawScene of each recent bare mi.Scene (render(mi_scene) wraps it on every call, and the
# renderer keeps its recordings per DraawScene: a new wrapper recorded anew, 5x slower than a
# replay). Holding the mi.Scene keeps its id from being reused; the oldest is let go.
_WRAPPED: dict = {}
WRAPPED_KEPT = 4


def _wrapped(mi_scene) -> DraawScene:
    key = id(mi_scene)
    entry = _WRAPPED.pop(key, None)
    if entry is None:             # (an entry holds its scene: its id is not reused meanwhile)
        entry = (mi_scene, _from_mitsuba_scene(mi_scene, "<mi.Scene>", {}))
    _WRAPPED[key] = entry                       # (most recent last)
    while len(_WRAPPED) > WRAPPED_KEPT:
        _WRAPPED.pop(next(iter(_WRAPPED)))
    return entry[1]


def _from_description(desc: dict, source: str, base_dir: str, overrides: dict) -> DraawScene:
    tmp = tempfile.TemporaryDirectory(prefix="draaw-mi-")
    mi_dict, settings, info = build_mitsuba_dict(desc, source, base_dir, tmp.name, _checked(overrides, source))
    scene = load_dict_or_error(mi_dict, source)
    import copy
    return DraawScene(scene, settings, source, info, mi_dict, tmp, description=copy.deepcopy(desc))


#: the smallest value of each integer override of :func:`load_scene` (the CLI names its flags
#: with them)
OVERRIDE_MINIMA = {"spp": 1, "max_depth": -1, "seed": 0}


def _checked(overrides: dict, source: str) -> dict:
    from .schema import number, resolution, string
    where = Where(source) / "override"
    out = dict(overrides)
    if out.get("resolution") is not None:
        out["resolution"] = resolution(out["resolution"], where / "resolution")
    for key, lo in OVERRIDE_MINIMA.items():
        if out.get(key) is not None:
            out[key] = number(out[key], where / key, lo=lo, integer=True)
    if out.get("sampler") is not None:
        from .description import SAMPLERS
        out["sampler"] = string(out["sampler"], where / "sampler", SAMPLERS)
    return out


# Mitsuba integrator classes (their to_string() names) -> the render version that is them
_INTEGRATOR_VERSIONS = {"PathIntegrator": "path", "PRBIntegrator": "prb",
                        "VolumetricSimplePathIntegrator": "volpath", "PRBVolpathIntegrator": "prbvolpath",
                        **{f"DraawV{i}Integrator": f"draaw_v{i}" for i in range(1, 5)}}


def _from_mitsuba_scene(scene, source: str, overrides: dict, mi_dict: dict | None = None,
                        named_integrator: bool = False, files: list | None = None) -> DraawScene:
    """``named_integrator``: the XML file or dict names its integrator, which then becomes
    the scene's render version (a scene without one renders with draaw-mi's default).
    ``files``: the files the scene reads besides its own (``info["files"]``)."""
    sensors = scene.sensors()
    if not sensors:
        raise SceneError(f"{source}: the scene has no sensor (camera)")
    settings = dict(DEFAULT_SETTINGS)
    size = sensors[0].film().size()
    settings["resolution"] = (int(size[0]), int(size[1]))
    settings["spp"] = int(sensors[0].sampler().sample_count())
    settings["sampler"] = sampler_plugin(sensors[0].sampler())
    # (the film's own: 'info' said box for an XML film with Mitsuba's default gaussian, and
    # fit's extra views were made with a box filter)
    settings["filter"] = filter_plugin(sensors[0].film().rfilter())
    integ = scene.integrator()
    if integ is not None:      # C++ integrators expose max_depth only through to_string()
        m = re.search(r"max_depth\s*=\s*(-?\d+)", str(integ))
        if m:
            depth = int(m.group(1))
            settings["max_depth"] = depth - 2 ** 32 if depth >= 2 ** 31 else depth   # -1 prints unsigned
        # (the file's hide_emitters was dropped: the sky it hides rendered, mean 0.95 for 0.05)
        settings["hide_emitters"] = bool(getattr(integ, "hide_emitters", False))
        if named_integrator:
            kind = str(integ).split("[", 1)[0].strip()
            if kind in _INTEGRATOR_VERSIONS:
                settings["version"] = _INTEGRATOR_VERSIONS[kind]
            else:
                import warnings
                warnings.warn(f"{source}: its integrator {kind} is not one of draaw-mi's render "
                              f"versions; it renders with {settings['version']!r} unless a version "
                              "is given", RuntimeWarning, stacklevel=3)
    settings["post"] = []
    checked = _checked(overrides, source)
    if checked.get("sampler") not in (None, settings["sampler"]):
        raise SceneError(f"{source}: sampler={checked['sampler']!r} cannot override the sampler of a "
                         f"Mitsuba scene ({settings['sampler']!r}); set it in the scene itself")
    if checked.get("filter") not in (None, settings["filter"]):
        raise SceneError(f"{source}: filter={checked['filter']!r} cannot override the filter of a "
                         f"Mitsuba scene ({settings['filter']!r}); set it in the scene's film")
    settings.update({k: v for k, v in checked.items() if v is not None})
    d = DraawScene(scene, settings, source, {"materials": [], "files": list(files or [])}, mi_dict)
    # (the checked value: the command line's "32x32" went in as a string, and a traceback out)
    if checked.get("resolution") and tuple(checked["resolution"]) != d.resolution:
        d = d.with_resolution(*checked["resolution"])
    return d


__all__ = ["DraawScene", "load_scene", "SCENE_SUFFIXES", "value_like", "check_like"]
