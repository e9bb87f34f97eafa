"""The loaded scene: :class:`DraawScene`, a Mitsuba scene with draaw-mi's settings and names.

Its parameters (:attr:`~DraawScene.params`, :attr:`~DraawScene.all_params` with the SDF
objects'), names resolved to parameter keys (:meth:`~DraawScene.key`), value checks, a copy at
another resolution, and its description with fitted values written back. Scenes are made by
:func:`draaw_mi.scene.load_scene` (:mod:`~draaw_mi.scene.loading`).
"""
from __future__ import annotations

import copy
import json
import os
from dataclasses import dataclass, field
from typing import Any

import drjit as dr
import mitsuba as mi
import numpy as np
import tomli_w

from ..errors import ParameterError, SceneError
from ..guard import FOREGROUND, RENDER_GUARD, let_go
from ..integrators.stamps import stamp
from ..integrators.features import detect_features, refuse_border_sampling
from ..materials import check_value
from ..sdf.params import PREFIX, SDFParameters
from .carry import carry_values
from .light_values import RGB_PARAMS, SCALAR_PARAMS, light_names, write_light
from .mitsuba_load import load_dict_or_error, load_mitsuba_file
from .param_keys import resolve_key, scene_media
from .schema import Where, resolution
from .sdf_dicts import write_back
from .toml_edit import edited_toml
from .xml_film import CROP, scaled_crop


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
    _own: Any = None              # own_traversal's
    _ids: Any = None              # _object_ids's
    # key -> the stamp of the value out_of_range last found fine (an array's stamp holds it:
    # Dr.Jit cannot give its variable's index to a new value before the next check)
    _checked: dict = field(default_factory=dict)

    def __post_init__(self):
        for sensor in self.mi_scene.sensors():     # (each render would corrupt memory)
            refuse_border_sampling(sensor, self.source, SceneError)

    def __del__(self):
        # its Mitsuba objects leave Dr.Jit's registry under the render guard, never beside a
        # preview's render on another thread (a segmentation fault): see guard.let_go
        if let_go is not None:                 # (None while the interpreter shuts down)
            let_go(self)

    def __repr__(self) -> str:
        """One line (a notebook cell that shows a scene printed its whole Mitsuba scene and
        description: 200 lines); ``summary()`` and ``draaw-mi info`` say more."""
        w, h = self.resolution
        s = self.settings
        materials = self.info.get("materials") or []
        return (f"DraawScene({self.source!r}, {w}x{h}, version {s.get('version')!r}, spp {s.get('spp')}, "
                f"{len(self.mi_scene.shapes())} shapes, {len(self.mi_scene.emitters())} emitters"
                + (f", materials {', '.join(materials)}" if materials else "") + ")")

    @property
    def resolution(self) -> tuple[int, int]:
        """The size of the images it renders, ``(width, height)``: the film's crop window (the
        whole film where it has none)."""
        size = self.mi_scene.sensors()[0].film().crop_size()
        return int(size[0]), int(size[1])

    @property
    def params(self):
        """``mi.traverse`` of the scene (cached; call ``.update()`` after changing values)."""
        if self._params is None:
            # (a traversal beside a preview's replay, which traverses live BSDFs too, crashed)
            with RENDER_GUARD, FOREGROUND:
                if self._params is None:
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

    def out_of_range(self, limit: int = 3, changed_only: bool = False) -> list[str]:
        """What is wrong with the scene's current parameter values, as :meth:`check_value` says
        it (at most ``limit`` messages): values set through :attr:`params` (or any traversal of
        the scene) are not checked when they are set, and one out of its range (a NaN colour, a
        negative roughness, a NaN texel of a roughness map) renders NaN, clamped or wrong
        pixels. Single values, colours, textures and media grids are read back (a 4096x4096 RGB
        map in about 0.3 s).

        ``changed_only``: only what changed since it was last found fine, whichever traversal
        set it: single values and colours by their numbers, textures and grids by their Dr.Jit
        variables, which a new array replaces (about 1.5 us a parameter). Each
        ``draaw_mi.render`` asks so after its render: the first reads every texture, later
        ones what was set since. The map last found fine is held until the next check: a map
        replaced before then (a fit's steps) keeps its old texels in memory until that render.

        >>> # scene.params["white.base_color.value"] = mi.Color3f(float("nan")); scene.params.update()
        >>> # scene.out_of_range() -> ["out_of_range: white.base_color.value=[nan, nan, nan]; expected ..."]
        """
        with RENDER_GUARD:                           # (values read beside no replay)
            found = []
            for key, value, seen in self._watched_values():
                if changed_only and self._checked.get(key) == seen:
                    continue
                v = np.array(value, dtype=np.float64)
                if not dr.is_tensor_v(value):
                    v = v.ravel()
                    v = v.tolist() if v.size > 1 else float(v[0])
                try:
                    self.check_value("out_of_range", key, key, v)
                except ParameterError as e:
                    found.append(str(e))
                    if len(found) >= limit:
                        break
                else:
                    self._checked[key] = seen
            return found

    def widened_values(self, limit: int = 3) -> list[str]:
        """The parameters, other than a shape's (a mesh's or a curve's arrays) and textures,
        that hold more than one value (at most ``limit``, each as ``"KEY holds N values"``): a plugin's single value or
        colour set through :attr:`params` to a wider array (``mi.Float([0.2, 0.3])``) renders
        nothing, failing inside Dr.Jit with words that name none of them ("size of output
        variable r2153 is 2 (must be 1)"). Read when a render fails.

        >>> # scene.params["white.roughness.value"] = mi.Float([0.2, 0.3]); scene.params.update()
        >>> # scene.widened_values() -> ['white.roughness.value holds 2 values']
        """
        found = []
        with RENDER_GUARD:
            for key, value, node in self._own_values():
                # (a shape's arrays are wide by design)
                if (not isinstance(node, mi.Shape) and dr.is_jit_v(value) and not dr.is_tensor_v(value)
                        and dr.width(value) > 1):
                    found.append(f"{key} holds {dr.width(value)} values")
                    if len(found) >= limit:
                        break
        return found

    @property
    def own_traversal(self):
        """``mi.traverse`` of the scene made once for draaw-mi's own reads (the values out of
        range, a copy's carried values): :attr:`params` may have been narrowed by the user
        (``params.keep([...])``); its values are the plugins' current ones all the same."""
        if self._own is None:
            with RENDER_GUARD, FOREGROUND:           # (as params: not beside a replay)
                if self._own is None:
                    self._own = mi.traverse(self.mi_scene)
        return self._own

    def _own_values(self):
        """``(key, value, plugin object)`` of every parameter of :attr:`own_traversal`, each
        value read from its plugin now."""
        own = self.own_traversal
        for key, (cur, vtype, node, _) in own.properties.items():
            yield key, (cur if vtype is None else own.get_property(cur, vtype, node)), node

    def _watched_values(self):
        """``(key, value, stamp)`` of every value :meth:`out_of_range` reads (:func:`_seen`)."""
        for key, value, _ in self._own_values():
            seen = _seen(value)
            if seen is not None:
                yield key, value, seen

    def _carry_checks(self, src: "DraawScene") -> None:
        """After :func:`~draaw_mi.scene.carry.carry_values` from ``src``: what ``src`` has
        checked and still holds is checked here too (the copy's textures are new variables
        with the same texels, not to be read back again); the rest is the file's, or set
        since the last check and checked at this copy's first render."""
        if not src._checked:
            return
        with RENDER_GUARD:
            held = {key for key, _, seen in src._watched_values() if src._checked.get(key) == seen}
            for key, _, seen in self._watched_values():
                if key in held:
                    self._checked[key] = seen

    def check_values(self, who: str, values: dict) -> None:
        """:meth:`check_value` of ``{name: (key, value)}`` set together: the SDF values are
        checked with each other (a round box's new size with its new radius), on top of the
        scene's current values."""
        sdf, names = {}, []
        for name, (key, value) in values.items():
            node_param = self.sdf_param(key)
            if node_param is not None:
                sdf[node_param] = value
                names.append(name)
            else:
                head = key.split(".")[0]
                media, emitters = self._object_ids()
                check_value(who, name, key, value, conductor=self._conductor_eta(key), medium=head in media,
                            emitter=head in emitters or "emitter" in key.split("."))
        if sdf:
            try:
                self.sdf.check_many(sdf)
            except ParameterError as e:
                raise ParameterError(f"{who}: {', '.join(names)}: {e}") from None

    def _object_ids(self) -> tuple[set, set]:
        """The names that head the keys of the scene's top-level media and emitters (an XML
        ``<medium id="fog">``'s keys are ``fog.*``, with no "medium" in them: checked as a
        medium's), found once. Only a key of one dot whose object is the medium or emitter
        itself counts: a nested one's id is its dict key (``interior``, ``emitter``), which a
        material may be named too."""
        if self._ids is None:
            s = self.mi_scene
            media, emitters = scene_media(s), list(s.emitters())
            heads: tuple[set, set] = (set(), set())
            for key, entry in self.own_traversal.properties.items():
                head, sep, rest = key.partition(".")
                if sep and "." not in rest:
                    for found, objects in zip(heads, (media, emitters)):
                        if any(entry[2] is obj for obj in objects):
                            found.add(head)
            self._ids = heads
        return self._ids

    def _conductor_eta(self, key: str) -> bool:
        """Whether ``key`` is a conductor's ``eta`` (its BSDF has a ``k`` beside it: only
        Mitsuba's conductors do)."""
        head, sep, tail = key.rpartition(".eta.")
        # (in the whole traversal: the user's params may be narrowed by keep())
        return bool(sep) and tail in ("value", "data") and f"{head}.k.{tail}" in self.own_traversal.properties

    def key(self, name: str) -> str:
        """Resolve ``material.parameter`` (or a full traverse key, an SDF object's
        ``sdf.NODE.PARAM``, or a light's or medium's own id: ``lamp.radiance``) to a key of
        :attr:`all_params` (:func:`~draaw_mi.scene.param_keys.resolve_key`).

        >>> # scene.key("gold.roughness") -> "gold.roughness.value"
        """
        return resolve_key(self, name)

    @property
    def resizable(self) -> bool:
        """Whether :meth:`with_resolution` can load the scene at another size: a description,
        a Mitsuba dict or an XML file, not an ``mi.Scene`` given as it is."""
        return self.mi_dict is not None or self.info.get("xml") is not None

    def with_resolution(self, width: int, height: int) -> "DraawScene":
        """The same scene with another film size. It reloads the Mitsuba scene and carries the
        current parameter values over (:func:`~draaw_mi.scene.carry.carry_values`): edits
        made through :attr:`params` stay; the copy has its own ``mi.traverse``."""
        width, height = resolution([width, height], Where("with_resolution") / "resolution")
        if (width, height) == self.resolution:
            return self
        settings = dict(self.settings, resolution=(int(width), int(height)))
        xml = self.info.get("xml")
        if self.mi_dict is None and xml is not None:      # an XML file: loaded again, resized
            scaled = DraawScene(load_mitsuba_file(xml["path"], xml["defines"], (int(width), int(height))),
                                settings, self.source, self.info, None, self._tmp, self.description)
            carry_values(self, scaled)
            scaled._carry_checks(self)
            return scaled
        if self.mi_dict is None:
            raise SceneError(f"{self.source}: cannot change the resolution of a scene given as "
                             "mi.Scene; edit its film instead (or load it from its XML file or dict)")
        d = dict(self.mi_dict)
        sensor = dict(d["sensor"])
        film = sensor["film"]
        # (a crop window renders the new size, showing the same part of the view)
        sized = scaled_crop(film, width, height) if set(film) & set(CROP) else {"width": width, "height": height}
        sensor["film"] = dict(film, **{k: int(v) for k, v in sized.items()})
        d["sensor"] = sensor
        scaled = DraawScene(load_dict_or_error(d, self.source), settings, self.source, self.info, d, self._tmp,
                          self.description)
        carry_values(self, scaled)
        scaled._carry_checks(self)
        return scaled

    def updated_description(self, values: dict, dest: str | None = None) -> dict:
        """The scene description with ``{"material.parameter": value}`` written into its
        ``[materials]`` tables, a light's radiance into its ``[[lights]]`` table
        (:mod:`~draaw_mi.scene.light_values`) and ``{"sdf.NODE.PARAM": value}`` into its ``[[sdf]]`` tables
        (for saving fitted scenes). ``dest``: the file it will be
        written to; file names relative to the scene's folder are rewritten relative to
        ``dest``'s folder (written elsewhere, the scene would lose its meshes and textures)."""
        if self.description is None:
            raise SceneError(f"{self.source}: only TOML/JSON/dict scenes can be written back")
        desc = copy.deepcopy(self.description)
        if dest is not None:
            desc = _rebased(desc, self.info.get("relative_files", {}), os.path.dirname(os.path.abspath(dest)))
        mats = desc.setdefault("materials", {})
        for name, value in values.items():
            # (every sdf.* name goes to the [[sdf]] tables, which say why one cannot be written)
            if self.sdf is not None and name.startswith(PREFIX) and name not in self.params:
                try:
                    write_back(desc.get("sdf"), name[len(PREFIX):], value)
                except ValueError as e:
                    raise SceneError(f"{self.source}: cannot write {name!r} back: {e}") from None
                continue
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

    def updated_text(self, values: dict, dest: str) -> str:
        """The text of :meth:`updated_description` for the file ``dest`` (``.toml`` or
        ``.json``). A TOML scene written to TOML keeps its file's comments and layout: only the
        lines of the values that changed are edited (:mod:`~draaw_mi.scene.toml_edit`; the file
        is read again, and where it changed since it was loaded it is written in full)."""
        desc = plain(self.updated_description(values, dest=dest), Where(self.source))
        if not dest.lower().endswith(".toml"):
            return json.dumps(desc, indent=2)
        if self.source.lower().endswith(".toml") and os.path.isfile(self.source):
            try:
                with open(self.source, encoding="utf-8") as fh:
                    text = edited_toml(fh.read(), self.description, desc)
            except (OSError, UnicodeDecodeError):
                text = None
            if text is not None:
                return text
        return tomli_w.dumps(desc)

    @property
    def sdf(self):
        """The scene's :class:`draaw_mi.sdf.scene.SDFScene` (``[[sdf]]`` entries), or ``None``."""
        return self.info.get("sdf")

    def features(self) -> dict:
        """Which effects the scene calls for (emitter kinds, textures, ...); ``aovs`` also
        where the scene's ``[render]`` table asks for them (render gives them to the
        integrator: the loaded scene's own integrator has none, so by it alone info would say "off")."""
        f = detect_features(self.mi_scene)
        f["aovs"] = f["aovs"] or bool(self.settings.get("aovs"))
        return f

    def summary(self) -> dict:
        """Everything ``draaw-mi info SCENE`` prints."""
        s = self.mi_scene
        return {
            "source": self.source,
            "resolution": list(self.resolution),
            # every sensor: "id (plugin, WxH)"; render(sensor=) / --sensor picks one
            "sensors": [f"{sn.id() or i} ({sn.class_name()}, {sn.film().crop_size()[0]}x{sn.film().crop_size()[1]})"
                        for i, sn in enumerate(s.sensors())],
            # the description's names, or for a Mitsuba scene each shape's id, else what its
            # file says of it ("merged mesh of 3 shapes: ..."; mitsuba_xml.shape_names)
            "shapes": self.info.get("shapes") or [sh.id() or "unnamed" for sh in s.shapes()
                                                  if not sh.id().startswith("__sdf_")],
            "lights": self.info.get("lights") or [_emitter_name(em) for em in s.emitters()],
            "materials": self.info.get("materials", []),
            "described": self.description is not None,   # (materials: the default draaw one)
            # materials no shape uses, left out of the Mitsuba scene (their code would enter
            # every kernel)
            "unused_materials": self.info.get("unused_materials", []),
            # materials only [[volumes]] use: copied into the voxels' blocks, with no parameters
            "volume_materials": self.info.get("volume_materials", []),
            "settings": {k: v for k, v in self.settings.items() if k != "post"},
            "post": [p.get("type") if isinstance(p, dict) else p for p in self.settings.get("post", [])],
            "features": self.features(),
            "volumes": self.info.get("volumes", []),
            **({"sdf": self.sdf.describe()} if self.sdf is not None else {}),
            # the integrator an XML file or dict declares (version "scene" renders with it)
            **({"integrator": self.info["integrator"]} if self.info.get("integrator") else {}),
        }


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


def plain(node, where: Where):
    """``node`` (a description) with the numbers and arrays :func:`load_scene` takes besides
    Python's own (numpy scalars and arrays, Dr.Jit arrays) as Python numbers and nested lists,
    which JSON and TOML write (a texture given as an array is written as its rows); a
    :class:`SceneError` naming the key of a value neither can hold.

    >>> plain({"m": {"roughness": np.float32(0.5), "base_color": np.full((1, 2, 3), 0.5)}}, Where("s"))
    {'m': {'roughness': 0.5, 'base_color': [[[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]]]}}
    """
    if isinstance(node, dict):
        return {k: plain(v, where / k) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [plain(v, where / i) for i, v in enumerate(node)]
    if node is None or isinstance(node, (str, bool, int, float)):
        return node
    if isinstance(node, np.generic) and isinstance(node.item(), (bool, int, float, str)):
        return node.item()
    try:
        arr = np.asarray(node)
    except Exception:  # noqa: BLE001 - whatever the object's __array__ raises
        arr = None
    if arr is not None and arr.dtype.kind in "biuf":
        return arr.tolist()
    raise where.error(f"{type(node).__name__} {str(node)[:60]!r} cannot be written to a scene file; "
                      "expected numbers, lists, numpy arrays or strings")


def _emitter_name(em) -> str:
    """An emitter's id; an area light without one is named by its shape's id (an XML file
    gives the ``<shape>`` the id, not the ``<emitter>`` inside it); else its class name."""
    kind = str(em).split("[", 1)[0]
    shape = em.get_shape()                     # (None but for area lights)
    # (a description's emitting shape holds its emitter under the dict key "emitter")
    if em.id() and not (shape is not None and shape.id() and em.id() == "emitter"):
        return em.id()
    if shape is not None and shape.id():
        return f"{shape.id()} ({kind})"
    return kind


def _seen(value):
    """The :func:`~draaw_mi.integrators.stamps.stamp` of a parameter's ``value``, or ``None`` for a value
    :meth:`DraawScene.out_of_range` does not read (a transform, a film size, a mesh's
    vertices)."""
    if not (dr.is_array_v(value) and dr.is_float_v(value)) or "Transform" in type(value).__name__:
        return None
    if not dr.is_tensor_v(value) and dr.width(value) != 1:
        return None
    return stamp(value)
