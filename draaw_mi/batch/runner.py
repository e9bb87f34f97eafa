"""Running a batch: validate, plan, lock, render and log (:func:`run`), and its status.

``draaw_mi.batch.run(manifest)`` validates a manifest (see :mod:`draaw_mi.batch.manifest`),
plans every frame (:mod:`~draaw_mi.batch.planner`), skips the frames already finished (file
present and its header's job hash equal to the plan's), renders the rest with an executor
(:mod:`~draaw_mi.batch.executors`) and logs every frame to a JSONL file beside the outputs.

=================  ================================================================
Parameter          Meaning
=================  ================================================================
``manifest``       TOML/JSON file name or dict
``out``            put every output under this folder (relative patterns resolve there; files
                   outside it are refused, default: the current folder)
``executor``       ``"inprocess"`` (default) or ``"dask"``
``workers``        Dask LocalCluster worker processes (default: 2 or the core count)
``scheduler``      ``tcp://host:port`` or ``tls://host:port`` of an existing Dask scheduler
                   (instead of a LocalCluster)
``tls``            ``{"ca_file", "cert", "key"}``: the files of a ``tls://`` scheduler's client
``retries``        tries after a frame's worker dies (a crash, out of memory), before the frame
                   is reported failed (default 2; dask runs only)
``dashboard``      serve the LocalCluster's dashboard on 127.0.0.1 (default: none)
``allow_outside_out``  let the manifest put files outside ``out`` (absolute or ``..`` patterns)
``dry_run``        plan and report, render nothing
``verify``         decode every finished frame; one that does not decode is ``damaged`` and
                   rendered again (without it, a frame's header, offset table and chunk
                   headers are checked, not its compressed bytes)
``overwrite``      replace frames that another manifest file made (default: refuse the run)
``progress``       tqdm bar with frames done / failed and ETA (``True``: in a log, lines instead);
                   ``"lines"``: a line every 10 s (logs)
``on_result``      callback called with every frame's result record (tests, UIs)
=================  ================================================================

Phases: validate (bad manifest → :class:`~draaw_mi.errors.SceneError`, nothing rendered) →
plan → lock the output folders (a second run on them → :class:`~draaw_mi.errors.BusyError`,
:mod:`~draaw_mi.batch.lock`) → remove temp files of killed runs → render → log → contact sheets.

>>> import draaw_mi.batch as batch                             # doctest: +SKIP
>>> res = batch.run("scenes/batch_example.toml", out="out")    # doctest: +SKIP
>>> res.complete, res.summary()                                # doctest: +SKIP
(True, 'batch: 36 frames: 36 rendered, 0 already done, 0 failed; all 36 frames present ...')
"""
from __future__ import annotations

import glob
import importlib.util
import json
import numbers
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import DraawError, ParameterError, SceneError, suggest
from ..progress import check_mode, progress_bar
from .confine import check_inside
from .executors import DEFAULT_RETRIES, EXECUTORS, TLS_KEYS, refuse_in_a_workers_import, run_dask, run_inprocess
from .exr import MANIFEST_ATTR, frame_status, preview_path, read_frame, read_header, write_preview
from .frame import SceneCache
from .lock import output_locks, running_pid
from .manifest import Manifest, fixed_folder, parse_manifest
from .planner import check_writable, file_identity, input_files, plan, prepare_outputs, same_file
from .sheet import contact_sheets, sheet_path

TEMP_PATTERNS = (".draaw-*.exr", ".draaw-*.png", ".draaw-probe-*")   # atomic writes, folder probes
PROBE_GRACE_S = 60.0          # a folder probe younger than this may be another run's


@dataclass
class BatchResult:
    """What a batch run did. ``complete``: every planned frame is finished on disk."""
    total: int
    skipped: int = 0
    rendered: int = 0
    previews: int = 0                                 # PNGs written from finished EXRs
    sheet_error: str = ""                             # why the contact sheets were not written
    log_error: str = ""                               # why the log stopped (a full disk)
    failed: list = field(default_factory=list)        # result records with "error"
    seconds: float = 0.0
    log: str = ""
    new_kernels: dict = field(default_factory=dict)   # job -> kernels first seen after its first frame
    results: list = field(default_factory=list)
    missing: int = 0
    # frames that read as finished but did not decode when the run read them after rendering
    # (for a contact sheet): not rendered again, counted in ``missing``
    damaged: list = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.missing == 0

    def summary(self) -> str:
        rate = f", {self.seconds / self.rendered:.2f} s/frame" if self.rendered else ""
        state = (f"all {self.total} frames present" if self.complete
                 else f"{self.missing} of {self.total} frames missing")
        recompiles = sum(self.new_kernels.values())
        extra = f"; WARNING: {recompiles} kernel(s) compiled after a job's first frame" if recompiles else ""
        previews = f" ({self.previews} previews from their EXRs)" if self.previews else ""
        if self.damaged:
            extra += (f"; {len(self.damaged)} frame(s) counted as done do not decode (first: "
                      f"{self.damaged[0]}): run again with --verify (verify=True) to render them again")
        if self.sheet_error:
            extra += f"; contact sheets not written: {self.sheet_error}"
        if self.log_error:
            extra += f"; WARNING: {self.log_error}"
        return (f"batch: {self.total} frames: {self.rendered} rendered, {self.skipped} already done"
                f"{previews}, {len(self.failed)} failed; {state} ({self.seconds:.1f} s{rate}); "
                f"log {self.log}{extra}")


def load(manifest, out: str | None = None, cache=None, allow_outside_out: bool = False):
    """Validate and plan: ``(Manifest, frame specs, scene cache)``. Raises on a bad manifest,
    and on one whose files would lie outside the output folder (unless ``allow_outside_out``:
    :mod:`~draaw_mi.batch.confine`)."""
    # (the string "false" is true: the run would write wherever the manifest says)
    _check_flag("batch", "allow_outside_out", allow_outside_out)
    m = manifest if isinstance(manifest, Manifest) else parse_manifest(manifest, out, allow_outside_out)
    cache = cache if cache is not None else SceneCache()
    specs = plan(m, cache)
    _check_log(m, specs, input_files(m, cache))
    _check_confined(m, specs)
    return m, specs, cache


def _check_flag(fn: str, name: str, value) -> None:
    """Refuse a ``value`` of the keyword ``name`` that is not True or False."""
    if not isinstance(value, (bool, np.bool_)):
        raise ParameterError(f"{fn}: {name}={value!r}; expected True or False")


def _check_confined(m: Manifest, specs: list) -> None:
    """Every frame's files and the log lie under the manifest's output folder, their fields
    filled in and symbolic links followed; each spec carries the folder for the writer's own
    check (a link made after planning)."""
    if m.root is None:
        return
    for s in specs:
        check_inside(s["output"], m.root, m.path, f"job {s['job']!r} frame {s['frame']}")
        s["root"] = m.root
    check_inside(log_path(m), m.root, m.path, "the log")


def _check_log(m: Manifest, specs: list, inputs: dict) -> None:
    """The log must be a file of its own, not a frame, a contact sheet or one of ``inputs``
    (:func:`~draaw_mi.batch.planner.input_files`: JSON lines appended to a scene broke its next
    load), nor a folder (IsADirectoryError from the run)."""
    path, log = log_path(m), same_file(log_path(m))
    if file_identity(path) in inputs:
        raise SceneError(f"{m.path}: log {path!r} is {inputs[file_identity(path)]}; give it a name of its own")
    for s in specs:
        files = [s["output"], *([preview_path(s)] if s["preview"] else []),
                 *([sheet_path(s)] if m.contact_sheet and s["frame"] == 0 else [])]
        if any(same_file(f) == log for f in files):
            raise SceneError(f"{m.path}: log {path!r} is an output of job {s['job']!r} frame "
                             f"{s['frame']}; give the log a name of its own")
    if os.path.isdir(path):
        raise SceneError(f"{m.path}: log {path!r} is a folder; expected a file name")


def log_path(m: Manifest) -> str:
    """The manifest's log: its ``log`` key, else ``<manifest>.batch.jsonl`` in the folder the
    output patterns share before their first field (``out/`` for ``out/{job}/{frame}.exr``).
    It depends on the patterns, not on the jobs: with the folder the frames share, adding a
    job would move the log, and ``--status`` would lose the errors recorded before."""
    if m.log:
        return m.log
    folders = [fixed_folder(job.output) for job in m.jobs]
    root = os.path.commonpath(folders)
    if os.path.dirname(root) == root:
        # outputs in unrelated trees (/data/..., /scratch/...): not a log (and a lock) at the
        # file system's root, but in the first job's folder
        root = folders[0]
    if m.path.startswith("<"):
        return os.path.join(root, "batch.jsonl")
    return os.path.join(root, os.path.splitext(os.path.basename(m.path))[0] + ".batch.jsonl")


class _Log:
    """Append-only JSONL log; every line is flushed and fsynced, so a kill loses at most the
    line being written (readers skip a torn last line)."""

    def __init__(self, path: str):
        self.path, self.error = path, None
        try:
            os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
            # (O_NOFOLLOW: a link put where the log goes since planning is not written through)
            fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o666)
            self.fh = os.fdopen(fd, "a", encoding="utf-8")
        except OSError as e:
            raise SceneError(f"batch: cannot open the log {path!r}: {e.strerror or e}") from None

    def write(self, **record):
        """Append one record. A write that fails (a full disk) turns the log off and keeps
        the reason in ``error``: the frames are what the run is for, and a log write in the
        run's ``finally`` must not replace the summary with a traceback."""
        if self.error is not None:
            return
        record = {"time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **record}
        try:
            self.fh.write(json.dumps(record, default=str) + "\n")
            self.fh.flush()
            os.fsync(self.fh.fileno())
        except OSError as e:
            self.error = f"log {self.path!r} not written from here on: {e.strerror or e}"

    def close(self):
        try:
            self.fh.close()
        except OSError as e:             # (the buffered rest of a failed write)
            self.error = self.error or f"log {self.path!r}: {e.strerror or e}"


def read_log(path: str) -> list[dict]:
    """The records of a batch log: lines that are not JSON objects (a torn last line from a
    killed run, bytes that are not UTF-8, a stray ``[1, 2]``) are skipped."""
    out = []
    if not os.path.isfile(path):
        return out
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict):
                out.append(rec)
    return out


def remove_temp_files(specs) -> list[str]:
    """Delete the temporary files that a killed run left in the output folders."""
    removed = []
    for folder in sorted({os.path.dirname(s["output"]) for s in specs}):
        for pattern in TEMP_PATTERNS:
            for path in glob.glob(os.path.join(glob.escape(folder), pattern)):
                try:
                    if "probe" in pattern and time.time() - os.path.getmtime(path) < PROBE_GRACE_S:
                        continue      # another run's folder probe, in the instant before its lock
                    os.unlink(path)
                    removed.append(path)
                except OSError:
                    pass
    return removed


def status(manifest, out: str | None = None, allow_outside_out: bool = False, verify: bool = False) -> dict:
    """Per frame ``done`` / ``missing`` / ``stale`` (present, other job) / ``foreign``
    (present, made by another manifest file) / ``damaged``
    (unreadable or cut short; with ``verify``, also a frame whose pixel data does not decode)
    / ``no-preview``, or ``failed`` with the last error the log recorded for the frame's
    present settings. Reads only: read-only outputs are fine. Returns ``{"frames": [...],
    "counts": {...}, "log": path, "running": pid}``, ``running`` the pid of a run holding the
    output folders now (its frames are a snapshot), else None."""
    _check_flag("batch.status", "verify", verify)
    m, specs, _ = load(manifest, out, allow_outside_out=allow_outside_out)
    errors = {}
    for rec in read_log(log_path(m)):
        if rec.get("event") == "frame":
            errors[(rec.get("job"), rec.get("frame"))] = (rec.get("hash"), rec.get("error"))
    frames = []
    counts = {"done": 0, "missing": 0, "stale": 0, "foreign": 0, "damaged": 0, "no-preview": 0, "failed": 0}
    for s in specs:
        st = frame_status(s, verify=verify)
        seen, err = errors.get((s["job"], s["frame"]), (None, None))
        if st == "done" or (seen is not None and seen != s["hash"]):
            err = None          # (an error of other settings for this frame, since edited)
        if err:
            st = "failed"
        counts[st] += 1
        frames.append({"job": s["job"], "frame": s["frame"], "output": s["output"], "status": st, "error": err})
    folders = sorted({os.path.dirname(s["output"]) for s in specs} | {os.path.dirname(log_path(m))})
    running = next((pid for pid in map(running_pid, folders) if pid is not None), None)
    return {"frames": frames, "counts": counts, "log": log_path(m), "running": running}


def run(manifest, out: str | None = None, executor: str = "inprocess", workers: int | None = None,
        scheduler: str | None = None, progress: bool | str = True, on_result=None, dry_run: bool = False,
        client=None, overwrite: bool = False, allow_outside_out: bool = False, retries: int | None = None,
        dashboard: bool = False, tls: dict | None = None, verify: bool = False) -> BatchResult:
    """Render every unfinished frame of ``manifest``; see the module docstring. A run with
    contact sheets verifies the finished frames (it decodes each of them for the sheets)."""
    check_mode(progress, "batch.run")
    refuse_in_a_workers_import()
    if executor not in EXECUTORS:
        raise ParameterError(f"batch.run: executor={executor!r}{suggest(executor, EXECUTORS)}")
    _check_workers(workers, scheduler, client, executor)
    dask = _dask_options(executor, workers, scheduler, client, retries, dashboard, tls)
    # (the string "false" is true: another manifest's frames would be replaced)
    _check_flag("batch.run", "overwrite", overwrite)
    _check_flag("batch.run", "dry_run", dry_run)
    _check_flag("batch.run", "verify", verify)
    if on_result is not None and not callable(on_result):      # (else it fails after frame 0)
        raise ParameterError(f"batch.run: on_result={on_result!r}; expected a function of a frame's "
                             "result record, or None")
    if executor == "dask" and client is None:
        if importlib.util.find_spec("distributed") is None:     # fail before planning, in one line
            raise DraawError("the dask executor needs Dask: pip install 'draaw-mi[batch]'")
    t0 = time.perf_counter()
    m, specs, cache = load(manifest, out, allow_outside_out=allow_outside_out)
    # (a run with contact sheets decodes every finished frame for them: a frame that does not
    # decode is found here and rendered again, not left out of its sheet)
    verify = verify or m.contact_sheet
    states = [frame_status(s, verify=verify) for s in specs]
    if not overwrite:
        _refuse_foreign(m, [s for s, st in zip(specs, states) if st == "foreign"])
    todo = [s for s, st in zip(specs, states) if st != "done"]
    res = BatchResult(total=len(specs), skipped=len(specs) - len(todo), log=log_path(m))
    log_dir = os.path.dirname(res.log)
    if todo:        # (permission bits, with their own messages; the run then writes a probe)
        check_writable(sorted({os.path.dirname(s["output"]) for s in todo} | {log_dir}), m.path)
    if dry_run:
        res.missing = len(todo)
        return res
    try:
        prepare_outputs(sorted({os.path.dirname(s["output"]) for s in todo} | {log_dir}), m.path)
    except SceneError:
        if todo:
            raise
        # every frame is done in folders that cannot be written (an archive on a read-only
        # share): complete, nothing to write (not an error)
        res.seconds = time.perf_counter() - t0
        return res
    # every folder a frame of the manifest lives in: those of finished frames exist (and may
    # be read-only), the rest prepare_outputs just created
    folders = {os.path.dirname(s["output"]) for s in todo} | {log_dir}
    done_folders = {os.path.dirname(s["output"]) for s in specs} - folders
    with output_locks(folders, m.path, optional=[f for f in done_folders if os.path.isdir(f)]):
        # read again under the lock: a run that held it may have finished frames since
        # planning, and a finished frame is never rendered twice
        states = [frame_status(s, verify=verify) for s in todo]
        previews = [s for s, st in zip(todo, states) if st == "no-preview"]
        kept = ("done", "no-preview") + (() if overwrite else ("foreign",))   # (written meanwhile)
        todo = [s for s, st in zip(todo, states) if st not in kept]
        res.skipped = len(specs) - len(todo)
        return _render(m, specs, todo, previews, cache, res, executor, dask, progress, on_result, t0)


def _check_workers(workers, scheduler, client, executor) -> None:
    """``workers`` sizes a new LocalCluster of this machine: 1 to the core count (more workers
    than cores oversubscribe them, workers x threads = cores cannot hold, and each worker holds
    its own scenes and kernels in memory), and meaningless with a cluster given."""
    if workers is None:
        if (scheduler or client is not None) and executor != "dask":
            raise ParameterError("batch.run: scheduler and client need executor='dask'")
        return
    cores = os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or not 1 <= workers <= cores:
        raise ParameterError(f"batch.run: workers={workers!r}: expected an integer from 1 to this "
                             f"machine's {cores} cores")
    if executor != "dask":
        raise ParameterError(f"batch.run: workers={workers} needs executor='dask'")
    if scheduler or client is not None:
        raise ParameterError(f"batch.run: workers={workers} sizes a new LocalCluster; the cluster "
                             "behind scheduler/client has its own workers")


def _refuse_foreign(m: Manifest, foreign: list) -> None:
    """Refuse a run that would replace frames another manifest file made: two manifests
    whose jobs share names (``job0`` by default) and an output folder would overwrite each
    other's finished frames without a word."""
    if not foreign:
        return
    first = foreign[0]["output"]
    other = (read_header(first) or {}).get(MANIFEST_ATTR, "another manifest")
    raise SceneError(f"batch.run: {len(foreign)} frame(s) of {m.path} would replace frames made by "
                     f"{other} (first: {first}); give the jobs other names or another output "
                     "folder, or pass overwrite=True (draaw-mi batch --overwrite) to replace them")


def _dask_options(executor, workers, scheduler, client, retries, dashboard, tls) -> dict:
    """``run_dask``'s keyword arguments, checked: ``retries`` (default 2) a whole number >= 0 for
    a dask run, ``dashboard`` a flag for a LocalCluster this run starts, ``tls`` three existing
    files for a ``tls://`` scheduler."""
    if retries is None:
        retries = DEFAULT_RETRIES
    elif isinstance(retries, bool) or not isinstance(retries, numbers.Integral) or retries < 0:
        raise ParameterError(f"batch.run: retries={retries!r}; expected an integer >= 0")
    elif executor != "dask":
        raise ParameterError(f"batch.run: retries={retries!r} is for executor='dask' (an in-process run "
                             "has no worker to lose)")
    _check_flag("batch.run", "dashboard", dashboard)
    if dashboard and (executor != "dask" or scheduler or client is not None):
        raise ParameterError("batch.run: dashboard=True shows the LocalCluster a dask run starts; a "
                             "scheduler's dashboard is its own (and there is none in-process)")
    if tls is not None:
        if not isinstance(tls, dict) or set(tls) != set(TLS_KEYS):
            raise ParameterError(f"batch.run: tls={tls!r}; expected a dict of the files "
                                 f"{', '.join(TLS_KEYS)} (draaw-mi batch --tls-ca-file, --tls-cert, --tls-key)")
        if not (isinstance(scheduler, str) and scheduler.startswith("tls://")):
            raise ParameterError(f"batch.run: tls certificates are for a tls:// scheduler; scheduler="
                                 f"{scheduler!r}")
        for key, path in tls.items():
            if not isinstance(path, (str, os.PathLike)) or not os.path.isfile(path):
                raise ParameterError(f"batch.run: tls {key} {path!r} is not a file")
        tls = {k: os.fspath(v) for k, v in tls.items()}
    return {"workers": workers, "scheduler": scheduler, "client": client, "retries": int(retries),
            "dashboard": bool(dashboard), "tls": tls}


def _render(m, specs, todo, previews, cache, res, executor, dask, progress, on_result, t0) -> BatchResult:
    """``run``'s rendering phase, with the output folders locked. ``previews``: finished
    frames whose PNG preview is missing or stale, written from their EXRs (one whose EXR does
    not decode is rendered again)."""

    remove_temp_files(specs)
    todo = list(todo)
    log = _Log(res.log)
    log.write(event="start", manifest=m.path if m.path.startswith("<") else os.path.abspath(m.path),
              frames=len(specs), todo=len(todo), executor=executor, pid=os.getpid())
    for s in previews:
        try:
            image, channels = read_frame(s["output"], with_names=True)
        except DraawError as e:       # its header and chunk table pass, its pixels do not decode
            log.write(event="damaged", job=s["job"], frame=s["frame"], output=s["output"], error=str(e),
                      action="rendered again")
            todo.append(s)
            res.skipped -= 1
            continue
        try:
            write_preview(s, image, channels)
            res.previews += 1
            log.write(event="preview", job=s["job"], frame=s["frame"], output=s["output"])
        except DraawError as e:
            r = {"job": s["job"], "frame": s["frame"], "output": s["output"], "error": str(e)}
            res.failed.append(r)
            log.write(event="frame", hash=s["hash"], **r)
    bar = progress_bar(len(todo), "batch", "frames", progress if todo else False, where="batch.run")
    first_kernels: dict = {}
    hashes = {s["output"]: s["hash"] for s in specs}     # logged: --status shows current errors only

    def handle(r):
        res.results.append(r)
        if "error" in r:
            res.failed.append(r)
        else:
            res.rendered += 1
            ks = set(r.get("kernels") or ())
            if r["job"] not in first_kernels:
                first_kernels[r["job"]] = ks
                res.new_kernels.setdefault(r["job"], 0)
            else:
                new = ks - first_kernels[r["job"]]
                r["new_kernels"] = len(new)
                res.new_kernels[r["job"]] += len(new)
                first_kernels[r["job"]] |= new
        log.write(event="frame", hash=hashes.get(r["output"]), **{k: v for k, v in r.items() if k != "kernels"})
        if bar is not None:
            # the counts first, without a redraw (else tqdm draws done=5 beside 4/6); the step
            # draws both, and writes a LineProgress line
            bar.set_postfix(done=res.rendered, failed=len(res.failed), refresh=False)
            bar.update(1)
        if on_result is not None:
            on_result(r)

    finished = False
    try:
        if executor == "inprocess":
            run_inprocess(todo, cache, handle)
        else:
            # (the workers' scratch under the output folder, as every file of the run)
            run_dask(todo, handle, scratch=os.path.join(os.path.dirname(res.log), ".draaw-dask-scratch"), **dask)
        finished = True
    finally:
        if bar is not None:
            bar.close()
        res.seconds = time.perf_counter() - t0
        if not finished:           # (interrupted: no contact sheets)
            _end(res, specs, log)
    try:
        if m.contact_sheet:
            _sheets(specs, res, log)
    finally:
        _end(res, specs, log)
    return res


def _sheets(specs, res: BatchResult, log: _Log) -> None:
    """Write the contact sheets; a frame that does not decode as they read it (damaged while
    the run rendered: a run with sheets verified the finished frames first) goes to
    ``res.damaged``."""
    damaged: list = []
    try:
        contact_sheets(specs, damaged=damaged)
    except DraawError as e:      # the frames are what the run is for: report, keep the result
        res.sheet_error = str(e)
    for s in damaged:
        res.damaged.append(s["output"])
        log.write(event="damaged", job=s["job"], frame=s["frame"], output=s["output"],
                  error="its pixel data does not decode (read for the contact sheet)")


def _end(res: BatchResult, specs, log: _Log) -> None:
    """Count the frames missing on the disk (and those found damaged), write the log's end
    record and close it."""
    res.missing = sum(frame_status(s) != "done" for s in specs if s["output"] not in res.damaged) + len(res.damaged)
    log.write(event="end", rendered=res.rendered, failed=len(res.failed), missing=res.missing,
              seconds=round(res.seconds, 3))
    log.close()
    res.log_error = log.error or ""
