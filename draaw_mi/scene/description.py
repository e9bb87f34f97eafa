"""Translate a validated draaw-mi scene description (TOML/JSON/dict) into a Mitsuba scene dict.

The description has these top-level tables (all optional but ``shapes``)::

    [render]     resolution = [W, H], spp, max_depth, version, seed, filter, sampler, hide_emitters,
                 aovs
    [camera]     origin/target/up (mirror) or GO-Draaw position + angles = [theta, phi]; fov, fov_axis
    [materials.NAME]   type = "draaw" (default) or any Mitsuba BSDF, with its parameters
    [[shapes]]   type = mesh | sphere | rectangle | disk | cube | cylinder, material, emission, ...
    [[lights]]   type = point | spot | area | constant | envmap | directional, intensity, color
    [[post]]     post-processing chain (see draaw_mi.post)
    [[volumes]]  voxel grids as solid voxels or smoke (see draaw_mi.media.scene_volumes)

Materials are declared once at the top of the Mitsuba dict under their own names, so their
parameters appear in ``mi.traverse`` as ``NAME.roughness.value`` and so on.
"""
from __future__ import annotations

import os
import re

import numpy as np

from ..materials.draaw_bsdf import ALL_PARAMS as DRAAW_PARAMS
from ..materials.draaw_bsdf import COLOR_PARAMS, OPTIONS, SCALAR_PARAMS
from . import camera as cam
from .meshes import load_mesh_parts, mesh_side_files, write_ply
from .schema import Where, boolean, check_keys, kind_of, number, resolution, rotations, shown, string, vector

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
LIGHT_KEYS = {
    "point": ("position", "snap_to_camera"),
    "spot": ("position", "snap_to_camera", "target", "cutoff_angle", "beam_width"),
    "area": ("shape", "position", "target", "up", "size", "radius"),
    "constant": (),
    "envmap": ("file",),
    "directional": ("direction",),
}
COMMON_LIGHT_KEYS = ("type", "name", "intensity", "color")
#: the names of [[shapes]] and [[lights]] entries without a 'name' (their traverse keys start
#: with them; scene.light_values finds a light's table by it)
SHAPE_NAME = "{kind}{i}"
LIGHT_NAME = "{kind}_light{i}"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr", ".hdr", ".bmp", ".tga", ".pfm", ".ppm")

DEFAULT_SETTINGS = {"resolution": (256, 256), "spp": 64, "max_depth": 6, "version": "v4", "seed": 0,
                    "filter": "box", "sampler": "independent", "hide_emitters": False, "aovs": []}


class BuildContext:
    """State shared while translating one description (base folder, temp folder, counters)."""

    def __init__(self, base_dir: str, tmp_dir: str, source: str):
        self.base_dir, self.tmp_dir, self.source = base_dir, tmp_dir, source
        self.counter = 0
        self.files: list[str] = []      # every file the scene reads (info["files"])
        self.relative: dict[str, str] = {}   # relative name as written -> the file (info["relative_files"])

    def path(self, p: str) -> str:
        """A file the scene names, resolved against its folder (and remembered)."""
        path = p if os.path.isabs(p) else os.path.normpath(os.path.join(self.base_dir, p))
        if path not in self.files:
            self.files.append(path)
        if not os.path.isabs(p):
            self.relative[p] = path
        return path

    def unique(self, stem: str) -> str:
        self.counter += 1
        return f"{stem}_{self.counter}"


def safe_id(name: str) -> str:
    """A Mitsuba object id from a free-form name ('.' is reserved in parameter paths).

    >>> safe_id("Blue_Light.001")
    'Blue_Light_001'
    """
    return re.sub(r"[^A-Za-z0-9_-]", "_", name)


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
        from ..errors import DraawError
        from ..integrators import resolve_version
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
        aovs = render["aovs"]
        if not isinstance(aovs, list) or not all(isinstance(a, str) for a in aovs):
            raise (w / "aovs").error(f"{aovs!r} is not a list of AOV names")
        s["aovs"] = list(aovs)
    return s


# --------------------------------------------------------------------------- transforms
def to_world(table: dict, where: Where):
    """``matrix`` or scale -> rotate -> translate, as an mi.ScalarTransform4f."""
    import mitsuba as mi

    t = mi.ScalarTransform4f()
    if "matrix" in table:
        for k in ("translate", "rotate", "scale"):
            if k in table:
                raise (where / k).error("cannot be combined with 'matrix'")
        m = table["matrix"]
        arr = np.array(m, dtype=float) if isinstance(m, list) else None
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
        t = t.rotate(axis=axis, angle=angle)
    if "scale" in table:
        sc = vector(table["scale"], where / "scale")
        if any(v == 0 for v in sc):
            raise (where / "scale").error(f"{table['scale']!r} has a zero component")
        t = t.scale(sc)
    return t


def _matrix_of(t) -> np.ndarray:
    return np.array(t.matrix, dtype=float).reshape(4, 4)


# --------------------------------------------------------------------------- materials
# negative values a resampled image keeps (Lanczos overshoot) and that are let through
NEGATIVE_SLACK = 1e-2


def _check_image_values(path: str, label: str, where: Where, what: str, nonneg: bool = True) -> "mi.Bitmap":
    """Refuse an image file with a non-finite value in its colour channels, or, with
    ``nonneg``, one below ``-NEGATIVE_SLACK`` (a half-float HDRI stores a sun above 65504 as
    +Inf: its environment map rendered NaN / Inf pixels in V3, V4 and Mitsuba's ``path``),
    naming the first bad pixel. Alpha and other layers are not looked at. Returns the image
    read (an environment map's tint uses it: the file is read once)."""
    import mitsuba as mi
    from ..guard import exr_reading_threads
    try:
        with exr_reading_threads():
            bitmap = mi.Bitmap(path)
    except Exception as e:  # noqa: BLE001 - Mitsuba's reader: one line
        raise where.error(f"{what} {label!r} cannot be read: {str(e).strip().splitlines()[-1]}") from None
    arr = np.asarray(bitmap)
    if np.issubdtype(arr.dtype, np.integer):
        return bitmap                             # 8/16-bit: finite and >= 0 by construction
    arr = arr.reshape(arr.shape[0], arr.shape[1], -1)[..., :3]
    bad = ~np.isfinite(arr) | (arr < -NEGATIVE_SLACK) if nonneg else ~np.isfinite(arr)
    if bad.any():
        y, x, c = (int(i[0]) for i in np.nonzero(bad))
        raise where.error(f"{what} {label!r} has the value {float(arr[y, x, c]):g} at pixel "
                          f"(x={x}, y={y}), channel {c}; expected finite values"
                          + (" >= 0" if nonneg else ""))
    return bitmap


def _tinted_image(bitmap: "mi.Bitmap", color) -> "mi.Bitmap":
    """``bitmap`` as linear float RGB, each channel times ``color`` (an environment map's
    tint)."""
    import mitsuba as mi
    linear = bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
    rgb = np.array(linear, dtype=np.float32).reshape(linear.height(), linear.width(), 3)
    return mi.Bitmap(rgb * np.asarray(color, np.float32))


def _texture_value(value, name: str, ctx: BuildContext, where: Where, lo: float | None = None):
    """Scene-file value -> what the draaw plugin (or a Mitsuba BSDF) accepts; ``lo``: the
    least a plain number or RGB triple may be (a reflectance's 0)."""
    import mitsuba as mi

    if isinstance(value, str):
        path = ctx.path(value)
        if not os.path.isfile(path):
            raise where.error(f"texture file {value!r} does not exist (looked for {path!r})")
        if not path.lower().endswith(IMAGE_SUFFIXES):
            raise where.error(f"{value!r} is not an image file; expected one of {', '.join(IMAGE_SUFFIXES)}")
        raw = name not in ("base_color", "reflectance", "specular_reflectance", "diffuse_reflectance")
        return {"type": "bitmap", "filename": path, "raw": raw}
    if _is_nested(value):
        value = _nested_array(value, where)
    if isinstance(value, np.ndarray):
        arr = value.astype(np.float32)
        if arr.ndim == 2:
            arr = arr[..., None]
        return {"type": "bitmap", "data": mi.TensorXf(np.ascontiguousarray(arr)), "raw": True}
    if isinstance(value, (list, tuple)):
        return {"type": "rgb", "value": vector(value, where, lo=lo)}
    if lo is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
        return number(value, where, lo=lo)            # (-0.5 rendered negative pixels)
    return value


def _is_nested(value) -> bool:
    return isinstance(value, (list, tuple)) and len(value) > 0 and isinstance(value[0], (list, tuple))


def _nested_array(value, where: Where) -> np.ndarray:
    """A TOML/JSON array of rows (``[[0.1, 0.9], [0.5, 0.3]]``: a 2x2 texture; rows of RGB
    triples: a colour texture) as a float array."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise where.error(f"{shown(value)} is not a rectangular array of numbers (a texture: rows "
                          "of values, or rows of RGB triples)") from None
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] not in (1, 3)) or arr.size == 0:
        # (an empty one, [[]], loaded and then aborted the process at the render)
        raise where.error(f"an array of shape {arr.shape}; a texture is rows of values (H, W) or "
                          "rows of RGB triples (H, W, 3), at least one of them")
    return arr


def material_dict(name: str, table: dict, ctx: BuildContext, where: Where, two_sided_default=True) -> dict:
    """A Mitsuba BSDF dict for one ``[materials.NAME]`` table (validated)."""
    if not isinstance(table, dict):
        raise where.error(f"expected a material table, got {table!r}")
    kind = table.get("type", "draaw")
    string(kind, where / "type")
    if kind == "draaw":
        check_keys(table, ("type",) + DRAAW_PARAMS + OPTIONS, where)
        out = {"type": "draaw", "two_sided": two_sided_default}
        for key, value in table.items():
            if key == "type":
                continue
            wk = where / key
            if key in SCALAR_PARAMS:
                lo, hi = SCALAR_PARAMS[key][1:]
                out[key] = number(value, wk, lo=lo, hi=hi) if isinstance(value, (int, float)) \
                    else _texture_value(value, key, ctx, wk)
            elif key in COLOR_PARAMS:
                if isinstance(value, (int, float, list, tuple)) and not isinstance(value, bool) \
                        and not _is_nested(value):
                    out[key] = {"type": "rgb", "value": vector(value, wk, lo=0.0)}
                else:
                    out[key] = _texture_value(value, key, ctx, wk)
            elif key == "normalmap":
                out[key] = _texture_value(value, key, ctx, wk)
            elif key == "normalmap_encoding":
                out[key] = string(value, wk, ("unsigned", "signed"))
            elif key == "two_sided":
                out[key] = boolean(value, wk)
            elif key == "alpha_min":
                out[key] = number(value, wk, lo=0.0, hi=0.1, lo_open=True)
        return out
    # Any other Mitsuba BSDF: pass the parameters through, colours and files as textures,
    # whose values must be finite (a NaN texel of a diffuse reflectance rendered NaN pixels in
    # every version), and >= 0 for reflectances and transmittances.
    out = {"type": kind}
    for key, value in table.items():
        if key != "type":
            nonneg = "reflectance" in key or "transmittance" in key or key == "base_color"
            if isinstance(value, str) and not value.lower().endswith(IMAGE_SUFFIXES):
                out[key] = value      # a plugin's own string: material = "Au", int_ior = "bk7",
                continue              # distribution = "beckmann" (each was "no texture file")
            out[key] = _texture_value(value, key, ctx, where / key, lo=0.0 if nonneg else None)
            if isinstance(value, str) and out[key].get("type") == "bitmap":
                _check_image_values(out[key]["filename"], value, where / key, "texture", nonneg)
            elif isinstance(out[key], dict) and "data" in out[key]:     # an array (numpy or rows)
                arr = np.asarray(out[key]["data"], dtype=np.float64)
                if not np.isfinite(arr).all() or (nonneg and (arr < -NEGATIVE_SLACK).any()):
                    raise (where / key).error("texture array has a non-finite"
                                              + (" or negative" if nonneg else "") + " value")
    return out


# --------------------------------------------------------------------------- shapes
def _emitter(shape: dict, where: Where) -> dict | None:
    if "emission" not in shape:
        return None
    e = shape["emission"]
    color = vector(shape.get("emission_color", [1.0, 1.0, 1.0]), where / "emission_color", lo=0.0)
    rgb = vector(e, where / "emission", lo=0.0)
    return {"type": "area", "radiance": {"type": "rgb", "value": [a * b for a, b in zip(rgb, color)]}}


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
            from ..errors import suggest
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
        for part in parts:
            own = None
            if mat_id is None:      # take the file's material (MTL Kd / texture / glTF PBR)
                own = safe_id(f"{name}_{part.material_name or part.name}")
                if own not in materials:
                    materials[own] = material_dict(own, {"type": "draaw", **part.material}, ctx, where / "file")
            ply = os.path.join(ctx.tmp_dir, ctx.unique("mesh") + ".ply")
            write_ply(ply, part.vertices, part.faces, part.uv)
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
    out[name] = finish(d, None)
    return out


# --------------------------------------------------------------------------- lights
def spot_up(position, target) -> list[float]:
    """The up vector of a spot light's frame: +y, unless it shines (nearly) along y."""
    d = np.subtract(target, position)
    return [0.0, 1.0, 0.0] if abs(d[1]) < 0.999 * np.linalg.norm(d) else [1.0, 0.0, 0.0]


def light_dicts(light: dict, index: int, look_at, ctx: BuildContext, where: Where) -> dict:
    import mitsuba as mi

    if not isinstance(light, dict):
        raise where.error(f"expected a light table, got {light!r}")
    kind = kind_of(light, where, LIGHT_KEYS)
    check_keys(light, COMMON_LIGHT_KEYS + LIGHT_KEYS[kind], where)
    name = string(light.get("name", LIGHT_NAME.format(kind=kind, i=index)), where / "name")
    if safe_id(name) != name or not name:
        raise (where / "name").error(f"{name!r} may only contain letters, digits, '_' and '-'")
    intensity = number(light.get("intensity", 1.0), where / "intensity", lo=0.0)
    color = vector(light.get("color", [1.0, 1.0, 1.0]), where / "color", lo=0.0)
    rgb = {"type": "rgb", "value": [intensity * c for c in color]}

    def position():
        if light.get("snap_to_camera", False):      # GO-Draaw's "snap light to camera"
            if "position" in light:
                raise (where / "position").error("cannot be combined with snap_to_camera = true")
            return [float(v) for v in look_at[0]]
        if "position" not in light:
            raise where.error(f"a {kind} light needs 'position' (or snap_to_camera = true)")
        return vector(light["position"], where / "position")

    if "snap_to_camera" in light:
        boolean(light["snap_to_camera"], where / "snap_to_camera")
    if kind == "point":
        return {name: {"type": "point", "position": position(), "intensity": rgb}}
    if kind == "spot":
        pos = position()
        target = vector(light.get("target", [float(v) for v in look_at[1]]), where / "target")
        if np.allclose(pos, target):
            raise (where / "target").error("equals the light's position")
        cutoff = number(light.get("cutoff_angle", 20.0), where / "cutoff_angle", lo=0.0, hi=90.0, lo_open=True)
        beam = number(light.get("beam_width", cutoff * 0.75), where / "beam_width", lo=0.0, hi=cutoff, lo_open=True)
        return {name: {"type": "spot", "intensity": rgb, "cutoff_angle": cutoff, "beam_width": beam,
                       "to_world": mi.ScalarTransform4f().look_at(origin=pos, target=target,
                                                                  up=spot_up(pos, target))}}
    if kind == "constant":
        return {name: {"type": "constant", "radiance": rgb}}
    if kind == "envmap":
        if "file" not in light:
            raise where.error("an envmap light needs 'file'")
        path = ctx.path(string(light["file"], where / "file"))
        if not os.path.isfile(path):
            raise (where / "file").error(f"environment map {light['file']!r} does not exist")
        image = _check_image_values(path, light["file"], where / "file", "environment map", nonneg=False)
        if list(color) == [1.0, 1.0, 1.0]:
            return {name: {"type": "envmap", "filename": path, "scale": intensity}}
        # Mitsuba's envmap has a scale but no tint: the image is tinted here (its 'color' was
        # accepted and then dropped, so the tuner's light colour vanished on reload)
        return {name: {"type": "envmap", "bitmap": _tinted_image(image, color), "scale": intensity}}
    if kind == "directional":
        d = vector(light.get("direction", [0.0, -1.0, 0.0]), where / "direction")
        if np.linalg.norm(d) == 0:
            raise (where / "direction").error("is the zero vector")
        return {name: {"type": "directional", "direction": d, "irradiance": rgb}}
    # area light: an emitting rectangle, disk or sphere that faces 'target'
    shape = string(light.get("shape", "rectangle"), where / "shape", ("rectangle", "disk", "sphere"))
    pos = vector(light.get("position", [0.0, 0.0, 0.0]), where / "position")
    emitter = {"type": "area", "radiance": rgb}
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    if shape == "sphere":
        r = number(light.get("radius", 0.5), where / "radius", lo=0.0, lo_open=True)
        return {name: {"type": "sphere", "center": pos, "radius": r, "emitter": emitter, "bsdf": black}}
    target = vector(light.get("target", [pos[0], pos[1] - 1.0, pos[2]]), where / "target")
    if np.allclose(pos, target):
        raise (where / "target").error("equals the light's position")
    fwd = np.subtract(target, pos)
    up = vector(light.get("up", [0.0, 0.0, 1.0] if abs(fwd[1]) > 0.9 * np.linalg.norm(fwd) else [0.0, 1.0, 0.0]),
                where / "up")
    # (an up along the facing, or zero, gave a NaN transform: a light that silently lit nothing)
    cam.check_look_at(pos, target, up, where)
    size = light.get("size", [1.0, 1.0])
    sx, sy = vector(size, where / "size", n=2, lo=0.0) if isinstance(size, list) else [number(size, where / "size", lo=0.0)] * 2
    if sx == 0 or sy == 0:
        raise (where / "size").error(f"{size!r} has a zero side")
    t = mi.ScalarTransform4f().look_at(origin=pos, target=target, up=up).scale([sx / 2, sy / 2, 1.0])
    return {name: {"type": shape, "to_world": t, "emitter": emitter, "bsdf": black}}


# --------------------------------------------------------------------------- whole scene
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
        materials[mname] = material_dict(mname, table, ctx, where / "materials" / mname)

    shape_entries: dict = {}
    for i, shape in enumerate(shapes):
        for key, d in shape_dicts(shape, i, materials, ctx, where / "shapes" / i).items():
            if key in shape_entries or key in materials:
                used = "a material" if key in materials else "another shape"
                raise (where / "shapes" / i / "name").error(f"duplicate name {key!r} (already used by {used})")
            shape_entries[key] = d

    # --- SDF objects ([[sdf]], see draaw_mi.sdf.scene): hidden proxy shapes carry their BSDFs
    sdf_scene = None
    if desc.get("sdf") is not None:
        from ..sdf.scene import sdf_dicts
        proxies, sdf_scene = sdf_dicts(desc["sdf"], materials, ctx, where / "sdf")
        shape_entries.update(proxies)
    # --- end SDF
    # ---- [[volumes]]: voxel grids (draaw_mi.media) -------------------------------------
    volume_info = []
    volumes = desc.get("volumes", [])
    if not isinstance(volumes, list):
        raise (where / "volumes").error("expected a list of volume tables ([[volumes]])")
    if volumes:
        from ..media.scene_volumes import volume_dicts
        for i, vol in enumerate(volumes):
            entries, vinfo = volume_dicts(vol, i, mats, ctx, where / "volumes" / i)
            for key, d in entries.items():
                if key in shape_entries or key in materials:
                    raise (where / "volumes" / i / "name").error(f"duplicate name {key!r}")
                shape_entries[key] = d
            volume_info.append(vinfo)
        from ..media.scene_volumes import check_smoke_boxes_disjoint
        check_smoke_boxes_disjoint(volume_info, where)
    # ---- end [[volumes]] ------------------------------------------------------------------

    if camera_table is None:
        from .framing import scene_bounds
        camera_table = cam.auto_camera(*scene_bounds(shape_entries, sdf_scene))
    look_at = cam.camera_to_look_at(camera_table, where / "camera")
    if volume_info:
        from ..media.scene_volumes import check_camera_outside_smoke
        w_px, h_px = settings["resolution"]
        reach = cam.near_reach(look_at[5], cam.x_fov(look_at[3], look_at[4], w_px, h_px), w_px, h_px)
        check_camera_outside_smoke(look_at[0], volume_info, where, reach)

    lights = desc.get("lights", [])
    if not isinstance(lights, list):
        raise (where / "lights").error("expected a list of light tables ([[lights]])")
    light_entries: dict = {}
    for i, light in enumerate(lights):
        for key, d in light_dicts(light, i, look_at, ctx, where / "lights" / i).items():
            if key in light_entries or key in shape_entries or key in materials:
                raise (where / "lights" / i / "name").error(f"duplicate name {key!r} (names of materials, "
                                                            "shapes and lights share one namespace)")
            light_entries[key] = d

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
        from ..errors import DraawError
        from ..post import load_chain
        try:
            load_chain(post)                       # validate names, parameters and ranges now
        except DraawError as e:
            raise (where / "post").error(str(e)) from None
    settings["post"] = post or []
    info = {"materials": list(materials), "shapes": list(shape_entries), "lights": list(light_entries),
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


def auto_light(bbox_min, bbox_max, origin) -> list[dict]:
    """Lights for a bare mesh file: a point light at the camera, its intensity following the
    mesh's size (a floor at 1e-3 made a mesh 1e-4 across 5x too bright), and a dim sky."""
    diag = float(np.linalg.norm(np.subtract(bbox_max, bbox_min)))
    diag = diag if diag > 0 else 1.0
    return [{"type": "point", "position": [float(v) for v in origin], "intensity": diag ** 2 * 3.0},
            {"type": "constant", "intensity": 0.15}]

