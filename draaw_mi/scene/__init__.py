"""Scenes: files and descriptions in, :class:`DraawScene` out; every scene table is read here.

* :mod:`~draaw_mi.scene.loading` -- :func:`load_scene` (TOML / JSON / dict, Mitsuba XML and
  dicts, ``mi.Scene``, bare meshes); :mod:`~draaw_mi.scene.draaw_scene` -- :class:`DraawScene`;
* :mod:`~draaw_mi.scene.description` -- a validated description -> a Mitsuba scene dict, with
  the tables' own modules: :mod:`~draaw_mi.scene.camera`, :mod:`~draaw_mi.scene.meshes`
  (:mod:`~draaw_mi.scene.smooth_normals`), :mod:`~draaw_mi.scene.material_dicts`,
  :mod:`~draaw_mi.scene.light_dicts`, :mod:`~draaw_mi.scene.volume_dicts` (``[[volumes]]``;
  where their smoke boxes may lie: :mod:`~draaw_mi.scene.smoke_boxes`),
  :mod:`~draaw_mi.scene.sdf_dicts` (``[[sdf]]``, with
  :mod:`~draaw_mi.scene.go_draaw_spheres`);
* :mod:`~draaw_mi.scene.schema` -- typed fields, ranges, unknown-key suggestions;
  :mod:`~draaw_mi.scene.values` -- values written into loaded parameters;
* :mod:`~draaw_mi.scene.camera_path` -- GO-Draaw's keyframe interpolation;
* :mod:`~draaw_mi.scene.mitsuba_load`, :mod:`~draaw_mi.scene.mitsuba_xml` -- Mitsuba's own
  loaders made safe, and what an XML file refers to.

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

from .._lazy import old_names
from .draaw_scene import DraawScene
from .loading import OVERRIDE_MAXIMA, OVERRIDE_MINIMA, SCENE_SUFFIXES, load_scene
from .values import check_like, value_like

__all__ = ["DraawScene", "OVERRIDE_MAXIMA", "OVERRIDE_MINIMA", "SCENE_SUFFIXES", "check_like", "load_scene", "value_like"]

# names the earlier release had here, served from their new modules with a DeprecationWarning
__getattr__ = old_names(__name__, {
    **dict.fromkeys(("DEFAULT_SETTINGS", "build_mitsuba_dict"), f"{__name__}.description"),
    **dict.fromkeys(("MESH_SUFFIXES", "bounds", "load_mesh_parts"), f"{__name__}.meshes"),
    **dict.fromkeys(("load_dict_or_error", "load_mitsuba_file", "mitsuba_error_message"), f"{__name__}.mitsuba_load"),
    **dict.fromkeys(("filter_plugin", "sampler_plugin"), "draaw_mi.integrators.features"),
    **dict.fromkeys(("SceneError", "ParameterError", "suggest"), "draaw_mi.errors"),
    "WRAPPED_KEPT": f"{__name__}.loading", "Where": f"{__name__}.schema", "auto_light": f"{__name__}.light_dicts"})
