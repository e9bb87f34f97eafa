"""The Save tab of :class:`~draaw_mi.widgets.MaterialTuner`: the tuned scene as a description
(:meth:`SavePanel.document`), written as TOML or shown as a Python snippet.

:class:`SavePanel` reads what the other panels hold through the callbacks it is given, and
keeps the scene file's own light and ``[[sdf]]`` values (loaded once) to tell edits made
apart from the file (:meth:`SavePanel.outside_edits`).
"""
from __future__ import annotations

import copy
import os

import ipywidgets as W
import numpy as np

from ..errors import DraawError
from ..guard import RENDER_GUARD
from ..rendering.session import holding
from ..scene import DraawScene
from ..scene.loading import from_description
from . import tuning


class SavePanel:
    """The tuner's description of its scene and the Save tab (see the module docstring).

    =================  =========================================================================
    Given              Used for
    =================  =========================================================================
    ``base_scene``     the scene as loaded (its description, file, resolution)
    ``scene()``        the scene the preview renders now (a reload's, at another resolution)
    ``materials``      the tuned material values (``{material: {parameter: value}}``)
    ``textures``       texture files chosen per material (``{material: {parameter: file}}``)
    ``chain()``        the post chain now
    ``camera()``       the camera now as a ``[camera]`` table, or None
    ``lights``         the :class:`~draaw_mi.widgets.lights_panel.LightsPanel`
    ``render()``       ``{"version": ..., "max_depth": ...}`` of the preview
    ``guard(fn)``      a control's action wrapped so that an error shows in red, not raised
    ``say(text)``      show a message in the panel
    ``save_path``      the file name the panel starts with
    =================  =========================================================================
    """

    def __init__(self, base_scene, *, scene, materials, textures, chain, camera, lights, render, guard, say,
                 save_path=None):
        self.base_scene, self.materials, self.textures, self.lights = base_scene, materials, textures, lights
        self._scene, self._chain, self._camera, self._render, self._say = scene, chain, camera, render, say
        self._file_values = None             # the file's own light and SDF values (outside_edits)
        self._values_at_close = None         # the scene's SDF values when the tuner closed
        src = base_scene.source
        default = save_path or (os.path.splitext(src)[0] + "_tuned.toml" if src.endswith((".toml", ".json"))
                                else "tuned.toml")
        self.save_path = W.Text(value=default, description="save to")
        save = W.Button(description="save TOML")
        save.on_click(guard(lambda _b: self.save(self.save_path.value)))
        show = W.Button(description="Python snippet")
        self.snippet_text = W.Textarea(layout=W.Layout(width="420px", height="160px"))
        show.on_click(guard(lambda _b: setattr(self.snippet_text, "value", self.snippet())))
        self.widget = W.VBox([W.HBox([self.save_path, save]), show, self.snippet_text])

    def document(self, dest: str | None = None) -> dict:
        """The tuned scene as a description dict (what :meth:`save` writes; ``dest``: the
        file it goes to, for file names relative to the scene's folder)."""
        cam = self._camera()
        render = dict(self._render())
        for key in ("filter", "sampler"):              # the scene's own, as loaded
            if self.base_scene.settings.get(key) is not None:
                render[key] = self.base_scene.settings[key]
        lights = self.lights.settings()
        # from the loaded scene's description: a reloaded scene's holds scaled lights already
        doc = tuning.document(self.base_scene, self.materials, camera=cam, render=render, post=self._chain(),
                              light_scale=lights["scale"], light_color=lights["color"], dest=dest,
                              values=self.outside_edits())
        for m, files in self.textures.items():
            doc["materials"][m].update(files)
        w, h = self.base_scene.resolution
        doc["render"]["resolution"] = [w, h]
        if lights["snap"] and cam is not None:          # point lights where the panel put them
            for light in doc.get("lights", []):        # (a snap_to_camera light follows the
                if light.get("type") == "point" and not light.get("snap_to_camera"):   # saved camera)
                    light["position"] = [float(x) for x in cam["origin"]]
        return doc

    def outside_edits(self) -> dict:
        """``{key: value}`` of the lights and ``[[sdf]]`` parameters the scene has apart from
        its file (set through ``scene.params`` before the panel was made, or through
        ``tuner.preview.update``): written into :meth:`document`, so that the resolution
        slider's reload and :meth:`save` keep them. Lights as the panel found them (its
        intensity and colour controls scale them), SDF values as the scene has them now."""
        if self.base_scene.description is None:
            return {}
        if self._file_values is None:                 # the file's own values, loaded once
            src = self.base_scene.source
            base = os.path.dirname(os.path.abspath(src)) if os.path.isfile(src) else os.getcwd()
            # read and freed under the render guard: a scene freed while another thread
            # records a frame kills the process
            with RENDER_GUARD:
                fresh = from_description(copy.deepcopy(self.base_scene.description), src, base, {})
                self._file_values = _editable_values(fresh, tuning.light_values(fresh))
                del fresh
        now = self._values_at_close
        if now is None:
            scene = self._scene()
            with holding(scene):                      # (its values read beside no frame)
                now = _editable_values(scene, self.lights.base)
        return {k: v for k, v in now.items()
                if k in self._file_values and not np.allclose(v, self._file_values[k], rtol=1e-6, atol=0)}

    def save(self, path: str) -> str:
        """Write the tuned scene to a TOML file (atomically) and return its path (``~`` is the
        home folder, as in a shell: it had made a folder named ``~``)."""
        path = os.path.expanduser(path)
        tuning.save_toml(path, self.document(dest=path))
        self._say(f"saved {_html(path)}")
        return path

    def snippet(self) -> str:
        """Python code reproducing the tuned materials."""
        return tuning.snippet(self.base_scene.source, self.materials, dict(self._render()),
                              resolution=self.base_scene.resolution)

    def close(self) -> None:
        """Keep what :meth:`document`, :meth:`save` and :meth:`snippet` read of the scenes
        (:class:`ClosedScene`, and the ``[[sdf]]`` values the scene has now) and let go of
        them: the tuner frees its scenes when it closes. Call it with the worker stopped."""
        if isinstance(self.base_scene, ClosedScene):
            return
        scene = self._scene()
        if scene is not None:
            with holding(scene):
                self._values_at_close = _editable_values(scene, self.lights.base)
        self.base_scene = ClosedScene(self.base_scene)
        self._scene = lambda: None


class ClosedScene:
    """What the Save panel reads of the loaded scene, kept as plain data (no Dr.Jit object)
    once the tuner has closed and freed the scene: its description, file, settings, resolution,
    the relative file names the loader resolved and its parameter names.
    :meth:`updated_description` is :meth:`DraawScene.updated_description
    <draaw_mi.scene.DraawScene.updated_description>` over these; anything else read of it raises
    a :class:`~draaw_mi.errors.DraawError` saying that the panel was closed."""

    def __init__(self, scene):
        self.description = copy.deepcopy(scene.description)
        self.source = scene.source
        self.settings = copy.deepcopy(dict(scene.settings))
        self.resolution = tuple(scene.resolution)
        self.info = {"relative_files": dict(scene.info.get("relative_files", {}))}
        self.sdf = None if scene.sdf is None else True        # (only whether it has [[sdf]])
        self.params = frozenset(scene.params.keys())          # (names: whether a key is one)

    updated_description = DraawScene.updated_description

    def __getattr__(self, name):
        if name.startswith("__"):              # (copy, pickle and hasattr ask for these)
            raise AttributeError(name)
        raise DraawError(f"MaterialTuner: the panel was closed (MaterialTuner.close) and its scene "
                         f"freed; its {name!r} is not kept. Open a new MaterialTuner")


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
