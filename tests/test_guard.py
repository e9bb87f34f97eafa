"""draaw_mi.guard.COLLECTOR_PAUSED: Python's cycle collector kept away from a render pass --
automatic collections off inside, and a gc.collect() of another thread waits for the block
to end (a scene freed by it beside a frozen render killed the process)."""
from __future__ import annotations

import gc
import threading
import time

from draaw_mi.guard import COLLECTOR_PAUSED


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


def test_a_collection_inside_the_block_of_its_own_thread_runs_at_once():
    """(V3 / V4's media release collects inside a frozen render: it must not wait on itself)"""
    with COLLECTOR_PAUSED:
        with COLLECTOR_PAUSED:
            assert not gc.isenabled()
            gc.collect()
        assert not gc.isenabled()
    assert gc.isenabled()
