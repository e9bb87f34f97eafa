"""The speed suite: scenes of different kinds for equal-error comparisons against ``path``.

Each scene is a Mitsuba dict built procedurally (``build(name, res)``), so the suite needs no
files except the thesis scene (``scenes/thesis.toml``) and, optionally, GO-Draaw's monkey mesh
(``../shared/data/go-draaw/monkey.obj``; the scene is skipped when it is absent).

==================  =============================================================================
scene               kind
==================  =============================================================================
``cornell``         enclosed: the Cornell box with draaw materials (max_depth 6)
``spheres``         open: the material-spheres grid on a floor under an area light
``metal_018``       open, one glossy metal sphere (roughness 0.18) on a diffuse floor (issue 10)
``metals``          open, glossy metals at roughness 0.05, 0.15 and 0.3
``small_light``     a small, very bright spherical light over objects on a floor
``many_lights``     24 small area lights of different powers (1:40) over a floor
``constant_env``    lit only by a constant environment: rough metal on a diffuse floor
``envmap``          an environment map with a bright sun-like spot, objects on a floor
``glass``           the thesis scene: smooth glass, gold, a near-mirror floor (max_depth 8)
``monkey``          GO-Draaw's monkey mesh, checker-textured and normal-mapped, area light
``cornell_tent``    the Cornell box under a tent pixel filter
``spheres_gauss``   the material spheres under a gaussian filter (Mitsuba's default)
``envmap_gauss``    the environment-map scene under a gaussian filter
``mitsuba_cbox``    Mitsuba's tutorial-style Cornell box, ``scenes/mitsuba_cbox.xml`` loaded by
                    ``mi.load_file`` untouched (its tent filter, Mitsuba's diffuse BSDFs)
``doorway``         a closed room lit only through a doorway by a lamp outside
``glossy_diffuse``  a floor lit only through a glossy metal panel (the lamp behind a wall)
``lights_2000``     2,000 small area lights of different powers (1:40) over objects
``spot_and_area``   a spot and an area light on Mitsuba's own BSDFs (a bump-mapped box, a
                    normal-mapped panel) under a gaussian filter
==================  =============================================================================

Every scene renders with a box pixel filter unless its entry names another (the ``_tent`` /
``_gauss`` scenes) or keeps its own (``mitsuba_cbox``: as shipped).

>>> sorted(SCENES)[:3]
['constant_env', 'cornell', 'cornell_tent']
"""
from __future__ import annotations

import hashlib
import os

import mitsuba as mi
import numpy as np

import draaw_mi

from ..batch.planner import file_hash
from ..scene.mitsuba_load import load_mitsuba_dict
from . import reference_scenes as rs

T = mi.ScalarTransform4f
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))   # the repository
GO_DRAAW = os.path.join(os.path.dirname(ROOT), "shared", "data", "go-draaw")

_KEEP: list = []          # scratch folders of loaded scenes whose files the built dicts name


def _base(res: int, fov=40.0, origin=(0.0, 2.2, 5.0), target=(0.0, 0.5, 0.0), floor=None) -> dict:
    film, sampler = rs._film(res, 64)
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": fov,
                    "to_world": T().look_at(origin=list(origin), target=list(target), up=[0, 1, 0]),
                    "film": film, "sampler": sampler},
         "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(6.0),
                   "bsdf": floor or rs.draaw([0.5, 0.5, 0.5], roughness=0.8, specular=0.3)}}
    return d


def _area(pos, size, radiance, angle=90.0) -> dict:
    return {"type": "rectangle",
            "to_world": T().translate(list(pos)).rotate([1, 0, 0], angle).scale(size),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(radiance)}}}


def cornell(res):
    return rs.cornell_draaw(res=res)


def spheres(res):
    return rs.material_spheres(res=res)


def metal_018(res):
    d = _base(res)
    d["ball"] = {"type": "sphere", "center": [0, 0.8, 0], "radius": 0.8,
                 "bsdf": rs.draaw([0.95, 0.64, 0.54], roughness=0.18, metallic=1.0)}
    d["light"] = _area([0.8, 3.0, 0.8], 0.7, [9.0, 8.5, 8.0])
    return d


def metals(res):
    d = _base(res)
    for i, (r, c) in enumerate(((0.05, [0.95, 0.93, 0.88]), (0.15, [1.0, 0.77, 0.34]),
                                (0.3, [0.95, 0.64, 0.54]))):
        d[f"m{i}"] = {"type": "sphere", "center": [-1.3 + 1.3 * i, 0.55, 0], "radius": 0.55,
                      "bsdf": rs.draaw(c, roughness=r, metallic=1.0)}
    d["light"] = _area([0.0, 3.2, 1.2], 0.9, [8.0, 8.0, 8.0])
    return d


def small_light(res):
    d = _base(res)
    d["ball"] = {"type": "sphere", "center": [-0.7, 0.5, 0], "radius": 0.5,
                 "bsdf": rs.draaw([0.8, 0.4, 0.2], roughness=0.4)}
    d["box"] = {"type": "cube", "to_world": T().translate([0.8, 0.4, -0.2]).rotate([0, 1, 0], 25)
                .scale(0.4), "bsdf": rs.draaw([0.3, 0.6, 0.4], roughness=0.25, metallic=0.5)}
    d["bulb"] = {"type": "sphere", "center": [0.3, 2.0, 1.0], "radius": 0.04,
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [600, 550, 500]}}}
    return d


def _ball_under_lights(res) -> dict:
    """A glossy ball on the floor, seen from above: the many-light scenes' stage."""
    d = _base(res, origin=(0.0, 3.0, 5.5))
    d["ball"] = {"type": "sphere", "center": [0, 0.6, 0], "radius": 0.6,
                 "bsdf": rs.draaw([0.7, 0.7, 0.7], roughness=0.3, metallic=0.3)}
    return d


def many_lights(res):
    d = _ball_under_lights(res)
    rng = np.random.default_rng(7)
    for i in range(24):
        x, z = -3.0 + 6.0 * (i % 6) / 5, -2.5 + 4.5 * (i // 6) / 3
        power = 1.0 if i % 6 else 40.0                     # a few strong lights, many weak ones
        col = 0.5 + 0.5 * rng.random(3)
        d[f"l{i}"] = _area([x, 2.5 + 0.3 * (i % 3), z], 0.12, list(power * 12.0 * col))
    return d


def constant_env(res):
    d = _base(res)
    d["ball"] = {"type": "sphere", "center": [0, 0.8, 0], "radius": 0.8,
                 "bsdf": rs.draaw([0.9, 0.9, 0.9], roughness=0.35, metallic=1.0)}
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    return d


def envmap(res):
    d = _base(res)
    h, w = 32, 64
    sky = np.zeros((h, w, 3), np.float32)
    sky[...] = np.linspace(1.0, 0.2, h)[:, None, None] * np.array([0.5, 0.7, 1.0])
    sky[5:8, 20:24] = [120.0, 115.0, 100.0]                 # the "sun"
    d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky)}
    d["ball"] = {"type": "sphere", "center": [-0.6, 0.6, 0], "radius": 0.6,
                 "bsdf": rs.draaw([0.9, 0.7, 0.5], roughness=0.2, metallic=1.0)}
    d["box"] = {"type": "cube", "to_world": T().translate([0.9, 0.4, 0.0]).rotate([0, 1, 0], 30)
                .scale(0.4), "bsdf": rs.draaw([0.3, 0.5, 0.7], roughness=0.6)}
    return d


def glass(res):
    sc = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "thesis.toml"), resolution=(res, res))
    # the folder, not the scene: a scene kept alive puts its BSDFs into every later loop's
    # trace (the glossy panel's guide learning took 15 against 11 ms after the suite's glass)
    _KEEP.append(sc._tmp)
    d = dict(sc.mi_dict)
    d.pop("integrator", None)
    return d


def monkey(res):
    path = os.path.join(GO_DRAAW, "monkey.obj")
    if not os.path.exists(path):
        return None
    d = _base(res, origin=(0.0, 1.4, 4.2), target=(0.0, 0.8, 0.0))
    mat = rs.draaw([0.8, 0.5, 0.3], roughness=0.35, metallic=0.2)
    mat["base_color"] = {"type": "bitmap", "data": rs._checker(32), "raw": True}
    mat["normalmap"] = {"type": "bitmap", "data": rs._bumps(32), "raw": True}
    d["monkey"] = {"type": "obj", "filename": path, "face_normals": False,
                   "to_world": T().translate([0.2, 0.1, 0]).scale(0.25), "bsdf": mat}
    d["light"] = _area([1.0, 3.0, 1.5], 0.8, [8.0, 7.5, 7.0], angle=100.0)
    return d


def mitsuba_cbox(res):
    return {"type": "xml", "filename": os.path.join(ROOT, "scenes", "mitsuba_cbox.xml")}


def _wall(center, normal, half, bsdf) -> dict:
    """A two-sided rectangle at ``center`` facing ``normal`` with half sizes ``half``."""
    c = np.asarray(center, float)
    up = [0, 0, 1] if abs(normal[1]) > 0.9 else [0, 1, 0]
    return {"type": "rectangle", "bsdf": bsdf,
            "to_world": T().look_at(origin=list(c), target=list(c + np.asarray(normal, float)), up=up)
            .scale([half[0], half[1], 1.0])}


def doorway(res):
    """A 4 x 2.5 x 4 room whose only light comes through a door in its right wall from a lamp
    outside; the camera sees the room's far corner, not the door's patch of floor."""
    white = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.7, 0.7]}}}
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 60,
                    "to_world": T().look_at(origin=[1.6, 1.4, 1.7], target=[-1.0, 0.8, -1.0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res}},
         "floor": _wall([0, 0, 0], [0, 1, 0], [2, 2], white),
         "ceiling": _wall([0, 2.5, 0], [0, -1, 0], [2, 2], white),
         "back": _wall([0, 1.25, -2], [0, 0, 1], [2, 1.25], white),
         "front": _wall([0, 1.25, 2], [0, 0, -1], [2, 1.25], white),
         "left": _wall([-2, 1.25, 0], [1, 0, 0], [2, 1.25], white),
         # right wall (x = 2) with a door at z in [-0.5, 0.5], y in [0, 1.8]
         "right_a": _wall([2, 1.25, -1.25], [-1, 0, 0], [0.75, 1.25], white),
         "right_b": _wall([2, 1.25, 1.25], [-1, 0, 0], [0.75, 1.25], white),
         "lintel": _wall([2, 2.15, 0], [-1, 0, 0], [0.5, 0.35], white),
         "ball": {"type": "sphere", "center": [-1.0, 0.5, -1.0], "radius": 0.5,
                  "bsdf": rs.draaw([0.8, 0.5, 0.3], roughness=0.4)},
         "lamp": _wall([3.2, 1.4, 0.0], [-1, -0.3, 0], [0.4, 0.4],
                       {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}})}
    d["lamp"]["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [60.0, 55.0, 50.0]}}
    return d


def glossy_diffuse(res):
    """A diffuse floor lit only by a lamp's light off a glossy metal panel overhead: a wall
    hides the lamp from the floor beyond it and from the camera."""
    d = _base(res, origin=(4.0, 2.6, 4.0), target=(1.3, 0.2, 0.0))
    d["wall"] = _wall([0.0, 0.9, 0.0], [1, 0, 0], [3.0, 0.9],
                      {"type": "twosided", "bsdf": {"type": "diffuse"}})
    d["panel"] = _wall([2.2, 3.8, 0.0], [-0.5, -0.87, 0.0], [0.9, 1.2],
                       rs.draaw([0.95, 0.93, 0.88], roughness=0.15, metallic=1.0))
    d["lamp"] = _wall([-0.6, 1.2, 0.0], [0.76, 0.65, 0.0], [0.3, 0.3],
                      {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}})
    d["lamp"]["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": [80.0, 75.0, 70.0]}}
    d["ball"] = {"type": "sphere", "center": [1.6, 0.4, 0.8], "radius": 0.4,
                 "bsdf": rs.draaw([0.3, 0.5, 0.8], roughness=0.5)}
    return d


def spot_and_area(res):
    """A spot aimed at a bump-mapped box and a normal-mapped panel, beside an area light over
    the floor: two kinds of light whose powers say little about what each gives the surfaces
    in view; Mitsuba's own BSDFs, as a user's scene has them."""
    d = _base(res, origin=(0.0, 1.6, 5.0), target=(0.0, 0.6, 0.0),
              floor={"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}})
    d["light"] = _area([0.0, 3.0, 1.0], 0.7, [10.0, 10.0, 10.0])
    d["spot"] = {"type": "spot", "intensity": {"type": "rgb", "value": [30.0, 30.0, 30.0]},
                 "cutoff_angle": 25.0,
                 "to_world": T().look_at(origin=[2, 3, 2], target=[0, 0.5, 0], up=[0, 1, 0])}
    rows = np.mgrid[0:32, 0:32][0] / 32.0
    height = (0.5 + 0.5 * np.sin(20.0 * rows))[..., None].astype(np.float32)
    d["box"] = {"type": "cube", "to_world": T().translate([-0.7, 0.5, 0]).rotate([0, 1, 0], 30).scale(0.45),
                "bsdf": {"type": "bumpmap", "scale": 0.5,
                         "arg": {"type": "bitmap", "raw": True, "bitmap": mi.Bitmap(height)},
                         "bsdf": {"type": "roughplastic", "alpha": 0.3}}}
    y, x = np.mgrid[0:32, 0:32] / 32.0
    n = np.stack([0.3 * np.sin(12.0 * x), 0.3 * np.cos(9.0 * y), np.ones_like(x)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    d["panel"] = {"type": "rectangle", "to_world": T().translate([0.8, 0.6, 0]).scale(0.6),
                  "bsdf": {"type": "normalmap", "bsdf": {"type": "diffuse"},
                           "normalmap": {"type": "bitmap", "raw": True,
                                         "bitmap": mi.Bitmap((0.5 * n + 0.5).astype(np.float32))}}}
    return d


def lights_2000(res):
    """2,000 small lights on a 50 x 40 grid, one in twenty 40x brighter (at random)."""
    d = _ball_under_lights(res)
    rng = np.random.default_rng(11)
    for i in range(2000):
        power = 40.0 if rng.random() < 0.05 else 1.0
        pos = [-3.0 + 6.0 * (i % 50) / 49, 2.5 + 0.2 * rng.random(), -2.5 + 4.5 * (i // 50) / 39]
        d[f"l{i}"] = _area(pos, 0.03, list(power * 3.0 * (0.5 + 0.5 * rng.random(3))))
    return d


# name -> (kind, builder, max_depth, pixel filter: a plugin name, or None for the scene's own)
SCENES = {
    "cornell": ("enclosed", cornell, 6, "box"),
    "spheres": ("open, area light", spheres, 6, "box"),
    "metal_018": ("open, glossy metal r=0.18", metal_018, 5, "box"),
    "metals": ("open, metals r=0.05/0.15/0.3", metals, 5, "box"),
    "small_light": ("small bright light", small_light, 5, "box"),
    "many_lights": ("24 lights, powers 1:40", many_lights, 5, "box"),
    "constant_env": ("constant environment only", constant_env, 5, "box"),
    "envmap": ("environment map with sun", envmap, 5, "box"),
    "glass": ("glass, thesis scene", glass, 8, "box"),
    "monkey": ("GO-Draaw mesh, texture + normal map", monkey, 5, "box"),
    "cornell_tent": ("enclosed, tent filter", cornell, 6, "tent"),
    "spheres_gauss": ("open, area light, gaussian filter", spheres, 6, "gaussian"),
    "envmap_gauss": ("environment map, gaussian filter", envmap, 5, "gaussian"),
    "mitsuba_cbox": ("Mitsuba's XML Cornell box (tent)", mitsuba_cbox, 6, None),
    "doorway": ("room lit through a doorway", doorway, 6, "box"),
    "glossy_diffuse": ("floor lit via a glossy panel", glossy_diffuse, 6, "box"),
    "lights_2000": ("2,000 small lights, powers 1:40", lights_2000, 5, "box"),
    "spot_and_area": ("spot + area light, Mitsuba BSDFs, gaussian", spot_and_area, 5, "gaussian"),
}


def build(name: str, res: int, sampler: str = "independent", spp: int = 64) -> dict | None:
    """The Mitsuba dict of suite scene ``name`` at ``res``², or ``None`` when its data is
    absent (the GO-Draaw mesh). ``sampler``: Mitsuba sampler plugin for the sensor. An XML
    scene is ``{"type": "xml", "filename": ..., "defines": {...}}`` (:func:`load_built`; its
    own sampler and filter, ``$res`` and ``$spp`` set)."""
    d = SCENES[name][1](res)
    if d is None:
        return None
    d = dict(d)
    if d["type"] == "xml":
        return dict(d, defines={"res": res, "spp": spp})
    d.pop("integrator", None)
    sensor = dict(d["sensor"])
    sensor["sampler"] = {"type": sampler, "sample_count": spp}
    film = dict(sensor["film"], width=res, height=res)
    if SCENES[name][3] is not None:
        film["rfilter"] = {"type": SCENES[name][3]}
    sensor["film"] = film
    d["sensor"] = sensor
    return d


def load_built(d: dict) -> mi.Scene:
    """The scene of a :func:`build` dict: a fixed emitter order for a dict, ``mi.load_file``
    with the defines for an XML file."""
    if d["type"] == "xml":
        return mi.load_file(d["filename"], **{k: str(v) for k, v in d["defines"].items()})
    return load_mitsuba_dict(d)


def digest(d: dict) -> str:
    """A short hash of a scene dict's content, for cache names: values, arrays, bitmaps and
    transforms by value, files named in it (a mesh, a temporary file of a loaded TOML scene) by
    their bytes rather than their path, so an edited builder or ``scenes/thesis.toml`` gets a
    new reference while a rebuilt, unchanged scene keeps its own.

    >>> digest({"a": [1, 2.5]}) == digest({"a": [1, 2.5]}) != digest({"a": [1, 2.25]})
    True
    """
    h = hashlib.sha256()

    def feed(o):
        if isinstance(o, dict):
            h.update(b"{")
            for k in sorted(o, key=str):
                h.update(repr(str(k)).encode() + b":")
                feed(o[k])
            h.update(b"}")
        elif isinstance(o, (list, tuple)):
            h.update(b"[")
            for v in o:
                feed(v)
            h.update(b"]")
        elif isinstance(o, str) and os.path.isfile(o):
            h.update(b"file:" + file_hash(o).encode())
        elif isinstance(o, (str, int, float, bool)) or o is None:
            h.update(repr(o).encode())
        else:                       # arrays, bitmaps, transforms: by value
            if hasattr(o, "matrix"):
                o = o.matrix
            a = np.asarray(o)
            h.update(type(o).__name__.encode() + str(a.dtype).encode() + repr(a.shape).encode())
            # (an object array's bytes are addresses: another run would miss its cache)
            h.update(repr(o).encode() if a.dtype == object else np.ascontiguousarray(a).tobytes())
    feed(d)
    return h.hexdigest()[:12]


def load(name: str, res: int, sampler: str = "independent") -> mi.Scene | None:
    d = build(name, res, sampler)
    return None if d is None else load_built(d)


def max_depth(name: str) -> int:
    return SCENES[name][2]
