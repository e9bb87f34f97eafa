"""Captures: what :func:`draaw_mi.fit` compares with each reference photo -- the camera it was
taken from *and* the light it was taken under.

A capture is a dict (or a JSON object in ``draaw-mi fit --captures``)::

    {"reference": "photo_03.png",          # optional here when fit() gets references
     "camera": {"origin": [...], "target": [...], "fov": 40},   # default: the scene's camera
     "lights": {"sun": 0.0, "lamp": 2.0},  # multiply named lights' emission (others: x1)
     "params": {"lamp.to_world": ...}}     # any other scene parameter, by its mi.traverse key

Several photos from one position under different lights constrain roughness and metallic
far better than more views under one light; ``lights`` switches the scene's lights on, off or
dims them per photo. Before each capture's render every parameter that any capture
overrides is set to this capture's value, or back to the scene's own.

>>> parse_captures([{"camera": {"origin": [0, 0, 3]}, "lights": {"sun": 0}}], references=[None])[0]["lights"]
{'sun': 0.0}
"""
from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, SceneError
from ..guard import in_foreground
from ..rendering.frozen import owned_tensor
from ..rendering.session import holding, session_of
from .views import view_sensors

CAPTURE_KEYS = ("reference", "camera", "lights", "params")
#: the parameters of an emitter that hold its emission (scaled by a capture's ``lights``)
EMISSION_SUFFIXES = ("irradiance.value", "radiance.value", "intensity.value", ".scale")


def parse_captures(captures, references) -> list:
    """``captures`` checked: a list of dicts with only :data:`CAPTURE_KEYS`, each with a
    reference when ``references`` is None, lights as ``{name: factor >= 0}``."""
    if not isinstance(captures, (list, tuple)) or not captures:
        raise ParameterError("fit: captures must be a non-empty list of dicts (camera, lights, params, reference)")
    out = []
    for i, c in enumerate(captures):
        if not isinstance(c, dict):
            raise ParameterError(f"fit: captures[{i}] is {type(c).__name__}; expected a dict with "
                                 f"keys among {', '.join(CAPTURE_KEYS)}")
        unknown = sorted(set(c) - set(CAPTURE_KEYS))
        if unknown:
            raise ParameterError(f"fit: captures[{i}] has the key(s) {', '.join(unknown)}; expected "
                                 f"keys among {', '.join(CAPTURE_KEYS)}")
        if references is None and "reference" not in c:
            raise ParameterError(f"fit: captures[{i}] has no 'reference', and fit() got no references")
        if references is not None and "reference" in c:
            raise ParameterError(f"fit: captures[{i}] has a 'reference' and fit() got references too; "
                                 "give them one way")
        lights = c.get("lights") or {}
        if not isinstance(lights, dict):
            raise ParameterError(f"fit: captures[{i}].lights={lights!r}; expected a dict of light name -> "
                                 "factor (0 switches a light off)")
        for name, f in lights.items():
            if isinstance(f, bool) or not isinstance(f, (int, float)) or not (math.isfinite(f) and f >= 0):
                raise ParameterError(f"fit: captures[{i}].lights[{name!r}]={f!r}; expected a finite factor >= 0")
        params = c.get("params") or {}
        if not isinstance(params, dict):
            raise ParameterError(f"fit: captures[{i}].params={params!r}; expected a dict of parameter -> value")
        out.append({"reference": c.get("reference"), "camera": c.get("camera"),
                    "lights": {str(k): float(v) for k, v in lights.items()}, "params": dict(params)})
    return out


def capture_references(captures: list, where: str | None = None) -> list:
    """The captures' own references; a relative path is taken from ``where`` (a JSON file's
    folder) when given."""
    refs = []
    for c in captures:
        r = c["reference"]
        if isinstance(r, (str, os.PathLike)) and where and not os.path.isabs(r):
            r = os.path.join(where, r)
        refs.append(r)
    return refs


def emission_keys(params, light: str) -> list:
    """The ``mi.traverse`` keys holding the emission of the light named ``light``.

    An area light's is ``<name>.emitter.radiance.value``, a point light's
    ``<name>.intensity.value``, a sun's ``<name>.irradiance.value``, a sky's
    ``<name>.radiance.value``, an environment map's ``<name>.scale``."""
    prefix = light + "."
    return [k for k in params.keys() if k.startswith(prefix) and k.endswith(EMISSION_SUFFIXES)]


@dataclass
class CaptureOverrides:
    """Per capture, the scene values to set before its render (``values[i]``: key -> value);
    :meth:`apply` sets them, and the scene's own for the keys this capture leaves alone."""
    values: list
    base: dict = field(default_factory=dict)
    lights_vary: bool = False          # some capture scales a light
    tables: dict = field(default_factory=dict)    # capture -> the integrator's light table

    @classmethod
    def build(cls, params, captures: list, fitted_keys: list, light_names) -> CaptureOverrides:
        base: dict = {}
        values = []
        for i, c in enumerate(captures):
            own = {}
            for name, factor in c["lights"].items():
                keys = emission_keys(params, name)
                if not keys:
                    raise ParameterError(f"fit: captures[{i}].lights names {name!r}, which is not a light of "
                                         f"the scene (lights: {', '.join(sorted(light_names)) or 'none'})")
                for k in keys:
                    base.setdefault(k, _copy(params[k]))
                    own[k] = base[k] * factor
            for k, v in c["params"].items():
                if k not in params:
                    raise ParameterError(f"fit: captures[{i}].params names {k!r}, which is not a scene "
                                         "parameter (an mi.traverse key)")
                base.setdefault(k, _copy(params[k]))
                if dr.is_tensor_v(params[k]):            # (copied: it may map numpy memory,
                    v = owned_tensor(np.asarray(v))      # which recordings must not take)
                own[k] = v if not isinstance(v, (list, tuple, int, float)) else type(params[k])(v)
            clash = sorted(set(own) & set(fitted_keys))
            if clash:
                raise ParameterError(f"fit: captures[{i}] overrides {', '.join(clash)}, which is fitted")
            values.append(own)
        return cls(values, base, lights_vary=any(c["lights"] for c in captures))

    @property
    def any(self) -> bool:
        return bool(self.base)

    def apply(self, params, i: int) -> None:
        """Set capture ``i``'s values (and the scene's own for the rest); the caller updates."""
        for k, v in self.base.items():
            params[k] = self.values[i].get(k, v)

    def select_lights(self, integrator, mi_scene, i: int) -> None:
        """Before capture ``i``'s render: its own light-selection table, where the integrator
        learns one (``draaw_v4``): a table learned under another capture's lights gives a
        light switched on here only the uniform floor of the samples (measured: 0.18-0.68 of
        the image's energy as noise at 8 spp on a tile under four lamps, against 0.003)."""
        if self.lights_vary and hasattr(integrator, "restore_selection"):
            integrator.restore_selection(mi_scene, self.tables.get(i))

    def remember_lights(self, integrator, mi_scene, i: int) -> None:
        """After capture ``i``'s render: keep the table it used (learned for its lights)."""
        if self.lights_vary and hasattr(integrator, "selection_state"):
            self.tables[i] = integrator.selection_state(mi_scene)

    def restore(self, params) -> None:
        for k, v in self.base.items():
            params[k] = v


def _copy(value):
    return type(value)(value) if dr.is_array_v(value) or isinstance(value, mi.Transform4f) else value


def light_names(params) -> list:
    """The names of the scene's lights (those with an emission parameter), sorted."""
    return sorted({k.split(".")[0] for k in params.keys() if k.endswith(EMISSION_SUFFIXES)})


@in_foreground
def render_capture(scene, capture: dict, spp: int = 64, version: str = "v4", seed: int = 0) -> np.ndarray:
    """Render ``scene`` (a :class:`~draaw_mi.scene.DraawScene`) as ``capture`` sees it: its
    camera, its lights and parameters; the scene's own values come back afterwards. The relit
    preview of a fit: a capture with a new camera or light. Returns (H, W, 3) linear float32.

    Example (``scene`` with a light named ``sun``)::

        img = render_capture(scene, {"camera": {"origin": [2, 1, 3]}, "lights": {"sun": 0.0}})
    """
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= seed <= 0xFFFFFFFF:
        raise ParameterError(f"render_capture: seed={seed!r}; expected an integer in [0, {0xFFFFFFFF}]")
    p = scene.params
    try:                       # (the checks a fit's captures pass, in this function's words)
        (c,) = parse_captures([capture], references=[None])
        over = CaptureOverrides.build(p, [c], [], light_names(p))
        sensor = view_sensors(scene, [c["camera"]])[0]
    except (ParameterError, SceneError) as e:
        said = str(e).removeprefix("fit: ").replace("captures[0]", "capture").replace("views[0]", "capture.camera")
        raise type(e)(f"render_capture: {said}") from None
    session = session_of(scene)
    integrator = session.integrator(version, scene.settings["max_depth"], scene.settings.get("hide_emitters", False))
    with holding(scene):
        try:
            over.apply(p, 0)
            p.update()
            session.scene_changed()
            over.select_lights(integrator, scene.mi_scene, 0)
            image = session.render_pass(integrator, spp, seed, sensor=sensor)
        finally:
            over.restore(p)
            p.update()
            session.scene_changed()
            if over.lights_vary and hasattr(integrator, "restore_selection"):
                integrator.restore_selection(scene.mi_scene, None)      # relearn for the scene's own
    return np.array(image)[..., :3]
