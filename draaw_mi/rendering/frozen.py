"""Frozen small renders: what a ``dr.freeze`` recording of ``mi.render`` takes as input.

Small renders (the Jupyter preview, the fit loop, a batch's frames) replay a recording instead
of re-tracing the Python integrator (:meth:`Session.recording <draaw_mi.rendering.session.Session.recording>`). A recording's key
sees the types of its inputs, not the host constants that Mitsuba's kernels bake in, so
everything a replay must follow is handed to it here (:func:`freeze_render`): the scene, its
host-side parameters and tensor shapes (:func:`scene_scalars`), the integrator's
scene-dependent state (V4's light table and edge map), the live Python BSDFs that the
scene does not hold (:func:`other_live_bsdfs`) and the media V3 / V4 keep alive
(:func:`~draaw_mi.integrators.volume.held_media`). What is found once per scene is kept in
the scene's :class:`~draaw_mi.rendering.session.Session` (``cache`` below: its ``scalars``,
``own_bsdfs`` and ``memo``).
"""
from __future__ import annotations

import contextlib
import gc
import sys
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import RenderError, caused_by_interrupt, exception_chain
from ..guard import COLLECTOR_PAUSED, background_replay, foreground_mark, foreground_moved, registry_changes
from ..integrators.features import scene_shapes
from ..materials.draaw_bsdf import LIVE_INSTANCES
from ..sdf.scene import PROXY_PREFIX


def freeze_supported(mi_scene) -> bool:
    """Whether renders of ``mi_scene`` may be recorded with ``dr.freeze``: not when the scene
    has SDF objects (the tracer reads node parameters while it is traced) or participating
    media (the volume code launches host-side work that a recording cannot hold; Dr.Jit 1.5
    aborts the process), nor a thin-lens camera's. The preview and the batch executor ask this too."""
    # flags and ids only (no JIT reads): a check between replays must not disturb the
    # recording's inputs; a shape group's members (with a medium) are found by a traversal,
    # made only where the scene has an instance (features.scene_shapes)
    for sh in scene_shapes(mi_scene):
        if sh.id().startswith(PROXY_PREFIX):
            return False                               # SDF proxies
        if sh.interior_medium() is not None or sh.exterior_medium() is not None:
            return False
    # a thin lens's camera reads state a recording does not capture ("created before
    # recording was started"): its renders are traced
    return all(s.get_medium() is None and not s.needs_aperture_sample() for s in mi_scene.sensors())


# Host-side parameters that no kernel reads (silhouette weights serve projective gradients,
# thread reordering only the GPU): left out of scene_scalars' key
_IGNORED_SCALARS = ("silhouette_sampling_weight", "allow_thread_reordering")


def scene_scalars(mi_scene, scene=None, cache=None) -> tuple:
    """The plain-number parameters of ``mi_scene`` (``mi.traverse`` entries held on the
    host: floats, ints, bools and one-level scalar arrays such as the film's size), read as
    they are now, and the shapes of its tensor parameters (textures, environment maps,
    grids). Kernels bake these in as constants, and a ``dr.freeze`` replay keeps its
    recording's (its key sees the inputs' types, not their sizes): the lights' sampling
    weights (Mitsuba's ``pdf_emitter_direction`` reads them through a virtual-call getter), a
    ``dielectric``'s ``eta``, the shutter, the film's size (a replay after
    ``sensor.film.size`` changes would return an image of the old size), a texture's ``to_uv``
    transform (a host-side matrix: a replay would keep the old tiling; also when a Python plugin
    exposes it with ``cb.put``), a texture's resolution
    (an environment map's data swapped for a smaller image: up to 45 off from the second
    replay on). Without this a replay after ``params.update`` of one of them goes on
    rendering the old value (``eta`` 1.5 -> 2.65 on the glass scene: up to 4.8 off the traced
    render; a sampling weight: up to 26). Passed to the recording as Python values, which are
    part of its key, a change records anew. ``scene``, the :class:`DraawScene` of ``mi_scene`` where there is
    one, and ``cache``, its session, make this a few microseconds (its parameter table is walked
    once); without them ``mi_scene`` is traversed on each call.

    >>> import mitsuba as mi
    >>> scene = mi.load_dict(mi.cornell_box())  # clip distances, shutter, light weight, film
    >>> [x if isinstance(x, tuple) else round(x, 3) for x in scene_scalars(scene)]
    [0.001, 100.0, 0.0, 0.0, 1.0, (256, 256), (256, 256), (0, 0)]
    """
    state = None if scene is None else cache
    access = None if state is None else state.scalars
    if access is None or access[0] is not scene.params:
        params = mi.traverse(mi_scene) if scene is None else scene.params
        groups: tuple = ([], [], [], [], [])      # plain, vectors, matrices, tensors, others
        for key in params.keys():
            value, vtype, node, _ = params.properties[key]
            if key.endswith(_IGNORED_SCALARS):
                continue
            # vtype None: a Python plugin's cb.put of the object itself, which params.update
            # changes in place (a nanobind type; a plain Python number it cannot change)
            probe = value if vtype is None else params.get_property(value, vtype, node)
            group = _key_group(probe, python_plugin=vtype is None)
            if group is not None:
                groups[group].append((value, vtype, node))
        access = (params,) + groups
        if state is not None:
            state.scalars = access
    get = access[0].get_property

    def read(value, vtype, node):
        return value if vtype is None else get(value, vtype, node)
    return (tuple(read(*e) for e in access[1])
            + tuple(tuple(read(*e)) for e in access[2])
            + tuple(_matrix_entries(read(*e)) for e in access[3])
            + tuple(tuple(read(*e).shape) for e in access[4])
            + tuple(repr(read(*e)) for e in access[5]))


def _key_group(value, python_plugin: bool) -> int | None:
    """Which part of :func:`scene_scalars`' key a parameter's value goes to: 0 a plain
    number, 1 a host-side vector (the film's size, crop size, offset), 2 a host-side matrix or
    transform (a texture's ``to_uv``), 3 a tensor (its shape: a texture's or grid's
    resolution), 4 another host-side value (a string, a ``Scalar*`` bounding box: its
    ``repr``); ``None``: nothing to key (a JIT array, which ``dr.freeze`` follows itself)."""
    kind = type(value)
    if kind in (float, int, bool):
        return None if python_plugin else 0
    if dr.is_tensor_v(kind):
        return 3
    if dr.is_array_v(kind):
        return None if dr.is_jit_v(kind) else (1 if dr.depth_v(kind) == 1 else 2)
    if hasattr(value, "matrix"):
        return None if dr.is_jit_v(type(value.matrix)) else 2
    if isinstance(value, str) or kind.__name__.startswith("Scalar"):
        return 4
    return None


def _matrix_entries(value) -> tuple:
    """A host-side matrix or transform's entries as a flat tuple of Python numbers (not
    ``getattr(value, "matrix")`` on an array: Dr.Jit reads that as a swizzle)."""
    return tuple(np.asarray(value if dr.is_array_v(value) else value.matrix).ravel().tolist())


def _held_media() -> list:
    """The media V3 / V4's majorant tables hold alive
    (:func:`draaw_mi.integrators.volume.held_media`); none while no scene with media has
    rendered (the media code, loaded with the first such scene, is not imported here)."""
    volume = sys.modules.get("draaw_mi.integrators.volume")
    return [] if volume is None else volume.held_media()


def _release_held_media() -> bool:
    """Drop V3 / V4's majorant tables (:func:`~draaw_mi.integrators.volume.release_tables`)
    and collect what they alone held; whether there were media to let go."""
    volume = sys.modules.get("draaw_mi.integrators.volume")
    if volume is None or not volume.held_media():
        return False
    volume.release_tables()
    gc.collect()
    return True


def other_live_bsdfs(mi_scene, cache=None) -> list:
    """The live draaw BSDFs that ``mi_scene``'s shapes do not hold (ordered by ``id``). With
    ``cache`` (the session of ``mi_scene``'s :class:`DraawScene`) the scene's own BSDFs are looked up
    once (a shape's BSDF cannot be replaced), and while the live ones are exactly the scene's
    own, no walk over them is needed (the walk over shapes and live BSDFs takes 10-67 us a
    render on the material spheres, with warm or cold caches; the lookup takes 1 us)."""
    state = cache
    own = None if state is None else state.own_bsdfs
    if own is None:
        ids = frozenset(id(sh.bsdf()) for sh in mi_scene.shapes())
        own = (ids, sum(1 for b in LIVE_INSTANCES if id(b) in ids))
        if state is not None:
            state.own_bsdfs = own
    if len(LIVE_INSTANCES) == own[1]:      # all live ones are the scene's (they live with it)
        return []
    return sorted((b for b in LIVE_INSTANCES if id(b) not in own[0]), key=id)


def owned_tensor(array) -> mi.TensorXf:
    """``array`` (numpy) as an ``mi.TensorXf`` in memory of Dr.Jit's own, for a recording's
    inputs. ``mi.TensorXf(array)`` maps a numpy array's memory without copying on the CPU
    backend (``dr.copy`` keeps the mapping); a recording of a fit's gradient pass (render,
    loss, backward) replayed with mapped texture tensors rendered other data than they held,
    and recorded anew at most calls (measured on the 8x8 tile of
    tests/fitting/test_fit_captures.py: images off by up to 1.4 from the fourth iteration
    on; 8 recordings for 4 captures, 3 with owned tensors). An arithmetic kernel with an
    opaque operand copies, and the copy is waited for: ``dr.eval`` only queues a kernel on
    the CPU backend, so behind a render still running the copy read the array after the
    caller had changed it (20 times in 20).

    >>> import numpy as np
    >>> a = np.ones((2, 2, 1), np.float32)
    >>> t = owned_tensor(a)
    >>> a[:] = 7.0
    >>> float(t.array[0]), t.shape
    (1.0, (2, 2, 1))
    """
    t = mi.TensorXf(np.asarray(array, dtype=np.float32)) + dr.opaque(mi.Float, 0.0)
    dr.eval(t)
    dr.sync_thread()
    return t


#: recordings one frozen render keeps (see freeze_render)
RECORDINGS_KEPT = 8

#: what Dr.Jit 1.5's replay says when the registry of virtual-call targets changed
_REGISTRY_CHANGED = "number of registry entries"

#: a guard.foreground_mark() that a background caller never replays at (it records anew)
_NO_CALLS_MARK = (-1, True)


def _first_cause(e: BaseException) -> str:
    """The first line of the innermost exception ``e`` was raised from (Dr.Jit's recorder
    wraps the error that stopped it in "error encountered while recording ... (see above)"),
    with the type of that exception; 200 characters at most.

    >>> try:
    ...     try:
    ...         raise RuntimeError("validate(): a virtual call on an object not in the inputs")
    ...     except RuntimeError as inner:
    ...         raise RuntimeError("record(): error encountered (see above)") from inner
    ... except RuntimeError as e:
    ...     print(_first_cause(e))
    RuntimeError: validate(): a virtual call on an object not in the inputs
    """
    e = exception_chain(e)[-1]
    lines = str(e).strip().splitlines()
    return f"{type(e).__name__}: {lines[0] if lines else ''}"[:200]


def widened_error(scene, error: BaseException):
    """A :class:`~draaw_mi.errors.RenderError` naming the parameter to blame for ``error``, a
    failed render of ``scene`` (a :class:`DraawScene`, or ``None``), where one of its single
    values holds more than one value (:meth:`DraawScene.widened_values`); else ``None``."""
    if scene is None or caused_by_interrupt(error) or not hasattr(scene, "widened_values"):
        return None
    # only a failure that speaks of sizes ("size of output variable r2153 is 2 (must be 1)"):
    # any other goes on to the recorder's retry and fallback, or to the caller, as it was
    if not any("size" in str(e).lower() for e in exception_chain(error)):
        return None
    wide = scene.widened_values(1)
    if not wide:
        return None
    return RenderError(f"render of {scene.source}: {wide[0]}; expected one, as its plugin takes "
                       "(a single value or a colour, set through scene.params: give it a value of width 1)")


@contextlib.contextmanager
def widened_named(scene):
    """Re-raise a render's failure as :func:`widened_error`'s error where it has one."""
    try:
        yield
    except RenderError:
        raise
    except Exception as e:
        why = widened_error(scene, e)
        if why is None:
            raise
        raise why from e


def freeze_render(integrator, body, limit: int = RECORDINGS_KEPT):
    """``dr.freeze(body)`` for ``body(mi_scene, seed, *args) -> result`` rendering with
    ``integrator``, with the integrator's scene-dependent state (V4's light-selection table and
    the edge map of the sensor rendered, from its ``freeze_state``) passed to the recording as
    an input. Without it the recording would run a different sampler than a traced render, or
    replay a stale table. The preview, the batch executor and the fit's gradient passes record
    their renders through this. ``limit``: the recordings kept (see below). A recording is not
    replayed once scenes were made or let go since it was made (:func:`draaw_mi.guard.registry_changes`),
    or once ``dr.set_thread_count`` changed the thread count: it is recorded anew. A ``background`` caller (a preview's worker) also records anew once
    another thread has begun a draaw-mi call since, and traces while such a call is in progress
    (:func:`draaw_mi.guard.background_replay`: replays beside or after one crashed Dr.Jit 1.5)."""
    state_of = getattr(integrator, "freeze_state", None)
    use_state = getattr(integrator, "frozen_state", None)

    def recorded(mi_scene, scalars, seed, state, live_bsdfs, args):
        if use_state is None:
            return body(mi_scene, seed, *args)
        with use_state(state):
            return body(mi_scene, seed, *args)

    # Every input opaque from the first recording: with literals kept (auto_opaque), a
    # stratifying sampler's state, which the first render changes, makes the second call
    # re-record and compile a kernel anew (a batch job would recompile at its third frame); the
    # walls are the same (benchmarks/results/render_overhead.md).
    # At most RECORDINGS_KEPT recordings, the least recently used dropped: each value of a
    # plain-number parameter (scene_scalars) records anew, on purpose, so an animated light
    # weight or a resized film would otherwise pile up compiled recordings for as long as the
    # integrator lives, and Dr.Jit's "recorded N times" warning would fire on every render.
    frozen = dr.freeze(recorded, auto_opaque=False, limit=limit, warn_after=1 << 30)

    failed = []                      # a recording that failed once: trace from then on
    # Dr.Jit's registry of virtual-call targets (every scene's shapes, BSDFs, emitters) as it
    # was when the recordings were made: a recording replayed after a scene was let go and
    # another made can find as many entries as it recorded and call the freed ones (a
    # segmentation fault beside a notebook cell that loads a scene again), and one replayed
    # after a scene was made refuses ('The number of registry entries ... did not match'):
    # both record anew. A background caller (a preview's worker) records anew too once another
    # thread began a draaw-mi call since, and traces while one is in progress
    # (guard.background_replay: replays after one crashed Dr.Jit 1.5)
    registry_at = registry_changes()
    calls_at = foreground_mark()
    # Dr.Jit's thread count as it was when the recordings were made: after a
    # dr.set_thread_count the recorder records anew, and a later return to the first count
    # replays the first recording, which crashed Dr.Jit 1.5 (2 -> 1 -> 2 threads: a segmentation
    # fault, plain mi.render under dr.freeze too); they are recorded anew instead
    threads_at = dr.thread_count()

    def call(mi_scene, seed, scene=None, cache=None, args: tuple = (), sensor=None, before_retry=None,
             background: bool = False):
        """Render ``mi_scene`` with ``seed``; ``scene``: its :class:`DraawScene`, if any, and
        ``cache`` its session (a cheaper read of its plain-number parameters, see
        :func:`scene_scalars`); ``args``: ``body``'s further inputs (PyTrees: a sensor, a
        reference image); ``sensor``: the sensor ``body`` renders from, when not the scene's
        first (its edge map is part of the state); ``before_retry``: called before a failed
        recording's pass is traced (a gradient pass puts its gradients back); ``background``:
        called from a thread other than the one that makes and frees scenes (a preview's)."""
        nonlocal registry_at, calls_at, threads_at
        if failed:
            return body(mi_scene, seed, *args)
        # every live Python BSDF that the scene does not hold itself (those it holds are
        # traversed with it): without them the recording of a BSDF call fails (see
        # materials.draaw_bsdf.LIVE_INSTANCES); a change in the set re-records
        # and the media V3 / V4 keep alive for their majorant tables (a few scenes'): a medium
        # call (volpath's, even in a scene without media) traced over them fails to record
        # when none is an input
        memo = None if cache is None else cache.memo
        state = None
        if state_of is not None:
            state = state_of(mi_scene, memo) if sensor is None else state_of(mi_scene, memo, sensor)
        for attempt in (1, 2):
            live = other_live_bsdfs(mi_scene, cache) + _held_media()
            if (registry_at != registry_changes() or threads_at != dr.thread_count()
                    or (background and foreground_moved(calls_at))):
                frozen.clear()          # (recorded anew below, or traced beside a call)
                registry_at, threads_at = registry_changes(), dr.thread_count()
                if background:
                    calls_at = foreground_mark()
            try:
                # (a collection freeing Dr.Jit memory while it records aborts; a background
                # replay beside another thread's draaw-mi call crashes: traced below instead)
                with COLLECTOR_PAUSED, background_replay(calls_at, background) as allowed:
                    if allowed:
                        return frozen(mi_scene, scene_scalars(mi_scene, scene, cache), seed, state, live,
                                      tuple(args))
            except RuntimeError as e:    # a scene the recorder cannot hold: trace it instead
                if caused_by_interrupt(e):                # (Ctrl-C: not the recorder's failure)
                    raise KeyboardInterrupt from None
                why = widened_error(scene, e)             # (the scene's fault, not the recorder's)
                if why is not None:
                    raise why from e
                if attempt == 1 and _REGISTRY_CHANGED in str(e):
                    # objects made outside draaw-mi's loads (a plain mi.load_dict): as above
                    registry_at, calls_at = None, _NO_CALLS_MARK
                    if before_retry is not None:
                        before_retry()
                    if background:       # (recorded anew at its next frame)
                        return body(mi_scene, seed, *args)
                    continue
                if attempt == 1 and live and _release_held_media():
                    # the media V3 / V4 held for other scenes may be what it could not hold:
                    # let them go (their scenes rebuild their tables) and record once more
                    if before_retry is not None:
                        before_retry()
                    continue
                error = e
                break
            else:                        # (not allowed: beside another thread's draaw-mi call)
                return body(mi_scene, seed, *args)
        failed.append(str(error))
        warnings.warn(f"freeze_render: dr.freeze could not record this render "
                      f"({_first_cause(error)}); it is traced from now on", RuntimeWarning, stacklevel=2)
        if before_retry is not None:
            before_retry()
        return body(mi_scene, seed, *args)
    call.frozen = frozen
    return call
