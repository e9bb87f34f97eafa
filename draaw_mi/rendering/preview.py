"""Progressive previews: 1-spp frames, a running mean while idle, reset on every change.

:class:`Preview` is the render engine behind :class:`draaw_mi.widgets.MaterialTuner`, usable on
its own (a script, a custom UI, the latency benchmark). Its phases, per frame:

1. **Apply changes.** Pending parameter values (``{"material.parameter": value}``, camera,
   lights) are written with ``params.update()`` under the scene's render lock. Values live in
   Dr.Jit arrays, so a slider move never recompiles a kernel; the seed is an opaque
   ``mi.UInt32`` for the same reason.
2. **Render one sample per pixel**, through a ``dr.freeze``-recorded function (replays the
   recorded kernels without re-tracing the Python integrator: 1-spp 256² V4 frames in
   0.66x the time of traced ones on a shared 2-core machine, 120 -> 80 ms and 322 -> 212 ms
   in two runs, see ``benchmarks/results/preview_latency.md``;
   ``freeze=False`` turns it off). The first frame after a change can be rendered at a
   reduced ``interactive_scale`` (a second, private copy of the scene; its parameters are kept
   in step) and shown upscaled; it is never mixed into the mean.
3. **Accumulate** full-resolution frames into a running mean (colour and the guide AOVs).
4. **Publish** a :class:`PreviewFrame`: optionally denoised with Intel OIDN guided by the mean
   albedo and normal (biased; :func:`draaw_mi.denoise`; OIDN costs about as much as a
   1-spp frame, so denoised refinement frames are published at most every
   ``denoise_interval`` = 0.25 s), then the post chain.

A worker thread (:meth:`Preview.start`) repeats this until ``max_spp`` and sleeps until the
next change; a frame whose parameters went stale while it rendered is dropped (cancellation
at frame granularity: a running kernel cannot be interrupted). :meth:`Preview.stop` ends it.

Example::

    >>> import draaw_mi
    >>> from draaw_mi.rendering.preview import Preview
    >>> scene = draaw_mi.load_scene({"render": {"resolution": [16, 16], "filter": "box"},
    ...     "materials": {"m": {"roughness": 0.5}}, "shapes": [{"type": "sphere", "material": "m"}],
    ...     "lights": [{"type": "constant"}], "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
    >>> pv = Preview(scene, version="v4", max_depth=3, freeze=False)
    >>> pv.step().spp
    1
    >>> pv.step().spp
    2
    >>> generation = pv.update({"m.roughness": 0.2})
    >>> pv.step().spp                                       # the mean restarted
    1
"""
from __future__ import annotations

import numbers
import operator
import threading
import time
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import post as _post
from ..errors import DraawError, ParameterError, suggest
from ..guard import RENDER_GUARD
from ..integrators import SCENE_VERSION, is_draaw, resolve_version
from ..post import load_chain
from ..scene import DraawScene, check_like, load_scene, value_like
from ..scene.camera import sensor_reach
from ..scene.schema import Where
from ..scene.smoke_boxes import check_camera_outside_smoke
from .denoiser import denoise, load_pyoidn
from .passes import pass_seed
from .preview_worker import PreviewFrame, PreviewSuperseded, PreviewWorker  # noqa: F401  (re-exported)
from .session import holding, session_of

GUIDES = ("albedo", "normal")


def _budget(value, where: str) -> int:
    """A refinement budget: an integer number of samples per pixel >= 1."""
    try:
        n = operator.index(value)
    except TypeError:
        n = None
    if n is None or isinstance(value, bool) or n < 1:
        raise ParameterError(f"{where}: max_spp={value!r}; expected an integer >= 1")
    return int(n)


def _depth(value, where: str) -> int:
    """A path depth: an integer >= -1 (-1: unbounded; 0 renders nothing, as in Mitsuba)."""
    try:
        n = operator.index(value)
    except TypeError:
        n = None
    if n is None or isinstance(value, bool) or n < -1:
        raise ParameterError(f"{where}: max_depth={value!r}; expected an integer >= -1")
    return int(n)


def _chain(value, where: str):
    """A post chain as given, once it is known to load (an unknown filter fails here, not at
    the first frame on the render thread)."""
    try:
        load_chain(value)
    except DraawError as e:
        raise ParameterError(f"{where}: {e}") from None
    return value


def _scale(value, where: str) -> float:
    """The interactive frame's resolution factor: a number in (0, 1]."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and 0.0 < value <= 1.0
    if not ok:
        raise ParameterError(f"{where}: interactive_scale={value!r}; expected a number in (0, 1]")
    return float(value)


def _check_rigid(name: str, to_world) -> None:
    """Refuse a camera transform that scales or shears (Mitsuba's perspective camera refuses it
    when the frame renders, on the worker thread, with the frame's other values)."""
    m = np.array(to_world.matrix if hasattr(to_world, "matrix") else to_world, dtype=np.float64)
    r = m.reshape(4, 4)[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-3):
        raise ParameterError(f"Preview.update: {name}: a camera transform with scale or shear "
                             f"(singular values {np.round(np.linalg.svd(r, compute_uv=False), 4).tolist()}); "
                             "expected a rigid transform (rotation and translation)")


class Preview(PreviewWorker):
    """Progressive running-mean renderer of one scene (see the module docstring).

    =======================  ========================================================================
    Parameter                Meaning
    =======================  ========================================================================
    ``scene``                a :class:`~draaw_mi.scene.DraawScene` (or anything ``load_scene`` takes)
    ``version``              integrator version (default: the scene's)
    ``max_depth``            path depth (default: the scene's)
    ``max_spp``              stop refining at this many samples per pixel (default 1024)
    ``denoise``              denoise published frames with OIDN (needs ``pyoidn``; biased)
    ``post``                 post chain for published frames (default: the scene's; ``[]``: none)
    ``interactive_scale``    resolution factor of the first frame after a change (1: full)
    ``freeze``               record the 1-spp render with ``dr.freeze`` and replay it
    ``seed``                 base seed; frame ``i`` uses an independent seed derived from it
    =======================  ========================================================================
    """
    def __init__(self, scene, version: str | None = None, max_depth: int | None = None,
                 max_spp: int = 1024, denoise: bool = False, post=None, interactive_scale: float = 1.0,
                 freeze: bool = True, seed: int = 0):
        self.scene = scene if isinstance(scene, DraawScene) else load_scene(scene)
        s = self.scene.settings
        self.version = s["version"] if version is None else version
        self.max_depth = _depth(s["max_depth"] if max_depth is None else max_depth, "Preview")
        self.post = _chain(s.get("post", []) if post is None else post, "Preview")
        self.interactive_scale = _scale(interactive_scale, "Preview")
        self.max_spp, self.freeze, self.seed = _budget(max_spp, "Preview"), bool(freeze), int(seed)
        self.denoise = bool(denoise)
        if self.denoise:
            load_pyoidn()
        self._lock = threading.RLock()            # guards the fields below (not the render)
        self._wake = threading.Condition(self._lock)
        self._pending: dict = {}
        self._generation = 0
        self._shown_generation = -1
        self._acc = None
        self._spp = 0
        self._frame_index = 0
        self._last_publish = 0.0
        self.denoise_interval = 0.25         # seconds between denoised refinement frames
        self._lo = None
        self._thread = None
        self._stop = threading.Event()
        self._callbacks = []
        self._error_callbacks = []
        self.frame: PreviewFrame | None = None
        self._delivered: PreviewFrame | None = None     # the last frame its callbacks have had
        self.error: Exception | None = None
        self._integrator_for(self.scene)
        if max_depth is not None:
            _warn_depth_not_applied(self.version, self.max_depth, "Preview")

    # ------------------------------------------------------------------ configuration
    def _integrator_for(self, scene, settings=None):
        """The integrator of the preview's settings (``settings``: ``(version, max_depth,
        denoise)`` as a frame read them under the lock; default the current ones), from
        ``scene``'s session (the scene, or its reduced-resolution copy); raises for a version
        that cannot show the scene."""
        version, max_depth, denoise = settings or (self.version, self.max_depth, self.denoise)
        session = session_of(scene)
        session.check_version_sees(version)
        # the denoiser's guides come from the draaw versions; Mitsuba's are denoised colour-only
        guides = GUIDES if denoise and is_draaw(version) else ()
        return session.integrator(version, max_depth, bool(self.scene.settings.get("hide_emitters", False)), guides)

    def _check_open(self, who: str) -> None:
        if self.scene is None:
            raise DraawError(f"{who}: this preview was closed (Preview.close); make a new one")

    def configure(self, **options):
        """Change ``version``, ``max_depth``, ``denoise``, ``post``, ``max_spp`` or
        ``interactive_scale`` and restart the accumulation (a new version or depth compiles
        its kernel once)."""
        self._check_open("Preview.configure")
        allowed = ("version", "max_depth", "denoise", "post", "max_spp", "interactive_scale")
        for k in options:
            if k not in allowed:
                raise ParameterError(f"Preview.configure: unknown option {k!r}{suggest(k, allowed)}")
        if "max_spp" in options:
            options["max_spp"] = _budget(options["max_spp"], "Preview.configure")
        if "interactive_scale" in options:
            options["interactive_scale"] = _scale(options["interactive_scale"], "Preview.configure")
        if "max_depth" in options:
            options["max_depth"] = _depth(options["max_depth"], "Preview.configure")
        if options.get("post") is not None:
            options["post"] = _chain(options["post"], "Preview.configure")
        with self._lock:
            old = {k: getattr(self, k) for k in options}
            try:
                for k, v in options.items():
                    setattr(self, k, v)
                if options.get("denoise"):
                    load_pyoidn()
                self._integrator_for(self.scene)
            except Exception:
                for k, v in old.items():        # all or nothing (a half-applied change would stick)
                    setattr(self, k, v)
                raise
            if "interactive_scale" in options:
                self._lo = None                 # made again at the new scale
            self._bump()
        if "max_depth" in options:
            _warn_depth_not_applied(self.version, self.max_depth, "Preview.configure")

    def _sensor_ids(self) -> set:
        return {sensor.id() for sensor in self.scene.mi_scene.sensors()}

    def key(self, name: str) -> str:
        """``material.parameter`` or a full ``mi.traverse`` key -> the traverse key."""
        self._check_open("Preview.key")
        return self.scene.key(name)

    def update(self, values: dict) -> int:
        """Queue parameter changes (``{"gold.roughness": 0.3, "sensor.x_fov": 40}``); the next
        frame shows them and the mean restarts. Returns the new generation number."""
        self._check_open("Preview.update")
        named = {name: (self.key(name), v) for name, v in values.items()}
        self.scene.check_values("Preview.update", named)       # (SDF values with each other)
        checked = {key: v for key, v in named.values()}
        # a value the scene cannot take is refused now, not at the next frame on the worker
        # thread; no Dr.Jit value is made here, so this does not wait for the frame in flight
        p = self.scene.all_params
        for name, (key, v) in named.items():
            try:
                check_like(p[key], v, key)
            except DraawError as e:
                raise ParameterError(f"Preview.update: {name}: {e}") from None
            if key.endswith("to_world") and key.rsplit(".", 1)[0] in self._sensor_ids():
                _check_rigid(name, v)        # (Mitsuba refused a scale on the worker thread)
            if key == "sensor.to_world":
                self.check_camera_outside_smoke(name, v)
        with self._lock:
            self._pending.update(checked)
            return self._bump()

    def check_camera_outside_smoke(self, name: str, to_world) -> None:
        """Raise :class:`~draaw_mi.errors.ParameterError` if ``to_world`` (a camera transform,
        ``name`` in the message) puts the camera inside a ``[[volumes]]`` smoke box, as a scene
        file's or a batch path's camera is refused (the smoke would be missing around it).
        :meth:`update` checks ``sensor.to_world``; the tuner checks before its lights follow."""
        self._check_open("Preview.check_camera_outside_smoke")
        volumes = self.scene.info.get("volumes", [])
        if not volumes:
            return
        m = np.asarray(getattr(to_world, "matrix", to_world), float).reshape(4, 4, -1)[:, :, 0]
        try:
            check_camera_outside_smoke(m[:3, 3], volumes, Where("Preview.update"), sensor_reach(self.scene))
        except DraawError as e:
            raise ParameterError(f"{e} ({name})") from None

    def _bump(self) -> int:
        self._generation += 1
        self._acc, self._spp = None, 0
        self.error = None
        self._wake.notify_all()
        return self._generation

    def close(self, timeout: float = 10.0) -> None:
        """Stop the worker (:meth:`stop`) and let go of the scene, its reduced-resolution copy
        and the callbacks: the preview renders no more. The scene is dropped under
        :data:`~draaw_mi.guard.RENDER_GUARD`, so when nothing else holds it its draaw BSDFs are
        freed here (each live one widens every later render's BSDF calls), not by a later
        garbage collection beside another thread's render (which kills the process)."""
        self.stop(timeout)
        with RENDER_GUARD:
            with self._lock:
                self._callbacks.clear()
                self._error_callbacks.clear()
                held, self.scene, self._lo = (self.scene, self._lo), None, None
                # (a failed frame's tracebacks held the scene: kept alive past close(), then
                # freed by a later collection outside the guard; the chain of causes stays)
                error, seen = self.error, set()
                while error is not None and id(error) not in seen:
                    seen.add(id(error))
                    error.__traceback__ = None
                    error = error.__cause__ or error.__context__
            del held

    def reset(self) -> int:
        """Restart the accumulation (e.g. after changing the scene from outside)."""
        with self._lock:
            self._lo = None              # (else its low-resolution copy shows the old values first)
            return self._bump()

    # ------------------------------------------------------------------ one frame
    def _apply_pending(self):
        with self._lock:
            pending, self._pending = self._pending, {}
        if not pending:
            return
        scenes = [self.scene] + ([self._lo] if self._lo is not None else [])
        with holding(*scenes):               # (the scene's lock first, as step takes them)
            for sc in scenes:
                p = sc.all_params               # (SDF objects' parameters too)
                old = {key: dr.copy(p[key]) for key in pending}    # (assigned in place)
                try:
                    for key, v in pending.items():
                        p[key] = value_like(p[key], v, key)
                    p.update()
                except Exception:
                    # put the old values back: a value params.update() refused stays queued
                    # in the parameters, and every later change would fail with it
                    for key, v in old.items():
                        p[key] = v
                    p.update()
                    raise
                session_of(sc).scene_changed()          # e.g. V4's light powers

    def _lo_scene(self):
        if self._lo is None:
            w, h = self.scene.resolution
            s = self.interactive_scale
            # (with_resolution carries every current value over)
            self._lo = self.scene.with_resolution(max(1, round(w * s)), max(1, round(h * s)))
        return self._lo

    def step(self) -> PreviewFrame | None:
        """Render one frame now (in the calling thread) and publish it; ``None`` when the
        parameters changed while it rendered (the stale frame is dropped), or when a denoised
        preview accumulated it without publishing (at most one denoised refinement frame per
        ``denoise_interval`` seconds; the first frame after a change is always published)."""
        with self._lock:
            if self.scene is None:
                raise DraawError("Preview.step: this preview was closed (Preview.close); make a new one")
            generation = self._generation
            interactive = (self._spp == 0 and self.interactive_scale < 1.0 and generation != self._shown_generation
                           and self.scene.mi_dict is not None)   # (XML / mi.Scene: no second resolution)
            index = self._frame_index
            self._frame_index += 1
            settings = (self.version, self.max_depth, self.denoise)     # as configure() left them
        self._apply_pending()
        target = self._lo_scene() if interactive else self.scene
        t0 = time.perf_counter()
        session = session_of(target)
        with holding(self.scene, target):    # (the scene's, then its reduced copy's)
            # an opaque seed: a new frame's seed is new data, not a new kernel
            seed = dr.opaque(mi.UInt32, pass_seed(self.seed, index + 1))
            img = session.render_pass(self._integrator_for(target, settings), 1, seed, freeze=self.freeze,
                                      background=True)
            arr = np.array(img, dtype=np.float32)
        render_s = time.perf_counter() - t0
        with self._lock:
            if generation != self._generation:
                return None
            if interactive:
                mean, spp = arr, 0           # denoised (cheaply) at its own size, then upscaled
            else:
                self._acc = arr.astype(np.float64) if self._acc is None else self._acc + arr
                self._spp += 1
                mean, spp = (self._acc / self._spp).astype(np.float32), self._spp
        if self.denoise and not interactive and spp > 1 and spp < self.max_spp and\
                time.perf_counter() - self._last_publish < self.denoise_interval:
            return None          # OIDN costs about a frame: refine several frames per denoise
        frame = self._finish(mean, spp, generation, interactive, render_s)
        with self._lock:
            if generation != self._generation:
                return None
            self.frame = frame
            self._last_publish = frame.t_ready
            self._shown_generation = generation
            callbacks = list(self._callbacks)
        for cb in callbacks:
            cb(frame)
        with self._lock:        # wait() returns once the callbacks have shown it (else a script
            self._delivered = frame      # reads the panel's previous image, status and error line)
            self._wake.notify_all()
        return frame

    def _upscale(self, arr):
        h, w = self.scene.resolution[1], self.scene.resolution[0]
        rows = np.minimum((np.arange(h) * arr.shape[0]) // h, arr.shape[0] - 1)
        cols = np.minimum((np.arange(w) * arr.shape[1]) // w, arr.shape[1] - 1)
        return arr[rows][:, cols]

    def _finish(self, mean, spp, generation, interactive, render_s) -> PreviewFrame:
        color = mean[..., :3]
        image, denoised = color, False
        if self.denoise:
            quality = "fast" if interactive else "high"
            if mean.shape[2] >= 9:
                # channel order of the guides: N.X..N.Z then albedo.R..B (AOV_CHANNELS order)
                image = denoise(np.ascontiguousarray(color), mean[..., 6:9], mean[..., 3:6], quality=quality)
            else:                        # Mitsuba's integrators: no guides
                image = denoise(np.ascontiguousarray(color), quality=quality)
            denoised = True
        if interactive:
            image, color = self._upscale(image), self._upscale(color)
        encoded = False
        if self.post:
            image = np.array(_post.apply(mi.TensorXf(np.ascontiguousarray(image)), self.post), dtype=np.float32)
            encoded = _post.display_encoded(self.post)
        return PreviewFrame(image=image, raw=color, spp=spp, generation=generation, interactive=interactive,
                            denoised=denoised, render_s=render_s, t_ready=time.perf_counter(),
                            encoded=encoded)

    @property
    def generation(self) -> int:
        return self._generation

    @property
    def spp(self) -> int:
        return self._spp


def _warn_depth_not_applied(version: str, max_depth: int, who: str) -> None:
    """Say that a depth asked of version ``scene`` (the integrator a scene declares, with its
    own settings) is not applied, as :func:`draaw_mi.render` says it: the frames had stayed as
    they were without a word (the tuner's depth slider too)."""
    if resolve_version(version) == SCENE_VERSION:
        warnings.warn(f"{who}: version 'scene' renders with the integrator the scene declares, with its own "
                      f"settings: max_depth={max_depth} not applied (give a version such as 'v4' or 'path' "
                      "to set it)", RuntimeWarning, stacklevel=3)
