"""The Save tab of :class:`~draaw_mi.widgets.MaterialTuner`: the tuned scene as a description
(:meth:`DocumentPanel.document`), written as TOML or shown as a Python snippet.

A mixin: it reads the tuner's ``base_scene``, ``scene``, ``materials``, ``post``,
``camera`` and camera controls, light controls, ``_light_base``, ``_textures``, ``preview``,
``message`` and ``_guard``; ``_file_values`` caches the scene file's own light and SDF values.
"""
from __future__ import annotations

import os

import ipywidgets as W
import numpy as np

from . import tuning


class DocumentPanel:
    """The tuner's description of its scene and the Save tab (see the module docstring)."""

    def _save_panel(self, save_path):
        default = save_path or (os.path.splitext(self.scene.source)[0] + "_tuned.toml"
                                if self.scene.source.endswith((".toml", ".json")) else "tuned.toml")
        self.save_path = W.Text(value=default, description="save to")
        save = W.Button(description="save TOML")
        save.on_click(self._guard(lambda _b: self.save(self.save_path.value)))
        show = W.Button(description="Python snippet")
        self.snippet_text = W.Textarea(layout=W.Layout(width="420px", height="160px"))
        show.on_click(self._guard(lambda _b: setattr(self.snippet_text, "value", self.snippet())))
        return W.VBox([W.HBox([self.save_path, save]), show, self.snippet_text])

    def document(self, dest: str | None = None) -> dict:
        """The tuned scene as a description dict (what :meth:`save` writes; ``dest``: the
        file it goes to, for file names relative to the scene's folder)."""
        cam = None
        if self.camera is not None:
            o, t, up = self._camera_now()
            cam = {"origin": o, "target": t, "up": up, "fov": float(self.fov.value),
                   "mirror": bool(self.camera.get("mirror", False))}
        render = {"version": self.preview.version, "max_depth": int(self.preview.max_depth)}
        for key in ("filter", "sampler"):     # (load_scene(..., filter=) went back to the file's)
            if self.base_scene.settings.get(key) is not None:
                render[key] = self.base_scene.settings[key]
        # from the loaded scene's description: a reloaded scene's holds scaled lights already
        doc = tuning.document(self.base_scene, self.materials, camera=cam, render=render, post=self.post,
                              light_scale=float(self.light_scale.value),
                              light_color=tuning.hex_to_linear(self.light_color.value), dest=dest,
                              values=self._outside_edits())
        for m, files in self._textures.items():
            doc["materials"][m].update(files)
        w, h = self.base_scene.resolution
        doc["render"]["resolution"] = [w, h]
        if self.snap_light.value and cam is not None:     # point lights where _set_lights put them
            for light in doc.get("lights", []):          # (a snap_to_camera light follows the
                if light.get("type") == "point" and not light.get("snap_to_camera"):   # saved camera
                    light["position"] = [float(x) for x in cam["origin"]]       # already; a position
                                                                                # beside it is refused)
        return doc

    def _outside_edits(self) -> dict:
        """``{key: value}`` of the lights and ``[[sdf]]`` parameters the scene had apart from
        its file (set through ``scene.params`` before the panel was made, or through
        ``tuner.preview.update``): written into :meth:`document`, so that the resolution
        slider's reload and :meth:`save` keep them (they went back to the file's values: a
        light 8x off what the preview showed). Lights as the panel found them (its intensity
        and colour controls scale them), SDF values as the scene has them now."""
        if self.base_scene.description is None:
            return {}
        if self._file_values is None:                 # the file's own values, loaded once
            import copy
            from .scene import _from_description
            src = self.base_scene.source
            base = os.path.dirname(os.path.abspath(src)) if os.path.isfile(src) else os.getcwd()
            fresh = _from_description(copy.deepcopy(self.base_scene.description), src, base, {})
            self._file_values = _editable_values(fresh, tuning.light_values(fresh))
        now = _editable_values(self.scene, self._light_base)
        return {k: v for k, v in now.items()
                if k in self._file_values and not np.allclose(v, self._file_values[k], rtol=1e-6, atol=0)}

    def save(self, path: str) -> str:
        """Write the tuned scene to a TOML file (atomically) and return its path."""
        tuning.save_toml(path, self.document(dest=path))
        self.message.value = f"saved {_html(path)}"
        return path

    def snippet(self) -> str:
        """Python code reproducing the tuned materials."""
        return tuning.snippet(self.base_scene.source, self.materials,
                              {"version": self.preview.version, "max_depth": int(self.preview.max_depth)},
                              resolution=self.base_scene.resolution)


def _editable_values(scene, lights: dict) -> dict:
    """The light intensities in ``lights`` (radiance / intensity: what a scene file can say;
    not an environment map's texels or scale) and ``scene``'s ``[[sdf]]`` parameters, as
    flat float arrays."""
    out = {k: np.asarray(v, np.float64).ravel() for k, v in lights.items()
           if k.endswith(tuning.LIGHT_SUFFIXES) and not k.endswith((".data", ".scale"))}
    if scene.sdf is not None:
        p = scene.all_params
        for k in p.keys():
            if k.startswith("sdf."):
                out[k] = np.asarray(p[k], np.float64).ravel()
    return out


def _html(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
