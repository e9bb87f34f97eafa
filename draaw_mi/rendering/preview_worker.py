"""The worker thread of a :class:`~draaw_mi.rendering.preview.Preview`: start, stop, wait, callbacks,
and the rule that one worker renders a scene at a time.

:class:`PreviewWorker` is a mixin: the :class:`~draaw_mi.rendering.preview.Preview` it is part of holds
the state it reads (``scene``, ``max_spp``; ``_lock`` with its condition ``_wake``, guarding
``_generation``, ``_shown_generation``, ``_pending``, ``_spp``, ``_delivered``, ``error`` and the
callback lists; the ``_stop`` event and ``_thread``) and renders a frame in ``step()``.
"""
from __future__ import annotations

import threading
import time
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import DraawError
from .session import session_of

_STARTS = threading.RLock()           # one preview start at a time: see PreviewWorker.start


@dataclass
class PreviewFrame:
    """One published preview image and what it holds."""
    image: np.ndarray          # (H, W, 3) float32, denoised / post-processed as asked; linear
                               # unless ``encoded``
    raw: np.ndarray            # (H, W, 3) the running mean itself (no denoise, no post)
    spp: int                   # samples per pixel in the mean (0 for an interactive frame)
    generation: int            # parameter generation the frame shows
    interactive: bool          # a reduced-resolution first frame after a change
    denoised: bool
    render_s: float            # seconds spent rendering this frame
    t_ready: float             # time.perf_counter() when it became available
    encoded: bool = False      # image is display-encoded (post.display_encoded of its chain)


class PreviewSuperseded(DraawError):
    """A preview's worker was stopped because another preview of its scene started."""


class PreviewWorker:
    """Runs ``step()`` on a daemon thread until ``max_spp``, then sleeps until the next change."""
    def on_frame(self, callback):
        """Call ``callback(frame)`` (from the worker thread) for every published frame."""
        with self._lock:
            self._callbacks.append(callback)

    def on_error(self, callback):
        """Call ``callback(exception)`` (from the worker thread) when a frame fails; the
        worker then waits for the next change (``error`` holds the exception until then)."""
        with self._lock:
            self._error_callbacks.append(callback)

    def start(self):
        """Start the worker thread (idempotent). One worker renders a scene at a time: a
        running preview of the same :class:`~draaw_mi.scene.DraawScene` (a notebook cell run
        again makes a new panel; left running, the old one would go on refining, fight the new
        one for the scene's lock and render its parameter changes without restarting its mean) is
        stopped, and its error callbacks get :class:`PreviewSuperseded`. The worker is the
        scene session's (:meth:`~draaw_mi.rendering.session.Session.add_worker`): closing the
        session, or the interpreter's exit, stops it."""
        if self.scene is None:
            raise DraawError("Preview.start: this preview was closed (Preview.close); make a new one")
        with _STARTS:                 # (two starts at once would each leave the other running)
            session = session_of(self.scene)
            for other in session.workers():
                if other is not self and other.running:
                    other._supersede()
            session.add_worker(self)
        if self._thread is not None and self._thread.is_alive():
            self._stop.clear()        # a worker that did not stop in time goes on: not a second
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="draaw-mi-preview", daemon=True)
        self._thread.start()

    def _supersede(self):
        """Stop: another preview of this scene started (see :meth:`start`)."""
        # (what takes the scene back: a new panel; start() again would render here while the
        # panel's controls, which may disagree with the scene the newer panel changed, stay off)
        self.stop(why="stopped: a newer preview of this scene is running (run this panel's cell "
                      "again to take the scene back)")

    _failed_generation = -1            # the generation whose frame failed: idle until a change

    def _idle(self) -> bool:
        done = self._spp >= self.max_spp or self._failed_generation == self._generation
        return done and not self._pending and self._shown_generation == self._generation

    def _run(self):
        while not self._stop.is_set():
            with self._lock:
                while self._idle() and not self._stop.is_set():
                    self._wake.wait(0.5)
            if self._stop.is_set():
                break
            with self._lock:
                generation = self._generation
            try:
                self.step()
            except Exception as e:  # noqa: BLE001 - shown by the UI; the thread waits for a change
                with self._lock:
                    if generation != self._generation:
                        continue          # changed meanwhile: the next frame tries the new values
                    self.error = e
                    self._failed_generation = generation    # idle until the next change
                    self._shown_generation = generation
                    self._wake.notify_all()
                    callbacks = list(self._error_callbacks)
                for cb in callbacks:
                    try:
                        cb(e)
                    except Exception as cb_error:  # noqa: BLE001 - the worker waits on, for the next change
                        warnings.warn(f"Preview: an on_error callback raised {cb_error!r} (for the "
                                      f"frame's {e!r}); the preview goes on", RuntimeWarning, stacklevel=1)

    def stop(self, timeout: float = 10.0, why: str | None = None):
        """Ask the worker to stop after its current frame and wait for it (at most
        ``timeout`` seconds). ``why``: a running worker's error callbacks get it as a
        :class:`PreviewSuperseded` (a panel then says why it stopped, and takes no more
        changes); nothing is said for a worker that was not running."""
        was_running = self.running
        self._stop.set()
        with self._lock:
            self._wake.notify_all()
        if self._thread is not None and self._thread is not threading.current_thread():
            # (called by a frame callback, on the worker itself: it stops after this frame)
            self._thread.join(timeout)
            if not self._thread.is_alive():       # (a worker still in its frame stays known:
                self._thread = None               # start() must not run a second one)
        if why is None or not was_running:
            return
        error = PreviewSuperseded(why)
        with self._lock:
            self.error = error
            callbacks = list(self._error_callbacks)
        for cb in callbacks:
            try:
                cb(error)
            except Exception:  # noqa: BLE001 - a panel gone (a closed comm) must not stop the others
                pass

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def wait(self, generation: int | None = None, spp: int = 0, timeout: float = 30.0) -> PreviewFrame | None:
        """Block until a frame of ``generation`` (default: the latest) with at least ``spp``
        samples (0: any frame, interactive included) is published and its :meth:`on_frame`
        callbacks have run (a panel shows it); ``None`` on timeout."""
        deadline = time.perf_counter() + timeout
        with self._lock:
            g = self._generation if generation is None else generation
            while True:
                f = self._delivered
                if f is not None and f.generation >= g and f.spp >= spp:
                    return f
                if self.error is not None and self._shown_generation >= g:
                    return None
                left = deadline - time.perf_counter()
                if left <= 0:
                    return None
                self._wake.wait(min(left, 0.5))
