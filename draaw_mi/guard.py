"""One render at a time in this process: :data:`RENDER_GUARD`.

Dr.Jit 1.5's ``dr.freeze`` recording breaks when another thread renders, synchronises or
creates plugins while it records or replays: measured, two threads rendering two scenes
(each with its own integrator; Mitsuba's own ``path`` too) failed with
'jit_var_schedule(): not permitted' and 'record(): error encountered while recording', and
with draaw-mi's frozen renders the process aborted (LLVM IR that did not parse, 'jit_var(r223):
unknown variable!') or crashed on a ``dr.sync_thread()``; a scene loaded meanwhile made a
replay fail ('number of registry entries (10) did not match ... (8)') and the preview fell
back to tracing for good. That is a preview's worker beside a render(), fit, batch or
``load_scene`` in the same notebook, or the user's own threads calling render().

Parameter updates count too: a batch's ``params.update()`` (its frame's camera) made while
the preview replayed its recording of another scene rendered 4 of 8 frames wrong (pixels off
by up to 1.6), seen in ``tests/test_render_threads.py``.

So draaw-mi holds :data:`RENDER_GUARD` around each render pass (with its evaluation and
sync), each preview frame and parameter update, each fit iteration (renders, gradient
passes, the optimiser's update), each batch frame and each scene load. Kernels use every
core already, so taking turns costs little. One integrator instance per setting serves every
thread for the same reason (:func:`draaw_mi.render.make_integrator`). It is re-entrant (a
guarded block may render again: the batch's fallback to :func:`draaw_mi.render`). Take a scene's own lock (``draaw_mi.frozen._SceneState.lock``)
before it, never after. Your own Dr.Jit work in another thread (a ``dr.backward`` of a
differentiable render, ``mi.render``) is not guarded: hold it there too while a preview runs::

    from draaw_mi.guard import RENDER_GUARD
    with RENDER_GUARD:
        dr.backward(loss)

Take it around such calls, never inside a Dr.Jit callback (an integrator's
``render_backward``, a ``dr.CustomOp``): Dr.Jit holds its AD lock there, which a preview's
frozen call waits for while it holds the guard -- tried, the two threads deadlocked.
"""
from __future__ import annotations

import contextlib
import threading

#: see the module docstring
RENDER_GUARD = threading.RLock()

#: fewest Dr.Jit threads with which Mitsuba 3.9.1 reads an EXR file (see exr_reading_threads)
EXR_READ_THREADS = 2


@contextlib.contextmanager
def exr_reading_threads():
    """At least :data:`EXR_READ_THREADS` Dr.Jit threads within the block, the count as it was
    after it; taken around Mitsuba's scene loads and image reads. Mitsuba 3.9.1 decodes EXR
    files on Dr.Jit's thread pool (``Bitmap::read_exr``: OpenEXR's tasks through nanothread)
    and with 0 or 1 threads waits for ever on an OpenEXR semaphore: ``draaw-mi render
    --threads 1`` of a scene with an EXR texture or environment map hung, so did a batch's
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
    import drjit as dr
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
