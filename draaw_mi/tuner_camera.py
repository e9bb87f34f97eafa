"""The camera panel of :class:`~draaw_mi.widgets.MaterialTuner`: field of view, orbit about
the target (sliders, or the mouse on an :class:`~draaw_mi.orbit_canvas.OrbitCanvas`), the
camera as JSON, and GO-Draaw camera paths stepped or played.

A mixin: it reads and writes the tuner's ``scene``, ``camera`` (origin, target, up, fov as
loaded), ``snap_light``, ``_camera_lights``, ``_guard``, ``_changed`` and ``_set_lights``;
the orbit is always relative to ``camera``, so the sliders and a drag describe the same
camera.
"""
from __future__ import annotations

import json

import ipywidgets as W
import numpy as np

from . import tuning
from .limits import FOV_RANGE
from .errors import DraawError


def slider(desc, value, lo, hi, step=0.01):
    """The tuner's float slider: continuous updates, a wide label, three decimals."""
    return W.FloatSlider(value=value, min=lo, max=hi, step=step, description=desc, continuous_update=True,
                         readout_format=".3f", style={"description_width": "120px"},
                         layout=W.Layout(width="380px"))


class CameraPanel:
    """Camera controls for the tuner (see the module docstring)."""

    def _fov_key(self):
        """The sensor's ``x_fov`` key (``cam.x_fov`` for an XML sensor called ``cam``: the
        slider showed 40 and every move failed on ``sensor.x_fov``)."""
        from .scene.camera import sensor_keys
        return sensor_keys(self.scene)[1]

    def _camera_panel(self):
        key = self._fov_key()
        fov = float(np.array(self.scene.params[key]).ravel()[0]) if key else 40.0
        # the range scene files allow (5..120 clamped a 150-degree camera, and saving wrote 120)
        self.fov = slider("FOV (x)", fov, min(1.0, fov), FOV_RANGE[1], 0.5)
        self.fov.disabled = key is None
        self.yaw = slider("orbit yaw °", 0.0, -180.0, 180.0, 1.0)
        self.pitch = slider("orbit pitch °", 0.0, -85.0, 85.0, 1.0)
        self.distance = slider("distance ×", 1.0, 0.2, 3.0, 0.01)
        # (the key as the panel found it: a reload keeps the scene's names)
        self.fov.observe(self._guard(lambda ch: self._changed({key: float(ch["new"])})), "value")
        for w in (self.yaw, self.pitch, self.distance):
            w.observe(self._guard(lambda ch: self._set_camera()), "value")
        get = W.Button(description="get camera")
        self.camera_text = W.Textarea(layout=W.Layout(width="380px", height="90px"))
        get.on_click(self._guard(lambda _b: self._get_camera()))
        # a camera path (GO-Draaw camera_positions.json keyframes), stepped or played
        self.path_file = W.Text(placeholder="camera_positions.json", description="camera path")
        load = W.Button(description="load path")
        load.on_click(self._guard(lambda _b: self.load_camera_path(self.path_file.value.strip())))
        self.path_frame = W.IntSlider(value=0, min=0, max=0, description="path frame", disabled=True)
        self.path_play = W.Play(value=0, min=0, max=0, interval=100, disabled=True)
        self._links = [W.jslink((self.path_play, "value"), (self.path_frame, "value"))]
        self.path_frame.observe(self._guard(lambda ch: self._path_step(int(ch["new"]))), "value")
        self._path = None
        rows = [self.fov] + ([self.yaw, self.pitch, self.distance, get, self.camera_text] if self.camera else [])
        rows += [W.HBox([self.path_file, load]), W.HBox([self.path_play, self.path_frame])]
        return W.VBox(rows)

    def load_camera_path(self, keys, frames: int = 120):
        """Load keyframes (a GO-Draaw ``camera_positions.json`` file name or a list of
        ``(x, y, z, theta, phi)`` / dicts) and interpolate ``frames`` frames along them; the
        *path frame* slider and its play button then move the camera."""
        from .camera_path import interpolate
        if isinstance(keys, str):
            if not keys:
                raise DraawError("camera path: no file name given")
            try:
                with open(keys) as fh:
                    keys = json.load(fh)
            except (OSError, json.JSONDecodeError) as e:
                raise DraawError(f"camera path {keys!r}: {e}") from None
        path = interpolate(keys, duration=frames, fps=1)         # (frames / 60 at 60 fps lost one)
        self._path = path
        for w in (self.path_frame, self.path_play):
            w.max = len(path) - 1
            w.disabled = False
        self._path_step(int(self.path_frame.value))
        return path

    def _path_step(self, i):
        if self._path is None:
            return
        from .scene.camera import go_draaw_look_at
        x, y, z, theta, phi = self._path[min(i, len(self._path) - 1)]
        try:
            o, t, up, mirror = go_draaw_look_at((x, y, z), theta, phi, float(self.fov.value))
        except ValueError as e:
            raise DraawError(f"camera path frame {i}: {e}") from None
        before = self.camera
        self.camera = {"origin": list(map(float, o)), "target": list(map(float, t)),
                       "up": list(map(float, up)), "fov": float(self.fov.value), "mirror": mirror}
        # the orbit is relative to the path's camera (a refused frame keeps the one before)
        self._orbit_to(0.0, 0.0, 1.0, undo=lambda: setattr(self, "camera", before))

    def _camera_now(self):
        return tuning.orbit(self.camera, self.yaw.value, self.pitch.value, self.distance.value)

    def _set_camera(self):
        if self.camera is None:
            raise DraawError("this scene has no [camera] table to orbit")
        from .scene.camera import look_at_transform
        o, t, up = self._camera_now()
        values = {"sensor.to_world": look_at_transform(o, t, up, self.camera.get("mirror", False))}
        # (refused before the lights follow: a camera moved into smoke moved them regardless)
        self.preview.check_camera_outside_smoke("camera", values["sensor.to_world"])
        if self.snap_light.value or self._camera_lights:
            self._set_lights(positions_only=True)
        self._changed(values)

    # the mouse on the canvas: a drag is relative to the orbit where the button went down
    def _drag_start(self):
        self._orbit_at_press = (float(self.yaw.value), float(self.pitch.value))

    def _drag_orbit(self, yaw, pitch):
        yaw0, pitch0 = getattr(self, "_orbit_at_press", (0.0, 0.0))
        if self.camera and self.camera.get("mirror"):     # its image is mirrored: the scene
            yaw = -yaw                                    # still turns the way the pointer goes
        self._orbit_to(yaw=(yaw0 + yaw + 180.0) % 360.0 - 180.0, pitch=pitch0 + pitch)

    def _zoom(self, factor):
        self._orbit_to(distance=float(self.distance.value) * factor)

    def _orbit_to(self, yaw=None, pitch=None, distance=None, undo=None):
        """Set the orbit sliders (clamped to their ranges) and move the camera once. A move
        the scene refuses (into smoke) puts the sliders back, and calls ``undo``: they stayed
        at the refused camera, which save() then wrote (a file that does not load)."""
        if self.camera is None:
            return
        sliders = (self.yaw, self.pitch, self.distance)
        old = [w.value for w in sliders]

        def put(values):
            self._syncing = True                 # one camera update, not one per slider
            try:
                for w, v in zip(sliders, values):
                    if v is not None:
                        w.value = min(max(float(v), w.min), w.max)
            finally:
                self._syncing = False

        def move():
            try:
                self._set_camera()
            except Exception:
                put(old)
                if undo is not None:
                    undo()
                raise
        put((yaw, pitch, distance))
        self._guard(move)()

    def _get_camera(self):
        o, t, up = self._camera_now()
        cam = {"origin": o.round(5).tolist(), "target": t.round(5).tolist(), "up": up.round(5).tolist(),
               "fov": round(float(self.fov.value), 4), **({"mirror": True} if self.camera.get("mirror") else {})}
        self.camera_text.value = json.dumps(cam)
        return cam
