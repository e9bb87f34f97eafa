"""``draaw_mi.widgets.MaterialTuner``: tune materials, lights, camera and post chain in Jupyter.

GO-Draaw's web front end as ipywidgets (``pip install 'draaw-mi[notebooks]'``) over
:class:`draaw_mi.rendering.preview.Preview`: every control writes Dr.Jit parameter values (no kernel is
recompiled by a slider), a worker thread renders 1-spp frames and refines them by a running
mean while idle, and frames reach the browser as JPEG while you interact and as PNG once the
image has been at rest for ``rest_after`` seconds. With ``jupyter_rfb`` installed (the
``notebooks`` extra) they go through an :class:`~draaw_mi.widgets.orbit_canvas.OrbitCanvas`: the
browser paces the frames, and dragging on the image orbits the camera, the wheel moves it
nearer or farther, a double-click puts it back (PNG frames at rest at most every
``LOSSLESS_EVERY`` seconds, and the last one; frames are drawn while the kernel is idle);
without it, through an ``ipywidgets.Image``.

Panels: **Materials** (per material: base colour picker and exact linear RGB text field,
sliders for every draaw parameter, base-colour texture and normal-map files), **Render**
(version, max depth, spp budget, resolution scale, OIDN denoise), **Light** (intensity scale,
colour, snap point lights to the camera), **Camera** (FOV, orbit yaw / pitch / distance, get),
**Post** (add, remove, reorder filters, amounts, or the chain as JSON), **Save** (scene TOML,
Python snippet). With ``reference=`` an error line and a false-colour error image follow the
preview. Bad input is shown in red in the panel; no traceback reaches the notebook.

Example (in a notebook)::

    from draaw_mi.widgets import MaterialTuner
    tuner = MaterialTuner("scenes/cornell.toml", reference="ref.exr")
    tuner                                  # shows the panel; tuner.close() stops the worker
"""
from __future__ import annotations

import collections
import contextlib
import hashlib
import json
import os
import threading
import time
import weakref

import numpy as np

from ..errors import DraawError
from ..fitting.reference import load_reference
from ..guard import RENDER_GUARD
from ..rendering.preview import Preview, PreviewSuperseded, _budget, _scale
from ..scene import DraawScene, load_scene
from . import rebuild, tuning
from .tuning import scaled_resolution  # noqa: F401 (public here: the resolution slider's rule)

try:
    import ipywidgets as W
except ImportError as _e:  # pragma: no cover - exercised by a test with the module hidden
    raise DraawError("draaw_mi.widgets needs ipywidgets; install it with: pip install "
                     f"'draaw-mi[notebooks]' ({_e})") from None

from .camera_panel import CameraPanel  # noqa: E402 (the panels need ipywidgets)
from .camera_panel import slider as _slider
from .lights_panel import LightsPanel  # noqa: E402
from .post_panel import PostPanel, close_widgets  # noqa: E402
from .save_panel import SavePanel, _html  # noqa: E402

VERSIONS = ("v1", "v2", "v3", "v4", "path")
LOSSLESS_EVERY = 0.5       # seconds between PNG frames on the canvas while refining at rest


class MaterialTuner:
    """An interactive panel for one scene (see the module docstring).

    =======================  =======================================================================
    Parameter                Meaning
    =======================  =======================================================================
    ``scene``                a DraawScene, a scene file (.toml / .json) or a description dict
    ``reference``            optional reference image (.exr linear, .png sRGB, or an array) of the
                             preview's size: shows RMSE and an error image
    ``version``              integrator version (default: the scene's)
    ``max_spp``              refinement budget (samples per pixel)
    ``denoise``              start with OIDN denoising on (needs ``pyoidn``)
    ``interactive_scale``    resolution of the first frame after a change (default 0.5)
    ``autostart``            start the worker thread now (False: call :meth:`refresh` yourself)
    ``rest_after``           seconds without a change after which frames are sent as PNG
    ``frame_channel``        ``"auto"`` (jupyter_rfb's canvas when installed, else an image
                             widget), ``"rfb"`` or ``"image"``
    =======================  =======================================================================

    The Light, Camera, Post and Save tabs are panel objects (``lights_panel``,
    ``camera_panel``, ``post_panel``, ``save_panel``), each given the state and the callbacks
    it uses; the tuner holds the materials, the render options and the preview.
    """

    def __init__(self, scene, reference=None, *, version: str | None = None, max_spp: int = 256,
                 denoise: bool = False, interactive_scale: float = 0.5, autostart: bool = True,
                 freeze: bool = True, rest_after: float = 0.5, save_path: str | None = None,
                 frame_channel: str = "auto"):
        if frame_channel not in ("auto", "rfb", "image"):
            raise DraawError(f"MaterialTuner: frame_channel={frame_channel!r}; expected 'auto', 'rfb' "
                             "or 'image'")
        self.base_scene = scene if isinstance(scene, DraawScene) else load_scene(scene)
        self.scene = self.base_scene
        self.materials = tuning.material_values(self.scene)
        chain = list(self.scene.settings.get("post", []))
        self.reference = None if reference is None else self._load_reference(reference)
        w, h = self.scene.resolution
        if self.reference is not None and self.reference.shape[:2] != (h, w):
            raise DraawError(f"MaterialTuner: reference of {self.reference.shape[1]}x{self.reference.shape[0]} "
                             f"pixels; expected the scene's {w}x{h} (the error line compares pixels)")
        max_spp = _budget(max_spp, "MaterialTuner")
        for name, flag in (("denoise", denoise), ("freeze", freeze), ("autostart", autostart)):
            if not isinstance(flag, (bool, np.bool_)):     # ("no" would turn denoising on)
                raise DraawError(f"MaterialTuner: {name}={flag!r}; expected True or False")
        if isinstance(rest_after, bool) or not isinstance(rest_after, (int, float)) or not rest_after >= 0:
            raise DraawError(f"MaterialTuner: rest_after={rest_after!r}; expected seconds >= 0")
        self.rest_after = float(rest_after)
        self._options = dict(version=version or self.scene.settings["version"], max_spp=int(max_spp),
                             denoise=bool(denoise), interactive_scale=_scale(interactive_scale, "MaterialTuner"),
                             freeze=bool(freeze), max_depth=None)
        self._last_change = time.perf_counter()
        self._syncing = False
        self._textures: dict = {}
        self.frames_shown = 0
        self._render_failed = False                 # the message line says a frame failed
        self._lossless_at = -float("inf")            # when the canvas last got a PNG
        self.last_format = None
        self.sent = collections.deque(maxlen=256)    # (generation, spp, format) of pushed frames
        self._autostart = autostart
        self._closed = False
        self.preview = self._new_preview(self.scene, chain)
        self._build(save_path, frame_channel, chain)
        if autostart:
            self._take_over_file()
            self.preview.start()

    # ------------------------------------------------------------------ plumbing
    def _take_over_file(self):
        """Stop the running panel of the same scene file, or of a scene description of the
        same content: a notebook cell run again makes a second panel on a second scene, and the
        old one would go on rendering (a sixth of the new one's frame rate) with nothing left to
        close it. Panels on one :class:`~draaw_mi.scene.DraawScene` are handled by
        :meth:`Preview.start`."""
        src = self.base_scene.source
        if os.path.isfile(src):
            key = os.path.realpath(src)
        elif self.base_scene.description is not None:    # a dict: its content is its name
            key = "description:" + hashlib.sha1(json.dumps(
                self.base_scene.description, sort_keys=True,
                default=lambda o: o.tolist() if isinstance(o, np.ndarray) else repr(o)).encode()).hexdigest()
        else:
            return
        with _PANELS_GUARD:
            ref = _PANELS.get(key)
            _PANELS[key] = weakref.ref(self)
        old = None if ref is None else ref()
        if old is not None and old is not self and old.preview.running:
            old.preview._supersede()

    @property
    def post(self) -> list:
        """The post chain (a list of filter tables), as the Post tab has it."""
        return self.post_panel.chain

    @property
    def camera(self) -> dict | None:
        """The camera as loaded, or as a camera path put it (origin, target, up, fov, mirror)."""
        return self.camera_panel.camera

    def document(self, dest: str | None = None) -> dict:
        """The tuned scene as a description dict (:meth:`SavePanel.document`)."""
        return self.save_panel.document(dest)

    def save(self, path: str) -> str:
        """Write the tuned scene to a TOML file (atomically) and return its path."""
        return self.save_panel.save(path)

    def snippet(self) -> str:
        """Python code reproducing the tuned materials."""
        return self.save_panel.snippet()

    def load_camera_path(self, keys, frames: int = 120):
        """Move the camera along GO-Draaw keyframes (:meth:`CameraPanel.load_camera_path`)."""
        self._check_open("load_camera_path")
        if isinstance(self.preview.error, PreviewSuperseded):
            raise DraawError(f"MaterialTuner.load_camera_path: {self.preview.error}; this panel no longer "
                             "changes the scene")
        return self.camera_panel.load_camera_path(keys, frames)

    def _new_preview(self, scene, chain) -> Preview:
        o = self._options
        # (max_depth: the slider's, which a rebuilt XML scene's own depth would replace)
        pv = Preview(scene, version=o["version"], max_depth=o["max_depth"], max_spp=o["max_spp"],
                     denoise=o["denoise"], post=chain, interactive_scale=o["interactive_scale"],
                     freeze=o["freeze"])
        pv.on_frame(self._current_only(pv, self._show))
        pv.on_error(self._current_only(pv, self._show_error))
        return pv

    def _current_only(self, pv, fn):
        """``fn`` as ``pv``'s callback: called while ``pv`` is the panel's preview only (an
        error of the preview a reload replaced would otherwise stay in red next to the new
        one's frames). ``pv`` held weakly: a replaced preview is freed, with its scene, when
        the panel drops it."""
        ref = weakref.ref(pv)
        return lambda arg: fn(arg) if self.preview is ref() else None

    def _guard(self, fn):
        """Run a control's action; a DraawError / bad value becomes a red message, not a traceback."""
        def run(*args):
            if self._syncing:
                return
            # a refused change is put back on its control (else save() and document(), which
            # read the controls, would write what the preview never showed)
            if self._closed:            # (its preview has no scene to change)
                self.message.value = _error_html(_closed_text("MaterialTuner"))
                with self._quiet():
                    _revert(args)
                return
            if isinstance(self.preview.error, PreviewSuperseded):
                # (a change here would go into the scene the newer panel shows, unrendered here,
                # and clear this panel's only word of why it has stopped)
                self.message.value = _error_html(f"{self.preview.error}; this panel no longer "
                                                 "changes the scene")
                with self._quiet():
                    _revert(args)
                return
            self.message.value = ""
            try:
                fn(*args)
            except (DraawError, ValueError, OSError, KeyError, TypeError) as e:
                self.message.value = _error_html(f"error: {e}")
                with self._quiet():
                    _revert(args)
        return run

    @contextlib.contextmanager
    def _quiet(self):
        """Widget changes inside apply nothing (controls set to keep them in step)."""
        was, self._syncing = self._syncing, True
        try:
            yield
        finally:
            self._syncing = was

    def _say(self, html: str) -> None:
        self.message.value = html

    def _check_open(self, who: str) -> None:
        if self._closed:
            raise DraawError(_closed_text(f"MaterialTuner.{who}"))

    def _changed(self, values: dict):
        self._check_open("update")
        self._last_change = time.perf_counter()
        self.preview.update(values)

    def _show(self, frame):
        """Worker-thread callback: encode and push the frame (JPEG while interacting)."""
        at_rest = (time.perf_counter() - self._last_change) > self.rest_after or frame.spp >= self.preview.max_spp
        fmt = "png" if at_rest and not frame.interactive else "jpeg"
        if self.canvas is not None:
            # jupyter_rfb encodes on the kernel's loop, ahead of the widgets' messages: a PNG of
            # every refinement frame would hold it (26 ms at 512²), so at most one per
            # LOSSLESS_EVERY seconds and the last one (budget reached)
            now = time.perf_counter()
            if fmt == "png" and frame.spp < self.preview.max_spp and now - self._lossless_at < LOSSLESS_EVERY:
                fmt = "jpeg"
            if fmt == "png":
                self._lossless_at = now
            self.canvas.push(tuning.to_uint8(frame.image, frame.encoded), lossless=fmt == "png")
        else:
            data = tuning.encode(frame.image, fmt, encoded=frame.encoded)
            self.image.format = fmt
            self.image.value = data
        if self._render_failed:            # a frame of a later change: the failure is past
            self._render_failed = False
            self.message.value = ""
        self.frames_shown += 1
        self.last_format = fmt
        self.last_frame = frame
        self.sent.append((frame.generation, frame.spp, fmt))
        text = (f"{frame.spp} spp · {frame.render_s * 1e3:.0f} ms/frame · {self.preview.version}"
                f"{' · denoised (biased)' if frame.denoised else ''}{' · preview' if frame.interactive else ''} · {fmt}")
        # against the (linear) reference: the linear mean when a chain's srgb encoded the image
        linear = frame.raw if frame.encoded else frame.image
        if self.reference is not None and linear.shape == self.reference.shape:
            e = tuning.errors(linear, self.reference)
            self.error_label.value = f"vs reference: RMSE {e['rmse']:.4f} · display RMSE {e['display_rmse']:.4f}"
            self.error_image.value = tuning.encode(tuning.error_image(linear, self.reference), "png")
        elif self.reference is not None:    # (else the last frame's numbers stay, stale)
            rh, rw = self.reference.shape[:2]
            self.error_label.value = (f"vs reference: none (the reference is {rw}x{rh}, this frame "
                                      f"{linear.shape[1]}x{linear.shape[0]}: resolution scale 1 compares)")
        self.status.value = text

    def _show_error(self, error):
        """Worker-thread callback: a frame failed; say so in red (the preview waits for the
        next change, and the panel still shows its last frame)."""
        if isinstance(error, PreviewSuperseded):        # another panel of this scene started
            self.message.value = _error_html(f"{error}")
            self.status.value = "stopped"
            return
        self.message.value = _error_html(f"render failed: {tuning.innermost_error(error)}; change a value to try again")
        self.status.value = "render failed"
        self._render_failed = True

    def refresh(self, frames: int = 1):
        """Render ``frames`` frames now in this thread (for scripts/tests without the worker)."""
        self._check_open("refresh")
        out = None
        for _ in range(frames):
            out = self.preview.step() or out
        return out

    def close(self):
        """Stop the worker thread, close every widget of the panel (:func:`close_widgets`) and
        let go of the scenes (:meth:`Preview.close`): the panel's draaw BSDFs are freed now,
        under :data:`~draaw_mi.guard.RENDER_GUARD` (each live one widens every later render's
        BSDF calls, and one freed by a later garbage collection beside another thread's render
        kills the process). A closed panel renders and changes nothing more (its controls say
        so in red; :meth:`refresh` and :meth:`load_camera_path` raise a DraawError), but
        :meth:`document`, :meth:`save` and :meth:`snippet` still give the panel's values as
        they were at close (:class:`~draaw_mi.widgets.save_panel.ClosedScene`)."""
        self._closed = True
        self.preview.close()
        self.save_panel.close()           # (keeps what saving needs; before the guard: lock order)
        panels = (self.camera_panel, self.lights_panel, self.post_panel, self.save_panel)
        close_widgets(self.widget, *self.camera_panel.links, *vars(self).values(),
                      *(w for panel in panels for w in vars(panel).values()),
                      getattr(self.canvas, "_output_context", None))   # jupyter_rfb's error output
        with RENDER_GUARD:
            self.scene = self.base_scene = None

    def _ipython_display_(self):
        from IPython.display import display  # optional: only in a notebook
        display(self.widget)

    @staticmethod
    def _load_reference(ref):
        return np.asarray(load_reference(ref, who="MaterialTuner"), np.float32)[..., :3]

    # ------------------------------------------------------------------ panels
    def _build(self, save_path, frame_channel, chain):
        self.message = W.HTML("")
        self.lights_panel = LightsPanel(self.base_scene, guard=self._guard, changed=self._changed,
                                        camera_now=lambda: self.camera_panel.camera_now())
        self.camera_panel = CameraPanel(
            self.base_scene, guard=self._guard, changed=self._changed, syncing=self._quiet,
            check=lambda name, to_world: self.preview.check_camera_outside_smoke(name, to_world),
            moved=self.lights_panel.follow_camera)
        self.post_panel = PostPanel(chain, guard=self._guard, configure=self._configure, syncing=self._quiet)
        self.save_panel = SavePanel(
            self.base_scene, scene=lambda: self.scene, materials=self.materials, textures=self._textures,
            chain=lambda: self.post_panel.chain, camera=self.camera_panel.current, lights=self.lights_panel,
            render=lambda: {"version": self.preview.version, "max_depth": int(self.preview.max_depth)},
            guard=self._guard, say=self._say, save_path=save_path)
        self.canvas = self.image = None
        if frame_channel in ("auto", "rfb"):
            try:
                from .orbit_canvas import OrbitCanvas  # optional: it needs jupyter_rfb
            except DraawError:
                if frame_channel == "rfb":
                    raise
            else:
                cam = self.camera_panel
                mouse = {} if self.camera is None else dict(   # without [camera]: no orbit
                    on_orbit=cam.drag_orbit, on_drag_start=cam.drag_start, on_zoom=cam.zoom,
                    on_reset=lambda: cam.orbit_to(0.0, 0.0, 1.0))
                self.canvas = OrbitCanvas(self.base_scene.resolution, **mouse)
        if self.canvas is None:
            self.image = W.Image(format="jpeg", layout=W.Layout(border="1px solid #ccc"))
        self.status = W.HTML("")
        self.error_label = W.HTML("")
        self.error_image = W.Image(format="png")
        tabs = [("Materials", self._materials_panel()), ("Render", self._render_panel()),
                ("Light", self.lights_panel.widget), ("Camera", self.camera_panel.widget),
                ("Post", self.post_panel.widget), ("Save", self.save_panel.widget)]
        self.tabs = W.Tab(children=[t[1] for t in tabs])
        for i, (name, _) in enumerate(tabs):
            self.tabs.set_title(i, name)
        left = W.VBox([self.canvas if self.canvas is not None else self.image, self.status, self.message] +
                      ([self.error_label, self.error_image] if self.reference is not None else []))
        self.widget = W.HBox([left, self.tabs])

    def _materials_panel(self):
        self.controls: dict = {}
        boxes, titles = [], []
        for m, vals in self.materials.items():
            rows, ctl = [], {}
            if "base_color" in vals:
                ctl["base_color"] = picker = W.ColorPicker(value=tuning.linear_to_hex(vals["base_color"]),
                                                            description="base colour", concise=False)
                ctl["base_color_text"] = text = W.Text(value=", ".join(f"{x:.4g}" for x in vals["base_color"]),
                                                       description="linear RGB", continuous_update=False)
                picker.observe(self._guard(lambda ch, m=m: self._set_color(m, tuning.hex_to_linear(ch["new"]))), "value")
                text.observe(self._guard(lambda ch, m=m: self._set_color(
                    m, tuning.parse_rgb(ch["new"], f"{m}.base_color"))), "value")
                rows += [picker, text]
            for p, (_, lo, hi) in tuning.SCALAR_PARAMS.items():
                if p in vals:
                    ctl[p] = s = _slider(p.replace("_", " "), vals[p], lo, hi)
                    s.observe(self._guard(lambda ch, m=m, p=p: self._set(m, p, float(ch["new"]))), "value")
                    rows.append(s)
            ctl["texture"] = W.Text(placeholder="image file for base_color", description="texture")
            ctl["normalmap"] = W.Text(placeholder="normal-map image file", description="normal map")
            apply = W.Button(description="load files", tooltip="reloads the scene with these textures")
            apply.on_click(self._guard(lambda _b, m=m: self._apply_textures(m)))
            rows += [ctl["texture"], ctl["normalmap"], apply]
            self.controls[m] = ctl
            boxes.append(W.VBox(rows))
            titles.append(m)
        acc = W.Accordion(children=boxes)
        for i, t in enumerate(titles):
            acc.set_title(i, t)
        if boxes:
            acc.selected_index = 0
        return acc

    def _set(self, m, p, value):
        self._changed({f"{m}.{p}": value})
        self.materials[m][p] = value

    def _set_color(self, m, rgb):
        self._changed({f"{m}.base_color": rgb})
        self.materials[m]["base_color"] = [float(x) for x in rgb]
        with self._quiet():                    # the picker and the text field in step
            self.controls[m]["base_color"].value = tuning.linear_to_hex(rgb)
            self.controls[m]["base_color_text"].value = ", ".join(f"{x:.4g}" for x in rgb)

    def _apply_textures(self, m):
        rebuild.apply_textures(self, m)

    def _reload(self, scale: float | None = None):
        """Rebuild the scene (:func:`~draaw_mi.widgets.rebuild.reload`)."""
        rebuild.reload(self, scale)

    def _render_panel(self):
        o = self._options
        c = self.controls_render = {
            "version": W.Dropdown(options=VERSIONS if o["version"] in VERSIONS else VERSIONS + (o["version"],),
                                  value=o["version"],
                                  description="version"),
            # -1: unbounded (Mitsuba's convention), 0: nothing is seen; a scene's 40 stays 40
            "max_depth": W.IntSlider(value=self.preview.max_depth, min=-1, max=max(16, self.preview.max_depth),
                                     description="max depth", tooltip="-1: no limit"),
            "max_spp": W.BoundedIntText(value=o["max_spp"], min=1, max=max(1 << 16, int(o["max_spp"])), description="spp budget"),
            "scale": W.FloatSlider(value=1.0, min=0.25, max=1.0, step=0.25, description="resolution",
                                   continuous_update=False),
            "denoise": W.Checkbox(value=o["denoise"], description="OIDN denoise (biased)"),
        }
        c["version"].observe(self._guard(lambda ch: self._configure(version=ch["new"])), "value")
        c["max_depth"].observe(self._guard(lambda ch: self._configure(max_depth=int(ch["new"]))), "value")
        c["max_spp"].observe(self._guard(lambda ch: self._configure(max_spp=int(ch["new"]))), "value")
        c["denoise"].observe(self._guard(lambda ch: self._configure(denoise=bool(ch["new"]))), "value")
        c["scale"].observe(self._guard(lambda ch: self._reload(ch["new"])), "value")
        return W.VBox(list(c.values()))

    def _configure(self, **kw):
        self._check_open("configure")
        self._last_change = time.perf_counter()
        self.preview.configure(**kw)
        self._options.update({k: v for k, v in kw.items() if k in self._options})

#: the newest running panel of each scene file (MaterialTuner._take_over_file)
_PANELS: dict = {}
_PANELS_GUARD = threading.Lock()


def _revert(args) -> None:
    """Put a refused change's control back to the value it had (else a dropdown set to a
    version the scene cannot render shows that version while the preview keeps the old one). Text
    fields keep what was typed, to be corrected."""
    change = args[0] if len(args) == 1 and isinstance(args[0], dict) else None
    owner = change.get("owner") if change else None
    if owner is None or "old" not in change or isinstance(owner, (W.Text, W.Textarea)):
        return
    owner.value = change["old"]        # (the tuner's _syncing is set: nothing is applied again)


def _closed_text(who: str) -> str:
    return (f"{who}: this panel was closed (MaterialTuner.close); open a new MaterialTuner to "
            "change or render the scene (document(), save() and snippet() still work)")


def _error_html(text: str) -> str:
    """``text`` as the panel's red error line (escaped)."""
    return f"<span style='color:#b00020'>{_html(text)}</span>"


__all__ = ["MaterialTuner"]
