"""One render session per scene: the one place where draaw-mi renders a pass.

A :class:`Session` belongs to one :class:`~draaw_mi.scene.DraawScene` (:func:`session_of`
makes it on first use and keeps it as long as the scene lives). It owns

* the scene's **lock** (an ``RLock``): two threads never render one scene at once, and a
  multi-pass render or a fit iteration keeps the scene to itself. The lock belongs to the
  scene, not to the session: a session made after :meth:`Session.close` has the same one, so
  a thread that took it just before the close still excludes the threads that come after;
* its **integrators** (:meth:`Session.integrator`, one instance per set of options; V4 keeps
  what it learns of the scene in its instance);
* its **recordings**: ``dr.freeze`` replays of one-pass renders and of a fit's gradient passes
  (:mod:`.frozen` says what a recording takes as input) and what is found once per scene for
  them;
* its **workers** (the preview's thread): :meth:`Session.close`, the context manager and a
  hook at interpreter exit stop them, so that no thread is inside a Dr.Jit kernel while
  Dr.Jit shuts down (a forgotten tuner would end its script with SIGSEGV or SIGABRT).

:meth:`Session.render_pass` renders one pass -- traced, or replayed from a recording -- and
:func:`apply_post` applies a post chain to its colour; :func:`draaw_mi.render`, a batch frame
and the preview render through them. :meth:`Session.gradient_pass` renders a differentiable
pass, its loss and its backward pass (:func:`draaw_mi.fit`'s captures), traced or replayed.

Renders of different scenes from different threads are serialised: every pass runs under
:data:`draaw_mi.guard.RENDER_GUARD` (see :mod:`draaw_mi.guard` for why), with Python's cycle
collector kept away from it (:data:`draaw_mi.guard.COLLECTOR_PAUSED`). ``mi.render`` with a
draaw integrator called directly takes the guard too (its primal render,
:meth:`~draaw_mi.integrators.common.DraawIntegrator.render`), but the collector is not kept
away from it: automatic collections stay on and a ``gc.collect()`` of another thread does not
wait for it. Take a scene's lock before the guard, never after: :func:`holding` takes them so.

>>> import draaw_mi
>>> from draaw_mi.rendering.session import session_of
>>> scene = draaw_mi.load_scene({"render": {"resolution": [8, 8], "filter": "box"},
...     "shapes": [{"type": "sphere"}], "lights": [{"type": "constant"}],
...     "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
>>> with session_of(scene) as session:
...     integrator = session.integrator("v4", max_depth=3)
...     session.render_pass(integrator, spp=4, seed=0).shape
(8, 8, 3)
"""
from __future__ import annotations

import atexit
import contextlib
import threading
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np

from .. import post
from ..errors import RenderError, caused_by_interrupt
from ..guard import COLLECTOR_PAUSED, RENDER_GUARD, let_go
from ..integrators import SCENE_VERSION, resolve_version
from ..integrators.features import detect_features
from ..scene.loading import integrator_depth, integrator_version
from .film_channels import film_channels, named_by_film
from .frozen import freeze_render, freeze_supported, widened_named
from .gradient_body import gradient_body, gradients_of, host_key, restore_gradients
from .passes import sample_passes
from .plugins import integrator_props, make_plugin

#: ``freeze="small"`` records renders of at most this many pixels and samples per pixel
FREEZE_MAX_PIXELS = 128 * 128
FREEZE_MAX_SPP = 16
#: recordings one gradient pass keeps: one per sensor (a fit's captures), and a second where a
#: replay's dry run fails once (measured: 8 for 4 captures, 10 with texel maps)
GRADIENT_RECORDINGS = 64
#: gradient passes (integrator, spp, loss) whose recordings a session keeps, the oldest dropped
GRADIENT_KEYS = 4
#: set False to trace every render (debugging)
FREEZE = True
#: seconds a worker gets to finish its frame when its session closes
WORKER_STOP_S = 10.0

# What Mitsuba's own integrators cannot show: draaw-mi traces SDF objects inside v1..v4 only,
# and path / prb pass through media as if they were empty
BLIND = {"path": ("sdf", "media"), "prb": ("sdf", "media"), "volpath": ("sdf",), "prbvolpath": ("sdf",)}
#: the most null collisions a ray crossing a smoke box may expect (its largest sigma_t times the
#: box's diagonal) in Mitsuba's volpath, whose delta tracking steps by one global majorant: a
#: voxel of sigma_t 1e30 took more than 10 minutes at 8x8 pixels, past SIGTERM (V4's
#: majorant grid: 0.29 s)
VOLPATH_MAX_STEPS = 1e6


#: what a running preview's panel says when its scene's session is closed
CLOSED_NOTICE = ("stopped: the scene's session was closed (rendering.close_all(), or a with "
                 "block on it); run this panel's cell again for a new one")


class Session:
    """Everything draaw-mi keeps to render one scene (see the module docstring).

    Beside the lock, integrators, recordings and workers it holds what is found once per
    scene: whether renders may be recorded (``freezable``), the film, the plain-number
    parameter readers (``scalars``) and own BSDFs (``own_bsdfs``) of :mod:`.frozen`, the pass
    plans of its sampler (``passes``) and ``memo``, where integrators (V4's
    ``freeze_state``) and the renderer keep their own findings.
    """
    def __init__(self, scene):
        self._scene = weakref.ref(scene)
        self.source = scene.source
        self.lock = _lock_of(scene)
        self.freezable = self.film = self.scalars = self.own_bsdfs = None
        self.memo: dict = {}
        self.passes: dict = {}
        self.recordings: dict = {}            # (id(integrator), spp) -> a recorded render; gradient passes' too
        self._integrators: dict = {}          # plugin properties -> integrator
        self._integrator_keys: dict = {}      # integrator()'s arguments as given -> properties
        self._workers: weakref.WeakSet = weakref.WeakSet()

    @property
    def scene(self):
        """The :class:`~draaw_mi.scene.DraawScene` (it owns the session, not the other way)."""
        scene = self._scene()
        if scene is None:
            raise RenderError(f"render session of {self.source}: its scene is gone")
        return scene

    # ------------------------------------------------------------------ integrators
    def integrator(self, version: str, max_depth: int, hide_emitters: bool = False, aovs=(), **options):
        """The integrator plugin for ``version`` with these options, made once per session.
        :class:`~draaw_mi.errors.RenderError` names an option the plugin does not take."""
        try:                                 # the arguments as given (a render's first step)
            fast = (version, max_depth, bool(hide_emitters), tuple(aovs), tuple(sorted(options.items())))
            integrator = self._integrators.get(self._integrator_keys.get(fast))
        except TypeError:                    # an unhashable option value
            fast = integrator = None
        if integrator is not None:
            return integrator
        if resolve_version(version) == SCENE_VERSION:
            return self._own_integrator(aovs, options)
        declared = self._declared(version, max_depth, hide_emitters, aovs, options)
        if declared is not None:
            if fast is not None:
                self._integrators[("declared",)] = declared
                self._integrator_keys[fast] = ("declared",)
            return declared
        props = integrator_props(version, max_depth, hide_emitters, aovs, **options)
        key = tuple(sorted((k, str(v)) for k, v in props.items()))
        if key not in self._integrators:
            with RENDER_GUARD:               # (a plugin made while a recording replays breaks it)
                if key not in self._integrators:        # (another thread may have made it meanwhile)
                    self._integrators[key] = make_plugin(props)
        if fast is not None:
            self._integrator_keys[fast] = key
        return self._integrators[key]

    def _declared(self, version: str, max_depth: int, hide_emitters: bool, aovs, options):
        """The integrator object an XML file, dict or ``mi.Scene`` declares where a render asks
        for the version that is it (``draaw_v4``, ``path``, ``prb``, ``volpath``, ...) with its
        ``max_depth`` and ``hide_emitters`` and nothing else, so that its other properties
        (``stratify``, ``light_selection``, ``rr_depth``, ...) hold; a new default plugin had
        rendered it. ``None`` otherwise."""
        if aovs or options or not self.scene.info.get("integrator"):
            return None
        declared = self.scene.mi_scene.integrator()
        if declared is None or integrator_version(declared) != resolve_version(version):
            return None
        same = integrator_depth(declared) == max_depth and \
            bool(getattr(declared, "hide_emitters", False)) == bool(hide_emitters)
        return declared if same else None

    def _own_integrator(self, aovs, options):
        """Version ``"scene"``: the integrator object the scene declares, with its file's
        settings (``max_depth`` and ``hide_emitters`` are its own)."""
        integrator = self.scene.mi_scene.integrator()
        if integrator is None:
            raise RenderError(f"render: version 'scene' renders with the integrator the scene "
                              f"declares; {self.source} declares none (pick v1..v4, path or prb)")
        if aovs or options:
            given = ", ".join([f"aovs {list(aovs)}"] * bool(aovs) + [repr(k) for k in options])
            raise RenderError(f"render: version 'scene' renders with the scene's own integrator as "
                              f"its file sets it; {given} cannot be given to it (pick v1..v4)")
        return integrator

    def plugin_name(self, version: str) -> str:
        """The integrator plugin ``version`` renders with (for version ``"scene"``, the one
        the scene declares: ``direct``, ``aov``, ...)."""
        plugin = resolve_version(version)
        own = self.scene.info.get("integrator") if plugin == SCENE_VERSION else None
        return own or plugin

    def scene_changed(self) -> None:
        """Tell the session's integrators that the scene's parameters changed: V4 recomputes
        its power-based light-selection table at the next render instead of keeping the old
        one (a table its light pilot learned stays: see
        :mod:`draaw_mi.integrators.light_pilot`). The preview, the batch and the fit call this
        after ``params.update()``; call it too after changing light intensities yourself
        (renders stay unbiased without it, but a stale table samples a dimmed light as often
        as before)."""
        mi_scene = self.scene.mi_scene
        for integrator in list(self._integrators.values()):
            forget = getattr(integrator, "forget_scene", None)
            if forget is not None:
                forget(mi_scene)

    # ------------------------------------------------------------------ what the scene holds
    def holds(self) -> dict:
        """``{"sdf": bool, "media": bool}``: whether the scene has ``[[sdf]]`` objects or
        participating media (found once)."""
        holds = self.memo.get("holds")
        if holds is None:
            feats = detect_features(self.scene.mi_scene)
            holds = self.memo["holds"] = {"sdf": bool(feats["sdf"]), "media": bool(feats["media"])}
        return holds

    def check_version_sees(self, version: str) -> None:
        """Raise :class:`~draaw_mi.errors.RenderError` when ``version`` cannot show what the
        scene holds: ``[[sdf]]`` objects for any of Mitsuba's integrators, media for
        ``path`` / ``prb``. The render would otherwise drop them without a word."""
        plugin = resolve_version(version)
        blind = BLIND.get(plugin)
        if not blind:
            return
        holds = self.holds()
        if "sdf" in blind and holds["sdf"]:
            raise RenderError(f"render: {self.source} has [[sdf]] objects, which Mitsuba's {plugin!r} "
                              "cannot see (draaw-mi traces them in v1..v4); pick v1..v4")
        if "media" in blind and holds["media"]:
            raise RenderError(f"render: {self.source} has participating media, which Mitsuba's "
                              f"{plugin!r} passes through as empty; pick v1..v4 or volpath")
        smokes = [v for v in self.scene.info.get("volumes", []) if v.get("mode") == "smoke"]
        for v in smokes if plugin in ("volpath", "prbvolpath") else ():
            steps = v["max_sigma_t"] * float(np.linalg.norm(np.subtract(v["bounds"][1], v["bounds"][0])))
            if steps > VOLPATH_MAX_STEPS:
                raise RenderError(f"render: the smoke {v['name']!r} of {self.source} (largest sigma_t "
                                  f"{v['max_sigma_t']:g}) takes Mitsuba's {plugin!r} about {steps:.2g} "
                                  f"steps a ray (at most {VOLPATH_MAX_STEPS:g}); pick v1..v4, whose "
                                  "majorant grid steps over it")

    def sample_passes(self, spp: int, pass_spp: int, sensor: int = 0) -> list[int]:
        """:func:`~draaw_mi.rendering.passes.sample_passes` of the scene's sensor ``sensor`` (an
        index), remembered where its sampler is one of Mitsuba's (they round counts by their
        kind alone)."""
        counts = self.passes.get((spp, pass_spp, sensor))
        if counts is None:
            mi_scene = self.scene.mi_scene
            with RENDER_GUARD:                # (probing forks the sampler: a plugin call)
                counts = sample_passes(mi_scene, spp, pass_spp, sensor)
            if type(mi_scene.sensors()[sensor].sampler()) is mi.Sampler:
                if len(self.passes) >= 64:
                    self.passes.clear()
                self.passes[(spp, pass_spp, sensor)] = counts
        return list(counts)

    # ------------------------------------------------------------------ one pass
    def freezes(self, spp: int, freeze="small") -> bool:
        """Whether a primal pass of ``spp`` samples replays a recording: ``freeze`` True when
        the scene can be recorded (no SDF objects, no media: :func:`.frozen.freeze_supported`,
        asked once), ``"small"`` only for films of at most :data:`FREEZE_MAX_PIXELS` pixels
        and :data:`FREEZE_MAX_SPP` samples (where tracing costs more than the kernels: the
        rule of :func:`draaw_mi.render`), False never. The film size is read every time
        (parameters can change it)."""
        if not FREEZE or not freeze or (freeze == "small" and spp > FREEZE_MAX_SPP):
            return False
        if self.freezable is None:
            mi_scene = self.scene.mi_scene
            self.freezable = freeze_supported(mi_scene)
            self.film = mi_scene.sensors()[0].film()          # a sensor's film stays its own
        if not self.freezable:
            return False
        if freeze != "small":
            return True
        w, h = self.film.size()
        return int(w) * int(h) <= FREEZE_MAX_PIXELS

    def render_pass(self, integrator, spp: int, seed: int, *, params=None, sensor=None, freeze="small",
                    background: bool = False):
        """Render one pass of ``spp`` samples with ``seed`` (an int, or an opaque ``mi.UInt32``
        that keeps a traced kernel from being compiled anew for each seed) and return the evaluated image
        (``mi.TensorXf`` (H, W, C), as ``mi.render`` gives it). ``params`` (``mi.traverse``
        parameters) makes it differentiable (traced; ``sensor`` as in ``mi.render``); otherwise it replays a recording where :meth:`freezes` says so. Same
        bits either way. ``background``: rendered by a thread beside the one that makes and frees
        scenes (a preview's worker), which replays only a recording made since the latest scene
        change and the latest draaw-mi call of another thread: it records anew, or traces while
        such a call is in progress (:func:`.frozen.freeze_render`)."""
        scene = self.scene
        by_film = params is None and named_by_film(integrator)
        with self.lock, RENDER_GUARD, COLLECTOR_PAUSED, interrupts_raised_as_such(), widened_named(scene):
            if params is None and sensor is None and not by_film and self.freezes(spp, freeze):
                if isinstance(seed, int):
                    seed = dr.opaque(mi.UInt32, seed)
                image = self.recording(integrator, spp)(scene.mi_scene, seed, scene, self, background=background)
            else:
                image = mi.render(scene.mi_scene, params, sensor=0 if sensor is None else sensor,
                                  integrator=integrator, seed=seed, spp=spp)
                if by_film:                        # (mi.render's tensor leaves channels out)
                    image = film_channels(scene.mi_scene, 0 if sensor is None else sensor)
            dr.eval(image)
            dr.sync_thread()
        return image

    def gradient_pass(self, integrator, spp: int, seed, loss, *, params, sensor, spp_grad=None, inputs=(),
                      freeze: bool = True):
        """Render one differentiable pass from ``sensor``, evaluate ``loss(image, *inputs) ->
        (value, extras)`` on it and backpropagate ``value``: the gradients accumulate on the
        scene parameters that track them and on what they were computed from. Returns
        ``(value, extras)``, ``value`` detached. The caller holds the scene (:func:`holding`)
        while it reads the results: the pass does not wait for its kernels.

        With ``freeze`` (and a scene that can be recorded, :meth:`freezes`) the render, the
        loss and the adjoint pass replay a recording: nothing is traced after the first passes
        from each sensor (an iteration of the SVBRDF benchmark's fit in 0.57-0.88x the traced
        one's time: ``benchmarks/results/fit_iteration_cost.md``). The recording traverses the
        scene's parameters itself; ``params`` (``mi.traverse`` parameters) serve the traced
        pass. ``loss`` is part of the recording's key (hashable: equal losses share recordings)
        and must read nothing but its arguments (a JIT value it closes over would be baked in);
        ``inputs`` are PyTrees (a reference image, a mask, ``None``). A pass that V4 renders
        adaptively (``spp`` >= 64: its pilot is read back) is traced. Same gradients either way,
        to float rounding."""
        scene = self.scene
        spp_grad = spp if spp_grad is None else spp_grad
        adaptive = getattr(integrator, "adaptive_applies", None)
        with self.lock, RENDER_GUARD, COLLECTOR_PAUSED, interrupts_raised_as_such(), widened_named(scene):
            if (freeze and self.freezes(spp, True)
                    and not (adaptive is not None and adaptive(scene.mi_scene, sensor, seed, spp))):
                key = ("gradient", id(integrator), int(spp), int(spp_grad), loss)
                fn = self.recordings.get(key)
                if fn is None:
                    kept = [k for k in self.recordings if k[0] == "gradient"]    # oldest first
                    for old in kept[:max(0, len(kept) - GRADIENT_KEYS + 1)]:
                        del self.recordings[old]           # (a notebook's many fits of one scene)
                    fn = self.recordings[key] = freeze_render(
                        integrator, gradient_body(integrator, spp, spp_grad, loss), limit=GRADIENT_RECORDINGS)
                if isinstance(seed, int):
                    seed = dr.opaque(mi.UInt32, seed)
                saved = gradients_of(params)
                value, extras = fn(scene.mi_scene, seed, scene, self, args=(sensor, host_key(sensor), tuple(inputs)),
                                   sensor=sensor, before_retry=lambda: restore_gradients(saved))
            else:
                value, extras = gradient_body(integrator, spp, spp_grad, loss, params)(
                    scene.mi_scene, seed, sensor, None, tuple(inputs))
            dr.eval(value, extras)
        return value, extras

    def recording(self, integrator, spp: int):
        """``f(mi_scene, seed: mi.UInt32, scene, session) -> image``: ``mi.render`` recorded with
        ``dr.freeze``, one recording per integrator and spp (:func:`.frozen.freeze_render`)."""
        key = (id(integrator), int(spp))
        fn = self.recordings.get(key)
        if fn is None:
            def render_once(mi_scene, seed):
                return mi.render(mi_scene, integrator=integrator, seed=seed, spp=spp)
            fn = self.recordings[key] = freeze_render(integrator, render_once)
        return fn

    # ------------------------------------------------------------------ workers and lifetime
    def add_worker(self, worker) -> None:
        """Register ``worker`` (an object with ``stop(timeout)``, e.g. a preview whose thread
        renders this scene): :meth:`close` and the interpreter's exit stop it. Held weakly."""
        self._workers.add(worker)

    def workers(self) -> list:
        """The registered workers (:meth:`add_worker`) that are still alive."""
        return list(self._workers)

    def close(self, timeout: float = WORKER_STOP_S, why: str | None = CLOSED_NOTICE) -> None:
        """Stop the workers (each finishes its frame, at most ``timeout`` seconds; a running
        one's panel is told ``why``) and let go of the recordings and integrators. The scene
        renders again afterwards, through a new session."""
        for worker in list(self._workers):
            worker.stop(timeout, why=why)
        self._workers.clear()
        with self.lock, RENDER_GUARD:
            self.recordings.clear()
            self._integrators.clear()
            self._integrator_keys.clear()
        scene = self._scene()
        with _SESSIONS_GUARD:
            if scene is not None and _SESSIONS.get(scene) is self:
                del _SESSIONS[scene]

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def __del__(self):
        # its recordings and integrators are freed under the render guard (guard.let_go)
        if let_go is not None:                 # (None while the interpreter shuts down)
            let_go(self)

    def __repr__(self) -> str:
        return (f"Session[{self.source}, {len(self._integrators)} integrators, {len(self.recordings)} "
                f"recordings, {len(self._workers)} workers]")


@contextlib.contextmanager
def interrupts_raised_as_such():
    """Ctrl-C while a pass runs leaves as the ``KeyboardInterrupt`` it is (a notebook's
    interrupt, the CLI's "interrupted" and exit status 130), not as the ``RuntimeError`` that
    Dr.Jit raises again for it (:func:`~draaw_mi.errors.caused_by_interrupt`).

    >>> try:
    ...     with interrupts_raised_as_such():
    ...         raise RuntimeError("drjit.custom(): error (see above)") from KeyboardInterrupt()
    ... except KeyboardInterrupt:
    ...     print("interrupted")
    interrupted
    """
    try:
        yield
    except RuntimeError as e:
        if caused_by_interrupt(e):
            raise KeyboardInterrupt from None
        raise


_SESSIONS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()     # DraawScene -> Session
_SESSIONS_GUARD = threading.Lock()
_LOCKS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()       # DraawScene -> RLock
_LOCKS_GUARD = threading.Lock()


def _lock_of(scene) -> threading.RLock:
    """The scene's lock, the same for each of its sessions (made on first use)."""
    with _LOCKS_GUARD:
        lock = _LOCKS.get(scene)
        if lock is None:
            lock = _LOCKS[scene] = threading.RLock()
    return lock


def session_of(scene) -> Session:
    """The render session of the :class:`~draaw_mi.scene.DraawScene` ``scene`` (made on first
    use; it lives as long as the scene, or until it is closed)."""
    session = _SESSIONS.get(scene)
    if session is None:
        with _SESSIONS_GUARD:
            session = _SESSIONS.get(scene)
            if session is None:
                session = _SESSIONS[scene] = Session(scene)
    return session


@contextlib.contextmanager
def holding(*scenes):
    """Hold the locks of ``scenes`` (:class:`~draaw_mi.scene.DraawScene` objects, in the order
    given), then :data:`~draaw_mi.guard.RENDER_GUARD`: the order in which every render takes
    them (:meth:`Session.render_pass`, :meth:`Session.close`), so that blocks which render or
    update parameters never wait on each other in a circle.

    >>> import draaw_mi
    >>> scene = draaw_mi.load_scene({"render": {"resolution": [8, 8]}, "shapes": [{"type": "sphere"}],
    ...     "lights": [{"type": "constant"}], "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}})
    >>> with holding(scene):
    ...     img = draaw_mi.render(scene, spp=1)       # (re-entrant: render takes them again)
    """
    with contextlib.ExitStack() as held:
        for scene in scenes:
            held.enter_context(_lock_of(scene))
        held.enter_context(RENDER_GUARD)
        yield


def close_all(timeout: float = WORKER_STOP_S, why: str | None = CLOSED_NOTICE) -> None:
    """Close every open session: their workers stop (their panels told ``why``). Runs at
    interpreter exit, before Dr.Jit shuts down (a worker still inside a kernel would crash the
    process), telling no panel."""
    with _SESSIONS_GUARD:
        sessions = list(_SESSIONS.values())      # (a closed session has left it)
    for session in sessions:
        session.close(timeout, why=why)


atexit.register(close_all, why=None)


def apply_post(image, chain, names):
    """``image`` with the post chain ``chain`` (a loaded :class:`~draaw_mi.post.Chain`)
    applied to its colour: R, G, B, and A where ``names`` (the image's channel names) has it
    fourth; AOV channels pass through. (Told by count, an RGB image with one AOV had its AOV
    read as alpha, and an RGBA image with AOVs had its colour encoded premultiplied.)"""
    colour = 4 if len(names) > 3 and names[3] == "A" else 3
    if image.shape[2] == colour:
        return post.apply(image, chain)
    color = post.apply(image[:, :, :colour], chain)
    return dr.concat([color, image[:, :, colour:]], axis=2)


def non_finite_count(image) -> int:
    """How many values of ``image`` (a tensor) are NaN or ±inf."""
    with RENDER_GUARD:
        n = int(dr.count(~dr.isfinite(image.array))[0])
    return n
