"""draaw_mi.guard.COLLECTOR_PAUSED: Python's cycle collector kept away from a render pass --
automatic collections off inside, and a gc.collect() of another thread waits for the block
to end (a scene freed by it beside a frozen render killed the process)."""
from __future__ import annotations

import _thread
import gc
import threading
import time
import warnings

import pytest

from draaw_mi import guard
from draaw_mi.guard import COLLECTOR_PAUSED


@pytest.fixture
def short_wait(monkeypatch):
    """Waits of 3 s, so that a wait on the wrong thing shows as a timeout, not a hang."""
    monkeypatch.setattr(guard, "COLLECTION_WAIT_S", 3.0)


def test_a_collection_of_another_thread_waits_for_the_paused_block():
    inside, events = threading.Event(), []

    def render():
        with COLLECTOR_PAUSED:
            inside.set()
            time.sleep(0.3)                 # (a frame in flight)
            events.append("block ended")

    t = threading.Thread(target=render)
    t.start()
    inside.wait(10)
    gc.collect()
    events.append("collected")
    t.join(10)
    assert events == ["block ended", "collected"]   # (without the hook: collected first)
    assert gc.isenabled()


def test_a_collection_inside_the_block_of_its_own_thread_runs_at_once(short_wait):
    """(V3 / V4's media release collects inside a frozen render: it must not wait on itself)"""
    with COLLECTOR_PAUSED:
        with COLLECTOR_PAUSED:
            assert not gc.isenabled()
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("error")          # (a timed-out wait warns)
                gc.collect()
            assert time.perf_counter() - t0 < 1.5      # (waiting on itself: the 3 s timeout)
        assert not gc.isenabled()
    assert gc.isenabled()


class _SlowToFree:
    """Garbage in a cycle whose finaliser takes a while: a collection in progress."""
    def __init__(self, started: threading.Event, events: list):
        self.me, self.started, self.events = self, started, events

    def __del__(self):
        self.started.set()
        time.sleep(0.3)
        self.events.append("collected")


def test_a_block_waits_for_a_collection_in_progress_on_another_thread(short_wait):
    started, events = threading.Event(), []

    def collect():
        _SlowToFree(started, events)
        gc.collect()

    t = threading.Thread(target=collect)
    t.start()
    assert started.wait(10)
    with COLLECTOR_PAUSED:
        events.append("block began")
    t.join(10)
    assert events == ["collected", "block began"]   # (without the wait: the block began first)


def test_a_ctrl_c_in_a_collections_wait_is_raised_after_it_and_the_wait_goes_on(short_wait):
    inside, events = threading.Event(), []

    def render():
        with COLLECTOR_PAUSED:
            inside.set()
            time.sleep(0.6)
            events.append("block ended")

    t = threading.Thread(target=render)
    t.start()
    inside.wait(10)
    threading.Timer(0.2, _thread.interrupt_main).start()    # (Ctrl-C while gc.collect() waits)
    with pytest.raises(KeyboardInterrupt):
        gc.collect()
        events.append("collected")
        time.sleep(2.0)                                      # (the interrupt raised again lands here)
    t.join(10)
    assert events == ["block ended", "collected"]   # (dropped by Python: collected first, no interrupt)


def test_a_wait_that_times_out_says_so(monkeypatch):
    monkeypatch.setattr(guard, "COLLECTION_WAIT_S", 0.2)
    inside, leave = threading.Event(), threading.Event()

    def render():
        with COLLECTOR_PAUSED:
            inside.set()
            leave.wait(10)

    t = threading.Thread(target=render)
    t.start()
    inside.wait(10)
    try:
        with pytest.warns(RuntimeWarning, match="waited for a render pass of another thread"):
            gc.collect()
    finally:
        leave.set()
        t.join(10)


class _Owner:
    """Something that holds things, as a scene holds its Mitsuba objects."""


class _Held:
    """A held thing that says on which thread it was freed."""
    freed_on: list = []

    def __del__(self):
        _Held.freed_on.append(threading.get_ident())


def _owner_of_one():
    owner = _Owner()
    owner.thing = _Held()
    return owner


def test_let_go_frees_at_once_where_no_other_thread_renders():
    _Held.freed_on = []
    owner, before = _owner_of_one(), guard.registry_changes()
    guard.let_go(owner)
    assert _Held.freed_on == [threading.get_ident()] and vars(owner) == {}
    assert guard.registry_changes() == before + 1


def test_let_go_beside_a_render_neither_waits_nor_frees_in_the_middle_of_it():
    """A scene let go on the main thread while a preview's worker renders: freed by the worker
    as it lets the guard go, not beside its render (a segmentation fault), and without making
    the main thread wait (a ``__del__`` that waits can deadlock)."""
    _Held.freed_on = []
    inside, release, seen = threading.Event(), threading.Event(), []

    def render():
        with guard.RENDER_GUARD:
            inside.set()
            release.wait(10)
            seen.append(list(_Held.freed_on))      # (still held at the end of the render)
    t = threading.Thread(target=render)
    t.start()
    inside.wait(10)
    started = time.perf_counter()
    guard.let_go(_owner_of_one())
    waited = time.perf_counter() - started
    release.set()
    t.join(10)
    assert waited < 1.0 and seen == [[]]
    assert _Held.freed_on == [t.ident]


def test_let_go_inside_a_render_of_the_same_thread_frees_when_the_render_ends():
    """Within its own render (a frozen recording in progress) a thread frees nothing: what it
    lets go waits for its outermost release of the guard."""
    _Held.freed_on = []
    with guard.RENDER_GUARD:
        with guard.RENDER_GUARD:
            guard.let_go(_owner_of_one())
        assert _Held.freed_on == []
    assert _Held.freed_on == [threading.get_ident()]


def test_a_scene_dropped_beside_a_render_is_freed_when_the_render_lets_go():
    """``DraawScene.__del__`` lets its objects go through :func:`guard.let_go`: its draaw BSDFs
    stay alive while another thread holds the guard and are gone once it lets go."""
    import draaw_mi
    from draaw_mi.materials.draaw_bsdf import LIVE_INSTANCES
    from conftest import tiny_description
    base = len(LIVE_INSTANCES)
    scene = draaw_mi.load_scene(tiny_description(resolution=[8, 8]))
    assert len(LIVE_INSTANCES) == base + 2
    inside, release, seen = threading.Event(), threading.Event(), []

    def render():
        with guard.RENDER_GUARD:
            inside.set()
            release.wait(10)
            seen.append(len(LIVE_INSTANCES))
    t = threading.Thread(target=render)
    t.start()
    inside.wait(10)
    del scene
    release.set()
    t.join(10)
    gc.collect()
    assert seen == [base + 2] and len(LIVE_INSTANCES) == base


def test_a_background_replay_is_refused_once_another_thread_began_a_call():
    """A preview's worker replays a recording only while no other thread has begun a draaw-mi
    call since it was made (Dr.Jit 1.5 crashed replaying after one); its own calls do not count."""
    mark = guard.foreground_mark()
    with guard.FOREGROUND:                                  # (this thread's own call)
        pass
    with guard.background_replay(mark) as allowed:
        assert allowed
    t = threading.Thread(target=lambda: guard.FOREGROUND.__enter__() or guard.FOREGROUND.__exit__())
    t.start()
    t.join(10)
    with guard.background_replay(mark) as allowed:
        assert not allowed
    with guard.background_replay(mark, background=False) as allowed:
        assert allowed                                      # (the main thread's own renders)
    assert guard.foreground_moved(mark)
    with guard.background_replay(guard.foreground_mark()) as allowed:
        assert allowed                                      # (a recording made afresh)


def test_a_call_waits_for_a_replay_of_another_thread():
    """A draaw-mi call that begins while a background thread replays waits for the replay."""
    events, inside = [], threading.Event()

    def worker():
        with guard.background_replay(guard.foreground_mark()) as allowed:
            inside.set()
            time.sleep(0.3)
            events.append(("replay ended", allowed))
    t = threading.Thread(target=worker)
    t.start()
    inside.wait(10)
    with guard.FOREGROUND:
        events.append(("call began", True))
    t.join(10)
    assert events == [("replay ended", True), ("call began", True)]


def test_let_go_just_before_the_holder_releases_is_still_freed():
    """A thing let go while the holder is between its last free and its release (the guard still
    held, so ``let_go`` leaves it pending) is freed once the guard is released, not left until
    the next render. The holder is paused there by a line tracer."""
    import inspect
    import sys
    _Held.freed_on = []
    code = guard._RenderGuard.release.__code__
    lines, first = inspect.getsourcelines(guard._RenderGuard.release)
    at = first + next(i for i, line in enumerate(lines) if "self._lock.release()" in line)
    paused, go = threading.Event(), threading.Event()

    def tracer(frame, event, arg):
        if frame.f_code is not code:
            return None

        def local(frame, event, arg):
            if event == "line" and frame.f_lineno == at and not paused.is_set():
                paused.set()
                go.wait(10)
            return local
        return local

    def holder():
        sys.settrace(tracer)
        with guard.RENDER_GUARD:
            pass
        sys.settrace(None)
    t = threading.Thread(target=holder)
    t.start()
    assert paused.wait(10)
    guard.let_go(_owner_of_one())            # pending: the holder has not released yet
    assert _Held.freed_on == []
    go.set()
    t.join(10)
    assert len(_Held.freed_on) == 1 and not guard.RENDER_GUARD._pending
