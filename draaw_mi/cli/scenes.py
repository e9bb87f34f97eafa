"""What the ``draaw-mi`` subcommands that read a scene share: ``-D name=value`` for a Mitsuba
XML file's ``$name`` parameters, loading the scene with it, telling a batch manifest from a
scene (and the reverse) by name, saying which integrator an XML scene renders with, and the
``info`` command."""
from __future__ import annotations

import json
import math
import os
import re
from importlib.util import find_spec

import drjit as dr
import mitsuba as mi

from .. import __version__, integrators, materials
from ..errors import DraawError
from ..integrators import SCENE_VERSION, resolve_version
from ..integrators import stratify
from ..integrators.features import sensor_gated_speedups
from ..integrators.light_tables import describe_selection
from ..rendering.session import session_of
from ..scene import load_scene
from ..scene.description import TOP_KEYS
from ..scene.loading import SCENE_SUFFIXES
from ..scene.schema import read_document
from ..scene.values import value_like
from .common import CliError

DEFINE_HELP = ("NAME=VALUE: a value for a Mitsuba XML scene's $NAME parameter (its <default "
               "name=NAME>), e.g. -D res=64 -D spp=16; repeatable")


def add_define_option(parser) -> None:
    """``-D NAME=VALUE`` (repeatable) on a subcommand that reads a scene."""
    parser.add_argument("-D", "--define", action="append", metavar="NAME=VALUE", help=DEFINE_HELP)


def parse_defines(given) -> dict | None:
    """``-D`` values as ``{name: value}`` (``None`` when none were given)."""
    if not given:
        return None
    out = {}
    for item in given:
        name, eq, value = item.partition("=")
        name = name.strip()
        if not eq or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name) or not value.strip():
            raise CliError(f"-D {item!r}: expected NAME=VALUE, e.g. -D res=64 (a Mitsuba XML "
                           "scene's $NAME parameter)")
        out[name] = value.strip()
    return out


def load_for_cli(args, **overrides):
    """``load_scene(args.scene, ...)`` with the command's ``-D`` values; a TOML/JSON scene
    given ``-D``, or a batch manifest given to a scene command, is one line naming the fix."""
    defines = parse_defines(getattr(args, "define", None))
    if defines is not None and not args.scene.lower().endswith(".xml"):
        raise CliError(f"-D {', '.join(f'{k}={v}' for k, v in defines.items())}: -D sets $name "
                       f"parameters of a Mitsuba XML scene; {args.scene} is not one (set its values "
                       "in the file, or with --resolution, --spp, ...)")
    try:
        return load_scene(args.scene, defines=defines, **overrides)
    except Exception as e:
        if "is a batch manifest" in str(e):
            raise CliError(f"{args.command}: {args.scene} is a batch manifest (it has [[jobs]]), "
                           f"not a scene; use `draaw-mi batch {args.scene}`") from None
        raise


SET_HELP = ("NAME=VALUE: set a scene parameter before rendering, named as `fit` names it "
            "(material.parameter, a light's key such as key.emitter.radiance, sdf.NODE.PARAM); VALUE a "
            "number or a JSON list, e.g. --set target.roughness=0.3 --set target.base_color=[0.9,0.2,0.1] "
            "(a textured parameter is filled with the value); repeatable")


def add_set_option(parser) -> None:
    """``--set NAME=VALUE`` (repeatable): a parameter's value for this render only."""
    parser.add_argument("--set", dest="sets", action="append", metavar="NAME=VALUE", help=SET_HELP)


def apply_sets(scene, given) -> dict:
    """Write ``--set`` values into the loaded ``scene``'s parameters (converted to each
    parameter's type, as batch overrides are); ``{name: value}`` of what was set. A name the
    scene lacks, a value that is not a number or JSON list, or one of the wrong size is a
    :class:`CliError` naming it."""
    if not given:
        return {}
    params, done = scene.all_params, {}
    for item in given:
        name, eq, text = item.partition("=")
        name = name.strip()
        if not eq or not name or not text.strip():
            raise CliError(f"--set {item!r}: expected NAME=VALUE, e.g. --set target.roughness=0.3")
        try:
            value = json.loads(text, parse_constant=_refuse_constant)
        except ValueError:
            value = None
        numbers = value if isinstance(value, list) else [value]
        if numbers and all(isinstance(x, list) for x in numbers):
            raise CliError(f"--set {item}: {text!r} is an array of arrays; --set takes a number or a JSON "
                           "list of numbers (a texture: one number, or one per channel, fills it)")
        if not numbers or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                  and math.isfinite(x) for x in numbers):
            raise CliError(f"--set {item}: {text!r} is not a finite number or a JSON list of finite "
                           "numbers")
        try:
            key = scene.key(name)
        except DraawError as e:
            raise CliError(f"--set {item}: {e}") from None
        try:
            # the ranges a scene file keeps to (roughness in [0, 1], colours >= 0, an SDF
            # object's radius > 0, ...), as the batch planner and the preview check theirs
            scene.check_values("--set", {name: (key, value)})     # ("--set: name=value; expected ...")
        except DraawError as e:
            raise CliError(str(e)) from None
        try:
            params[key] = value_like(params[key], value, key)
        except DraawError as e:
            raise CliError(f"--set {item}: {e}") from None
        done[name] = value
    params.update()
    session_of(scene).scene_changed()        # e.g. V4's light powers after a radiance change
    return done


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a finite number")


def refuse_scene_as_manifest(path: str) -> None:
    """One line when the file given to ``draaw-mi batch`` is a scene, not a manifest."""
    lower = path.lower()
    if not os.path.isfile(path) or not lower.endswith(SCENE_SUFFIXES):
        return
    if lower.endswith((".toml", ".json")):
        try:
            doc = read_document(path, "manifest")
        except Exception:  # noqa: BLE001 - the manifest reader says what is wrong with it
            return
        scene_keys = sorted(set(doc) & set(TOP_KEYS)) if isinstance(doc, dict) else []
        if "jobs" in doc or not scene_keys:
            return
        what = f"a scene (it has {', '.join(f'[{k}]' for k in scene_keys)}), not a batch manifest"
    else:
        what = "a scene file, not a batch manifest (a .toml or .json file with [[jobs]])"
    raise CliError(f"batch: {path} is {what}; use `draaw-mi render {path} -o OUT.exr`")


def integrator_note(args, scene) -> str | None:
    """What a render of an XML/dict scene that declares an integrator does with it, when the
    user may not expect it: rendered with the file's own integrator (``direct``, ...) as no
    ``--version`` was given, or with ``--version`` instead of the one the file declares."""
    own = scene.info.get("integrator")
    if own is None:
        return None
    if args.version is None:
        if scene.settings["version"] == SCENE_VERSION:
            return (f"{args.scene} renders with its own integrator {own!r} (Mitsuba's, with the "
                    "file's settings); --version picks another")
        return None
    if resolve_version(args.version) == SCENE_VERSION:
        return None                  # (asked for the file's own integrator, and rendered with it)
    if resolve_version(args.version) != resolve_version(scene.settings["version"]):
        return (f"{args.scene} declares integrator {own!r}; rendered with --version "
                f"{args.version} ({resolve_version(args.version)}) instead")
    return None


def check_own_integrator_flags(args, scene) -> None:
    """``--max-depth`` does not reach an XML scene's own integrator (its file sets its depth)."""
    version = args.version or scene.settings["version"]
    if resolve_version(version) == SCENE_VERSION and not scene.info.get("integrator"):
        raise CliError(f"--version {version}: {args.scene} declares no integrator of its own to render "
                       "with; give a render version (v4, path, ...)")
    if args.max_depth is not None and resolve_version(version) == SCENE_VERSION:
        raise CliError(f"--max-depth {args.max_depth}: {args.scene} renders with its own integrator "
                       f"{scene.info.get('integrator', '?')!r}, whose depth its file sets; set it "
                       "there, or give --version (path, v4, ...) with --max-depth")


# extra -> the modules it installs (pyproject.toml's optional-dependencies, all of each but the
# test tooling of dev and browser; tests/cli/test_cli.py compares them with the file)
EXTRAS = {"denoise": ("pyoidn",), "batch": ("dask", "distributed"),
          "notebooks": ("ipywidgets", "jupyter_rfb", "ipykernel", "jupyterlab", "pyoidn"),
          "docs": ("sphinx", "myst_nb", "furo", "sphinxarg")}


def extras_present() -> dict:
    """{extra: the modules of it that cannot be found ([] when all are there)}, by
    ``importlib.util.find_spec``: nothing is imported."""
    return {extra: [m for m in modules if find_spec(m) is None] for extra, modules in EXTRAS.items()}


def extras_line(missing: dict) -> str:
    """``denoise yes, batch no (pip install 'draaw-mi[batch]'), ...``

    >>> extras_line({"denoise": [], "batch": ["distributed"]})
    "denoise yes, batch no (no distributed: pip install 'draaw-mi[batch]')"
    """
    return ", ".join(f"{extra} yes" if not gone else
                     f"{extra} no (no {', '.join(gone)}: pip install 'draaw-mi[{extra}]')"
                     for extra, gone in missing.items())


def cmd_info(args) -> int:
    """``draaw-mi info [SCENE]``: the set-up, and what a scene holds."""
    missing = extras_present()
    out = {
        "draaw_mi": __version__,
        "variant": mi.variant(),
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "llvm": ".".join(map(str, dr.detail.llvm_version())) if mi.variant().startswith("llvm") else None,
        "threads": dr.thread_count(),
        "plugins": {"bsdf": list(getattr(materials, "PLUGINS", ["draaw"])),
                    "integrators": sorted(set(getattr(integrators, "PLUGINS", [])))},
        "versions": dict(integrators.VERSION_ALIASES),
        "extras": {extra: not gone for extra, gone in missing.items()},
    }
    if args.scene:
        loaded = load_for_cli(args)
        out["scene"] = loaded.summary()
        gated = samples = lights = reuse = None
        # (for any scene, not only one whose version is v4: a Mitsuba XML scene's is its own
        # integrator's, and --version v4 renders it)
        if loaded.mi_scene.sensors():
            sensor = loaded.mi_scene.sensors()[0]
            gated = sensor_gated_speedups(sensor)
            st = out["scene"]["settings"]
            # (the one a render uses: an XML scene's own draaw_v4, its stratify and light selection)
            v4 = session_of(loaded).integrator("v4", int(st["max_depth"]), bool(st.get("hide_emitters", False)), [])
            samples = stratify.describe(v4, loaded.mi_scene, sensor, int(out["scene"]["settings"]["spp"]))
            lights = describe_selection(loaded.mi_scene, v4.light_selection)
            table, why = v4.reuse_decision(loaded.mi_scene, sensor, int(st["spp"]))
            reuse = ("2x2 pixel tiles share the light after a bounce off "
                     + ("any surface without delta lobes" if table.reevaluates else "Lambertian surfaces")
                     + f" ({why})" if table is not None else f"off ({why})")
        out["scene"]["v4_gated"] = gated
        out["scene"]["v4_reuse"] = reuse
        out["scene"]["v4_samples"] = samples
        out["scene"]["v4_lights"] = lights
    if args.json:
        print(json.dumps(out, indent=2, default=str))
        return 0
    for key, value in out.items():
        if key in ("scene", "versions", "plugins"):
            continue
        print(f"{key:>10}: {extras_line(missing) if key == 'extras' else value}")
    print(f"{'bsdfs':>10}: {', '.join(out['plugins']['bsdf'])}")
    by_plugin: dict = {}
    for alias, plugin in out["versions"].items():
        if alias != plugin:
            by_plugin.setdefault(plugin, []).append(alias)
    for plugin in sorted(set(out["versions"].values())):
        print(f"{'version':>10}: {plugin} ({', '.join(by_plugin.get(plugin, [])) or plugin})")
    if args.scene:
        s = out["scene"]
        print(f"\nscene {s['source']}: {s['resolution'][0]}x{s['resolution'][1]}")
        print(f"    shapes: {len(s['shapes'])} ({', '.join(s['shapes'][:12])}{' ...' if len(s['shapes']) > 12 else ''})")
        print(f"    lights: {', '.join(s['lights']) or 'none'}")
        if len(s["sensors"]) > 1:
            print(f"   sensors: {', '.join(s['sensors'])} (the first renders; another with --sensor)")
        none = "(the default draaw material)" if s.get("described") else "(from the file)"
        print(f" materials: {', '.join(s['materials']) or none}")
        if s.get("volume_materials"):
            print(f"   volumes: {', '.join(s['volume_materials'])} (copied into the volumes' voxels)")
        if s.get("unused_materials"):
            print(f"    unused: {', '.join(s['unused_materials'])} (no shape uses them: left out "
                  "of the scene)")
        for v in s.get("volumes", []):
            print("    volume: " + _volume_line(v))
        print("  settings: " + ", ".join(f"{k}={v}" for k, v in s["settings"].items()))
        if s.get("integrator"):
            used = ("with it (version 'scene')" if s["settings"]["version"] == SCENE_VERSION
                    else f"as version {s['settings']['version']!r}")
            print(f"integrator: {s['integrator']} (declared by the file; renders {used})")
        if s["post"]:
            print(f"      post: {' -> '.join(map(str, s['post']))}")
        if s.get("sdf"):
            print(f"       sdf: {len(s['sdf'])} nodes")
            for line in s["sdf"]:
                print(f"            {line}")
        on = [k for k, v in s["features"].items() if v]
        off = [k for k, v in s["features"].items() if not v]
        print(f"  features: on: {', '.join(on) or 'none'}; off: {', '.join(off) or 'none'}")
        if s.get("v4_samples"):
            print(f"v4 samples: {s['v4_samples']}")
        if s.get("v4_lights"):
            print(f" v4 lights: {s['v4_lights']}")
        if s.get("v4_reuse"):
            print(f"  v4 reuse: {s['v4_reuse']}")
        if s.get("v4_gated"):
            print(f"   v4 note: {s['v4_gated']}")
    return 0


def _volume_line(v: dict) -> str:
    """One line of ``draaw-mi info`` for a [[volumes]] entry."""
    shape = "x".join(map(str, v["shape"]))
    lo, hi = v["bounds"]
    box = f"box {[round(x, 3) for x in lo]}..{[round(x, 3) for x in hi]}"
    if v["mode"] == "smoke":
        return (f"{v['name']}: smoke {shape}, {v['cells']} cells with density, max sigma_t "
                f"{v['max_sigma_t']:g}, g={v['g']:g}, {box}")
    return f"{v['name']}: solid {shape}, {v['voxels']} voxels, {v['faces']} exterior faces, {box}"
