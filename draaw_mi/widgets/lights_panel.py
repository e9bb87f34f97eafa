"""The Light tab of :class:`~draaw_mi.widgets.MaterialTuner`: one intensity scale and colour
over every light, and point lights snapped to the camera.

:class:`LightsPanel` owns the scene's light values as loaded (``base``: each light
parameter's value), the point-like lights' places, the lights that follow the camera, and
what the preview has of them now (``now``: the tint and which lights snapped).
"""
from __future__ import annotations

import ipywidgets as W
import numpy as np

from . import tuning


class LightsPanel:
    """The tuner's light controls (see the module docstring).

    ===============  ===========================================================================
    Given            Used for
    ===============  ===========================================================================
    ``scene``        the loaded scene (its lights as loaded)
    ``guard(fn)``    a control's action wrapped so that an error shows in red, not raised
    ``changed(v)``   queue parameter values for the preview
    ``camera_now()`` ``(origin, target, up)`` of the camera now, or None (no camera)
    ===============  ===========================================================================
    """

    def __init__(self, scene, *, guard, changed, camera_now):
        self._changed, self._camera_now = changed, camera_now
        self.base = tuning.light_values(scene)
        self.positions = tuning.light_positions(scene)
        # lights at the camera in the preview: snap_to_camera ones always, the others while the
        # snap box is ticked
        self.camera_lights = tuning.camera_lights(scene)
        self.now = {"tint": (1.0, 1.0, 1.0), "snapped": frozenset()}    # as the preview has them
        self.light_scale = W.FloatLogSlider(value=1.0, base=2, min=-4, max=4, description="intensity ×")
        self.light_color = W.ColorPicker(value="#ffffff", description="colour")
        self.snap_light = W.Checkbox(value=False, description="snap point lights to the camera")
        for w in (self.light_scale, self.light_color, self.snap_light):
            w.observe(guard(lambda ch: self.set_lights()), "value")
        self.widget = W.VBox([self.light_scale, self.light_color, self.snap_light])

    def follows_camera(self) -> bool:
        """Whether a camera move moves lights (snapped ones, or snap_to_camera lights)."""
        return bool(self.snap_light.value or self.camera_lights)

    def follow_camera(self) -> None:
        """Move the lights that follow the camera (a camera move is about to be queued)."""
        if self.follows_camera():
            self.set_lights(positions_only=True)

    def set_lights(self, positions_only: bool = False):
        """Push the lights' intensities and places; ``positions_only``: only their places (a
        camera move)."""
        vals, now = self._places()
        if not positions_only:
            more, tint = self._intensities()
            vals.update(more)
            now["tint"] = tint
        self._changed(vals)
        self.now.update(now)               # once the preview has them

    def settings(self) -> dict:
        """The controls' values: ``scale``, ``color`` (linear RGB) and ``snap``."""
        return {"scale": float(self.light_scale.value), "color": tuning.hex_to_linear(self.light_color.value),
                "snap": bool(self.snap_light.value)}

    def _intensities(self) -> tuple[dict, tuple]:
        """The lights' values under the intensity and colour controls, and the tint."""
        col = np.array(tuning.hex_to_linear(self.light_color.value))
        s = float(self.light_scale.value)
        tint = tuple(float(c) for c in col)
        vals = {}
        for k, base in self.base.items():
            if k.endswith(".data"):         # an environment map's texels: its tint, only on a
                if tint != self.now["tint"]:          # change (it rebuilds the map's sampling)
                    vals[k] = base * col.astype(np.float32)
                continue
            v = base * s * (col if base.size == 3 else 1.0 if k.endswith(".scale") else col.mean())
            vals[k] = [float(x) for x in v] if v.size == 3 else float(v[0])
        return vals, tint

    def _places(self) -> tuple[dict, dict]:
        """Where the point-like lights go: at the camera if they snap (snap_to_camera ones
        always, the others while the box is ticked), else where the scene had them; and
        which ones snap."""
        camera = self._camera_now()
        snapped = frozenset() if camera is None else frozenset(self.camera_lights).union(
            self.positions if self.snap_light.value else ())
        vals = {}
        if snapped or self.now["snapped"]:      # unsnapped: back where the scene had them
            eye, target, _ = camera if snapped else (None, None, None)
            for k, pos in self.positions.items():
                vals[k] = (eye if k in snapped else pos).tolist()
            for k, aim in self.camera_lights.items():
                if k.endswith(".to_world") and k in snapped:
                    frame = tuning.spot_at(eye, target if aim is None else aim)
                    if frame is not None:
                        vals[k] = frame
        return vals, {"snapped": snapped}
