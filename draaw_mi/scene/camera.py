"""Cameras: look-at, or GO-Draaw's position + two spherical angles, as Mitsuba sensors.

GO-Draaw (go-draaw-spec.md §2.8) spans the image as a bilinear patch between three points on
the unit sphere, ``S(θ, φ) = (sin φ cos θ, sin φ sin θ, cos φ)``: top-left ``S(θ, φ)``,
top-right ``S(θ + F, φ)``, bottom-left ``S(θ, φ + F)``. draaw-mi replaces that patch with a
proper pinhole camera looking through the patch's centre ``(TR + BL) / 2``, with image-up
along ``TL − BL`` and the horizontal field of view F, without the patch's non-uniform
distortion (documented deviation). The patch's image-right, ``TR − TL``, lies along
``sin φ · e_θ``; a Mitsuba look-at camera's is ``view × up``, the opposite way where
``sin φ > 0``. There GO-Draaw's view is the mirror image of any look-at camera's (no
rotation gives it), and the camera is mirrored left-right (:func:`go_draaw_look_at`'s
``mirror``, :func:`look_at_transform`): GO-Draaw's view, with its handedness, at every φ.
"""
from __future__ import annotations

import math

import mitsuba as mi
import numpy as np

from ..integrators.features import filter_plugin, sampler_plugin  # noqa: F401 (re-exported)
from ..limits import FOV_RANGE
from .schema import Where, boolean, check_keys, number, string, vector

CAMERA_KEYS = ("origin", "target", "up", "mirror", "position", "angles", "fov", "fov_axis", "near_clip",
               "far_clip")

# target - origin must exceed this fraction of their distance from the world origin (float32
# resolves about 1.2e-7 of it; a direction from a few ulps is noise)
FLOAT32_SEPARATION = 1e-5


def spherical(theta: float, phi: float) -> np.ndarray:
    """GO-Draaw's unit-sphere point ``S(θ, φ)``.

    >>> np.round(spherical(0.0, math.pi / 2), 6).tolist()
    [1.0, 0.0, 0.0]
    """
    return np.array([math.sin(phi) * math.cos(theta), math.sin(phi) * math.sin(theta), math.cos(phi)])


def x_fov(fov: float, fov_axis: str, width: int, height: int) -> float:
    """The horizontal field of view (Mitsuba's ``x_fov`` parameter, degrees) of a camera whose
    ``fov`` is measured along ``fov_axis`` on a ``width`` x ``height`` film, as Mitsuba's
    perspective sensor converts it (``mi.parse_fov``).

    >>> round(x_fov(30.0, "y", 32, 16), 4), x_fov(30.0, "x", 32, 16)
    (56.3736, 30.0)
    """
    if fov_axis == "x":
        return float(fov)
    props = mi.Properties()
    props["fov"] = float(fov)
    props["fov_axis"] = str(fov_axis)
    return float(mi.parse_fov(props, width / height))


def sensor_keys(scene) -> tuple[str | None, str | None]:
    """The ``mi.traverse`` keys of the ``to_world`` and ``x_fov`` of the sensor that renders
    ``scene`` (a :class:`~draaw_mi.scene.DraawScene`): its first; ``None`` for what it lacks.
    Found by the object, not by the name: a Mitsuba XML sensor is called after its ``id``
    (``Camera.to_world``) or, without one, ``object_<address>.to_world``, so a key chosen by
    "sensor" in its name would miss it and refuse camera tables for such scenes.

    >>> import mitsuba as mi
    >>> from draaw_mi.scene import load_scene
    >>> sensor_keys(load_scene(mi.load_dict({"type": "scene", "Camera": {"type": "perspective"}})))
    ('Camera.to_world', 'Camera.x_fov')
    """
    sensors = scene.mi_scene.sensors()
    if not sensors:
        return None, None
    params, first, found = scene.params, sensors[0], {}
    for key in params.keys():
        if params.properties[key][2] is first:
            for leaf in ("to_world", "x_fov"):
                if key.endswith("." + leaf):
                    found.setdefault(leaf, key)
    return found.get("to_world"), found.get("x_fov")


def near_reach(near: float, x_fov_deg: float, width: int, height: int) -> float:
    """How far from a pinhole camera its rays start at most: the near clip plane's distance
    along the corner rays, ``near * sqrt(1 + tan^2(x/2) + tan^2(y/2))``.

    >>> round(near_reach(0.01, 90.0, 100, 100), 6)
    0.017321
    """
    tx = math.tan(math.radians(float(x_fov_deg)) / 2.0)
    ty = tx * float(height) / float(width)
    return float(near) * math.sqrt(1.0 + tx * tx + ty * ty)


def sensor_reach(scene, x_fov_deg: float | None = None) -> float:
    """:func:`near_reach` of the first sensor of a :class:`~draaw_mi.scene.DraawScene`, at
    its own ``x_fov`` or ``x_fov_deg`` (a batch camera table's); 0 for a sensor without a
    near clip."""
    sensor = scene.mi_scene.sensors()[0]
    near = getattr(sensor, "near_clip", None)
    if near is None:
        return 0.0
    if x_fov_deg is None:
        key = sensor_keys(scene)[1]
        x_fov_deg = float(scene.params[key][0]) if key else 45.0
    return near_reach(float(near()), x_fov_deg, *scene.resolution)


def scene_fov(scene) -> tuple[float, str]:
    """``(fov, fov_axis)`` of a :class:`~draaw_mi.scene.DraawScene`'s camera, the way its
    file gives them; a scene without (a Mitsuba XML scene) gives its sensor's ``x_fov``
    along ``"x"`` (45 degrees without one). Convert with :func:`x_fov`."""
    cam = scene.info.get("camera", {})
    if cam.get("fov"):
        return float(cam["fov"]), cam.get("fov_axis", "x")
    key = sensor_keys(scene)[1]
    return (float(scene.params[key][0]) if key else 45.0), "x"


def go_draaw_look_at(position, theta: float, phi: float, fov_deg: float):
    """Convert GO-Draaw's (position, θ, φ, FOV) into ``(origin, target, up, mirror)`` for a
    pinhole camera: ``mirror`` where the patch's image-right ``TR − TL`` is the look-at
    camera's left (``sin φ > 0``); build the transform with :func:`look_at_transform`.

    >>> [go_draaw_look_at([0, 0, 0], 0.3, phi, 45.0)[3] for phi in (1.2, -2.08)]
    [True, False]
    """
    f = math.radians(fov_deg)
    tl, tr, bl = spherical(theta, phi), spherical(theta + f, phi), spherical(theta, phi + f)
    centre = 0.5 * (tr + bl)
    up = tl - bl
    n_c, n_u = np.linalg.norm(centre), np.linalg.norm(up)
    if n_c < 1e-9 or n_u < 1e-9:
        raise ValueError("degenerate GO-Draaw camera angles")
    d = centre / n_c
    up = up / n_u
    up = up - d * float(np.dot(up, d))           # orthogonalise
    if np.linalg.norm(up) < 1e-9:
        raise ValueError("degenerate GO-Draaw camera angles")
    up = up / np.linalg.norm(up)
    # Mitsuba's perspective sensor puts the film's +x (image-right) along view x up
    mirror = bool(np.dot(tr - tl, np.cross(d, up)) < 0.0)
    origin = np.asarray(position, dtype=float)
    return origin, origin + d, up, mirror


def look_at_transform(origin, target, up, mirror: bool = False):
    """A camera's ``to_world``: Mitsuba's look-at transform, mirrored left-right (camera-space
    x negated, determinant -1) for ``mirror`` (a GO-Draaw camera's, :func:`go_draaw_look_at`).
    Mitsuba's perspective sensor takes it as it is: rays, ray differentials and the projection
    of points (``sample_direction``) are the look-at camera's, columns reversed.

    >>> m = look_at_transform([0, 0, 5], [0, 0, 0], [0, 1, 0], mirror=True)
    >>> round(float(np.linalg.det(np.array(m.matrix))), 4)
    -1.0
    """
    t = mi.ScalarTransform4f().look_at(origin=[float(v) for v in origin], target=[float(v) for v in target],
                                       up=[float(v) for v in up])
    return t @ mi.ScalarTransform4f().scale([-1.0, 1.0, 1.0]) if mirror else t


def camera_to_look_at(cam: dict, where: Where):
    """Validate a ``[camera]`` table; return (origin, target, up, fov_deg, fov_axis, near, far,
    mirror). ``mirror``: GO-Draaw's angles decide it (:func:`go_draaw_look_at`); a look-at
    table may say ``mirror = true`` (a mirrored GO-Draaw camera the tuner orbited and saved)."""
    check_keys(cam, CAMERA_KEYS, where)
    fov = number(cam.get("fov", 40.0), where / "fov", lo=FOV_RANGE[0], hi=FOV_RANGE[1])
    fov_axis = string(cam.get("fov_axis", "x"), where / "fov_axis", ["x", "y", "smaller", "larger", "diagonal"])
    near = number(cam.get("near_clip", 1e-2), where / "near_clip", lo=0.0, lo_open=True)
    far = number(cam.get("far_clip", 1e4), where / "far_clip", lo=near, lo_open=True)
    if "angles" in cam or "position" in cam:
        for k in ("origin", "target", "up", "mirror"):
            if k in cam:
                raise (where / k).error("cannot be combined with GO-Draaw's 'position' + 'angles'")
        if "position" not in cam or "angles" not in cam:
            raise where.error("a GO-Draaw camera needs both 'position' and 'angles' = [theta, phi]")
        pos = vector(cam["position"], where / "position")
        theta, phi = vector(cam["angles"], where / "angles", n=2)
        try:
            origin, target, up, mirror = go_draaw_look_at(pos, theta, phi, fov)
        except ValueError:
            raise (where / "angles").error(f"{[theta, phi]} with fov {fov:g} gives a degenerate view "
                                           "(GO-Draaw's image patch has no centre or no height)") from None
    else:
        origin = np.array(vector(cam.get("origin", [0.0, 0.0, 5.0]), where / "origin"))
        target = np.array(vector(cam.get("target", [0.0, 0.0, 0.0]), where / "target"))
        up = np.array(vector(cam.get("up", [0.0, 1.0, 0.0]), where / "up"))
        check_look_at(origin, target, up, where)
        mirror = boolean(cam.get("mirror", False), where / "mirror")
    return origin, target, up, fov, fov_axis, near, far, mirror


def check_look_at(origin, target, up, where) -> None:
    """Raise ``where``'s error unless ``origin``, ``target`` and ``up`` make a camera: a view
    direction float32 can hold and an ``up`` further from it in float32 than float32's
    rounding of the two can move them (scene files' cameras, area lights, and the batch's ``look_at`` keyframes
    and frames)."""
    origin, target, up = (np.asarray(v, dtype=np.float64) for v in (origin, target, up))
    d = target - origin
    if np.linalg.norm(d) < 1e-9:
        raise (where / "target").error("equals 'origin'; the camera needs a view direction")
    if np.linalg.norm(d) < FLOAT32_SEPARATION * max(1.0, np.linalg.norm(origin), np.linalg.norm(target)):
        # Mitsuba builds the camera in float32: origin [1e4, 1, 0] and a target 1e-4 away
        # are one point there, and the transform would come out NaN (an image of plain sky)
        raise (where / "target").error(
            f"is {np.linalg.norm(d):g} from 'origin', too close to tell apart in float32 at "
            f"{max(np.linalg.norm(origin), np.linalg.norm(target)):g} from the world origin; "
            "move it further along the view direction")
    # Mitsuba builds the look-at in float32 (left = normalize(cross(up, dir))): a direction
    # and an up parallel there, or nearly (the cross product then is rounding noise), give a
    # NaN or arbitrarily rolled camera; origin [0.3, 3, 0.3] and target [0.3, 0, 0.30000001]
    # are straight down in float32, along up [0, 1, 0]
    up32 = up.astype(np.float32).astype(np.float64)
    if not np.any(up32):
        raise (where / "up").error(f"{up.tolist()} is the zero vector" + (" in float32" if np.any(up) else "")
                                   + "; expected a direction not along the view")
    d32 = (target.astype(np.float32) - origin.astype(np.float32)).astype(np.float64)
    sine = np.linalg.norm(np.cross(d32, up32)) / (np.linalg.norm(d32) * np.linalg.norm(up32))
    # the angle float32 rounding can move the direction and up by (origin and target rounded,
    # then subtracted: eps32 of the larger per component; up rounded), 8x: a camera looking
    # down from [0, 5, 1e-5] at the origin (2e-6 rad from up, exact in float32) is a camera
    eps32 = float(np.finfo(np.float32).eps)
    noise = 8 * eps32 * (max(np.abs(origin).max(), np.abs(target).max()) / np.linalg.norm(d32) + 1.0)
    if not sine >= noise:
        raise (where / "up").error(
            f"{up.tolist()} is parallel to the view direction {d32.tolist()} (in float32, as Mitsuba "
            f"builds the camera; the angle between them, {math.degrees(math.asin(min(sine, 1.0))):.2g} "
            f"degrees, is within float32's rounding, {math.degrees(noise):.2g}); pick another up vector")


def clipped_away(origin, near: float, far: float, boxes) -> str | None:
    """What the camera at ``origin`` cannot see of the shapes' bounding boxes ``boxes``
    (pairs of corners) for its clip planes: all of them closer than ``near`` or beyond ``far``
    (a scene drawn at 1e-4 or 1e4 of the usual size with the default planes, 0.01 and 1e4,
    rendered plain sky, and every gradient 0), else None.

    >>> clipped_away([0, 1, 4], 0.01, 1e4, [([-3, 0, -3], [3, 0, 3])]) is None
    True
    >>> clipped_away([0, 1e-4, 4e-4], 0.01, 1e4, [([-3e-4, 0, -3e-4], [3e-4, 0, 3e-4])])[:21]
    'every shape is within'
    """
    o = np.asarray(origin, float)
    nearest, farthest = [], []
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
            continue                                       # (an empty or infinite shape)
        nearest.append(float(np.linalg.norm(np.maximum(np.maximum(lo - o, o - hi), 0.0))))
        farthest.append(float(np.linalg.norm(np.maximum(np.abs(lo - o), np.abs(hi - o)))))
    if not nearest:
        return None
    if max(farthest) < near:
        # (a near_clip must be > 0: shapes all at the camera's position are shown by none)
        fix = (f"set [camera] near_clip (e.g. {1e-3 * max(farthest):.2g})" if max(farthest) > 0
               else "move the camera off them")
        return (f"every shape is within {max(farthest):.3g} of the camera, closer than its near_clip "
                f"{near:g}; {fix}")
    if min(nearest) > far:
        return (f"every shape is at least {min(nearest):.3g} from the camera, beyond its far_clip "
                f"{far:g}; set [camera] far_clip (e.g. {10 * max(farthest):.2g})")
    return None


_KEPT: dict = {}      # (sampler plugin, spp) -> the count it keeps


def count_kept(sampler, spp: int) -> int:
    """The sample count a Mitsuba sampler keeps when given ``spp``: stratifying ones round up
    (``ldsampler`` 5 -> 16, ``orthogonal`` 5 -> 9, ``multijitter`` 5 -> 6) and say so in a raw
    log line, which this asks without. ``sampler``: a plugin name (answers remembered) or a
    ``mi.Sampler`` (a fork of it is asked). A sensor built with the kept count loads without
    the line; a render takes the samples it asks in passes the sampler keeps
    (:func:`draaw_mi.rendering.passes.sample_passes`).

    >>> count_kept("ldsampler", 5), count_kept("independent", 5)
    (16, 5)
    """
    spp = int(spp)
    named = isinstance(sampler, str)
    if named and (sampler == "independent" or spp < 1):
        return spp
    if named and (sampler, spp) in _KEPT:
        return _KEPT[(sampler, spp)]
    logger = mi.logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)
    try:
        probe = mi.load_dict({"type": sampler}) if named else sampler.fork()
        probe.set_sample_count(spp)
    finally:
        logger.set_log_level(level)
    kept = int(probe.sample_count())
    if named:
        _KEPT[(sampler, spp)] = kept
    return kept


def sensor_dict(look_at, width: int, height: int, spp: int, rfilter,
                sampler: str = "independent") -> dict:
    """Mitsuba sensor dict: a perspective camera, ``sampler`` (a Mitsuba sampler plugin) with
    ``spp`` samples, an RGB ``hdrfilm`` with the ``rfilter`` reconstruction filter: a plugin
    name, or a filter object (another film's, with its parameters: a gaussian's ``stddev``)."""
    origin, target, up, fov, fov_axis, near, far, mirror = look_at
    return {
        "type": "perspective",
        "fov": fov,
        "fov_axis": fov_axis,
        "near_clip": near,
        "far_clip": far,
        "to_world": look_at_transform(origin, target, up, mirror),
        "sampler": {"type": sampler, "sample_count": count_kept(sampler, spp)},
        "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
                 "rfilter": {"type": rfilter} if isinstance(rfilter, str) else rfilter},
    }


def auto_camera(bbox_min, bbox_max, fov: float = 40.0):
    """A camera framing a bounding box from the front-top-right, for bare mesh files, with
    clip planes that follow the box's size (the defaults, 0.01 and 1e4, show plain sky for
    a mesh 1e-4 or 1e4 across).

    >>> cam = auto_camera([0, 0, 0], [1e-4, 1e-4, 1e-4])
    >>> cam["near_clip"] < 1e-4 < cam["far_clip"] < 1e-2
    True
    """
    lo, hi = np.asarray(bbox_min, float), np.asarray(bbox_max, float)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    if not radius > 0:
        radius = 1.0                                   # a point (or nothing): a unit view
    dist = radius / math.sin(math.radians(fov) / 2) * 1.05
    direction = np.array([0.45, 0.35, 1.0])
    direction /= np.linalg.norm(direction)
    origin = centre + direction * dist
    return {"origin": origin.tolist(), "target": centre.tolist(), "up": [0.0, 1.0, 0.0], "fov": fov,
            "near_clip": 1e-3 * dist, "far_clip": 10.0 * (dist + radius)}
