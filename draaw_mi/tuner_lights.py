"""The Light tab of :class:`~draaw_mi.widgets.MaterialTuner`: one intensity scale and colour
over every light, and point lights snapped to the camera.

A mixin: it reads the tuner's ``_light_base`` (each light parameter's value in the scene),
``_light_positions``, ``_camera_lights``, ``_lights_now``, ``camera`` and ``_camera_now``,
``_guard`` and ``_changed``.
"""
from __future__ import annotations

import ipywidgets as W
import numpy as np

from . import tuning


class LightPanel:
    """The tuner's light controls (see the module docstring)."""

    def _light_panel(self):
        self.light_scale = W.FloatLogSlider(value=1.0, base=2, min=-4, max=4, description="intensity ×")
        self.light_color = W.ColorPicker(value="#ffffff", description="colour")
        self.snap_light = W.Checkbox(value=False, description="snap point lights to the camera")
        for w in (self.light_scale, self.light_color, self.snap_light):
            w.observe(self._guard(lambda ch: self._set_lights()), "value")
        return W.VBox([self.light_scale, self.light_color, self.snap_light])

    def _set_lights(self, positions_only: bool = False):
        """Push the lights' intensities and places; ``positions_only``: only their places (a
        camera move)."""
        vals, now = self._light_places()
        if not positions_only:
            more, tint = self._light_intensities()
            vals.update(more)
            now["tint"] = tint
        self._changed(vals)
        self._lights_now.update(now)        # once the preview has them

    def _light_intensities(self) -> tuple[dict, tuple]:
        """The lights' values under the intensity and colour controls, and the tint."""
        col = np.array(tuning.hex_to_linear(self.light_color.value))
        s = float(self.light_scale.value)
        tint = tuple(float(c) for c in col)
        vals = {}
        for k, base in self._light_base.items():
            if k.endswith(".data"):         # an environment map's texels: its tint (rewriting
                if tint != self._lights_now["tint"]:        # them rebuilds its sampling
                    vals[k] = base * col.astype(np.float32)       # distribution: only on a change)
                continue
            v = base * s * (col if base.size == 3 else 1.0 if k.endswith(".scale") else col.mean())
            vals[k] = [float(x) for x in v] if v.size == 3 else float(v[0])
        return vals, tint

    def _light_places(self) -> tuple[dict, dict]:
        """Where the point-like lights go: at the camera if they snap (snap_to_camera ones
        always, the others while the box is ticked), else where the scene had them; and
        which ones snap."""
        snapped = frozenset() if self.camera is None else frozenset(self._camera_lights).union(
            self._light_positions if self.snap_light.value else ())
        vals = {}
        if snapped or self._lights_now["snapped"]:      # unsnapped: back where the scene had them
            eye, target, _ = self._camera_now() if snapped else (None, None, None)
            for k, pos in self._light_positions.items():
                vals[k] = (eye if k in snapped else pos).tolist()
            for k, aim in self._camera_lights.items():
                if k.endswith(".to_world") and k in snapped:
                    frame = tuning.spot_at(eye, target if aim is None else aim)
                    if frame is not None:
                        vals[k] = frame
        return vals, {"snapped": snapped}
