"""Executors: run frame specs in this process, or as idempotent tasks on a Dask cluster.

Both call :func:`~draaw_mi.batch.frame.safe_render_frame` and hand each result record to a
callback in the calling process (which logs it and advances the progress bar). Workers write
the EXR files themselves (a shared file system is assumed for remote clusters).

* ``inprocess``: scenes come from the planner's cache (loaded once), frames run in order, so
  the kernels of a job compile at its first frame and are reused after (recorded per frame).
* ``dask``: a ``LocalCluster`` of spawned worker processes, one task at a time each, with Dr.Jit
  threads per worker set so that workers × threads = cores — or an existing scheduler
  (``tcp://host:port``), whose workers keep their own Dr.Jit thread setting. Each worker loads a scene once and keeps it; a frame is a task with
  retries, so a lost worker costs only the frame it was rendering.
"""
from __future__ import annotations

import os
import uuid

import drjit as dr

from ..errors import DraawError
from .frame import safe_render_frame
from .worker import dask_render_frame

EXECUTORS = ("inprocess", "dask")


def run_inprocess(specs, cache, on_result, track_kernels: bool = True) -> None:
    """Render ``specs`` one after another in this process."""
    old = dr.flag(dr.JitFlag.KernelHistory)
    if track_kernels:
        dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for spec in specs:
            on_result(safe_render_frame(spec, cache, track_kernels))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, old)


def dask_client(workers: int | None = None, scheduler: str | None = None):
    """A Dask client: to ``scheduler``, or to a new LocalCluster of ``workers`` processes.

    Returns ``(client, cluster, drjit_threads)``; ``cluster`` is None for a remote scheduler.
    """
    try:
        import logging

        from distributed import Client, LocalCluster
    except ImportError:
        raise DraawError("the dask executor needs Dask: pip install 'draaw-mi[batch]' "
                         "(or pip install 'dask[distributed]')") from None
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as e:
            raise DraawError(f"--scheduler {scheduler!r}: cannot connect ({e})") from None
        return client, None, None
    cores = os.cpu_count() or 1
    n = workers or min(cores, 2)
    threads = max(1, cores // n)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    client.draaw_drjit_threads = threads      # run_dask passes it to each worker's first task
    return client, cluster, threads


def run_dask(specs, on_result, workers: int | None = None, scheduler: str | None = None,
             client=None, retries: int = 3) -> None:
    """Render ``specs`` as Dask tasks; results arrive in completion order."""
    from distributed import as_completed

    own = client is None
    cluster, threads = None, getattr(client, "draaw_drjit_threads", None)
    if own:
        client, cluster, threads = dask_client(workers, scheduler)
    # task keys unique to this run: a key that names only the frame's content (its hash) is
    # the same for another run of the manifest into another folder on a shared scheduler,
    # and Dask merges tasks of one key (that run's frames would go to the first run's files)
    run_token = uuid.uuid4().hex[:12]
    try:
        futures = {}
        for spec in specs:
            fut = client.submit(dask_render_frame, spec, threads, pure=False, retries=retries,
                                key=f"draaw-frame-{spec['job']}-{spec['frame']}-{run_token}")
            futures[fut] = spec
        for fut in as_completed(list(futures)):
            spec = futures[fut]
            try:
                res = fut.result()
            except Exception as e:  # noqa: BLE001 - KilledWorker, lost scheduler, ...
                res = {"job": spec["job"], "frame": spec["frame"], "output": spec["output"],
                       "error": f"{type(e).__name__}: {e}"}
            on_result(res)
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
