"""``[[lights]]`` tables -> Mitsuba emitter (or emitting shape) dicts, and the lights a bare
mesh file gets."""
from __future__ import annotations

import os

import mitsuba as mi
import numpy as np

from ..integrators.features import BLACK_SURFACE_PREFIX
from . import camera as cam
from .context import BuildContext, safe_id
from .material_dicts import check_image_values, tinted_image
from .schema import Where, boolean, check_keys, kind_of, number, string, vector

LIGHT_KEYS = {
    "point": ("position", "snap_to_camera"),
    "spot": ("position", "snap_to_camera", "target", "cutoff_angle", "beam_width"),
    "area": ("shape", "position", "target", "up", "size", "radius"),
    "constant": (),
    "envmap": ("file",),
    "directional": ("direction",),
}
COMMON_LIGHT_KEYS = ("type", "name", "intensity", "color")
#: the name of a [[lights]] entry without a 'name' (its traverse keys start with it;
#: scene.light_values finds a light's table by it)
LIGHT_NAME = "{kind}_light{i}"


def spot_up(position, target) -> list[float]:
    """The up vector of a spot light's frame: +y, unless it shines (nearly) along y."""
    d = np.subtract(target, position)
    return [0.0, 1.0, 0.0] if abs(d[1]) < 0.999 * np.linalg.norm(d) else [1.0, 0.0, 0.0]


def light_dicts(light: dict, index: int, look_at, ctx: BuildContext, where: Where) -> dict:

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
            raise (where / "file").error(f"environment map {light['file']!r} does not exist (looked for {path!r})")
        image = check_image_values(path, light["file"], where / "file", "environment map", nonneg=False)
        if list(color) == [1.0, 1.0, 1.0]:
            return {name: {"type": "envmap", "filename": path, "scale": intensity}}
        # Mitsuba's envmap has a scale but no tint: the image is tinted here (so its 'color' is
        # not dropped, and the tuner's light colour survives a reload)
        return {name: {"type": "envmap", "bitmap": tinted_image(image, color), "scale": intensity}}
    if kind == "directional":
        d = vector(light.get("direction", [0.0, -1.0, 0.0]), where / "direction")
        if np.linalg.norm(d) == 0:
            raise (where / "direction").error("is the zero vector")
        return {name: {"type": "directional", "direction": d, "irradiance": rgb}}
    # area light: an emitting rectangle, disk or sphere that faces 'target'
    shape = string(light.get("shape", "rectangle"), where / "shape", ("rectangle", "disk", "sphere"))
    # (no default: one at the origin sat in the floor of most scenes, a black image)
    if "position" not in light:
        raise where.error(f"an area light needs 'position' (the centre of its {shape})")
    pos = vector(light["position"], where / "position")
    emitter = {"type": "area", "radiance": rgb}
    # (absorbing: the integrators know it by its id and leave other BSDFs' code out)
    black = {"type": "diffuse", "id": BLACK_SURFACE_PREFIX + name,
             "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    # the keys that size the light: a rectangle's size, a sphere's radius, a disk's radius (or
    # size, an ellipse); a key of another shape is refused, not ignored (the light would keep
    # its default size)
    takes = {"rectangle": ("size",), "disk": ("radius", "size"), "sphere": ("radius",)}[shape]
    for key in ("radius", "size"):
        if key in light and key not in takes:
            raise (where / key).error(f"a {shape} area light has no {key!r}; it is sized by "
                                      + " or ".join(repr(k) for k in takes))
    if shape == "disk" and "radius" in light and "size" in light:
        raise (where / "radius").error("give a disk light 'radius' or 'size' (an ellipse), not both")
    if shape == "sphere":
        # a sphere shines all around: a 'target' or 'up' is refused, not ignored
        for key in ("target", "up"):
            if key in light:
                raise (where / key).error("a sphere area light shines in every direction and has "
                                          f"no {key!r}; use shape = \"rectangle\" or \"disk\" to aim it")
        r = number(light.get("radius", 0.5), where / "radius", lo=0.0, lo_open=True)
        return {name: {"type": "sphere", "center": pos, "radius": r, "emitter": emitter, "bsdf": black}}
    target = vector(light.get("target", [pos[0], pos[1] - 1.0, pos[2]]), where / "target")
    if np.allclose(pos, target):
        raise (where / "target").error("equals the light's position")
    fwd = np.subtract(target, pos)
    up = vector(light.get("up", [0.0, 0.0, 1.0] if abs(fwd[1]) > 0.9 * np.linalg.norm(fwd) else [0.0, 1.0, 0.0]),
                where / "up")
    # (an up along the facing, or zero, would give a NaN transform: a light that lights nothing)
    cam.check_look_at(pos, target, up, where)
    if shape == "disk" and "radius" in light:
        r = number(light["radius"], where / "radius", lo=0.0, lo_open=True)
        size = [2.0 * r, 2.0 * r]
    else:
        size = light.get("size", [1.0, 1.0])
    sx, sy = vector(size, where / "size", n=2, lo=0.0) if isinstance(size, list) else [number(size, where / "size", lo=0.0)] * 2
    if sx == 0 or sy == 0:
        raise (where / "size").error(f"{size!r} has a zero side")
    t = mi.ScalarTransform4f().look_at(origin=pos, target=target, up=up).scale([sx / 2, sy / 2, 1.0])
    return {name: {"type": shape, "to_world": t, "emitter": emitter, "bsdf": black}}



def auto_light(bbox_min, bbox_max, origin) -> list[dict]:
    """Lights for a bare mesh file: a point light at the camera, its intensity following the
    mesh's size (a floor at 1e-3 would make a mesh 1e-4 across 5x too bright), and a dim sky."""
    diag = float(np.linalg.norm(np.subtract(bbox_max, bbox_min)))
    diag = diag if diag > 0 else 1.0
    return [{"type": "point", "position": [float(v) for v in origin], "intensity": diag ** 2 * 3.0},
            {"type": "constant", "intensity": 0.15}]
