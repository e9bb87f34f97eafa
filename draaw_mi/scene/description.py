"""Translate a validated draaw-mi scene description (TOML/JSON/dict) into a Mitsuba scene dict.

The description has these top-level tables (all optional but ``shapes``)::

    [render]     resolution = [W, H], spp, max_depth, version, seed, filter, sampler, hide_emitters,
                 aovs
    [camera]     origin/target/up (mirror) or GO-Draaw position + angles = [theta, phi]; fov, fov_axis
    [materials.NAME]   type = "draaw" (default) or any Mitsuba BSDF, with its parameters
    [[shapes]]   type = mesh | sphere | rectangle | disk | cube | cylinder, material, emission, ...
    [[lights]]   type = point | spot | area | constant | envmap | directional, intensity, color
    [[post]]     post-processing chain (see draaw_mi.post)
    [[volumes]]  voxel grids as solid voxels or smoke (see draaw_mi.scene.volume_dicts)

Materials are declared once at the top of the Mitsuba dict under their own names, so their
parameters appear in ``mi.traverse`` as ``NAME.roughness.value`` and so on; a material that
no shape, SDF object or light uses is left out (``info["unused_materials"]``), parameters and
all.
"""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from ..errors import DraawError, suggest
from ..integrators import resolve_version
from ..integrators.common import AOV_CHANNELS
from ..post import load_chain
from ..sdf.scene import PROXY_PREFIX
from . import camera as cam
from .context import BuildContext, safe_id
from .framing import scene_bounds
from .light_dicts import light_dicts
from .material_dicts import material_dict
from .meshes import load_mesh_parts, mesh_side_files, write_ply
from .schema import Where, boolean, check_keys, kind_of, number, resolution, rotations, string, vector
from .sdf_dicts import sdf_dicts
from .smoke_boxes import check_camera_outside_smoke, check_smoke_boxes_disjoint
from .smooth_normals import smooth_parts

TOP_KEYS = ("render", "camera", "materials", "shapes", "lights", "post", "sdf", "volumes")
RENDER_KEYS = ("resolution", "spp", "max_depth", "version", "seed", "filter", "sampler", "hide_emitters",
               "aovs")
FILTERS = ("box", "gaussian", "tent", "lanczos", "mitchell", "catmullrom")
# Mitsuba's samplers. multijitter has 2-10x less variance than the independent sampler at the
# same time on the speed suite's scenes, for `path` on all of them and for V4 on all but the
# small-light and glass scenes (benchmarks/results/speed_suite.md, "Samplers"); the default stays independent (Mitsuba's, and what V4's adaptive sampling needs)
# until V3's heavy-tailed glossy split, noted there, is settled.
SAMPLERS = ("independent", "multijitter", "stratified", "ldsampler", "orthogonal")
TRANSFORM_KEYS = ("translate", "rotate", "scale", "matrix")
SHAPE_KEYS = {
    "mesh": ("file", "smooth"),
    "sphere": ("center", "radius"),
    "rectangle": (),
    "disk": (),
    "cube": (),
    "cylinder": ("p0", "p1", "radius"),
}
COMMON_SHAPE_KEYS = ("type", "name", "material", "emission", "emission_color") + TRANSFORM_KEYS
#: the name of a [[shapes]] entry without a 'name' (its traverse keys start with it)
SHAPE_NAME = "{kind}{i}"

DEFAULT_SETTINGS = {"resolution": (256, 256), "spp": 64, "max_depth": 6, "version": "v4", "seed": 0,
                    "filter": "box", "sampler": "independent", "hide_emitters": False, "aovs": []}


# --------------------------------------------------------------------------- settings
def parse_settings(desc: dict, where: Where) -> dict:
    render = desc.get("render", {})
    check_keys(render, RENDER_KEYS, where / "render")
    w = where / "render"
    s = dict(DEFAULT_SETTINGS)
    if "resolution" in render:
        s["resolution"] = resolution(render["resolution"], w / "resolution")
    if "spp" in render:
        s["spp"] = number(render["spp"], w / "spp", lo=1, hi=2 ** 24, integer=True)
    if "max_depth" in render:
        s["max_depth"] = number(render["max_depth"], w / "max_depth", lo=-1, hi=1024, integer=True)
    if "version" in render:
        s["version"] = string(render["version"], w / "version")
        try:
            resolve_version(s["version"])          # a typo names the file and the field
        except DraawError as e:
            raise (w / "version").error(str(e).replace("render version ", "", 1)) from None
    if "seed" in render:
        s["seed"] = number(render["seed"], w / "seed", lo=0, hi=2 ** 32 - 1, integer=True)
    if "filter" in render:
        s["filter"] = string(render["filter"], w / "filter", FILTERS)
    if "sampler" in render:
        s["sampler"] = string(render["sampler"], w / "sampler", SAMPLERS)
    if "hide_emitters" in render:
        s["hide_emitters"] = boolean(render["hide_emitters"], w / "hide_emitters")
    if "aovs" in render:
        s["aovs"] = aov_list(render["aovs"], w / "aovs")
    return s


def aov_list(aovs, where: Where) -> list:
    """A list of AOV names (or ``["all"]``), checked: a misspelt one failed at the render,
    naming neither file nor key."""
    if not isinstance(aovs, list) or not all(isinstance(a, str) for a in aovs):
        raise where.error(f"{aovs!r} is not a list of AOV names")
    for name in aovs:
        if name not in AOV_CHANNELS and name != "all":
            raise where.error(f"{name!r} is not an AOV{suggest(name, list(AOV_CHANNELS) + ['all'])}")
    return list(aovs)


# --------------------------------------------------------------------------- transforms
def to_world(table: dict, where: Where):
    """``matrix`` or scale -> rotate -> translate, as an mi.ScalarTransform4f."""
    t = mi.ScalarTransform4f()
    if "matrix" in table:
        for k in ("translate", "rotate", "scale"):
            if k in table:
                raise (where / k).error("cannot be combined with 'matrix'")
        m = table["matrix"]
        # four rows of four numbers (not a word, a bool or a numeric string, which numpy reads:
        # "a" raised a ValueError traceback, "1" rendered)
        numbers = (isinstance(m, list) and len(m) == 4
                   and all(isinstance(r, list) and len(r) == 4 for r in m)
                   and all(isinstance(x, (int, float)) and not isinstance(x, bool) for r in m for x in r))
        arr = np.array(m, dtype=float) if numbers else None
        if arr is None or arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
            raise (where / "matrix").error(f"{m!r} is not a 4x4 list of finite numbers")
        if abs(np.linalg.det(arr[:3, :3])) < 1e-12:
            raise (where / "matrix").error("is singular")
        return mi.ScalarTransform4f(arr.tolist())
    if "translate" in table:
        t = t.translate(vector(table["translate"], where / "translate"))
    # chained transforms apply right to left: the list is walked backwards so that its first
    # rotation acts first, as for SDF objects (schema.rotations)
    for axis, angle in reversed(rotations(table, where)):
        # (a unit axis: Mitsuba's rotate takes the axis as given, and [1, 1, 0] stretched the
        # shape; the SDF objects' rotations normalise it too)
        t = t.rotate(axis=list(np.divide(axis, np.linalg.norm(axis))), angle=angle)
    if "scale" in table:
        sc = vector(table["scale"], where / "scale")
        if any(v == 0 for v in sc):
            raise (where / "scale").error(f"{table['scale']!r} has a zero component")
        t = t.scale(sc)
    return t


def _matrix_of(t) -> np.ndarray:
    return np.array(t.matrix, dtype=float).reshape(4, 4)


# --------------------------------------------------------------------------- materials


# --------------------------------------------------------------------------- shapes
def _emitter(shape: dict, where: Where) -> dict | None:
    if "emission" not in shape:
        if "emission_color" in shape:           # (it was ignored: nothing emitted, no word)
            raise (where / "emission_color").error("given without 'emission'; give the shape's "
                                                   "emission too (the colour multiplies it)")
        return None
    e = shape["emission"]
    color = vector(shape.get("emission_color", [1.0, 1.0, 1.0]), where / "emission_color", lo=0.0)
    rgb = vector(e, where / "emission", lo=0.0)
    return {"type": "area", "radiance": {"type": "rgb", "value": [a * b for a, b in zip(rgb, color)]}}


# the scene dict's own keys, which a material, shape, light or volume name would overwrite (a
# light named "sensor" was deleted by the camera) or break ("type"); "integrator" is where
# readers of the dict find its integrator; SDF proxies' ids start with PROXY_PREFIX
RESERVED_NAMES = ("type", "sensor", "integrator")


def check_not_reserved(key: str, where: Where) -> None:
    """Raise ``where``'s error if ``key`` is one of the scene dict's own keys."""
    if key in RESERVED_NAMES or key.startswith(PROXY_PREFIX):
        raise where.error(f"{key!r} is reserved ({', '.join(RESERVED_NAMES)} and names starting with "
                          f"{PROXY_PREFIX!r} are the scene's own keys); pick another name")


def shape_dicts(shape: dict, index: int, materials: dict, ctx: BuildContext, where: Where) -> dict:
    """Mitsuba dicts (keyed by unique ids) for one ``[[shapes]]`` entry."""
    if not isinstance(shape, dict):
        raise where.error(f"expected a shape table, got {shape!r}")
    kind = kind_of(shape, where, SHAPE_KEYS, default="mesh" if "file" in shape else None)
    check_keys(shape, COMMON_SHAPE_KEYS + SHAPE_KEYS[kind], where)
    name = string(shape.get("name", SHAPE_NAME.format(kind=kind, i=index)), where / "name")
    if safe_id(name) != name or not name:
        raise (where / "name").error(f"{name!r} may only contain letters, digits, '_' and '-'")
    mat_ref = shape.get("material")
    if isinstance(mat_ref, dict):
        mat_id = f"{name}_material"
        materials[mat_id] = material_dict(mat_id, mat_ref, ctx, where / "material")
    elif mat_ref is None:
        mat_id = None
    else:
        mat_id = string(mat_ref, where / "material")
        if mat_id not in materials:
            raise (where / "material").error(f"unknown material {mat_id!r}{suggest(mat_id, materials)}")
    emitter = _emitter(shape, where)
    transform = to_world(shape, where)
    out: dict = {}

    def finish(d: dict, own_material: str | None) -> dict:
        ref = own_material or mat_id
        d["bsdf"] = {"type": "ref", "id": ref} if ref else {"type": "draaw", "two_sided": True}
        if emitter:
            d["emitter"] = dict(emitter)
        return d

    if kind == "mesh":
        if "file" not in shape:
            raise where.error("a mesh needs 'file'")
        path = ctx.path(string(shape["file"], where / "file"))
        ctx.files.extend(f for f in mesh_side_files(path) if f not in ctx.files)
        parts = load_mesh_parts(path, where / "file")
        smooth = boolean(shape.get("smooth", False), where / "smooth")
        # smooth across the file's split vertices and its material borders, sharp at creases
        smoothed = smooth_parts(parts) if smooth else [None] * len(parts)
        for part, smoothed_part in zip(parts, smoothed):
            own = None
            if mat_id is None:      # take the file's material (MTL Kd / texture / glTF PBR)
                # a part without a material of its own: "NAME_PARTn", or "NAME_PARTn_material"
                # where the file has several parts ("NAME_PARTn" is then the part's shape)
                own = safe_id(f"{name}_{part.material_name}" if part.material_name else
                              f"{name}_{part.name}" + ("_material" if len(parts) > 1 else ""))
                if own not in materials:
                    materials[own] = material_dict(own, {"type": "draaw", **part.material}, ctx, where / "file")
            ply = os.path.join(ctx.tmp_dir, ctx.unique("mesh") + ".ply")
            # (vertices, faces, uv[, normals]): the part re-indexed with its smooth normals
            write_ply(ply, *(smoothed_part or (part.vertices, part.faces, part.uv)))
            d = {"type": "ply", "filename": ply, "to_world": transform, "face_normals": not smooth}
            out[safe_id(f"{name}_{part.name}") if len(parts) > 1 else name] = finish(d, own)
        return out
    if kind == "sphere":
        d = {"type": "sphere", "center": vector(shape.get("center", [0, 0, 0]), where / "center"),
             "radius": number(shape.get("radius", 1.0), where / "radius", lo=0.0, lo_open=True),
             "to_world": transform}
    elif kind == "cylinder":
        d = {"type": "cylinder", "p0": vector(shape.get("p0", [0, 0, 0]), where / "p0"),
             "p1": vector(shape.get("p1", [0, 0, 1]), where / "p1"),
             "radius": number(shape.get("radius", 1.0), where / "radius", lo=0.0, lo_open=True),
             "to_world": transform}
        if np.allclose(d["p0"], d["p1"]):
            raise (where / "p1").error("equals 'p0'; a cylinder needs a non-zero axis")
    else:
        d = {"type": kind, "to_world": transform}
    if kind in ("sphere", "cylinder"):
        _check_round(kind, name, d, shape, transform, where)
    out[name] = finish(d, None)
    return out


def _check_round(kind: str, name: str, d: dict, shape: dict, transform, where: Where) -> None:
    """Raise a :class:`SceneError` at the shape's ``scale`` (or ``matrix``) when its transform
    stretches a sphere unevenly, or a cylinder unevenly across its axis: Mitsuba keeps one
    radius (it only logs "'to_world' transform shouldn't contain non-uniform scaling"), so the
    shape would render round, unlike the one described.

    The transform's linear part ``L`` keeps a sphere round where ``L^T L = a I``, and a
    cylinder of axis ``u`` round where ``L^T L = a I + (b - a) u u^T`` (``u`` stretched by
    itself, the plane across it evenly)."""
    lin = _matrix_of(transform)[:3, :3]
    gram = lin.T @ lin
    if kind == "sphere":
        even = np.trace(gram) / 3 * np.eye(3)
    else:
        u = np.subtract(d["p1"], d["p0"], dtype=float)
        u /= np.linalg.norm(u)
        across = np.linalg.svd(np.eye(3) - np.outer(u, u))[0][:, 0]   # (a unit vector across u)
        a, b = across @ gram @ across, u @ gram @ u
        even = a * np.eye(3) + (b - a) * np.outer(u, u)
    # (relative 2e-3 of L^T L, about 1e-3 of a scale: a rotation written to 4 decimals,
    # 0.7071, or a scale of 1.00001 is round; Mitsuba's camera tells scale at 1e-3 too)
    if np.abs(gram - even).max() <= 2e-3 * np.abs(gram).max():
        return
    key = "matrix" if "matrix" in shape else "scale"
    what = "unevenly" if kind == "sphere" else "unevenly across its axis"
    raise (where / key).error(
        f"{shape.get(key)!r} stretches {kind} {name!r} {what}, which Mitsuba's {kind} cannot "
        f"show (it keeps one radius: a round {kind} would render); scale it evenly"
        + (" (or along its axis: p0 to p1)" if kind == "cylinder" else "")
        + ", or give the shape as a mesh (a file of the stretched shape)")


# --------------------------------------------------------------------------- lights

# --------------------------------------------------------------------------- whole scene
def _referenced_ids(entries) -> set[str]:
    """The ids of every ``{"type": "ref", "id": ...}`` inside ``entries`` (Mitsuba dicts).

    >>> sorted(_referenced_ids({"a": {"type": "sphere", "bsdf": {"type": "ref", "id": "red"}}}))
    ['red']
    """
    found: set[str] = set()
    stack = [entries]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            if node.get("type") == "ref" and isinstance(node.get("id"), str):
                found.add(node["id"])
            stack.extend(node.values())
        elif isinstance(node, (list, tuple)):
            stack.extend(node)
    return found


def build_mitsuba_dict(desc: dict, source: str, base_dir: str, tmp_dir: str, overrides: dict | None = None):
    """Validate ``desc`` and return (mitsuba_dict, settings, info) where ``info`` lists names."""
    where = Where(source)
    if not isinstance(desc, dict):
        raise where.error(f"expected a table at the top level, got {type(desc).__name__}")
    check_keys(desc, TOP_KEYS, where)
    ctx = BuildContext(base_dir, tmp_dir, source)
    settings = parse_settings(desc, where)
    for key, value in (overrides or {}).items():
        if value is not None:
            settings[key] = value
    width, height = settings["resolution"]

    camera_table = desc.get("camera")
    shapes = desc.get("shapes", [])
    if not isinstance(shapes, list):
        raise (where / "shapes").error("expected a list of shape tables ([[shapes]])")
    if not shapes and not desc.get("sdf") and not desc.get("volumes"):
        raise where.error("the scene has no shapes; add at least one [[shapes]] entry")

    materials: dict = {}
    mats = desc.get("materials", {})
    if not isinstance(mats, dict):
        raise (where / "materials").error("expected a table of named materials")
    for mname, table in mats.items():
        if safe_id(mname) != mname:
            raise (where / "materials" / mname).error(f"material name {mname!r} may only contain letters, "
                                                      "digits, '_' and '-'")
        check_not_reserved(mname, where / "materials" / mname)
        materials[mname] = material_dict(mname, table, ctx, where / "materials" / mname)

    shape_entries: dict = {}
    for i, shape in enumerate(shapes):
        before = set(materials)
        entries = shape_dicts(shape, i, materials, ctx, where / "shapes" / i)
        for key in [*entries, *(m for m in materials if m not in before)]:   # (its own materials)
            check_not_reserved(key, where / "shapes" / i / "name")
        for key, d in entries.items():
            if key in shape_entries or key in materials:
                used = "a material" if key in materials else "another shape"
                raise (where / "shapes" / i / "name").error(f"duplicate name {key!r} (already used by {used})")
            shape_entries[key] = d

    # --- SDF objects ([[sdf]], see draaw_mi.sdf.scene): hidden proxy shapes carry their BSDFs
    sdf_scene = None
    if desc.get("sdf") is not None:
        proxies, sdf_scene = sdf_dicts(desc["sdf"], materials, ctx, where / "sdf")
        shape_entries.update(proxies)
    # --- end SDF
    # ---- [[volumes]]: voxel grids (draaw_mi.media) -------------------------------------
    volume_info = []
    volumes = desc.get("volumes", [])
    if not isinstance(volumes, list):
        raise (where / "volumes").error("expected a list of volume tables ([[volumes]])")
    if volumes:
        from .volume_dicts import volume_dicts  # (with draaw_mi.media: 10 ms to import; volumes only)
        for i, vol in enumerate(volumes):
            entries, vinfo = volume_dicts(vol, i, mats, ctx, where / "volumes" / i)
            for key, d in entries.items():
                check_not_reserved(key, where / "volumes" / i / "name")
                if key in shape_entries or key in materials:
                    raise (where / "volumes" / i / "name").error(f"duplicate name {key!r}")
                shape_entries[key] = d
            volume_info.append(vinfo)
        check_smoke_boxes_disjoint(volume_info, where)
    # ---- end [[volumes]] ------------------------------------------------------------------

    if camera_table is None:
        camera_table = cam.auto_camera(*scene_bounds(shape_entries, sdf_scene))
    look_at = cam.camera_to_look_at(camera_table, where / "camera")
    if volume_info:
        w_px, h_px = settings["resolution"]
        reach = cam.near_reach(look_at[5], cam.x_fov(look_at[3], look_at[4], w_px, h_px), w_px, h_px)
        check_camera_outside_smoke(look_at[0], volume_info, where, reach)

    lights = desc.get("lights", [])
    if not isinstance(lights, list):
        raise (where / "lights").error("expected a list of light tables ([[lights]])")
    light_entries: dict = {}
    for i, light in enumerate(lights):
        for key, d in light_dicts(light, i, look_at, ctx, where / "lights" / i).items():
            check_not_reserved(key, where / "lights" / i / "name")
            if key in light_entries or key in shape_entries or key in materials:
                raise (where / "lights" / i / "name").error(f"duplicate name {key!r} (names of materials, "
                                                            "shapes and lights share one namespace)")
            light_entries[key] = d

    # a material no shape, SDF object or light references stays out of the Mitsuba scene:
    # Dr.Jit's BSDF calls trace every live BSDF, so its textures and lobes would enter every
    # kernel (a [[volumes]] material is copied into its voxel meshes, not referenced)
    used = _referenced_ids(shape_entries) | _referenced_ids(light_entries)
    copied = {v.get("material") for v in volumes if isinstance(v, dict)}      # (not unused)
    unused = [m for m in materials if m not in used and m not in copied]
    in_volumes = [m for m in materials if m in copied and m not in used]
    materials = {m: d for m, d in materials.items() if m in used}
    scene = {"type": "scene"}
    scene.update(materials)
    scene.update(shape_entries)
    scene.update(light_entries)
    scene["sensor"] = cam.sensor_dict(look_at, width, height, settings["spp"], settings["filter"],
                                      settings["sampler"])
    post = desc.get("post")
    if post is not None and not isinstance(post, list):
        raise (where / "post").error("expected a list of filter tables ([[post]])")
    if post:
        try:
            load_chain(post)                       # validate names, parameters and ranges now
        except DraawError as e:
            raise (where / "post").error(str(e)) from None
    settings["post"] = post or []
    info = {"materials": list(materials), "unused_materials": unused, "volume_materials": in_volumes, "shapes": list(shape_entries), "lights": list(light_entries),
            "camera": {"origin": list(map(float, look_at[0])), "target": list(map(float, look_at[1])),
                       "up": list(map(float, look_at[2])), "fov": look_at[3], "fov_axis": look_at[4],
                       "mirror": look_at[7]}}
    if sdf_scene is not None:
        info["sdf"] = sdf_scene
        info["shapes"] = [k for k in info["shapes"] if k not in sdf_scene.proxy_ids]
    if volume_info:
        info["volumes"] = volume_info
    info["files"] = [f for f in ctx.files if os.path.isfile(f)]
    info["relative_files"] = dict(ctx.relative)
    return scene, settings, info
