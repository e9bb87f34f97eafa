"""``OrbitCanvas``: preview frames through ``jupyter_rfb``, and the mouse on the image.

A :class:`jupyter_rfb.RemoteFrameBuffer` (``pip install 'draaw-mi[notebooks]'``) that the
:class:`~draaw_mi.widgets.MaterialTuner` shows in place of an ``ipywidgets.Image`` when
``jupyter_rfb`` is installed. What it adds over the image widget:

* **back-pressure**: frames go out only while the browser has acknowledged all but
  ``max_buffered_frames`` of the earlier ones, so a slow connection gets fewer frames, never
  a growing queue (the latest frame always wins);
* **direct manipulation**: drag with the left button to orbit the camera, use the wheel to
  move it nearer or farther, double-click to go back to where it started; the callbacks
  receive the drag in degrees and the wheel as a distance factor;
* JPEG while frames change (``quality``), a lossless PNG once they are at rest (``push(...,
  lossless=True)``, and jupyter_rfb's own PNG redraw 0.3 s after the last JPEG).

Frames may be pushed from any thread (the preview's worker thread does): the draw is
scheduled on the event loop the canvas was created on, because jupyter_rfb sends only from
that loop. So frames reach the browser while the kernel is idle: a cell that drives the
tuner shows its last frame when it ends (``frame_channel="image"`` shows them as they come).

Example (in a notebook)::

    from draaw_mi.widgets.orbit_canvas import OrbitCanvas
    canvas = OrbitCanvas((256, 256), on_orbit=lambda yaw, pitch: print(yaw, pitch))
    canvas.push(image_uint8)          # (256, 256, 3) uint8; shows it
    canvas                            # drag on it: prints degrees
"""
from __future__ import annotations

import asyncio
import contextlib
import io
import math
import threading
from typing import Callable

import numpy as np

from ..errors import DraawError, ParameterError


def _in_notebook() -> bool:
    """Whether an IPython kernel (Jupyter) runs this process."""
    try:
        from IPython import get_ipython  # (optional: present in a notebook)
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and getattr(shell, "kernel", None) is not None


try:
    from jupyter_rfb import RemoteFrameBuffer
except ImportError as _e:  # pragma: no cover - exercised by a test with the module hidden
    raise DraawError("draaw_mi.widgets.orbit_canvas needs jupyter_rfb; install it with: pip install "
                     f"'draaw-mi[notebooks]' ({_e})") from None

#: degrees of orbit per drag across the whole width of the canvas
DEGREES_PER_WIDTH = 180.0
#: smaller frames are shown enlarged by a whole factor to about this many CSS pixels
MIN_DISPLAY = 256
#: distance factor per wheel pixel (a notch is about 100 px: a factor of 1.22)
WHEEL_RATE = 0.002
WHEEL_EXP_MAX = 50.0          # a wheel step zooms by at most e^50 (the zoom clamps anyway)


class OrbitCanvas(RemoteFrameBuffer):
    """A frame buffer for an image of ``size`` = (width, height) pixels (see the module
    docstring).

    ==================  =======================================================================
    Parameter           Meaning
    ==================  =======================================================================
    ``size``            (width, height) of the frames in pixels: the canvas's CSS size
                        (enlarged by a whole factor below ``MIN_DISPLAY``)
    ``on_orbit``        ``f(yaw_deg, pitch_deg)``: a drag, relative to where it started
                        (dragging right turns the scene right, dragging down shows more of
                        its top); called on every move with the left button held and at the
                        release; ``None``: no dragging (the cursor stays the default)
    ``on_drag_start``   ``f()``: the left button went down (remember the camera there)
    ``on_zoom``         ``f(factor)``: the wheel; > 1 is farther (scrolling down)
    ``on_reset``        ``f()``: a double-click
    ``quality``         JPEG quality of frames that are not lossless (1..99)
    ==================  =======================================================================

    >>> c = OrbitCanvas((4, 2))                         # doctest: +SKIP
    >>> c.push(np.zeros((2, 4, 3), np.uint8)); c.get_frame().shape   # doctest: +SKIP
    (2, 4, 3)
    """
    def __init__(self, size, *, on_orbit: Callable | None = None, on_drag_start: Callable | None = None,
                 on_zoom: Callable | None = None, on_reset: Callable | None = None, quality: int = 80):
        problem = None
        try:                                     # ('x', a 3-tuple, None, inf, "12": named below)
            w, h = (0, 0) if isinstance(size, (str, bytes)) else (int(v) for v in size)
        except (TypeError, ValueError, OverflowError):
            w = h = 0
        try:
            q = int(quality)
        except (TypeError, ValueError, OverflowError):
            q = 0
        if w < 1 or h < 1:
            problem = f"OrbitCanvas: size={size!r}; expected (width, height), two integers >= 1"
        elif isinstance(quality, bool) or not 1 <= q <= 99:
            problem = (f"OrbitCanvas: quality={quality!r}; expected 1..99 (lossless frames are asked "
                       "for with push(..., lossless=True))")
        # the widget is made before the check can fail: a half-made one breaks in __del__;
        # small previews are shown enlarged by a whole factor, to about MIN_DISPLAY pixels
        k = max(1, MIN_DISPLAY // max(w, h, 1))
        # jupyter_rfb displays an output context while it is made; outside a notebook that
        # display is a print ("RFBOutputContext()" in a script's output): keep it quiet there
        quiet = contextlib.nullcontext() if _in_notebook() else contextlib.redirect_stdout(io.StringIO())
        with quiet:
            super().__init__(css_width=f"{max(w, 1) * k}px", css_height=f"{max(h, 1) * k}px",
                             resizable=True, cursor="grab" if on_orbit else "default",
                             quality=min(max(q, 1), 99))
        if problem:
            self.close()
            raise ParameterError(problem)
        self.size = (w, h)
        self.jpeg_quality = q
        self.on_orbit, self.on_drag_start, self.on_zoom, self.on_reset = on_orbit, on_drag_start, on_zoom, on_reset
        self.frames_pushed = 0
        self._lock = threading.Lock()
        self._frame: np.ndarray | None = None
        self._lossless = False
        self._drag: tuple[float, float] | None = None     # where the left button went down
        self._view_width = float(w * k)                   # CSS width, updated by resize events
        # the loop of the notebook's kernel: running while a cell makes the canvas; else
        # the browser's first event (a resize, which arrives on that loop) supplies it
        self._loop: asyncio.AbstractEventLoop | None = _running_loop()

    # ------------------------------------------------------------------ frames
    def push(self, image: np.ndarray, lossless: bool = False) -> None:
        """Show ``image`` ((H, W, 3) uint8, sRGB) next; from any thread. Only the latest
        pushed frame is kept: one the browser has not asked for yet is replaced."""
        a = np.asarray(image)
        if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] not in (3, 4):
            raise ParameterError(f"OrbitCanvas.push: image of dtype {a.dtype} and shape {a.shape}; "
                                 "expected (H, W, 3) uint8")
        with self._lock:
            self._frame, self._lossless = a, bool(lossless)
            self.frames_pushed += 1
        loop = self._loop
        if loop is not None and not loop.is_closed():
            # jupyter_rfb schedules its draws on the running loop of the calling thread: from
            # the worker thread there is none, and the frame would never be sent
            loop.call_soon_threadsafe(self.request_draw)

    def get_frame(self):
        """jupyter_rfb's draw: the latest frame (JPEG, or PNG when it was pushed lossless)."""
        with self._lock:
            frame, lossless = self._frame, self._lossless
        self.quality = 100 if lossless else self.jpeg_quality
        return frame

    # ------------------------------------------------------------------ events
    def handle_event(self, event: dict) -> None:
        """Map jupyter_rfb's pointer, wheel and resize events onto the callbacks."""
        kind = event.get("type") or event.get("event_type")
        if self._loop is None:               # made off the loop: frames can be drawn from now on
            self._loop = _running_loop()
            if self._loop is not None and self._frame is not None:
                self.request_draw()
        if kind == "resize":
            self._view_width = max(float(event.get("width", self._view_width)), 1.0)
        elif kind == "pointer_down" and event.get("button") == 1 and self.on_orbit:
            self._drag = (float(event["x"]), float(event["y"]))
            self.cursor = "grabbing"
            if self.on_drag_start:
                self.on_drag_start()
        elif kind == "pointer_move" and self._drag is not None:
            if 1 not in tuple(event.get("buttons", ())):
                # not "released": the browser's throttled move from before the press can
                # arrive after it (seen in Chromium); the drag ends with pointer_up only
                return
            self._orbit(event)
        elif kind == "pointer_up" and event.get("button") == 1 and self._drag is not None:
            # the browser holds the last move back (20 ms) but sends the release at once:
            # the release's position is where the drag ends
            self._orbit(event)
            self._end_drag()
        elif kind == "wheel" and self.on_zoom:
            dy = float(event.get("dy", 0.0))
            if dy and math.isfinite(dy):        # (exp of a step of 1e6 overflowed)
                self.on_zoom(math.exp(min(max(WHEEL_RATE * dy, -WHEEL_EXP_MAX), WHEEL_EXP_MAX)))
        elif kind == "double_click" and self.on_reset:
            self.on_reset()

    def _orbit(self, event):
        scale = DEGREES_PER_WIDTH / self._view_width
        self.on_orbit(-(float(event["x"]) - self._drag[0]) * scale,
                      (float(event["y"]) - self._drag[1]) * scale)

    def _end_drag(self):
        self._drag = None
        self.cursor = "grab"


def _running_loop():
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None
