"""Batch rendering to multi-layer EXR that never loses a frame, in-process or on Dask.

``draaw_mi.batch.run(manifest, out=...)`` renders a manifest of scenes x camera paths x
parameter overrides to EXR frames, atomically and resumably (see :mod:`~draaw_mi.batch.runner`):

* :mod:`~draaw_mi.batch.manifest` reads and validates a manifest into jobs;
* :mod:`~draaw_mi.batch.planner` expands jobs into self-contained, hashed frame specs
  (:mod:`~draaw_mi.batch.digests`: file hashes and versions);
* :mod:`~draaw_mi.batch.frame` renders one frame spec through the scene's render session;
* :mod:`~draaw_mi.batch.exr` writes and reads the frame files, :mod:`~draaw_mi.batch.lock`
  keeps one run per folder, :mod:`~draaw_mi.batch.sheet` makes contact sheets;
* :mod:`~draaw_mi.batch.executors` run frames in this process or on Dask
  (:mod:`~draaw_mi.batch.worker` is the Dask task).
"""
from __future__ import annotations

import sys

from .._lazy import ShadowedModule, old_names
from .exr import frame_status, read_header
from .manifest import parse_manifest
from .planner import plan
from .runner import BatchResult, load, run, status

__all__ = ["BatchResult", "frame_status", "load", "parse_manifest", "plan", "read_header", "run", "status"]

# names the earlier release had here, served from their new modules with a DeprecationWarning
__getattr__ = old_names(__name__, {
    **dict.fromkeys(("PROBE_GRACE_S", "TEMP_PATTERNS", "log_path", "read_log", "remove_temp_files"),
                    f"{__name__}.runner"),
    "Manifest": f"{__name__}.manifest"})

# draaw_mi/batch/plan.py is now planner.py (draaw_mi.batch.plan is the function)
sys.modules.setdefault(f"{__name__}.plan", ShadowedModule(f"{__name__}.plan", f"{__name__}.planner"))
