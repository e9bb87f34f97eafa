"""The ``draaw-mi`` command line's arguments: :func:`build_parser` (the commands are in
:mod:`~draaw_mi.cli.commands`)."""
from __future__ import annotations

import argparse

from .. import __version__
from .common import PROGRESS_HELP, CliError
from .scenes import add_define_option, add_set_option


class OneLineParser(argparse.ArgumentParser):
    """A bad argument: :class:`~draaw_mi.cli.common.CliError` (one line, status 2), not a usage dump."""

    def error(self, message):
        command = self.prog.removeprefix("draaw-mi").strip()      # ("draaw-mi: error:" comes first)
        raise CliError(f"{command + ': ' if command else ''}{message} (see --help)")


def build_parser() -> argparse.ArgumentParser:
    """The ``draaw-mi`` parser and its subcommands' arguments."""
    p = OneLineParser(prog="draaw-mi", description="Differentiable GO-Draaw-style renderer on Mitsuba 3.")
    # (the tool's version; a command's --version is the render version it uses)
    p.add_argument("-V", "--version", action="version", version=f"draaw-mi {__version__}",
                   help="print draaw-mi's version and exit (`draaw-mi info` says more)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    r = sub.add_parser("render", help="render a scene to EXR (and PNG)")
    r.add_argument("scene", help="scene file: .toml, .json, .xml or a mesh (.obj, .ply, .glb, ...)")
    r.add_argument("-o", "--output", required=True, help="output image: .exr (float32, AOVs as named "
                   "channels) or .png (8-bit sRGB, colour only)")
    r.add_argument("--png", help="also write an sRGB PNG")
    r.add_argument("--version", dest="version", help="render version: v1..v4 (GO-Draaw names accepted), "
                   "path, prb; volpath, prbvolpath for media; scene: the integrator an XML scene "
                   "declares (its default when it declares one that is not a version); default: the "
                   "scene's render.version")
    r.add_argument("--spp", type=int, help="samples per pixel (default: the scene's render.spp)")
    r.add_argument("--resolution", help="WxH, e.g. 640x480 (an XML scene's film too)")
    add_define_option(r)
    add_set_option(r)
    r.add_argument("--seed", type=int, help="random seed (same seed, same image; default: the scene's render.seed)")
    r.add_argument("--sampler", help="Mitsuba sampler: independent (default; V4 stratifies it itself), "
                   "multijitter (up to 10x less variance for path and V1-V3, but correlated below 256 "
                   "spp: not for references), stratified, ldsampler, orthogonal")
    r.add_argument("--max-depth", type=int, help="maximum path depth (-1: unbounded)")
    r.add_argument("--time-budget", type=float, help="stop after this many seconds (at least one pass)")
    r.add_argument("--post", help="post-processing chain (JSON file) applied after rendering")
    r.add_argument("--threads", type=int, help="Dr.Jit worker threads (default: all cores)")
    r.add_argument("--no-progress", action="store_true", help=PROGRESS_HELP)
    r.add_argument("--sensor", default="0",
                   help="which of the scene's sensors renders: its index or its id (default 0, the first)")
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
    f.add_argument("--loss", default="l2", choices=["l2", "l1", "relative_l2"],
                   help="image loss: l2 (default), l1 (robust to a few bright pixels), relative_l2 "
                   "(each pixel's error relative to its brightness)")
    f.add_argument("--exposure", default="fixed", choices=["fixed", "fit"],
                   help="fixed (default): compare the render as it is; fit: the loss is insensitive to "
                   "a global exposure difference (the scale is reported in stops)")
    f.add_argument("--post", help="post-processing chain (JSON) applied inside the loss (default: the "
                   "scene's [[post]], as `draaw-mi render` applies it)")
    f.add_argument("--seed", type=int, default=0, help="random seed of the renders (default 0: the same "
                   "seed, the same run, noise included)")
    add_define_option(f)
    f.add_argument("--no-progress", action="store_true", help=PROGRESS_HELP)

    b = sub.add_parser("bench", help="measure what accuracy costs in time (error vs time study)")
    b.add_argument("scenes", nargs="*", help="scene files (default: the sample scenes); with "
                   "--suite speed: suite scene names (default: all of them)")
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
    a.add_argument("--verify", action="store_true",
                   help="decode every finished frame (with --status, --dry-run or a run): one whose pixel "
                   "data does not decode is damaged, and a run renders it again (without it, a frame's "
                   "header, offset table and chunk sizes are checked, not its compressed bytes)")
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
