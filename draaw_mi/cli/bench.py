"""``draaw-mi bench``: the accuracy/time study (:mod:`draaw_mi.bench`), its SDF tracer study,
GO-Draaw's camera-path frame times and the speed suite (``--suite speed``)."""
from __future__ import annotations

import json
import os
import shlex
import sys

from ..bench import speed as speed_bench
from ..bench import study as bench
from ..bench import suite as speed_suite
from ..bench.sdf_study import has_sdf, run_sdf_study
from ..errors import DraawError, suggest
from ..integrators import SCENE_VERSION, resolve_version
from ..io import write_text
from ..rendering.denoiser import load_pyoidn
from ..scene import load_scene
from ..scene.camera_path import as_keyframes
from ..scene.schema import Where
from ..scene.schema import resolution as parse_res
from .common import CliError, int_list, progress_mode, read_json

# the options of the accuracy study that the SDF tracer study and the speed suite do not use:
# (attribute, flag); given when not None (their defaults are resolved in cmd_bench)
_STUDY_ONLY = (("spp", "--spp"), ("versions", "--versions"), ("gt_spp", "--gt-spp"),
               ("max_depth", "--max-depth"), ("adaptive", "--adaptive"), ("denoise", "--denoise"),
               ("camera_path", "--camera-path"), ("frames", "--frames"))
_SDF_STUDY_OPTIONS = "--quick, --repeats, --resolution, --out, --no-progress"


def _given(args, names) -> list[str]:
    """The flags among ``names`` (attributes of _STUDY_ONLY, or "quick") given on the command line."""
    flags = dict(_STUDY_ONLY, quick="--quick")
    return [flags[a] for a in names if (getattr(args, a) if a == "quick" else getattr(args, a) is not None)]


def _split_sdf_scenes(args, scenes) -> tuple[list, list]:
    """(scenes with [[sdf]] entries, the others); refuses the accuracy study's options when
    every scene goes to the SDF tracer study (which does not use them), and names them on
    stderr when some do (they apply to the other scenes only)."""
    sdf = [sc for sc in scenes if has_sdf(sc)]
    rest = [sc for sc in scenes if sc not in sdf]
    ignored = _given(args, [a for a, _ in _STUDY_ONLY])
    if sdf and ignored:
        names = ", ".join(os.path.basename(str(sc)) for sc in sdf)
        why = (f"{names} {'has' if len(sdf) == 1 else 'have'} [[sdf]] objects: the SDF tracer study "
               f"measures {'it' if len(sdf) == 1 else 'them'}, which does not use {', '.join(ignored)}")
        if not rest:
            raise CliError(f"bench: {why} (its options: {_SDF_STUDY_OPTIONS}); leave "
                           f"{'it' if len(ignored) == 1 else 'them'} out")
        print(f"draaw-mi: note: {why} ({'it applies' if len(ignored) == 1 else 'they apply'} to the "
              "other scenes only)", file=sys.stderr)
    return sdf, rest


def _bench_sdf_scenes(args, scenes, res, progress):
    """Run the SDF tracer-knob study (draaw_mi.bench.sdf_study) on the scenes with [[sdf]] entries
    (Mitsuba's path, the main study's ground truth, cannot see SDFs)."""
    for sc in scenes:
        scene = load_scene(sc, **({"resolution": res} if res else {}))
        r = run_sdf_study(scene, args.out, spp=4 if args.quick else 16,
                          repeats=(2 if args.quick else 3) if args.repeats is None else args.repeats,
                          progress=progress, quick=args.quick)
        print(f"wrote {args.out}/sdf_study_{r['scene']}.json/.csv/.md and "
              f"sdf_error_vs_time_{r['scene']}.png ({len(r['rows'])} tracer settings)")


def _cmd_speed_suite(args) -> int:
    """``draaw-mi bench --suite speed``: the speed suite (draaw_mi.bench.speed) with bench's options."""
    for name in args.scenes:
        if name not in speed_suite.SCENES:
            raise CliError(f"bench --suite speed: unknown scene {name!r}{suggest(name, list(speed_suite.SCENES))}")
    ignored = _given(args, ["max_depth", "adaptive", "quick", "denoise", "camera_path", "frames"])
    if ignored:                                     # (refused, not dropped silently)
        raise CliError(f"bench --suite speed: {', '.join(ignored)} {'does' if len(ignored) == 1 else 'do'} "
                       "not apply to the speed suite (each scene has its own max_depth; its options: "
                       "--versions, --spp, --gt-spp, --repeats, --resolution, --out); leave "
                       f"{'it' if len(ignored) == 1 else 'them'} out")
    versions = args.versions.split(",") if args.versions else ["v4"]
    for v in versions:
        try:
            resolve_version(v)
        except DraawError as e:
            raise CliError(f"bench --suite speed: --versions {args.versions!r}: {e}") from None
        if resolve_version(v) == SCENE_VERSION:   # (it failed after the reference had rendered)
            raise CliError(f"bench --suite speed: --versions {v!r}: the suite's scenes are built in "
                           "Python and name no integrator of their own; give v1..v4, path or prb")
    plugins = ["path"] + [resolve_version(v) for v in versions if resolve_version(v) != "path"]
    ref_spp = 1024 if args.gt_spp is None else args.gt_spp        # (the suite's own default)
    repeats = 3 if args.repeats is None else args.repeats
    argv = ["--integrators", ";".join(plugins), "--repeats", str(repeats),
            "--ref-spp", str(ref_spp),
            "--out", os.path.join(args.out, "speed_suite.md"),
            "--cache", os.path.join(args.out, "refs")]         # references reused by later runs
    if args.scenes:
        argv += ["--scenes", ",".join(args.scenes)]
    if repeats < 1:
        raise CliError(f"bench --suite speed: --repeats {repeats}; expected an integer >= 1")
    why = speed_bench.check_ref_spp(ref_spp)
    if why:
        raise CliError(f"bench --suite speed: --gt-spp {ref_spp} (the reference's spp); {why}")
    if args.spp:
        spps = int_list(args.spp, "--spp")
        if len(spps) != 1 or spps[0] < 1:
            raise CliError(f"bench --suite speed: --spp {args.spp!r}; expected one integer >= 1 "
                           "(the spp of the reference error each version is timed to)")
        argv += ["--spp", str(spps[0])]
    if args.resolution:
        text = args.resolution.strip()
        try:                              # (N is N x N here)
            w, h = parse_res(int(text) if text.isdigit() else text, Where("--resolution"))
        except DraawError:
            w, h = 0, 1
        if w != h:
            raise CliError(f"bench --suite speed: --resolution {args.resolution!r}; the suite's "
                           "images are square (give N or NxN, sides in 1..16384)")
        argv += ["--res", str(w)]
    if not any(speed_suite.build(n, 8) is not None for n in (args.scenes or speed_suite.SCENES)):
        raise CliError("bench --suite speed: every requested scene was skipped (the GO-Draaw data "
                       f"is absent: looked for {speed_suite.GO_DRAAW}/monkey.obj); nothing to measure")
    _check_out_folder(args.out)
    _make_out_folder(args.out)
    return speed_bench.main(argv, command="draaw-mi " + shlex.join(args.argv))


def _check_out_folder(out: str) -> None:
    """``--out`` names a folder (made if missing), not a file, nor a folder under a file:
    ``os.makedirs`` had raised a FileExistsError or NotADirectoryError traceback."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise CliError(f"bench --out {out!r}: exists and is not a folder; name a folder (made if missing)")
    above = os.path.dirname(os.path.abspath(out))
    while not os.path.exists(above):
        above = os.path.dirname(above)
    if not os.path.isdir(above):
        raise CliError(f"bench --out {out!r}: {above!r} is a file, not a folder; name a folder (made if missing)")


def _make_out_folder(out: str) -> None:
    """Make ``--out`` once every other check passed, or say in one line why it cannot be made
    (a read-only place, /proc)."""
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as e:
        raise CliError(f"bench --out {out!r}: cannot be made ({e.strerror or e}); name a folder you can "
                       "write") from None


#: bench's options that take text: an empty one (``--spp "$SPP"``, SPP unset) is refused, not
#: read as "the default" (the full 66-setting grid had started)
_TEXT_OPTIONS = ("versions", "spp", "max_depth", "resolution", "camera_path", "denoise", "out")


def cmd_bench(args) -> int:
    for name in _TEXT_OPTIONS:
        value = getattr(args, name, None)
        if value is not None and not str(value).strip():
            raise CliError(f"bench: --{name.replace('_', '-')} {value!r}: empty; give a value, or leave "
                           "the option out for its default")
    if args.suite == "speed":
        return _cmd_speed_suite(args)

    root = speed_suite.ROOT                                   # the repository
    scenes = args.scenes or [os.path.join(root, "scenes", f) for f in ("cornell.toml", "material_spheres.toml",
                                                                         "sdf_csg.toml")]
    versions = args.versions.split(",") if args.versions else list(bench.DEFAULT_VERSIONS)
    for v in versions:
        try:
            resolve_version(v)
        except DraawError as e:
            raise CliError(f"bench --versions: {e}") from None
    _check_out_folder(args.out)
    names: dict[str, str] = {}
    for path in scenes:
        if not os.path.isfile(path):              # (before --out is made: nothing left behind)
            raise CliError(f"bench: scene file {path!r} does not exist")
        # (the study keys its ground truths, rows and plots by the file's name)
        base = os.path.splitext(os.path.basename(path))[0]
        if base in names and os.path.abspath(names[base]) != os.path.abspath(path):
            raise CliError(f"bench: two scenes named {base!r} ({names[base]}, {path}); the study keys its "
                           "ground truths and results by the file name: rename one")
        names[base] = path
    if args.repeats is not None and args.repeats < 1:
        raise CliError(f"--repeats {args.repeats}: expected an integer >= 1")
    given = args.resolution
    if given and given.strip().isdigit():              # N: N x N, as --suite speed takes it
        given = f"{given.strip()}x{given.strip()}"
    res = parse_res(given, Where("bench") / "--resolution") if given else None
    if args.quick:
        spps = int_list(args.spp, "--spp") if args.spp else [1, 4, 16]
        res = res or (64, 64)
        gt_spp = 1024 if args.gt_spp is None else args.gt_spp     # (an explicit 4096 stays 4096)
    else:
        spps = int_list(args.spp, "--spp") if args.spp else [2 ** k for k in range(11)]
        gt_spp = 4096 if args.gt_spp is None else args.gt_spp
    # 3 also with --quick, not 2: a small render's dr.freeze recording is made again once while
    # the other versions' recordings settle, and the median of two is half that render (the
    # first scene's 1-spp times come out 5-10x high); an explicit --repeats is kept, also with
    # --quick
    repeats = 3 if args.repeats is None else args.repeats
    depths = int_list(args.max_depth, "--max-depth") if args.max_depth else None
    denoise_spp = int_list(args.denoise, "--denoise") if args.denoise else []
    frames = 60 if args.frames is None else args.frames
    adaptive = 8 if args.adaptive is None else args.adaptive
    # every number checked before the ground truth renders (minutes at the defaults)
    for name, values, lo in (("--spp", spps, 1), ("--gt-spp", [gt_spp], 1), ("--max-depth", depths or [], -1),
                             ("--frames", [frames], 1), ("--denoise", denoise_spp, 1)):
        bad = [v for v in values if v < lo]
        if bad:
            raise CliError(f"bench: {name} {bad[0]}; expected an integer >= {lo}"
                           + (" (-1: unbounded)" if name == "--max-depth" else ""))
    if adaptive and (adaptive < 2 or adaptive & (adaptive - 1)):
        raise CliError(f"bench: --adaptive {adaptive}; expected a power of two >= 2 (block size "
                       "in pixels) or 0 (none)")
    if args.frames is not None and not args.camera_path:
        raise CliError(f"bench: --frames {args.frames} times the frames of a --camera-path; give one")
    keys = read_json(args.camera_path, "--camera-path") if args.camera_path else None
    if keys is not None:              # checked before the study, which runs for minutes
        as_keyframes(keys)
        if frames < 2:
            raise CliError(f"bench: --frames {frames}; a camera path needs at least 2 frames")
    sdf_scenes, scenes = _split_sdf_scenes(args, scenes)
    _make_out_folder(args.out)
    progress = progress_mode(args.no_progress)
    _bench_sdf_scenes(args, sdf_scenes, res, progress)          # SDF scenes: tracer study
    if not scenes:
        return 0
    result = bench.run_study(scenes, versions=versions, spps=spps, max_depths=depths,
                             adaptive=(None, adaptive) if adaptive else (None,),
                             repeats=repeats, resolution=res, gt_spp=gt_spp, out_dir=args.out, progress=progress,
                             **_bench_denoise(denoise_spp))
    print(f"wrote {args.out}/results.json, results.csv, summary.md and plots ({len(result['rows'])} settings)")
    if keys is not None:
        scene = load_scene(scenes[0], **({"resolution": res} if res else {}))
        rows = bench.frame_times(scene, keys, versions=versions, frames=frames, progress=progress)
        path = os.path.join(args.out, "frame_times.json")
        write_text(path, json.dumps(rows, indent=1))
        for r in rows:
            print(f"{r['version']:>6}: mean {r['mean_s'] * 1e3:.1f} ms, median {r['median_s'] * 1e3:.1f} ms, "
                  f"p90 {r['p90_s'] * 1e3:.1f} ms")
        print(f"wrote {path}")
    return 0


def _bench_denoise(denoise_spp: list) -> dict:
    if not denoise_spp:
        return {}
    load_pyoidn()                                     # the install hint before the study starts
    return {"denoise_spp": denoise_spp}
