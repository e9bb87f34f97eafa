"""The ``draaw-mi`` command line: render, info, post, fit, bench, batch.

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

import argparse
import contextlib
import json
import os
import sys
import tempfile
import warnings

import drjit as dr
import numpy as np

from .. import batch, post
from ..batch.exr import HASH_ATTR, MANIFEST_ATTR, read_header, render_metadata
from ..errors import DraawError
from ..fitting import fit, fit_two_starts
from ..io import read_exr, write_exr, write_png
from ..post import display_encoded
from ..rendering import render
from ..scene import OVERRIDE_MINIMA
from .bench import cmd_bench
from .common import EXIT_BAD_INPUT, PROGRESS_HELP, CliError, progress_mode, read_json  # noqa: F401 (re-exported)
from .scenes import (
    add_define_option,
    add_set_option,
    apply_sets,
    check_own_integrator_flags,
    cmd_info,
    integrator_note,
    load_for_cli,
    refuse_scene_as_manifest,
)


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2, no usage dump
        command = self.prog.removeprefix("draaw-mi").strip()      # ("draaw-mi: error:" comes first)
        raise CliError(f"{command + ': ' if command else ''}{message} (see --help)")


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


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="draaw-mi", description="Differentiable GO-Draaw-style renderer on Mitsuba 3.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("render", help="render a scene to EXR (and PNG)")
    r.add_argument("scene", help="scene file: .toml, .json, .xml or a mesh (.obj, .ply, .glb, ...)")
    r.add_argument("-o", "--output", required=True, help="output image: .exr (float32, AOVs as named "
                   "channels) or .png (8-bit sRGB, colour only)")
    r.add_argument("--png", help="also write an sRGB PNG")
    r.add_argument("--version", dest="version", help="render version: v1..v4 (GO-Draaw names accepted), "
                   "path, prb; volpath, prbvolpath for media; scene: the integrator an XML scene "
                   "declares (its default when it declares one that is not a version)")
    r.add_argument("--spp", type=int, help="samples per pixel")
    r.add_argument("--resolution", help="WxH, e.g. 640x480 (an XML scene's film too)")
    add_define_option(r)
    add_set_option(r)
    r.add_argument("--seed", type=int, help="random seed (same seed, same image)")
    r.add_argument("--sampler", help="Mitsuba sampler: independent (default), multijitter (up to 10x less "
                   "variance at the same time), stratified, ldsampler, orthogonal")
    r.add_argument("--max-depth", type=int, help="maximum path depth (-1: unbounded)")
    r.add_argument("--time-budget", type=float, help="stop after this many seconds (at least one pass)")
    r.add_argument("--post", help="post-processing chain (JSON file) applied after rendering")
    r.add_argument("--threads", type=int, help="Dr.Jit worker threads (default: all cores)")
    r.add_argument("--no-progress", action="store_true", help=PROGRESS_HELP)
    r.add_argument("--denoise", action="store_true",
                   help="denoise with Intel OIDN guided by albedo/normal AOVs (biased; needs pyoidn)")

    i = sub.add_parser("info", help="show the set-up, or what a scene contains and calls for")
    i.add_argument("scene", nargs="?", help="scene file")
    i.add_argument("--json", action="store_true", help="print JSON")
    add_define_option(i)

    f = sub.add_parser("fit", help="fit material parameters to reference images")
    f.add_argument("scene", help="scene file (.toml, .json, .xml)")
    f.add_argument("--reference", action="append",
                   help="reference image (.exr linear, or .png sRGB); repeat once per view")
    f.add_argument("--captures", help="JSON file: a list of captures, each {\"reference\": FILE, \"camera\": "
                   "{...}, \"lights\": {NAME: FACTOR}} (a photo, where it was taken from and under which of "
                   "the scene's lights; paths relative to the JSON file); instead of --reference/--views")
    f.add_argument("--batch", type=int, help="captures rendered per iteration (default all)")
    f.add_argument("--two-starts", action="store_true", help="with --captures: metallic maps from the scene's "
                   "start and from 0, merged by region and refined (draaw_mi.fitting.fit_two_starts; ~3x the time)")
    f.add_argument("--polish", type=int, default=0, metavar="N", help="N more iterations at 8x --spp and "
                   "0.4x the rate of the fit they continue (fit(polish=N); with --two-starts, of the refine): settles "
                   "what a noisy gradient leaves, e.g. near-mirror roughness")
    f.add_argument("--maps", metavar="FOLDER", help="write fitted texture maps into FOLDER as EXR, 8- and "
                   "16-bit PNG")
    f.add_argument("--param", action="append", required=True,
                   help="parameter to fit, as material.parameter (e.g. gold.roughness) or an SDF object's "
                        "sdf.NODE.PARAM (e.g. sdf.ball.radius); repeatable")
    f.add_argument("-o", "--output", help="write the fitted scene (.toml/.json; a TOML scene keeps its "
                   "comments and layout, only the fitted values change) or the values (.json)")
    f.add_argument("--plot", help="write a PNG plot of loss and parameters over iterations")
    f.add_argument("--views", help="JSON file: a list of camera tables, one per --reference (without 'fov': "
                   "the scene camera's)")
    f.add_argument("--version", help="differentiable integrator (default: the scene's render.version "
                   "where it is one of v1..v4 or prb, else v4)")
    f.add_argument("--spp", type=int, default=16, help="samples per pixel per iteration (default 16)")
    f.add_argument("--iterations", type=int, default=100, help="Adam iterations (default 100)")
    f.add_argument("--lr", type=float, default=0.05, help="learning rate (default 0.05)")
    f.add_argument("--loss", default="l2", choices=["l2", "l1", "relative_l2"])
    f.add_argument("--exposure", default="fixed", choices=["fixed", "fit"],
                   help="'fit' makes the loss insensitive to a global exposure difference")
    f.add_argument("--post", help="post-processing chain (JSON) applied inside the loss (default: the "
                   "scene's [[post]], as `draaw-mi render` applies it)")
    f.add_argument("--seed", type=int, default=0)
    add_define_option(f)
    f.add_argument("--no-progress", action="store_true", help=PROGRESS_HELP)

    b = sub.add_parser("bench", help="measure what accuracy costs in time (error vs time study)")
    b.add_argument("scenes", nargs="*", help="scene files (default: the sample scenes); with "
                   "--suite speed: suite scene names (default: all ten)")
    b.add_argument("--suite", choices=["speed"], help="speed: V4 (or --versions) against path on "
                   "the speed suite's scenes, time to reach path's error (draaw_mi.bench.speed); "
                   "--spp is one spp (default 64), --gt-spp the reference spp "
                   "(default 1024; a multiple of 64, at least 128), --resolution N or NxN the sizes "
                   "(default 128 and 256); --max-depth, --adaptive, --quick, --denoise, "
                   "--camera-path and --frames do not apply")
    b.add_argument("--quick", action="store_true", help="small grid, about 30 s on 2 cores")
    b.add_argument("--out", default="out/bench", help="output folder (default out/bench)")
    b.add_argument("--versions", help="comma-separated, default v1,v2,v3,v4,path")
    b.add_argument("--spp", help="comma-separated spp list, default 1,2,4,...,1024")
    b.add_argument("--max-depth", help="comma-separated max_depth list (default: the scene's)")
    b.add_argument("--adaptive", type=int, help="adaptive block size to include (default 8; 0: none)")
    b.add_argument("--repeats", type=int, help="timed repeats per setting (median; default 3, the "
                   "SDF tracer study's 2 with --quick)")
    b.add_argument("--resolution", help="WxH for every scene (default: the scene's)")
    b.add_argument("--gt-spp", type=int, help="ground-truth spp (Mitsuba path; default 4096, 1024 "
                   "with --quick; --suite speed: the reference's, default 1024)")
    b.add_argument("--camera-path", help="JSON keyframes (GO-Draaw camera_positions.json form): "
                   "also measure frame-time statistics along this path")
    b.add_argument("--frames", type=int, help="frames along --camera-path (default 60)")
    b.add_argument("--no-progress", action="store_true", help=PROGRESS_HELP)
    b.add_argument("--denoise", help="comma-separated spp list: also measure OIDN-denoised renders "
                   "at these spp (biased points; needs pyoidn)")

    q = sub.add_parser("post", help="apply a post-processing chain to an EXR")
    q.add_argument("input", help="input EXR")
    q.add_argument("-o", "--output", required=True, help="output EXR (or .png)")
    q.add_argument("--chain", required=True, help="chain JSON file: a list of filter dicts")
    _batch_parser(sub)
    return p


def _batch_parser(sub) -> None:
    a = sub.add_parser("batch", help="render the frames of a batch manifest to multi-layer EXR (resumable)",
                       description="Render every unfinished frame of a batch manifest (see "
                       "draaw_mi.batch.manifest for its keys; output pattern fields: {job} {scene} "
                       "{version} {spp} {frame}, e.g. out/{job}/{frame:04d}.exr). A frame whose EXR "
                       "is present, complete and made with the same settings is not rendered again.",
                       epilog="Exit status: 0 when every frame exists, 1 when some are missing "
                       "(failed frames are listed and logged), 2 for a bad manifest or "
                       "arguments (nothing rendered), 130 when interrupted.")
    a.add_argument("manifest", help="batch manifest (.toml or .json)")
    a.add_argument("--out", help="put every output under this folder (relative patterns resolve there; "
                   "a pattern or log outside it is refused; default: the current folder)")
    a.add_argument("--allow-outside-out", action="store_true",
                   help="let the manifest write outside --out (absolute or '..' output patterns and "
                   "log; symbolic links out of it): only for manifests you trust")
    mode = a.add_mutually_exclusive_group()
    mode.add_argument("--dry-run", action="store_true", help="list the frames and their state; render nothing")
    mode.add_argument("--status", action="store_true", help="say which frames are done, missing or failed")
    a.add_argument("--overwrite", action="store_true",
                   help="replace frames that another manifest file rendered to the same outputs "
                   "(without it such a run is refused)")
    a.add_argument("--executor", default="inprocess", choices=["inprocess", "dask"],
                   help="inprocess (default: this process, scenes loaded once) or dask (a "
                   "LocalCluster of worker processes, or --scheduler; pip install 'draaw-mi[batch]')")
    a.add_argument("--workers", type=int, help="Dask LocalCluster worker processes (default: min(cores, 2))")
    a.add_argument("--scheduler", help="address of an existing Dask scheduler, tcp://HOST:PORT or "
                   "tls://HOST:PORT (with --tls-ca-file, --tls-cert, --tls-key, or Dask's own TLS "
                   "configuration)")
    a.add_argument("--tls-ca-file", help="the CA certificate a tls:// scheduler's certificate is checked with")
    a.add_argument("--tls-cert", help="this client's certificate for a tls:// scheduler")
    a.add_argument("--tls-key", help="the private key of --tls-cert")
    a.add_argument("--retries", type=int, default=None,
                   help="tries after a frame's worker dies (a crash, out of memory) before the frame "
                   "counts as failed (default 2; a --scheduler's own allowed-failures applies there)")
    a.add_argument("--dashboard", action="store_true",
                   help="serve the LocalCluster's dashboard on 127.0.0.1 and print its address "
                   "(default: no dashboard)")
    a.add_argument("--no-progress", action="store_true", help=PROGRESS_HELP)


def _cmd_render(args) -> int:
    _writable(args.output, (".exr", ".png"), "output")
    if args.png:
        _writable(args.png, (".png",), "--png")
        if os.path.abspath(args.png) == os.path.abspath(args.output):
            raise CliError(f"--png {args.png}: the same file as -o; -o {args.output} already writes the PNG")
    if args.threads is not None:
        if args.threads < 1:
            raise CliError(f"--threads {args.threads}: expected an integer >= 1")
        dr.set_thread_count(args.threads)
    for key, lo in OVERRIDE_MINIMA.items():      # (named as the flag, not as "override.spp")
        value = getattr(args, key)
        if value is not None and value < lo:
            raise CliError(f"--{key.replace('_', '-')} {value}: expected an integer >= {lo}")
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
    image, info = render(scene, version=args.version, time_budget=args.time_budget, post=post,
                                  progress=progress_mode(args.no_progress), return_info=True,
                                  denoise=args.denoise)
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
                  text={k: str(v) for k, v in meta.items()} if png == args.output else None)
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
        st = batch.status(args.manifest, out=args.out, allow_outside_out=args.allow_outside_out)
        for f in st["frames"]:
            if args.dry_run or f["status"] != "done":
                print(f"{f['job']:>16} {f['frame']:>5}  {f['status']:<10} {f['output']}"
                      + (f"  ({f['error']})" if f["error"] else ""))
        c = st["counts"]
        nopreview = f", {c['no-preview']} without their preview" if c["no-preview"] else ""
        damaged = f", {c['damaged']} damaged (unreadable or cut short)" if c["damaged"] else ""
        damaged += f", {c['foreign']} made by another manifest" if c["foreign"] else ""
        print(f"{len(st['frames'])} frames: {c['done']} done, {c['missing']} missing, {c['stale']} stale "
              f"(other job settings){damaged}{nopreview}, {c['failed']} failed; log {st['log']}")
        return 0 if c["done"] == len(st["frames"]) else 1
    res = batch.run(args.manifest, out=args.out, executor=args.executor, workers=args.workers,
                    scheduler=args.scheduler, progress=progress_mode(args.no_progress),
                    overwrite=args.overwrite, allow_outside_out=args.allow_outside_out, retries=args.retries,
                    dashboard=args.dashboard, tls=tls)
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


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:                         # the commands, not "the following arguments are required"
        _parser().print_help(sys.stderr)
        return EXIT_BAD_INPUT
    try:
        args = _parser().parse_args(argv)
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
    except Exception as e:  # noqa: BLE001 - environment problems (DraawError at import) are one line too
        if any(c.__name__ == "DraawError" for c in type(e).__mro__):
            print(f"draaw-mi: error: {e}", file=sys.stderr)
            return EXIT_BAD_INPUT
        raise
    except KeyboardInterrupt:
        print("draaw-mi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
