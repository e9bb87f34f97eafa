"""The Dask task: render one frame spec in a worker process, with a per-worker scene cache.

Kept in its own small module so that unpickling the task in a spawned worker imports only
this and :mod:`draaw_mi` (which selects the variant and registers the plugins).
"""
from __future__ import annotations

import threading

import drjit as dr

from .frame import SceneCache, safe_render_frame

_CACHE = None
_GUARD = threading.Lock()


def dask_render_frame(spec: dict, drjit_threads: int | None = None) -> dict:
    """Render ``spec`` with this worker's scene cache (set up on the first task)."""
    global _CACHE
    with _GUARD:
        if _CACHE is None:
            if drjit_threads:
                dr.set_thread_count(int(drjit_threads))   # DRJIT_NUM_THREADS is ignored
            _CACHE = SceneCache()
    return safe_render_frame(spec, _CACHE)
