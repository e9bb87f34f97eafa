"""One render at a time in this process: :data:`RENDER_GUARD`.

A ``dr.freeze`` recording in Dr.Jit 1.5 breaks when another thread renders, synchronises,
creates plugins or updates parameters while it records or replays: the recording fails
('jit_var_schedule(): not permitted', 'record(): error encountered while recording'), a
replay reads another scene's values, or the process aborts. In a notebook that is a
preview's worker beside a render, fit, batch or scene load of the main thread.

So every render of draaw-mi runs under :data:`RENDER_GUARD`: each pass of a render session
(:mod:`draaw_mi.rendering.session`, with its evaluation and sync), each preview frame and
parameter update, each fit iteration (renders, gradient passes, the optimiser's update), each
batch frame, each scene load and plugin made, and every primal ``mi.render`` with a draaw
integrator (:meth:`DraawIntegrator.render <draaw_mi.integrators.common.DraawIntegrator.render>`).
Kernels use every core already, so taking turns costs little. The guard is re-entrant, but a
scene's lock comes before it, never after: a block that renders a scene holds that scene's
lock first (``with holding(scene):``, :func:`draaw_mi.rendering.session.holding`), else it
can wait on a preview of the scene that holds the lock and waits for the guard.

Mitsuba's own integrators called directly (``mi.render`` with ``path``) and your own Dr.Jit
work beside a running preview (a ``dr.backward`` of a differentiable render) are not
guarded by draaw-mi: hold the guard around them, and mark them as your work
(:data:`FOREGROUND`: a preview traces beside it and records anew after it)::

    from draaw_mi.guard import FOREGROUND, RENDER_GUARD
    with RENDER_GUARD, FOREGROUND:
        dr.backward(loss)

Take it around such calls, never inside a Dr.Jit callback (an integrator's
``render_backward``, a ``dr.CustomOp``): Dr.Jit holds its AD lock there, which a preview's
frozen call waits for while it holds the guard, and the two threads would deadlock.

Freeing a scene is Dr.Jit work too: a draaw BSDF or a scene's buffers freed on one thread
while another records or replays a render aborts the process ("jit_var(r1343): unknown
variable!") or crashes it. So a scene and its render session are let go under the guard
(:func:`let_go`, from their ``__del__``): at once, or, while another thread holds the guard, by
that thread as it lets the guard go; scene loads and these frees are counted
(:func:`registry_changes`) so that no recording made before is replayed as if nothing had
changed. Python's cycle collector frees at arbitrary times on arbitrary
threads, so while a render pass runs (:data:`COLLECTOR_PAUSED`) automatic collections are off
and a ``gc.collect()`` of another thread waits for the pass to end (at most
:data:`COLLECTION_WAIT_S` seconds, then it goes on with a ``RuntimeWarning``). While a
collection waits so, a ``gc.collect()`` elsewhere returns at once having collected nothing
(Python runs one collection at a time).
"""
from __future__ import annotations

import _thread
import atexit
import contextlib
import functools
import gc
import threading
import warnings

import drjit as dr


class _RenderGuard:
    """A re-entrant lock (``with``, :meth:`acquire`, :meth:`release`) that also frees, while
    held, what :func:`let_go` was handed, and counts the frees and scene loads that change
    Dr.Jit's registry (:func:`registry_changes`). What another thread lets go while the guard
    is held is freed by the holder as it lets the guard go (its outermost release), never in
    the middle of that thread's render."""
    __slots__ = ("_lock", "_depth", "_pending", "changes")

    def __init__(self):
        self._lock = threading.RLock()
        self._depth = 0                 # the holder's nesting depth (only the holder changes it)
        self._pending: list = []        # what other threads let go meanwhile
        self.changes = 0

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        got = self._lock.acquire(blocking, timeout)
        if got:
            self._depth += 1
        return got

    def release(self) -> None:
        outermost = self._depth == 1
        if outermost:
            while self._pending:        # (a free may let go of more: freed here too)
                held = self._pending.pop()
                del held
                self.changes += 1
        self._depth -= 1
        self._lock.release()
        # (what another thread let go just before this release, finding the guard held, is
        # freed now by whoever takes it)
        while outermost and self._pending and self.acquire(blocking=False):
            self.release()

    def __enter__(self) -> bool:
        return self.acquire()

    def __exit__(self, *exc) -> bool:
        self.release()
        return False


#: see the module docstring
RENDER_GUARD = _RenderGuard()


def let_go(owner) -> None:
    """Drop what ``owner`` holds (its ``__dict__``) under :data:`RENDER_GUARD`: at once when
    no other thread holds the guard, else when that thread lets it go. For a ``__del__``:
    a scene's Mitsuba objects leave Dr.Jit's registry of virtual-call targets, which a
    recording or replay of another thread would read freed (a segmentation fault), and which
    a recording replayed afterwards must not assume unchanged (:func:`registry_changes`).
    Never waits, so a ``__del__`` that runs where the current thread holds another lock cannot
    deadlock with a render that waits for that lock."""
    held = dict(owner.__dict__)
    owner.__dict__.clear()
    RENDER_GUARD._pending.append(held)
    del held
    if RENDER_GUARD.acquire(blocking=False):        # (else the holder frees it)
        RENDER_GUARD.release()


class _Foreground:
    """The draaw-mi calls in progress (:func:`draaw_mi.render`, :func:`draaw_mi.fit`, scene
    loads, a batch frame rendered in this process), counted per thread, with the sequence number
    of each thread's latest call (:func:`foreground_mark`), and the ``dr.freeze`` replays of
    background threads (a preview's worker, :func:`background_replay`). Dr.Jit 1.5 crashes
    (a segmentation fault in a later replay, ``PyType_GetName`` inside ``FrozenFunction``) when a
    background thread replays a recording after another thread rendered, fitted or updated a
    scene: 1-2 runs in 3 of 15-20 s of renders or fits beside a preview, also with the calls
    and the replays never overlapping in time; traced frames beside them never crashed (0 in 6
    runs). So a background thread replays only recordings made since the latest draaw-mi call
    of any other thread, and such a call waits for a replay in progress to end (a frame of a
    few milliseconds) before it starts. Nested and re-entrant."""
    __slots__ = ()
    depth: dict = {}                    # thread ident -> nesting depth of its calls
    latest: dict = {}                   # thread ident -> sequence number of its latest call
    sequence = 0
    replaying: dict = {}                # thread ident -> its replays in progress
    cond = threading.Condition()

    def __enter__(self):
        cls, me = _Foreground, threading.get_ident()
        with cls.cond:
            cls.depth[me] = cls.depth.get(me, 0) + 1
            if cls.depth[me] > 1:
                return
            cls.sequence += 1
            cls.latest[me] = cls.sequence
            if not cls.cond.wait_for(lambda: not any(t != me for t in cls.replaying), timeout=COLLECTION_WAIT_S):
                warnings.warn(f"draaw_mi.guard: a call waited for a replay of another thread for "
                              f"{COLLECTION_WAIT_S:g} s and went on", RuntimeWarning, stacklevel=2)

    def __exit__(self, *exc):
        cls = _Foreground
        with cls.cond:
            _count_out(cls.depth, threading.get_ident())
        return False


def _count_out(counts: dict, me: int) -> int:
    """One less for thread ``me`` in the per-thread ``counts`` (dropped at 0); what is left."""
    n = counts.pop(me) - 1
    if n:
        counts[me] = n
    return n


#: ``with FOREGROUND:`` around a draaw-mi call of the caller's thread (see :class:`_Foreground`)
FOREGROUND = _Foreground()


def in_foreground(fn):
    """``fn`` run inside :data:`FOREGROUND` (a decorator for draaw-mi's entry points)."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with FOREGROUND:
            return fn(*args, **kwargs)
    return wrapper


def foreground_mark() -> tuple:
    """Where draaw-mi's calls stand now, for a recording made now: the latest call's sequence
    number, and whether a thread other than this one is inside a call."""
    cls, me = _Foreground, threading.get_ident()
    with cls.cond:
        return cls.sequence, any(t != me for t in cls.depth)


def foreground_moved(mark: tuple) -> bool:
    """Whether a draaw-mi call began since ``mark`` (:func:`foreground_mark`), or one was in
    progress beside it: a background thread no longer replays a recording made at ``mark``."""
    return mark[1] or _Foreground.sequence > mark[0]


def _others_since(mark: tuple, me: int) -> bool:
    cls = _Foreground
    return mark[1] or any(t != me and (n > mark[0] or t in cls.depth) for t, n in cls.latest.items())


@contextlib.contextmanager
def background_replay(mark: tuple, background: bool = True):
    """Around a ``dr.freeze`` replay of a recording made at ``mark`` (:func:`foreground_mark`):
    yields whether it may run. Always for a caller that is not ``background``; for a background
    thread only when no other thread began a draaw-mi call since, or is in one (a call that
    begins meanwhile waits for the replay to end; see :class:`_Foreground`)."""
    if not background:
        yield True
        return
    cls, me = _Foreground, threading.get_ident()
    with cls.cond:
        allowed = not _others_since(mark, me)
        if allowed:
            cls.replaying[me] = cls.replaying.get(me, 0) + 1
    try:
        yield allowed
    finally:
        if allowed:
            with cls.cond:
                _count_out(cls.replaying, me)
                cls.cond.notify_all()


def registry_changes() -> int:
    """How many times scenes were made or let go (:func:`let_go`, :func:`note_registry_change`):
    a ``dr.freeze`` recording made before a change may hold freed virtual-call targets, or
    miss new ones, and is recorded anew (:func:`draaw_mi.rendering.frozen.freeze_render`)."""
    return RENDER_GUARD.changes


def note_registry_change() -> None:
    """Count a change of Dr.Jit's registry (Mitsuba objects made: a scene loaded); call it
    holding :data:`RENDER_GUARD`."""
    RENDER_GUARD.changes += 1


#: the longest a ``gc.collect()`` waits for a render pass of another thread to end (and a
#: pass for a collection of another thread, a draaw-mi call for a replay of another thread):
#: then it goes on regardless, with a ``RuntimeWarning`` (a pass that long on a background
#: thread is not a preview's)
COLLECTION_WAIT_S = 60.0


class _CollectorPaused:
    """Python's cycle collector kept away from a render (see the module docstring): automatic
    collections off (on again when the last paused block of any thread ends, if they were on
    when the first began), a collection in progress or waiting on another thread finished
    before the first block of a thread starts (so back-to-back passes cannot starve it), and a
    ``gc.collect()`` of another thread made to wait until no block runs
    (:func:`_collection_waits`). Nested and across threads. A class rather than a generator
    context manager: it runs on every replay of a frozen render."""
    __slots__ = ()
    depth: dict = {}                   # thread ident -> nesting depth of its paused blocks
    was_enabled = False
    collecting = None                  # ident of the thread in a collection, if any
    waiting = 0                        # collections waiting for the blocks to end
    exiting = False                    # the interpreter is shutting down: nothing waits
    interrupted: BaseException | None = None   # an interrupt that landed in a collection's wait
    cond = threading.Condition(threading.RLock())   # (an automatic collection may start inside)

    def __enter__(self):
        cls, me = _CollectorPaused, threading.get_ident()
        with cls.cond:
            if me not in cls.depth:
                _wait(lambda: cls.exiting or (cls.collecting in (None, me) and not cls.waiting),
                      "a render pass waited for a collection of another thread")
                if not cls.depth:
                    cls.was_enabled = gc.isenabled()
                    gc.disable()
            cls.depth[me] = cls.depth.get(me, 0) + 1

    def __exit__(self, *exc):
        cls, me = _CollectorPaused, threading.get_ident()
        with cls.cond:
            if not _count_out(cls.depth, me) and not cls.depth:
                if cls.was_enabled:
                    gc.enable()
                cls.cond.notify_all()
        return False


#: ``with COLLECTOR_PAUSED:`` around a render pass (see :class:`_CollectorPaused`)
COLLECTOR_PAUSED = _CollectorPaused()


def _wait(ready, what: str) -> None:
    """Wait on the condition (held) until ``ready()``, at most :data:`COLLECTION_WAIT_S`
    seconds, then warn and go on."""
    if not _CollectorPaused.cond.wait_for(ready, timeout=COLLECTION_WAIT_S):
        warnings.warn(f"draaw_mi.guard: {what} for {COLLECTION_WAIT_S:g} s and went on",
                      RuntimeWarning, stacklevel=3)


def _collection_waits(phase: str, info: dict) -> None:
    """``gc.callbacks`` hook: a collection starts only once no other thread is in a
    :data:`COLLECTOR_PAUSED` block (at most :data:`COLLECTION_WAIT_S` seconds), and is known
    while it runs (a block of another thread waits for its end). An exception raised in a
    ``gc`` callback is dropped by Python and the collection goes on: a Ctrl-C that lands in
    the wait is kept, the wait goes on, and the interrupt is raised in the main thread again
    just after the collection is over."""
    cls, me = _CollectorPaused, threading.get_ident()
    with cls.cond:
        if phase == "start":
            cls.waiting += 1
            try:
                while True:
                    try:
                        _wait(lambda: cls.exiting or not any(t != me for t in cls.depth),
                              "a gc.collect() waited for a render pass of another thread")
                        break
                    except KeyboardInterrupt as e:  # (kept, raised again at "stop")
                        cls.interrupted = e
                    except Exception:               # noqa: BLE001 - (a warning made an error)
                        break
            finally:
                cls.waiting -= 1
            cls.collecting = me
        else:
            cls.collecting = None
            cls.cond.notify_all()
            if cls.interrupted is not None and not cls.exiting:
                cls.interrupted = None
                # (from another thread, a moment later: raised in this callback, it would be
                # dropped again)
                threading.Timer(0.05, _thread.interrupt_main).start()


def _exiting() -> None:
    _CollectorPaused.exiting = True
    with _CollectorPaused.cond:
        _CollectorPaused.cond.notify_all()


gc.callbacks.append(_collection_waits)
# (nothing waits once the interpreter shuts down: a daemon worker stopped inside a block would
# make the final collections wait. threading's exit hooks run before atexit's, whose handlers
# registered after this module (last in, first out) may collect)
_register = getattr(threading, "_register_atexit", None)
(_register or atexit.register)(_exiting)
atexit.register(lambda: _collection_waits in gc.callbacks and gc.callbacks.remove(_collection_waits))

#: fewest Dr.Jit threads with which Mitsuba 3.9.1 reads an EXR file (see exr_reading_threads)
EXR_READ_THREADS = 2


@contextlib.contextmanager
def exr_reading_threads():
    """At least :data:`EXR_READ_THREADS` Dr.Jit threads within the block, the count as it was
    after it; taken around Mitsuba's scene loads and image reads. Mitsuba 3.9.1 decodes EXR
    files on Dr.Jit's thread pool (``Bitmap::read_exr``: OpenEXR's tasks through nanothread)
    and with 0 or 1 threads waits for ever on an OpenEXR semaphore: without this, ``draaw-mi
    render --threads 1`` of a scene with an EXR texture or environment map hangs, as do a batch's
    Dask workers on two cores (one thread each) and a ``dr.set_thread_count(1)`` notebook.
    Holds :data:`RENDER_GUARD` when it changes the count (no render runs meanwhile).

    >>> import drjit as dr
    >>> n = dr.thread_count(); dr.set_thread_count(1)
    >>> with exr_reading_threads():
    ...     dr.thread_count()
    2
    >>> dr.thread_count(); dr.set_thread_count(n)
    1
    """
    if dr.thread_count() >= EXR_READ_THREADS:
        yield
        return
    with RENDER_GUARD:
        before = dr.thread_count()
        dr.set_thread_count(EXR_READ_THREADS)
        try:
            yield
        finally:
            dr.set_thread_count(before)
