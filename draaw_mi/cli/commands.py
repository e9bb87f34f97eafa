"""The ``draaw-mi`` command line: render, info, post, fit, bench, batch (their arguments:
:mod:`~draaw_mi.cli.parser`).

Bad input exits with status 2 and one line on stderr (``draaw-mi: error: ...``), no traceback.

Examples::

    draaw-mi render scenes/cornell.toml -o out/cornell.exr --png out/cornell.png --spp 256
    draaw-mi render cbox.xml -o out/cbox.png -D res=64 -D spp=16      # a Mitsuba XML file's $res, $spp
    draaw-mi info scenes/material_spheres.toml
    draaw-mi post out/cornell.exr -o out/graded.exr --chain chain.json
    draaw-mi batch scenes/batch_example.toml --out out/batch [--executor dask --workers 2]
    draaw-mi fit scenes/fit_sphere.toml --reference ref.exr --param target.roughness \
             --param target.metallic -o fitted.toml --plot fit.png
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import threading
import tempfile
import warnings

import drjit as dr
import numpy as np

from .. import batch, post
from ..batch.exr import HASH_ATTR, MANIFEST_ATTR, read_header, render_metadata
from ..errors import DraawError, SceneError
from ..fitting import fit, fit_two_starts
from ..io import openexr, read_exr, write_exr, write_png
from ..post import display_encoded
from ..rendering import render
from ..scene import OVERRIDE_MAXIMA, OVERRIDE_MINIMA
from ..scene.description import SAMPLERS
from ..scene.schema import Where, resolution, string
from .bench import cmd_bench
from .common import EXIT_BAD_INPUT, PROGRESS_HELP, CliError, progress_mode, read_json  # noqa: F401 (re-exported)
from .parser import build_parser
from .scenes import (
    apply_sets,
    check_own_integrator_flags,
    cmd_info,
    integrator_note,
    load_for_cli,
    refuse_scene_as_manifest,
)


def _writable(path: str, suffixes: tuple[str, ...], what: str) -> str:
    if not path.lower().endswith(suffixes):
        raise CliError(f"{what} {path!r} must end with {' or '.join(suffixes)}")
    folder = os.path.dirname(os.path.abspath(path)) or "."
    probe = folder
    while not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if os.path.isdir(path):
        raise CliError(f"{what} {path!r} is a folder")
    if not os.path.isdir(probe) or not os.access(probe, os.W_OK | os.X_OK):
        raise CliError(f"{what} {path!r} is not writable (folder {probe!r})")
    # permission bits do not tell for root, read-only mounts or /proc: write and delete a file
    # in the nearest existing folder (else the render runs for nothing, and fails at its write)
    try:
        fd, name = tempfile.mkstemp(prefix=".draaw-probe-", dir=probe)
        os.close(fd)
        os.unlink(name)
    except OSError as e:
        raise CliError(f"{what} {path!r} is not writable (folder {probe!r}: {e.strerror})") from None
    return path


def _cmd_render(args) -> int:
    _writable(args.output, (".exr", ".png"), "output")
    if args.output.lower().endswith(".exr"):
        openexr(f"draaw-mi render -o {args.output}")   # before the render, not after it
    if args.png:
        _writable(args.png, (".png",), "--png")
        if os.path.abspath(args.png) == os.path.abspath(args.output):
            raise CliError(f"--png {args.png}: the same file as -o; -o {args.output} already writes the PNG")
    if args.threads is not None:
        if args.threads < 1:
            raise CliError(f"--threads {args.threads}: expected an integer >= 1")
        dr.set_thread_count(args.threads)
    for key, lo in OVERRIDE_MINIMA.items():      # (named as the flag, not as "override.spp")
        value, hi = getattr(args, key), OVERRIDE_MAXIMA.get(key)
        if value is not None and (value < lo or (hi is not None and value > hi)):
            raise CliError(f"--{key.replace('_', '-')} {value}: expected an integer "
                           + (f">= {lo}" if hi is None else f"in [{lo}, {hi}]"))
    try:                                         # (named as the flags, not "override.resolution.width")
        if args.resolution is not None:
            resolution(args.resolution, Where("--resolution"))
        if args.sampler is not None:
            string(args.sampler, Where("--sampler"), SAMPLERS)
    except SceneError as e:
        raise CliError(str(e)) from None
    if args.time_budget is not None and not 0 < args.time_budget < float("inf"):
        raise CliError(f"--time-budget {args.time_budget:g}: expected a finite number of seconds > 0")
    overrides = {"resolution": args.resolution, "spp": args.spp, "seed": args.seed, "max_depth": args.max_depth,
                 "sampler": args.sampler}
    scene = load_for_cli(args, **{k: v for k, v in overrides.items() if v is not None})
    check_own_integrator_flags(args, scene)
    sets = apply_sets(scene, args.sets)
    post = None
    if args.post:
        post = _load_chain(args.post)
    # (render's pass layout does not follow the progress mode: the same image in a terminal
    # as in a pipe)
    sensor = int(args.sensor) if args.sensor.isdigit() else args.sensor
    image, info = render(scene, version=args.version, time_budget=args.time_budget, post=post,
                                  progress=progress_mode(args.no_progress), return_info=True,
                                  denoise=args.denoise, sensor=sensor)
    arr = np.array(image)
    del image
    dr.flush_malloc_cache()      # the render's cached buffers, before the EXR's own copies
    chain = info["post"]                                                 # what render() applied
    meta = render_metadata(args.scene, scene, info, post=chain)
    if sets:                                   # the scene file alone no longer describes the image
        meta["draaw:set"] = json.dumps(sets)
    # the film's colour channels by name (R, G, B[, A], X, Y, Z[, A] or Y[, A] of an XML
    # film's pixel_format), not the first three: a luminance film's depth AOV would be the
    # PNG's alpha, an xyz film's X, Y, Z its R, G, B
    for png in [p for p in (args.output, args.png) if p and p.lower().endswith(".png")]:
        write_png(png, arr, channels=info["channels"], encoded=display_encoded(chain),
                  text={k: str(v) for k, v in meta.items()})
    raw_note = ""
    if args.output.lower().endswith(".exr"):
        exr, names = arr, info["channels"]
        if info.get("raw") is not None:         # --denoise: the undenoised render beside it
            exr, names = np.concatenate([arr, info["raw"]], axis=2), names + ["raw.R", "raw.G", "raw.B"]
            raw_note = "; plus the undenoised render in its channels raw.R/G/B"
        write_exr(args.output, exr, channels=names, metadata=meta)
    note = integrator_note(args, scene)
    if note:
        print(f"draaw-mi: note: {note}", file=sys.stderr)
    # (the render's own count: a post chain and denoising read NaN/inf as 0)
    finite = bool(np.isfinite(arr).all()) and not info.get("non_finite")
    print(f"wrote {args.output} ({arr.shape[1]}x{arr.shape[0]}, {len(info['channels'])} channels, "
          f"{info['spp']} spp, {info['integrator']}{', denoised' if info.get('denoised') else ''}, "
          f"{info['seconds']:.2f} s"
          + ("" if finite else ", WARNING: non-finite pixels") + ")" + raw_note)
    if args.png and args.png != args.output:
        print(f"wrote {args.png}")
    return 0


def _load_chain(path: str):
    return post.load_chain(path)


def _cmd_fit(args) -> int:

    if args.output:
        _writable(args.output, (".toml", ".json"), "output")
    if args.plot:
        _writable(args.plot, (".png",), "--plot")
    views = read_json(args.views, "--views") if args.views else None
    captures, references = None, list(args.reference or [])
    if args.captures:
        if references or views is not None:
            raise CliError("--captures carries each capture's reference and camera: give it without "
                           "--reference and --views")
        captures = read_json(args.captures, "--captures")
        if not isinstance(captures, list):
            raise CliError(f"--captures {args.captures!r}: expected a JSON list of captures")
        folder = os.path.dirname(os.path.abspath(args.captures))
        captures = [dict(c, reference=os.path.join(folder, c["reference"]))
                    if isinstance(c, dict) and isinstance(c.get("reference"), str) else c for c in captures]
    elif not references:
        raise CliError("fit: give --reference (one per view) or --captures")
    if args.two_starts and not captures:
        raise CliError("fit: --two-starts merges fits by each capture's error: give it with --captures")
    scene = load_for_cli(args)
    if args.output:               # fail before the fit, not after it: can the values be written?
        if scene.description is None and not args.output.lower().endswith(".json"):
            raise CliError(f"-o {args.output!r}: {args.scene} is not a TOML/JSON scene; only the "
                           "values can be written, to a .json file")
        if scene.description is not None:
            scene.updated_description({name: 0.0 for name in args.param})
    post = _load_chain(args.post) if args.post else None
    res = (fit_two_starts if args.two_starts else fit)(
        scene, None if captures else references, params=list(args.param), version=args.version,
        spp=args.spp, iterations=args.iterations, lr=args.lr, loss=args.loss, views=views,
        post=post, exposure=args.exposure, seed=args.seed, captures=captures, batch=args.batch,
        progress=progress_mode(args.no_progress), polish=args.polish)
    for st in res.stages:
        what = (f"captures error {st['error']:.4g}" if "error" in st else f"{st['iterations']} iterations at "
                f"{st['spp']} spp") + (f", {st['taken']} of {st['regions']} region(s) taken" if "regions" in st else "")
        print(f"{st['stage']}: {what} ({st['seconds']:.1f} s)")
    for name, value in res.values.items():
        if hasattr(value, "shape"):        # a texture
            mean = ", ".join(f"{m:.4g}" for m in value.reshape(-1, value.shape[-1]).mean(axis=0))
            print(f"{name} = texture {'x'.join(map(str, value.shape))} (mean {mean})")
        else:
            print(f"{name} = {value if isinstance(value, list) else round(value, 5)}")
    if args.exposure == "fit":
        print(f"exposure = {res.exposure_stops:+.4f} stops (render x {2 ** res.exposure_stops:.4f} matches the reference)")
    print(f"loss {res.losses[0]:.4g} -> {res.losses[-1]:.4g} in {res.iterations} iterations, "
          f"{res.seconds:.1f} s, {'converged' if res.converged else 'not converged'}")
    for i, c in enumerate(res.captures):
        if not c["explained"]:
            print(f"capture {i} not explained: {c['why']}")
    if args.output:
        for path in res.save(args.output, scene):
            print(f"wrote {path}")
    if args.maps:
        for path in res.save_maps(args.maps):
            print(f"wrote {path}")
    if args.plot:
        res.plot(args.plot)
        print(f"wrote {args.plot}")
    return 0


def _cmd_post(args) -> int:


    _writable(args.output, (".exr", ".png"), "output")
    chain = _load_chain(args.chain)
    arr, names = read_exr(args.input, with_names=True)
    n_color = 4 if names[:4] == ["R", "G", "B", "A"] else 3 if names[:3] == ["R", "G", "B"] else 0
    if n_color == 0:
        raise CliError(f"{args.input}: no R, G, B channels to post-process (channels: {', '.join(names)})")
    bad = int(np.count_nonzero(~np.isfinite(arr[..., :3])))
    if bad:
        print(f"draaw-mi: warning: {args.input}: {bad} non-finite colour values (NaN/inf) "
              "read as 0", file=sys.stderr)
    color = np.array(post.apply(arr[..., :n_color], chain))
    result = np.concatenate([color, arr[..., n_color:]], axis=2)
    # the chain the image has been through: the one render applied (its header's draaw:post),
    # then this one
    header = read_header(args.input) or {}
    before = _recorded_chain(header)
    # the chain as the user wrote it (chain.to_list() would record every default too)
    chain_doc = read_json(args.chain, "--chain")                 # (valid: load_chain read it)
    after = chain_doc["chain"] if isinstance(chain_doc, dict) else chain_doc     # ({"chain": [...]})
    if args.output.lower().endswith(".png"):
        # encoded by either chain (an input rendered with a chain ending in srgb): stored as
        # it is (by the new chain's alone, such an input would be encoded twice)
        try:
            encoded = post.display_encoded(before + after)
        except DraawError as e:
            # (a filter of another version): whether it encoded cannot be told; read as linear
            print(f"draaw-mi: warning: {args.input}: its draaw:post chain does not load ({e}); "
                  "its colour is read as linear", file=sys.stderr)
            encoded = post.display_encoded(after)
        write_png(args.output, result, channels=names, encoded=encoded)
    else:
        # the input's draaw:* attributes go along (what rendered it), draaw:post with this chain
        # after the render's (the README says post keeps it)
        meta = {k: v for k, v in header.items() if k.startswith("draaw:") and isinstance(v, (str, int, float))}
        meta["draaw:post"] = json.dumps(before + after)
        # no longer the frame a batch rendered: without its hash, and made by post, the batch
        # reports it as foreign and leaves it alone unless told to overwrite (with the hash kept,
        # post run in place on a frame would pass to the batch as done with a chain its manifest
        # never named)
        if meta.pop(HASH_ATTR, None) is not None:
            meta[MANIFEST_ATTR] = "draaw-mi post"
        write_exr(args.output, result, channels=names, metadata=meta)
    print(f"wrote {args.output}")
    return 0


def _recorded_chain(header: dict) -> list:
    """The post chain an EXR's ``draaw:post`` header attribute says its colour has been
    through, as recorded (``[]``: none, or not a JSON list)."""
    try:
        before = json.loads(header.get("draaw:post", "[]"))
    except (TypeError, ValueError):
        return []
    if isinstance(before, dict):                               # ({"chain": [...]})
        before = before.get("chain", [])
    return before if isinstance(before, list) else []


def _cmd_batch(args) -> int:
    """Exit 0 when every frame of the manifest exists (done), 1 when some are missing."""
    refuse_scene_as_manifest(args.manifest)
    cores = os.cpu_count() or 1
    if args.workers is not None and not 1 <= args.workers <= cores:
        raise CliError(f"--workers {args.workers}: expected an integer from 1 to this machine's {cores} cores")
    if args.workers and args.scheduler:
        raise CliError("--workers sizes a new LocalCluster; the --scheduler's cluster has its own workers")
    if args.scheduler and not args.scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://")):
        raise CliError(f"--scheduler {args.scheduler!r}: expected an address such as tcp://HOST:8786")
    if args.retries is not None and args.retries < 0:
        raise CliError(f"--retries {args.retries}: expected an integer >= 0")
    given = [flag for flag, v in (("--workers", args.workers), ("--scheduler", args.scheduler),
                                  ("--dashboard", args.dashboard), ("--retries", args.retries is not None)) if v]
    if given and args.executor != "dask":
        raise CliError(f"{', '.join(given)}: {'needs' if len(given) == 1 else 'need'} --executor dask")
    if args.dashboard and args.scheduler:
        raise CliError("--dashboard shows the LocalCluster this run starts; the --scheduler's dashboard is its own")
    tls = {"ca_file": args.tls_ca_file, "cert": args.tls_cert, "key": args.tls_key}
    if any(tls.values()):
        missing = [f"--tls-{k.replace('_', '-')}" for k, v in tls.items() if not v]
        if missing:
            raise CliError(f"a TLS client needs --tls-ca-file, --tls-cert and --tls-key; missing {', '.join(missing)}")
        if not (args.scheduler or "").startswith("tls://"):
            raise CliError(f"--tls-ca-file, --tls-cert and --tls-key are for a --scheduler tls://HOST:PORT; got "
                           f"{args.scheduler!r}")
    else:
        tls = None
    if args.status or args.dry_run:
        st = batch.status(args.manifest, out=args.out, allow_outside_out=args.allow_outside_out,
                          verify=args.verify)
        for f in st["frames"]:
            if args.dry_run or f["status"] != "done":
                print(f"{f['job']:>16} {f['frame']:>5}  {f['status']:<10} {f['output']}"
                      + (f"  ({f['error']})" if f["error"] else ""))
        c = st["counts"]
        nopreview = f", {c['no-preview']} without their preview" if c["no-preview"] else ""
        what = "unreadable, cut short or not decoding" if args.verify else "unreadable or cut short"
        damaged = f", {c['damaged']} damaged ({what})" if c["damaged"] else ""
        damaged += f", {c['foreign']} made by another manifest" if c["foreign"] else ""
        print(f"{len(st['frames'])} frames: {c['done']} done, {c['missing']} missing, {c['stale']} stale "
              f"(other job settings){damaged}{nopreview}, {c['failed']} failed; log {st['log']}"
              + (f" (a run is in progress: pid {st['running']})" if st["running"] else ""))
        return 0 if c["done"] == len(st["frames"]) else 1
    res = batch.run(args.manifest, out=args.out, executor=args.executor, workers=args.workers,
                    scheduler=args.scheduler, progress=progress_mode(args.no_progress),
                    overwrite=args.overwrite, allow_outside_out=args.allow_outside_out, retries=args.retries,
                    dashboard=args.dashboard, tls=tls, verify=args.verify)
    for r in res.failed:
        print(f"failed: {r['job']} frame {r['frame']}: {r['error']}", file=sys.stderr)
    print(res.summary())
    return 0 if res.complete else 1


def _bench_command(args) -> int:
    return cmd_bench(args)


@contextlib.contextmanager
def _warnings_as_lines():
    """Python warnings as ``draaw-mi: warning: ...`` lines on stderr, as the commands' own
    (not as ``.../cli.py:189: RuntimeWarning: ...`` and the source line after it)."""
    def show(message, category, filename, lineno, file=None, line=None):
        print(f"draaw-mi: warning: {message}", file=sys.stderr if file is None else file)
    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill PID``), raised where the program is, as Ctrl-C's interrupt is: a batch
    then writes its log's end record and releases its locks (the default action ended the
    process on the spot), and a render stops between passes."""


def _on_sigterm(signum, frame):
    _TERMINATED.append(signum)
    raise Terminated()


_TERMINATED: list = []


def main(argv=None) -> int:
    """``draaw-mi``: the exit status of the command ``argv`` (default: the process's arguments);
    SIGTERM ends it as Ctrl-C does, with status 143 (128 + 15)."""
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if in_main else None
    _TERMINATED.clear()
    try:
        return _main(argv)
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)


def _main(argv) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:                         # the commands, not "the following arguments are required"
        build_parser().print_help(sys.stderr)
        return EXIT_BAD_INPUT
    try:
        args = build_parser().parse_args(argv)
        args.argv = list(argv)               # as typed: reports repeat the command that made them
        handler = {"render": _cmd_render, "info": cmd_info, "post": _cmd_post, "fit": _cmd_fit,
                   "bench": _bench_command, "batch": _cmd_batch}[args.command]
        try:
            with _warnings_as_lines():
                return handler(args)
        except DraawError as e:
            raise CliError(str(e)) from None
    except CliError as e:
        print(f"draaw-mi: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ImportError as e:
        print(f"draaw-mi: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        # the reader left (`draaw-mi info --json ... | head`): end quietly, as a shell tool
        # does on SIGPIPE, with standard output sent nowhere so that Python's flush at exit
        # does not fail on the closed pipe again
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):       # (a stdout without a file: a test's)
            pass
        return 128 + signal.SIGPIPE
    except Exception as e:  # noqa: BLE001 - environment problems (DraawError at import) are one line too
        if any(c.__name__ == "DraawError" for c in type(e).__mro__):
            print(f"draaw-mi: error: {e}", file=sys.stderr)
            return EXIT_BAD_INPUT
        raise
    except KeyboardInterrupt:
        if _TERMINATED:
            print("draaw-mi: terminated", file=sys.stderr)
            return 128 + signal.SIGTERM
        print("draaw-mi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
