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
