"""Executors: run frame specs in this process, or as idempotent tasks on a Dask cluster.

Both call :func:`~draaw_mi.batch.frame.safe_render_frame` and hand each result record to a
callback in the calling process (which logs it and advances the progress bar). Workers write
the EXR files themselves (a shared file system is assumed for remote clusters).

* ``inprocess``: scenes come from the planner's cache (loaded once), frames run in order, so
  the kernels of a job compile at its first frame and are reused after (recorded per frame).
* ``dask``: a ``LocalCluster`` of spawned worker processes, one task at a time each, with Dr.Jit
  threads per worker set so that workers × threads = cores — or an existing scheduler
  (``tcp://host:port``, or ``tls://host:port`` with certificates), whose workers keep their own
  Dr.Jit thread setting. Each worker loads a scene once and keeps it; a frame is a task with
  retries, so a lost worker costs only the frame it was rendering, and a frame that kills
  every worker it runs on is given up after ``retries`` more tries (reported as failed).

Nothing is exposed beyond this machine by default: the LocalCluster's scheduler and workers
listen on 127.0.0.1, and its dashboard is off (``dashboard=True``: on 127.0.0.1 too).
"""
from __future__ import annotations

import logging
import os
import shutil
import sys
import uuid

import drjit as dr

from ..errors import DraawError, RenderError
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


#: tries a frame is given after its worker dies, before it counts as failed (``--retries``)
DEFAULT_RETRIES = 2

#: the Security fields of a TLS client, by the names batch.run's ``tls`` takes
TLS_KEYS = {"ca_file": "tls_ca_file", "cert": "tls_client_cert", "key": "tls_client_key"}


def dask_client(workers: int | None = None, scheduler: str | None = None, tls: dict | None = None,
                dashboard: bool = False, retries: int = DEFAULT_RETRIES, scratch: str | None = None):
    """A Dask client: to ``scheduler``, or to a new LocalCluster of ``workers`` processes.

    ``tls``: ``{"ca_file", "cert", "key"}`` files for a ``tls://`` scheduler (without them,
    Dask's own configuration, ``distributed.comm.tls``, applies). A new LocalCluster listens on
    127.0.0.1 only; ``dashboard`` serves its dashboard there too (``client.dashboard_link``);
    a task whose worker dies is tried ``retries`` more times, then reported (Dask's
    ``allowed-failures``; a remote scheduler's own setting applies to it), and a worker holds
    one task at a time (``worker-saturation`` 1: a task queued behind a crash would count as a
    failure too; a remote scheduler's should say the same).
    ``scratch``: the folder a new LocalCluster's scheduler and workers keep their scratch
    space in (Dask's default is ``dask-scratch-space`` in the temporary folder, outside a
    batch's ``--out``).
    Returns ``(client, cluster, drjit_threads)``; ``cluster`` is None for a remote scheduler.
    """
    try:
        import dask  # (optional: the batch extra; 0.3 s with distributed)
        from distributed import Client, LocalCluster, Security
    except ImportError:
        raise DraawError("the dask executor needs Dask: pip install 'draaw-mi[batch]' "
                         "(or pip install 'dask[distributed]')") from None
    if scheduler:
        security = None
        if tls:
            security = Security(require_encryption=True, **{TLS_KEYS[k]: v for k, v in tls.items()})
        try:
            client = Client(scheduler, timeout="20s", **({"security": security} if security else {}))
        except (OSError, ValueError, TypeError) as e:
            raise DraawError(f"--scheduler {scheduler!r}: cannot connect ({_first_line(e)})") from None
        return client, None, None
    cores = os.cpu_count() or 1
    n = workers or min(cores, 2)
    threads = max(1, cores // n)
    # one task at a time on a worker (no queued second one): a frame that kills its worker
    # then takes no innocent frame with it (each task on a dying worker counts one failure)
    # the scheduler's work space too (Dask's temporary-directory: its lock files, and its
    # scheduler-* folders after a kill) in ``scratch``, not in the system's temporary folder
    with dask.config.set({"distributed.scheduler.allowed-failures": int(retries),
                          "distributed.scheduler.worker-saturation": 1.0,
                          **({"temporary-directory": scratch} if scratch else {})}):
        # the scheduler's HTTP routes (health, metrics; the dashboard only with ``dashboard``)
        # on a free port of 127.0.0.1: without an address they took 8787, and a second
        # cluster on the machine warned that the port was in use
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0", scheduler_kwargs={"dashboard": bool(dashboard)},
                               silence_logs=logging.ERROR,
                               **({"local_directory": scratch} if scratch else {}))
    client = Client(cluster)
    client.draaw_drjit_threads = threads      # run_dask passes it to each worker's first task
    return client, cluster, threads


def refuse_in_a_workers_import() -> None:
    """Raise :class:`~draaw_mi.errors.RenderError` when called while a spawned process (a Dask
    worker) imports the main script again (``__main__`` named ``__mp_main__``): a script that
    runs a batch at its top level, without ``if __name__ == "__main__":``, would run it once more
    in every worker, each stopped at the output folder's lock."""
    frame = sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__") != "__mp_main__":
        frame = frame.f_back             # (the script runs as __mp_main__ before it is __main__)
    if frame is not None:
        raise RenderError("batch.run: called while a worker process imports your script again; run "
                          "the batch under `if __name__ == \"__main__\":`")


def run_dask(specs, on_result, workers: int | None = None, scheduler: str | None = None,
             client=None, retries: int = DEFAULT_RETRIES, dashboard: bool = False, tls: dict | None = None,
             scratch: str | None = None) -> None:
    """Render ``specs`` as Dask tasks; results arrive in completion order. A frame whose
    worker died on every try is a failed frame (``KilledWorker``), as is any other task error;
    the run goes on with the other frames. ``scratch``: the workers' scratch folder of a
    LocalCluster this run starts (removed after it)."""
    from distributed import as_completed  # (optional: the batch extra)
    from distributed.scheduler import KilledWorker

    own = client is None
    cluster, threads = None, getattr(client, "draaw_drjit_threads", None)
    if own:
        try:
            client, cluster, threads = dask_client(workers, scheduler, tls=tls, dashboard=dashboard,
                                                   retries=retries, scratch=scratch)
        except RuntimeError as e:
            if scratch:            # (the folder the failed cluster made: removed on every path)
                shutil.rmtree(scratch, ignore_errors=True)
            if "failed to start" not in str(e) or scheduler is not None:
                raise
            # spawned workers import the main script again: one that calls batch.run at its top
            # level runs it in every worker, which stops at the output lock ("Nanny failed to
            # start", pages of tracebacks)
            raise RenderError("batch: Dask's worker processes failed to start. A script that runs a "
                             "batch with the dask executor must do it under `if __name__ == "
                             "\"__main__\":` (each worker imports the script again); the workers' "
                             "own errors are above") from None
        if dashboard and cluster is not None:
            print(f"batch: Dask dashboard at {client.dashboard_link}", file=sys.stderr, flush=True)
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
            except KilledWorker:
                tries = f" {retries + 1} times" if own and scheduler is None else ""
                res = {"job": spec["job"], "frame": spec["frame"], "output": spec["output"],
                       "error": f"KilledWorker: the worker rendering it died{tries} (a crash or out of "
                                "memory: the workers' logs say which); the other frames go on"}
            except Exception as e:  # noqa: BLE001 - a lost scheduler, an unpicklable result, ...
                res = {"job": spec["job"], "frame": spec["frame"], "output": spec["output"],
                       "error": f"{type(e).__name__}: {_first_line(e)}"}
            on_result(res)
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
                if scratch:
                    shutil.rmtree(scratch, ignore_errors=True)


def _first_line(e: Exception) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__
