"""The Camera tab of :class:`~draaw_mi.widgets.MaterialTuner`: field of view, orbit about the
target (sliders, or the mouse on an :class:`~draaw_mi.widgets.orbit_canvas.OrbitCanvas`), the
camera as JSON, and GO-Draaw camera paths stepped or played.

:class:`CameraPanel` owns the camera as loaded (``camera``: origin, target, up, fov, mirror)
and its widgets; the orbit is always relative to ``camera``, so the sliders and a drag
describe the same camera. It is given the callbacks it uses (see its docstring).
"""
from __future__ import annotations

import json
import numbers

import ipywidgets as W
import numpy as np

from ..errors import DraawError
from ..limits import FOV_RANGE
from ..scene.camera import go_draaw_look_at, look_at_transform, sensor_keys
from ..scene.camera_path import interpolate
from . import tuning

MAX_PATH_FRAMES = 100_000        # frames a camera path of the panel may have


def slider(desc, value, lo, hi, step=0.01):
    """The tuner's float slider: continuous updates, a wide label, three decimals."""
    return W.FloatSlider(value=value, min=lo, max=hi, step=step, description=desc, continuous_update=True,
                         readout_format=".3f", style={"description_width": "120px"},
                         layout=W.Layout(width="380px"))


class CameraPanel:
    """Camera controls for the tuner (see the module docstring).

    ================  ==========================================================================
    Given             Used for
    ================  ==========================================================================
    ``scene``         the loaded scene (its sensor's keys, its camera table)
    ``guard(fn)``     a control's action wrapped so that an error shows in red, not raised
    ``changed(v)``    queue parameter values (``{"sensor.to_world": ...}``) for the preview
    ``check(tw)``     refuse a camera transform (one inside a smoke box)
    ``moved()``       called before a camera move is queued (lights that follow the camera)
    ``syncing``       a context manager in which widget changes apply nothing
    ================  ==========================================================================
    """

    def __init__(self, scene, *, guard, changed, check, moved, syncing):
        self._guard, self._changed, self._check, self._moved, self._syncing = guard, changed, check, moved, syncing
        cam = scene.info.get("camera")
        self.camera = {k: list(map(float, cam[k])) for k in ("origin", "target", "up")} if cam else None
        if cam:
            self.camera["fov"] = float(cam.get("fov", 40.0))
            self.camera["mirror"] = bool(cam.get("mirror", False))     # a GO-Draaw camera's
        # the sensor's x_fov key as the panel finds it (an XML sensor called 'cam': cam.x_fov);
        # a reload keeps the scene's names
        key = sensor_keys(scene)[1]
        fov = float(np.array(scene.params[key]).ravel()[0]) if key else 40.0
        # the range scene files allow, down to the scene's own field of view
        self.fov = slider("FOV (x)", fov, min(1.0, fov), FOV_RANGE[1], 0.5)
        self.fov.disabled = key is None
        self.yaw = slider("orbit yaw °", 0.0, -180.0, 180.0, 1.0)
        self.pitch = slider("orbit pitch °", 0.0, -85.0, 85.0, 1.0)
        self.distance = slider("distance ×", 1.0, 0.2, 3.0, 0.01)
        self.fov.observe(guard(lambda ch: changed({key: float(ch["new"])})), "value")
        for w in (self.yaw, self.pitch, self.distance):
            w.observe(guard(lambda ch: self.set_camera()), "value")
        get = W.Button(description="get camera")
        self.camera_text = W.Textarea(layout=W.Layout(width="380px", height="90px"))
        get.on_click(guard(lambda _b: self.get_camera()))
        # a camera path (GO-Draaw camera_positions.json keyframes), stepped or played
        self.path_file = W.Text(placeholder="camera_positions.json", description="camera path")
        load = W.Button(description="load path")
        load.on_click(guard(lambda _b: self.load_camera_path(self.path_file.value.strip())))
        self.path_frame = W.IntSlider(value=0, min=0, max=0, description="path frame", disabled=True)
        self.path_play = W.Play(value=0, min=0, max=0, interval=100, disabled=True)
        self.links = [W.jslink((self.path_play, "value"), (self.path_frame, "value"))]
        self.path_frame.observe(guard(lambda ch: self._path_step(int(ch["new"]))), "value")
        self._path = None
        self._orbit_at_press = (0.0, 0.0)
        rows = [self.fov] + ([self.yaw, self.pitch, self.distance, get, self.camera_text] if self.camera else [])
        rows += [W.HBox([self.path_file, load]), W.HBox([self.path_play, self.path_frame])]
        self.widget = W.VBox(rows)

    def load_camera_path(self, keys, frames: int = 120):
        """Load keyframes (a GO-Draaw ``camera_positions.json`` file name or a list of
        ``(x, y, z, theta, phi)`` / dicts) and interpolate ``frames`` frames along them (an
        integer in [2, :data:`MAX_PATH_FRAMES`]); the *path frame* slider and its play button
        then move the camera."""
        if isinstance(keys, str):
            if not keys:
                raise DraawError("camera path: no file name given")
            try:
                with open(keys) as fh:
                    keys = json.load(fh)
            except (OSError, json.JSONDecodeError) as e:
                raise DraawError(f"camera path {keys!r}: {e}") from None
        if isinstance(frames, bool) or not isinstance(frames, numbers.Integral) \
                or not 2 <= frames <= MAX_PATH_FRAMES:
            # (frames were passed on as seconds at 1 fps: "duration=0", 2.7 rounded, 1e9
            # allocated 7.5 GiB)
            raise DraawError(f"MaterialTuner.load_camera_path: frames={frames!r}; expected an "
                             f"integer in [2, {MAX_PATH_FRAMES}]")
        path = interpolate(keys, duration=int(frames), fps=1)    # one frame per step: all of them
        self._path = path
        for w in (self.path_frame, self.path_play):
            w.max = len(path) - 1
            w.disabled = False
        self._path_step(int(self.path_frame.value))
        return path

    def _path_step(self, i):
        if self._path is None:
            return
        x, y, z, theta, phi = self._path[min(i, len(self._path) - 1)]
        try:
            o, t, up, mirror = go_draaw_look_at((x, y, z), theta, phi, float(self.fov.value))
        except ValueError as e:
            raise DraawError(f"camera path frame {i}: {e}") from None
        before = self.camera
        self.camera = {"origin": list(map(float, o)), "target": list(map(float, t)),
                       "up": list(map(float, up)), "fov": float(self.fov.value), "mirror": mirror}
        # the orbit is relative to the path's camera (a refused frame keeps the one before)
        self.orbit_to(0.0, 0.0, 1.0, undo=lambda: setattr(self, "camera", before))

    def camera_now(self):
        """``(origin, target, up)`` of the camera as the orbit moved it (None: no camera)."""
        if self.camera is None:
            return None
        return tuning.orbit(self.camera, self.yaw.value, self.pitch.value, self.distance.value)

    def current(self) -> dict | None:
        """The camera as a ``[camera]`` table would say it (None: the scene has none)."""
        if self.camera is None:
            return None
        o, t, up = self.camera_now()
        return {"origin": o, "target": t, "up": up, "fov": float(self.fov.value),
                "mirror": bool(self.camera.get("mirror", False))}

    def set_camera(self):
        """Queue the orbited camera; a camera the scene refuses (in smoke) is refused before
        the lights that follow it move."""
        if self.camera is None:
            raise DraawError("this scene has no [camera] table to orbit")
        o, t, up = self.camera_now()
        values = {"sensor.to_world": look_at_transform(o, t, up, self.camera.get("mirror", False))}
        self._check("camera", values["sensor.to_world"])
        self._moved()
        self._changed(values)

    # the mouse on the canvas: a drag is relative to the orbit where the button went down
    def drag_start(self):
        self._orbit_at_press = (float(self.yaw.value), float(self.pitch.value))

    def drag_orbit(self, yaw, pitch):
        yaw0, pitch0 = self._orbit_at_press
        if self.camera and self.camera.get("mirror"):     # its image is mirrored: the scene
            yaw = -yaw                                    # still turns the way the pointer goes
        self.orbit_to(yaw=(yaw0 + yaw + 180.0) % 360.0 - 180.0, pitch=pitch0 + pitch)

    def zoom(self, factor):
        self.orbit_to(distance=float(self.distance.value) * factor)

    def orbit_to(self, yaw=None, pitch=None, distance=None, undo=None):
        """Set the orbit sliders (clamped to their ranges) and move the camera once. A move
        the scene refuses (into smoke) puts the sliders back and calls ``undo``, so the
        panel and a saved scene keep the camera the preview shows."""
        if self.camera is None:
            return
        sliders = (self.yaw, self.pitch, self.distance)
        old = [w.value for w in sliders]

        def put(values):
            with self._syncing():                 # one camera update, not one per slider
                for w, v in zip(sliders, values):
                    if v is not None:
                        w.value = min(max(float(v), w.min), w.max)

        moved = []

        def move():
            try:
                self.set_camera()
            except Exception:
                put(old)
                if undo is not None:
                    undo()
                raise
            moved.append(True)
        put((yaw, pitch, distance))
        self._guard(move)()
        if not moved:                # refused (a closed or superseded panel): as it was
            put(old)
            if undo is not None:
                undo()

    def get_camera(self):
        """The orbited camera as a ``[camera]`` table, also shown as JSON in the panel."""
        o, t, up = self.camera_now()
        cam = {"origin": o.round(5).tolist(), "target": t.round(5).tolist(), "up": up.round(5).tolist(),
               "fov": round(float(self.fov.value), 4), **({"mirror": True} if self.camera.get("mirror") else {})}
        self.camera_text.value = json.dumps(cam)
        return cam
