"""Helpers of the material tuner that need no widgets: material values, lights, the orbit
camera, frame encoding, errors against a reference, saving and the Python snippet.

Kept apart from :mod:`draaw_mi.widgets` so that scripts and tests can use them without
ipywidgets.

>>> orbit({"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0]}, yaw=90)[0].round(6).tolist()
[4.0, 0.0, 0.0]
"""
from __future__ import annotations

import copy
import io
import math
import os

import mitsuba as mi
import numpy as np
import tomli_w
from PIL import Image

from ..errors import ParameterError, exception_chain
from ..io import srgb_decode, srgb_encode, write_text
from ..limits import FLOAT32_MAX
from ..materials.draaw_bsdf import ALL_PARAMS, COLOR_PARAMS, SCALAR_PARAMS
from ..scene.camera import look_at_transform as look_at  # (a camera's to_world; public here)
from ..scene.light_dicts import spot_up
from ..scene.light_values import light_names

LIGHT_SUFFIXES = (".emitter.radiance.value", ".radiance.value", ".intensity.value", ".irradiance.value")


# --------------------------------------------------------------------------- materials
def material_values(scene) -> dict:
    """``{material: {parameter: value}}`` for every draaw parameter held as a constant
    (textured parameters are left out: they have no single value to put on a slider)."""
    params = scene.params
    out: dict = {}
    for name in scene.info.get("materials", []):
        vals = {}
        for p in ALL_PARAMS:
            key = f"{name}.{p}.value"
            if key not in params:
                continue
            arr = np.array(params[key], dtype=np.float64).ravel()
            if p in COLOR_PARAMS:
                vals[p] = [float(x) for x in (arr if arr.size == 3 else np.repeat(arr[:1], 3))]
            else:
                vals[p] = float(arr[0])
        if vals:
            out[name] = vals
    return out


def parse_rgb(text: str, where: str) -> list[float]:
    """``"0.8, 0.3, 0.2"`` (or one number for grey) -> three floats >= 0 (ParameterError).

    >>> parse_rgb("0.5", "x")
    [0.5, 0.5, 0.5]
    """
    parts = [p for p in str(text).replace(";", ",").replace(" ", ",").split(",") if p.strip()]
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise ParameterError(f"{where}: {text!r} is not a colour; expected three numbers such as "
                             "'0.8, 0.3, 0.2'") from None
    if len(nums) == 1:
        nums = nums * 3
    if len(nums) != 3 or not all(0 <= x <= FLOAT32_MAX for x in nums):      # (NaN fails too)
        raise ParameterError(f"{where}: {text!r}; expected three finite numbers >= 0 (linear RGB)")
    return nums


def hex_to_linear(value: str) -> list[float]:
    """A colour picker's sRGB ``#rrggbb`` (or ``#rgb``, or a CSS name such as ``"blue"``, which
    ipywidgets' picker also takes) -> linear RGB in [0, 1].

    >>> hex_to_linear("blue"), hex_to_linear("#00f")
    ([0.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    """
    from matplotlib.colors import to_rgb  # (72 ms to import: colour names only)
    try:
        c = list(to_rgb(value.strip()))
    except (ValueError, AttributeError):
        raise ParameterError(f"colour {value!r}; expected #rrggbb or a CSS colour name") from None
    return [float(x) for x in srgb_decode(np.array(c))]


def linear_to_hex(rgb) -> str:
    """Linear RGB -> sRGB ``#rrggbb`` (clipped to [0, 1]) for a colour picker.

    >>> linear_to_hex([1.0, 0.0, 0.2140])
    '#ff007f'
    """
    out = []
    for x in rgb:
        x = min(max(float(x), 0.0), 1.0)
        s = 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055
        out.append(int(round(s * 255)))
    return "#" + "".join(f"{v:02x}" for v in out)


# --------------------------------------------------------------------------- lights
def _emitter_keys(scene, suffix: str) -> list[str]:
    """Traverse keys ending in ``suffix`` whose object is an emitter (named or not: an XML
    scene's unnamed environment map is ``object_<address>.scale``)."""
    props = scene.params.properties
    return [k for k in props if k.endswith(suffix) and isinstance(props[k][2], mi.Emitter)]


def light_values(scene) -> dict:
    """``{traverse key: base value}`` of every emitter's radiance / intensity (RGB, flat), an
    environment map's ``scale`` (one number) and its texels ``data`` ((H, W, 3): its tint).

    >>> import draaw_mi
    >>> sorted(light_values(draaw_mi.load_scene({"shapes": [{"type": "sphere"}],
    ...        "lights": [{"type": "point", "position": [0, 0, 5]}]})))
    ['point_light0.intensity.value']
    """
    params = scene.params
    out = {}
    for key in params.keys():
        if key.endswith(LIGHT_SUFFIXES) and not key.endswith(".bsdf.reflectance.value"):
            out[key] = np.array(params[key], dtype=np.float64).ravel()
    for key in _emitter_keys(scene, ".scale"):
        out[key] = np.array(params[key], dtype=np.float64).ravel()
    for key in _emitter_keys(scene, ".data"):
        out[key] = np.array(params[key], dtype=np.float32)
    return out


def light_positions(scene) -> dict:
    """``{traverse key: position}`` of every point-like light (what "snap to the camera" moves)."""
    return {k: np.array(scene.params[k], dtype=np.float64).ravel() for k in _emitter_keys(scene, ".position")}


def camera_lights(scene) -> dict:
    """The lights that the scene file puts at the camera (``snap_to_camera = true``), which
    follow the camera wherever it goes, as a render of the saved scene has them:
    ``{"name.position": None}`` for a point light, ``{"name.to_world": target}`` for a spot
    light (its ``target``; None: the camera's)."""
    desc = getattr(scene, "description", None) or {}
    out = {}
    for name, light in zip(light_names(desc), desc.get("lights") or []):
        if isinstance(light, dict) and light.get("snap_to_camera") is True:
            if light.get("type") == "spot":
                out[f"{name}.to_world"] = light.get("target")
            else:
                out[f"{name}.position"] = None
    return {k: v for k, v in out.items() if k in scene.params.keys()}


def spot_at(eye, target):
    """A spot light's ``to_world`` at ``eye`` shining at ``target`` (as the scene builder
    makes it); None where the two coincide (no direction: the light stays where it was)."""
    if np.allclose(eye, target):
        return None
    return look_at(eye, target, spot_up(eye, target))


# --------------------------------------------------------------------------- camera
def orbit(camera: dict, yaw: float = 0.0, pitch: float = 0.0, distance: float = 1.0):
    """Rotate the camera ``origin`` about ``target``: ``yaw`` degrees about ``up``, ``pitch``
    degrees towards it (clamped short of the pole), distance scaled by ``distance``.
    Returns (origin, target, up) as numpy arrays."""
    o = np.asarray(camera["origin"], float)
    t = np.asarray(camera["target"], float)
    up = np.asarray(camera.get("up", [0, 1, 0]), float)
    up = up / max(np.linalg.norm(up), 1e-12)
    d = o - t
    r = np.linalg.norm(d)
    if r < 1e-12 or not (distance > 0):
        raise ParameterError(f"orbit: camera origin equals target or distance={distance!r}; expected > 0")
    # frame: up, and two axes spanning the plane orthogonal to it
    h = d - np.dot(d, up) * up
    if np.linalg.norm(h) < 1e-9 * r:
        h = np.cross(up, [1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.cross(up, [0.0, 0.0, 1.0])
    e1 = h / np.linalg.norm(h)
    e2 = np.cross(up, e1)
    el0 = math.asin(max(-1.0, min(1.0, float(np.dot(d, up)) / r)))
    # short of the pole, or where the camera is already (else a camera 0.6 degrees from
    # overhead moves 2.5 cm on Save without the orbit being touched)
    lim = max(math.radians(89), abs(el0))
    el = max(-lim, min(lim, el0 + math.radians(pitch)))
    az = math.radians(yaw)
    direction = math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up
    return t + direction * r * distance, t, up


# --------------------------------------------------------------------------- frames and errors
def to_uint8(image: np.ndarray, encoded: bool = False) -> np.ndarray:
    """Linear HDR -> sRGB-encoded, clipped, uint8 (H, W, 3); ``encoded``: the image is
    display-encoded already (a post chain that ends in a display curve:
    :func:`draaw_mi.post.display_encoded`), only clipped."""
    x = np.nan_to_num(np.asarray(image, dtype=np.float32)[..., :3], nan=0.0, posinf=1.0, neginf=0.0)
    return (np.clip(x if encoded else srgb_encode(x), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def encode(image: np.ndarray, fmt: str = "jpeg", quality: int = 80, encoded: bool = False) -> bytes:
    """An image as JPEG (``quality``) or PNG bytes, for ``ipywidgets.Image`` (``encoded``: see
    :func:`to_uint8`)."""
    buf = io.BytesIO()
    im = Image.fromarray(image if image.dtype == np.uint8 else to_uint8(image, encoded))
    if fmt == "jpeg":
        im.save(buf, format="JPEG", quality=int(quality))
    elif fmt == "png":
        im.save(buf, format="PNG", compress_level=1)
    else:
        raise ParameterError(f"encode: fmt={fmt!r}; expected 'jpeg' or 'png'")
    return buf.getvalue()


def errors(image: np.ndarray, reference: np.ndarray) -> dict:
    """Linear RMSE and the RMSE of the sRGB-encoded display images."""
    a = np.nan_to_num(np.asarray(image, np.float32)[..., :3])
    b = np.asarray(reference, np.float32)[..., :3]
    if a.shape != b.shape:
        raise ParameterError(f"reference image of shape {b.shape}; expected the preview's {a.shape}")
    return {"rmse": float(np.sqrt(np.mean((a - b) ** 2))),
            "display_rmse": float(np.sqrt(np.mean((srgb_encode(a) - srgb_encode(b)) ** 2)))}


def error_image(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The absolute display difference in false colour (magma, 0 .. 0.25) as uint8 RGB."""
    from matplotlib import colormaps  # (86 ms to import: the difference view only)
    d = np.abs(srgb_encode(np.nan_to_num(image[..., :3])) - srgb_encode(reference[..., :3])).mean(axis=2)
    return (colormaps["magma"](np.clip(d / 0.25, 0, 1))[..., :3] * 255).astype(np.uint8)


# --------------------------------------------------------------------------- saving
def document(scene, materials: dict, *, camera: dict | None = None, render: dict | None = None,
             post=None, light_scale: float = 1.0, light_color=(1.0, 1.0, 1.0),
             dest: str | None = None, values: dict | None = None) -> dict:
    """The scene description with the tuned values written in (for ``tomli_w``); ``dest``:
    the file it goes to (relative file names follow, see ``DraawScene.updated_description``);
    ``values``: more ``{traverse or sdf key: value}`` to write (a light's, before the
    intensity and colour controls scale it)."""
    flat = {f"{m}.{p}": v for m, vals in materials.items() for p, v in vals.items()}
    for key, v in (values or {}).items():
        arr = np.asarray(v, np.float64).ravel()
        flat[key] = [float(x) for x in arr] if arr.size > 1 else float(arr[0])
    desc = scene.updated_description(flat, dest)
    if camera is not None:
        cam = {k: v for k, v in desc.get("camera", {}).items() if k not in ("position", "angles", "mirror")}
        cam.update({k: [float(x) for x in camera[k]] for k in ("origin", "target", "up")})
        if camera.get("mirror"):        # a GO-Draaw camera's mirrored view, as a look-at table
            cam["mirror"] = True
        if "fov" in camera:             # the horizontal FOV (Mitsuba's x_fov)
            cam["fov"] = float(camera["fov"])
            cam["fov_axis"] = "x"       # (a "y" kept beside it would make 56.4 degrees 94 on reload)
        desc["camera"] = cam
    if render:
        desc["render"] = dict(desc.get("render", {}), **render)
    if post is not None:
        desc["post"] = copy.deepcopy(list(post))
    col = [float(c) for c in light_color]
    if light_scale != 1.0 or col != [1.0, 1.0, 1.0]:
        for light in desc.get("lights", []):
            if "intensity" in light:
                light["intensity"] = float(light["intensity"]) * float(light_scale)
            elif light.get("type") in ("point", "spot", "area", "constant", "envmap", "directional", "sun"):
                light["intensity"] = float(light_scale)
            if col != [1.0, 1.0, 1.0]:
                light["color"] = _tinted(light.get("color", 1.0), col)
        # emitting shapes too: the preview scales their radiance with the lights' (else a saved
        # panel stays at 5 where the preview shows 10)
        for shape in desc.get("shapes", []):
            if "emission" not in shape:
                continue
            e = shape["emission"]
            shape["emission"] = ([float(x) * float(light_scale) for x in e] if isinstance(e, list)
                                 else float(e) * float(light_scale))
            if col != [1.0, 1.0, 1.0]:
                shape["emission_color"] = _tinted(shape.get("emission_color", 1.0), col)
    return desc


def _tinted(base, col) -> list[float]:
    """A scene file's colour (one number or RGB) times the tint ``col``."""
    base = base if isinstance(base, list) else [float(base)] * 3
    return [float(b) * c for b, c in zip(base, col)]


def save_toml(path: str, doc: dict) -> None:
    """Write ``doc`` as TOML atomically (``draaw_mi.io.write_text``)."""
    if not str(path).lower().endswith(".toml"):
        raise ParameterError(f"save: {path!r}; expected a .toml file name")
    write_text(path, tomli_w.dumps(doc))


def snippet(source: str, materials: dict, settings: dict | None = None, resolution=None) -> str:
    """Python code that loads the scene and sets the tuned values (materials; the camera,
    lights and post chain go into a saved scene file). ``source``: the scene file (made
    absolute) or ``"<dict>"``; ``resolution``: (W, H) the scene was loaded at."""
    if source.startswith("<"):       # a dict or mi.Scene: no file to name
        load = "draaw_mi.load_scene(description)   # the dict the tuner was given"
    else:
        res = f", resolution={tuple(int(x) for x in resolution)!r}" if resolution else ""
        load = f"draaw_mi.load_scene({os.path.abspath(source)!r}{res})"
    lines = ["import draaw_mi", "", f"scene = {load}", "params = scene.params"]
    for m, vals in materials.items():
        for p, v in vals.items():        # (repr: every digit; 4 figures would make 0.123456 0.1235)
            if isinstance(v, list):
                lines.append(f"params[{f'{m}.{p}.value'!r}] = mi.Color3f({', '.join(repr(float(x)) for x in v)})")
            else:
                lines.append(f"params[{f'{m}.{p}.value'!r}] = {float(v)!r}")
    lines.insert(1, "import mitsuba as mi")
    lines.append("params.update()")
    args = ", ".join(f"{k}={v!r}" for k, v in (settings or {}).items())
    lines.append(f"image = draaw_mi.render(scene{', ' + args if args else ''})")
    return "\n".join(lines) + "\n"


def scaled_resolution(size, scale: float) -> tuple[int, int]:
    """The film for the resolution slider: ``size`` (W, H) itself at scale 1, else one factor
    on both axes, at least 8 pixels on the shorter one (8 per axis would turn 32x24 at 0.25
    into 8x8, and a 6x6 scene at 1.0 into 8x8).

    >>> scaled_resolution((32, 24), 0.25), scaled_resolution((6, 6), 1.0), scaled_resolution((640, 480), 0.5)
    ((11, 8), (6, 6), (320, 240))
    """
    w, h = int(size[0]), int(size[1])
    s = min(1.0, max(float(scale), 8.0 / min(w, h)))
    if s >= 1.0:
        return w, h
    return max(1, round(w * s)), max(1, round(h * s))


def innermost_error(error: BaseException) -> str:
    """The text of the exception at the bottom of ``error``'s chain (``raise ... from``, or
    raised while handling): Dr.Jit's wrappers say only "error while performing a custom
    differentiable operation. (see above)", and nothing is above in a panel.

    >>> try:
    ...     try:
    ...         raise ValueError("the BSDF failed")
    ...     except ValueError as e:
    ...         raise RuntimeError("drjit.custom(): error (see above)") from e
    ... except RuntimeError as e:
    ...     innermost_error(e)
    'ValueError: the BSDF failed'
    """
    e = exception_chain(error, suppressed=True)[-1]
    return str(error) if e is error else f"{type(e).__name__}: {e}"


__all__ = ["material_values", "parse_rgb", "hex_to_linear", "linear_to_hex", "light_values", "light_positions", "orbit",
           "look_at", "to_uint8", "encode", "errors", "error_image", "document", "save_toml", "snippet",
           "SCALAR_PARAMS", "scaled_resolution", "innermost_error"]
