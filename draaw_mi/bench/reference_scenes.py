"""Small reference scenes (Mitsuba dicts) used by the integrator tests and benchmarks.

* :func:`cornell_draaw` -- Mitsuba's Cornell box with ``draaw`` materials (rough dielectric
  walls, a rough dielectric large box, a glossy metal small box).
* :func:`material_spheres` -- a grid of ``draaw`` spheres sweeping roughness (columns) x
  metallic (rows) on a grey floor under a rectangular area light.
* :func:`gradient_plane` -- a ``draaw`` floor with an area light's highlight in view (the
  gradient tests' scene).
* :func:`feature_scene` -- a small scene whose keywords switch single features on (emitter
  kinds, textures, normal map, glass, rough conductor, two-sided panel): expectation and
  kernel-size tests.

They stand in for ``scenes/cornell.toml`` / ``scenes/material_spheres.toml`` where those are
not available (``draaw_mi.load_scene`` builds the official ones).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np

T = mi.ScalarTransform4f

CORNELL_LIGHT = [18.387, 13.9873, 6.75357]
SPHERE_ROUGHNESS = (0.05, 0.15, 0.35, 0.7)
SPHERE_METALLIC = (0.0, 0.5, 1.0)


def _film(res: int | tuple[int, int], spp: int) -> tuple[dict, dict]:
    w, h = (res, res) if isinstance(res, int) else res
    film = {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"},
            "pixel_format": "rgb"}
    return film, {"type": "independent", "sample_count": spp}


def draaw(base, roughness=0.5, metallic=0.0, specular=0.5, **kw) -> dict:
    d = {"type": "draaw", "base_color": {"type": "rgb", "value": list(base)},
         "roughness": roughness, "metallic": metallic, "specular": specular}
    d.update(kw)
    return d


def cornell_draaw(res: int | tuple[int, int] = 64, spp: int = 16,
                  integrator: dict | None = None) -> dict:
    """Mitsuba's ``cornell_box()`` with draaw materials and a box filter.

    Differentiable keys: ``large-box.bsdf.{base_color,roughness,metallic,specular}.value``,
    ``small-box.bsdf.*``, ``white.*``, ``red.*``, ``green.*``, ``light.emitter.radiance.value``.
    """
    d = mi.cornell_box()
    d["sensor"]["film"], d["sensor"]["sampler"] = _film(res, spp)
    d["white"] = draaw([0.885809, 0.698859, 0.666422], roughness=0.7)
    d["green"] = draaw([0.105421, 0.37798, 0.076425], roughness=0.7)
    d["red"] = draaw([0.570068, 0.0430135, 0.0443706], roughness=0.7)
    d["large-box"]["bsdf"] = draaw([0.8, 0.8, 0.8], roughness=0.4, metallic=0.0, specular=0.6)
    d["small-box"]["bsdf"] = draaw([0.95, 0.7, 0.4], roughness=0.35, metallic=1.0)
    d["integrator"] = integrator or {"type": "draaw_v4", "max_depth": 6}
    return d


def material_spheres(res: int | tuple[int, int] = 64, spp: int = 16,
                     integrator: dict | None = None,
                     roughness=SPHERE_ROUGHNESS, metallic=SPHERE_METALLIC) -> dict:
    """Spheres ``s_<i>_<j>`` (row i: metallic, column j: roughness) on a floor, area light.

    Differentiable keys: ``s_<i>_<j>.bsdf.*.value``, ``light.emitter.radiance.value``.
    """
    film, sampler = _film(res, spp)
    d = {
        "type": "scene",
        "integrator": integrator or {"type": "draaw_v4", "max_depth": 6},
        "sensor": {
            "type": "perspective", "fov": 38.0,
            "to_world": T().look_at(origin=[0.0, 4.6, 6.0], target=[0.0, 0.2, 0.1],
                                    up=[0.0, 1.0, 0.0]),
            "film": film, "sampler": sampler,
        },
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(8.0),
                  "bsdf": draaw([0.45, 0.45, 0.45], roughness=0.8, specular=0.3)},
        "back": {"type": "rectangle",
                 "to_world": T().translate([0, 0, -2.5]).scale(8.0),
                 "bsdf": draaw([0.6, 0.6, 0.65], roughness=0.9, specular=0.2)},
        "light": {"type": "rectangle",
                  "to_world": T().translate([0.0, 3.5, 1.6]).rotate([1, 0, 0], 75).scale([2.2, 0.8, 1.0]),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [9.0, 8.5, 8.0]}}},
    }
    nx, ny = len(roughness), len(metallic)
    colors = ([0.9, 0.25, 0.2], [0.95, 0.75, 0.35], [0.85, 0.85, 0.9])
    for i, m in enumerate(metallic):
        for j, r in enumerate(roughness):
            x = (j - (nx - 1) / 2) * 1.15
            z = (i - (ny - 1) / 2) * 1.3
            d[f"s_{i}_{j}"] = {"type": "sphere", "center": [x, 0.45, z], "radius": 0.45,
                               "bsdf": draaw(colors[i % 3], roughness=r, metallic=m)}
    return d


def gradient_plane(res: int | tuple[int, int] = 16, spp: int = 64,
                   integrator: dict | None = None, **material) -> dict:
    """A ``draaw`` floor (``plane``) under a rectangular area light, seen at an angle so the
    light's highlight is in view, and a diffuse back wall for some indirect light.

    Differentiable keys: ``plane.bsdf.{base_color,roughness,metallic,specular,reflection,
    direct_to_scatter}.value``, ``light.emitter.radiance.value``.
    """
    film, sampler = _film(res, spp)
    mat = dict(base=[0.6, 0.5, 0.4], roughness=0.4, metallic=0.3, specular=0.6,
               reflection=0.2, direct_to_scatter=0.8)
    mat.update(material)
    base = mat.pop("base")
    return {
        "type": "scene",
        "integrator": integrator or {"type": "draaw_v4", "max_depth": 4},
        "sensor": {"type": "perspective", "fov": 50.0,
                   "to_world": T().look_at(origin=[0.0, 1.2, 2.4], target=[0.0, 0.0, 0.0],
                                           up=[0.0, 1.0, 0.0]),
                   "film": film, "sampler": sampler},
        "plane": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(1.5),
                  "bsdf": draaw(base, **mat)},
        "wall": {"type": "rectangle", "to_world": T().translate([0, 1.0, -1.5]).scale(1.5),
                 "bsdf": draaw([0.7, 0.7, 0.7], roughness=0.9, specular=0.0)},
        "light": {"type": "rectangle",
                  "to_world": T().translate([0.0, 1.3, -0.9]).rotate([1, 0, 0], 60).scale(0.4),
                  "emitter": {"type": "area",
                              "radiance": {"type": "rgb", "value": [6.0, 5.5, 5.0]}}},
    }


def _checker(n: int = 16, a=(0.8, 0.3, 0.2), b=(0.2, 0.5, 0.8)):
    ij = np.add.outer(np.arange(n), np.arange(n)) % 2
    img = np.where(ij[..., None] == 0, np.array(a), np.array(b)).astype(np.float32)
    return mi.TensorXf(img)


def _bumps(n: int = 16):
    """A tangent-space normal map (0..1 encoding) of gentle sinusoidal bumps."""
    u = (np.arange(n) + 0.5) / n
    x = 0.35 * np.sin(2 * np.pi * 2 * u)[None, :].repeat(n, 0)
    y = 0.35 * np.cos(2 * np.pi * 2 * u)[:, None].repeat(n, 1)
    nrm = np.stack([x, y, np.ones_like(x)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return mi.TensorXf((0.5 * nrm + 0.5).astype(np.float32))


def feature_scene(res: int | tuple[int, int] = 16, spp: int = 16,
                  integrator: dict | None = None, *, area: bool = True, point: bool = False,
                  spot: bool = False, envmap: bool = False, constant: bool = False,
                  texture: bool = False, normalmap: bool = False, glass: bool = False,
                  conductor: bool = False, two_sided: bool = False) -> dict:
    """A floor, a draaw sphere and a draaw cube; every keyword switches one scene feature
    on (emitter kinds, a bitmap texture, a draaw normal map, a dielectric sphere, a rough
    conductor sphere, a two-sided draaw panel seen from behind)."""
    film, sampler = _film(res, spp)
    ball = draaw([0.8, 0.5, 0.3], roughness=0.3, metallic=0.4)
    if texture:
        ball["base_color"] = {"type": "bitmap", "data": _checker(), "raw": True}
    if normalmap:
        ball["normalmap"] = {"type": "bitmap", "data": _bumps(), "raw": True}
    d = {
        "type": "scene",
        "integrator": integrator or {"type": "draaw_v4", "max_depth": 5},
        "sensor": {"type": "perspective", "fov": 45.0,
                   "to_world": T().look_at(origin=[0.0, 1.6, 4.0], target=[0.0, 0.4, 0.0],
                                           up=[0.0, 1.0, 0.0]),
                   "film": film, "sampler": sampler},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3.0),
                  "bsdf": draaw([0.5, 0.5, 0.5], roughness=0.7, specular=0.4)},
        "ball": {"type": "sphere", "center": [-0.6, 0.5, 0.0], "radius": 0.5, "bsdf": ball},
        "box": {"type": "cube", "to_world": T().translate([0.7, 0.35, -0.3]).rotate([0, 1, 0], 30)
                .scale(0.35), "bsdf": draaw([0.3, 0.6, 0.4], roughness=0.5, specular=0.7)},
    }
    if area:
        d["light"] = {"type": "rectangle",
                      "to_world": T().translate([0.0, 2.5, 0.5]).rotate([1, 0, 0], 90).scale(0.6),
                      "emitter": {"type": "area",
                                  "radiance": {"type": "rgb", "value": [8.0, 7.5, 7.0]}}}
    if point:
        d["pt"] = {"type": "point", "position": [1.5, 2.0, 1.5],
                   "intensity": {"type": "rgb", "value": [4.0, 3.0, 2.0]}}
    if spot:
        d["spot"] = {"type": "spot", "cutoff_angle": 35.0,
                     "to_world": T().look_at([-1.5, 2.5, 1.5], [0.0, 0.0, 0.0], [0, 1, 0]),
                     "intensity": {"type": "rgb", "value": [6.0, 6.0, 8.0]}}
    if envmap:
        h, w = 16, 32
        sky = np.zeros((h, w, 3), np.float32)
        sky[..., 0] = np.linspace(0.9, 0.2, h)[:, None]
        sky[..., 1] = 0.5
        sky[..., 2] = np.linspace(0.3, 1.0, w)[None, :]
        d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky), "scale": 0.6}
    if constant:
        d["ambient"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.2, 0.25, 0.3]}}
    if glass:
        d["glass"] = {"type": "sphere", "center": [0.1, 0.3, 0.9], "radius": 0.3,
                      "bsdf": {"type": "dielectric", "int_ior": 1.5}}
    if conductor:
        d["metal"] = {"type": "sphere", "center": [0.9, 0.25, 0.8], "radius": 0.25,
                      "bsdf": {"type": "roughconductor", "material": "Au", "alpha": 0.2}}
    if two_sided:
        d["panel"] = {"type": "rectangle",
                      "to_world": T().translate([-1.2, 0.6, 0.9]).rotate([0, 1, 0], 200).scale(0.4),
                      "bsdf": draaw([0.9, 0.9, 0.3], roughness=0.4, two_sided=True)}
    return d
