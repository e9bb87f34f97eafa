"""SVBRDF (texture-map) fitting: base colour, roughness and metallic maps recovered from
captures of synthetic objects, the multi-scale fit (``maps="pyramid"``) and
:func:`~draaw_mi.fitting.two_starts.fit_two_starts` (``--methods two-starts``: two such fits,
metallic from the start and from 0, merged region by region) beside the texel-by-texel one
(``maps="texels"``) in the same run.

Objects: a sphere (Mitsuba's UV sphere), GO-Draaw's monkey (its own UVs, read from
``../shared/data/go-draaw``), a flat tile. Ground truth: procedural maps in UV space (smooth
colour blobs, smooth roughness 0.15-0.8, sharp metallic patches: :func:`truth_maps`).
Captures: cameras around the object, each photo under an environment map (sky, ground, a sun
and two coloured lamps) plus one lamp of its own. References: Mitsuba's ``path`` at
``--ref-spp``. Held out: a view none of the captures had, under a lamp none had.

Where the lamps stand (``--layout``): ``ring`` (the default) beside the cameras, so the
tile never shows a highlight; ``sweep`` where each camera sees the lamp's mirror image, at a
point that moves over the object; ``globe`` as ``sweep`` with the cameras spread over all
directions (the sphere's poles in view); ``flash`` beside the camera; ``pairs`` two captures
per camera position. ``--lamp softbox`` makes each lamp an area light (a highlight patch, not a
point). ``patterns``: every lamp off, each capture's environment a pattern of bright bands
(:func:`pattern_environment`). ``--truth constant`` / ``scalar`` fit one material (as maps /
as three scalars): can the captures tell it apart at all? ``--capture-spp`` adds how well the
fitted maps reproduce the captures (against the truth's renders, same seeds): a fit whose
captures PSNR is low stopped short; one whose maps are wrong at a high captures PSNR met
what the captures cannot tell apart. ``results/svbrdf_fit.md`` has what each gives.

Run from the repository root::

    .venv/bin/python benchmarks/svbrdf_fit.py --layout sweep --lamp softbox --ref-spp 4096 \
        --iterations 600 --capture-spp 256 --out /tmp/t.md          # the last recorded table
    .venv/bin/python benchmarks/svbrdf_fit.py --objects sphere --captures 4 8 16
    .venv/bin/python benchmarks/svbrdf_fit.py --objects tile --layout sweep --lamp softbox

Metrics over the texels the captures observed (the pyramid fit's ``result.observed``):
albedo PSNR (peak 1), roughness and metallic MAE; relit PSNR: the held-out render of the
fitted maps against the truth's (both 256 spp, one seed, clipped to [0, 1], peak 1).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import draaw_mi  # noqa: E402
import mitsuba as mi  # noqa: E402  (its variant is set by draaw_mi)
from draaw_mi.errors import ParameterError  # noqa: E402
from draaw_mi.fitting.maps import LR_SCALES, TV_WEIGHTS, MapOptions  # noqa: E402
from draaw_mi.fitting.two_starts import fit_two_starts  # noqa: E402
from draaw_mi.fitting.views import LOSSES  # noqa: E402

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data", "go-draaw")
PARAMS = ["obj.base_color", "obj.roughness", "obj.metallic"]
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "svbrdf_fit_latest.md")


def truth_maps(n: int, seed: int = 1):
    """``(base colour (n, n, 3), roughness (n, n, 1), metallic (n, n, 1))``: colour blobs,
    smooth roughness in [0.15, 0.8], metallic patches of 0/1 (30 % of the texels)."""
    rng = np.random.default_rng(seed)
    v, u = np.meshgrid((np.arange(n) + .5) / n, (np.arange(n) + .5) / n, indexing="ij")

    def blobs(k, s):
        f = np.zeros((n, n))
        for _ in range(k):
            cu, cv, a = rng.random(), rng.uniform(.2, .8), rng.uniform(-1, 1)
            du = np.minimum(abs(u - cu), 1 - abs(u - cu))
            f += a * np.exp(-(du ** 2 + (v - cv) ** 2) / (2 * s * s))
        return (f - f.min()) / (np.ptp(f) + 1e-9)

    col = np.stack([0.1 + 0.8 * blobs(4, .12) for _ in range(3)], -1)
    rough = 0.15 + 0.65 * blobs(5, .15)
    m = blobs(6, .08)
    metal = (m > np.quantile(m, 0.7)).astype(float)
    return col.astype(np.float32), rough[..., None].astype(np.float32), metal[..., None].astype(np.float32)


#: ``--truth constant``: one material everywhere (base colour, roughness, metallic): whether a
#: capture layout can tell the material apart at all, without the maps' own difficulty
CONSTANT_TRUTH = (0.5, 0.25, 0.0)


#: ``--start`` (other than ``truth``): the first maps' metallic, and how the table says it
#: (colour and roughness start at 0.5 in both; the draaw material's defaults are colour 0.5,
#: roughness 0.5, metallic 0)
STARTS = {"half": (0.5, "maps of 0.5"), "default": (0.0, "the material defaults (0.5, 0.5, 0)")}


def as_scalars(desc: dict) -> dict:
    """``desc`` with its material's maps replaced by their means (``--truth scalar``: one base
    colour, roughness and metallic, fitted as three scalars rather than maps)."""
    m = desc["materials"]["obj"]
    m["base_color"] = np.mean(np.asarray(m["base_color"]), axis=(0, 1)).tolist()
    m["roughness"] = float(np.mean(m["roughness"]))
    m["metallic"] = float(np.mean(m["metallic"]))
    return desc


def constant_maps(n: int):
    """:data:`CONSTANT_TRUTH` as ``(n, n, 3), (n, n, 1), (n, n, 1)`` maps."""
    c, r, m = CONSTANT_TRUTH
    return (np.full((n, n, 3), c, np.float32), np.full((n, n, 1), r, np.float32),
            np.full((n, n, 1), m, np.float32))


def environment(path: str, w: int = 128, h: int = 64) -> str:
    """A procedural environment map (EXR): sky gradient, a banded ground, a sun, two lamps."""
    th = (np.arange(h) + .5) / h * np.pi
    ph = (np.arange(w) + .5) / w * 2 * np.pi
    t, p = np.meshgrid(th, ph, indexing="ij")
    up = np.cos(t)
    env = np.stack([0.5 + 0.3 * up, 0.6 + 0.3 * up, 0.9 + 0.2 * up], -1) * (up > 0)[..., None]
    env += np.array([0.25, 0.2, 0.12]) * ((up <= 0) * (0.6 + 0.4 * (np.sin(6 * p) > 0)))[..., None]
    for t0, p0, s, c in ((0.6, 1.0, 0.08, [40, 38, 30]), (1.3, 3.5, 0.25, [0.2, 1.5, 0.3]),
                         (1.2, 5.0, 0.2, [1.8, 0.4, 0.3])):
        d2 = (t - t0) ** 2 + (np.minimum(abs(p - p0), 2 * np.pi - abs(p - p0)) * np.sin(t0)) ** 2
        env += np.array(c) * np.exp(-d2 / (2 * s * s))[..., None]
    draaw_mi.write_exr(path, env.astype(np.float32))
    return path


def scene_description(obj: str, maps, env: str, res: int, n_lights: int, layout: str = "ring",
                      lamp: str = "point") -> dict:
    c, r, m = maps
    shape = {"sphere": {"type": "sphere", "radius": 1.0},
             "monkey": {"type": "mesh", "file": os.path.join(DATA, "monkey.obj"), "scale": 0.2,
                        "translate": [0.15, -0.63, 0.0]},
             "tile": {"type": "rectangle", "scale": 1.0}}[obj]
    return {"render": {"resolution": [res, res], "spp": 16, "max_depth": 2, "filter": "gaussian"},
            "camera": {"origin": [0, 0, 3.2], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 40},
            "materials": {"obj": {"base_color": c.tolist(), "roughness": r[..., 0].tolist(),
                                  "metallic": m[..., 0].tolist()}},
            "shapes": [{**shape, "name": "thing", "material": "obj"}],
            "lights": [lamp_light(obj, j, n_lights, layout, lamp) for j in range(n_lights + 1)]
            + [{"type": "envmap", "name": "env", "file": env}]}


#: the captures' own lights (``--lamp``): a point light, or a square softbox (an area light
#: of side SOFTBOX_SIZE giving the same irradiance at the object) whose mirror image is a patch,
#: not a point, so one capture's highlight covers many texels
LAMPS = ("point", "softbox")
SOFTBOX_SIZE = 1.6


#: a softbox sits this much farther out than the point light it replaces (along the same ray
#: from the object), above the cameras: nearer, it would stand in another capture's view
SOFTBOX_DISTANCE = 1.6


def lamp_light(obj: str, j: int, k: int, layout: str, lamp: str) -> dict:
    """Lamp ``L{j}``'s ``[[lights]]`` entry: a point light at :func:`light_position`, or a
    softbox on the same ray from the object (its mirror point on the tile under ``sweep`` and
    ``patterns``)."""
    pos = np.array(light_position(obj, j, k, layout), dtype=float)
    if lamp == "point":
        return {"type": "point", "name": f"L{j}", "position": pos.tolist(), "intensity": 20.0}
    target = np.zeros(3)
    if layout in HIGHLIGHT_LAYOUTS and obj == "tile":
        c = np.array(camera(obj, j, k, layout)["origin"], dtype=float)
        target = np.array([(pos[0] + c[0]) / 2, (pos[1] + c[1]) / 2, 0.0])
    pos = target + SOFTBOX_DISTANCE * (pos - target)
    radiance = 20.0 * SOFTBOX_DISTANCE ** 2 / SOFTBOX_SIZE ** 2        # the point light's irradiance
    return {"type": "area", "name": f"L{j}", "shape": "rectangle", "position": pos.tolist(),
            "target": target.tolist(), "size": [SOFTBOX_SIZE, SOFTBOX_SIZE], "intensity": radiance}


#: how the captures' cameras and lamps are placed (``--layout``)
LAYOUTS = ("flash", "globe", "pairs", "patterns", "ring", "sweep")
#: the layouts whose lamps stand where a camera sees their mirror image (:func:`highlight_lamp`),
#: and the camera layout their captures' lamps and held-out view are placed from
HIGHLIGHT_CAMERAS = {"globe": "globe", "patterns": "sweep", "sweep": "sweep"}
HIGHLIGHT_LAYOUTS = tuple(HIGHLIGHT_CAMERAS)


def globe_direction(i: int, k: int) -> np.ndarray:
    """``globe``: capture ``i``'s camera direction from the object, one of ``k`` points spread
    over the sphere of directions (a Fibonacci lattice: heights ``1 - 2 (i + 1/2) / k``,
    golden-angle azimuths), so the cameras see the sphere's poles (61 degrees above and below
    its equator for 8 captures) as well as its equator, where ``sweep``'s stand at 21 and -7
    degrees. The held-out view (``i == k``) sits on the equator half-way along the lattice,
    between the two captures nearest the equator in height (and 41 degrees from the nearest
    camera for 8 captures).

    >>> d = globe_direction(0, 8); round(float(d[2]), 3), round(float(np.linalg.norm(d)), 6)
    (0.875, 1.0)
    >>> round(float(globe_direction(8, 8)[2]), 6)
    0.0
    """
    t = (k - 1) / 2 if i >= k else i
    h = 1 - 2 * (t + 0.5) / k
    a = t * np.pi * (3 - np.sqrt(5))
    r = np.sqrt(1 - h * h)
    return np.array([r * np.cos(a), r * np.sin(a), h])


def camera(obj: str, i: int, k: int, layout: str = "ring") -> dict:
    """Capture ``i`` of ``k``'s camera: around the object (the tile: above it). In ``pairs``
    two captures share each position (``k // 2`` positions)."""
    if layout == "pairs" and i < k:
        i, k = i // 2, max(k // 2, 1)
    a = 2 * np.pi * (i + 0.5 * (i >= k)) / k
    if obj == "tile":
        r = 1.6 if layout in ("ring", *HIGHLIGHT_LAYOUTS) else (0.5 if i % 2 else 1.0)      # a flash's mirror point on the tile
        return {"origin": [r * np.cos(a), r * np.sin(a), 2.6 + 0.4 * (i % 2)], "target": [0, 0, 0],
                "up": [0, 1, 0] if abs(np.cos(a)) > 0.5 else [1, 0, 0], "fov": 40}
    if layout == "globe":
        d = globe_direction(i, k)
        if obj == "sphere":
            return {"origin": (3.2 * d).tolist(), "target": [0, 0, 0], "up": [0, 0, 1], "fov": 40}
        return {"origin": [3.2 * 0.9 * d[1], 3.2 * d[2], 3.2 * 0.9 * d[0] + 0.2], "target": [0, 0, 0],
                "up": [0, 1, 0], "fov": 40}
    z = 1.2 if i % 2 else -0.4
    if obj == "sphere":
        return {"origin": [3.2 * np.cos(a), 3.2 * np.sin(a), z], "target": [0, 0, 0], "up": [0, 0, 1], "fov": 40}
    return {"origin": [3.2 * np.sin(a) * 0.9, z, 3.2 * np.cos(a) * 0.9 + 0.2], "target": [0, 0, 0],
            "up": [0, 1, 0], "fov": 40}


def light_position(obj: str, j: int, k: int, layout: str = "ring") -> list:
    """Lamp ``j`` of ``k`` (+1 held out, ``j == k``): on a ring around the object (``ring``, and
    the held-out lamp of ``flash`` and ``pairs``); ``flash``: beside capture ``j``'s camera
    (0.15 above it); ``pairs``: even captures a flash, odd ones a lamp on the ring; ``sweep``,
    ``globe`` and ``patterns``: :func:`highlight_lamp`."""
    if layout in HIGHLIGHT_LAYOUTS:               # patterns: only the held-out lamp shines
        return highlight_lamp(obj, j, k, layout)
    if j < k and (layout == "flash" or (layout == "pairs" and j % 2 == 0)):
        o = np.array(camera(obj, j, k, layout)["origin"], dtype=float)
        up = np.array([0.0, 1.0, 0.0] if obj == "monkey" else [0.0, 0.0, 1.0])
        return (o + 0.15 * up).tolist()
    b = 2 * np.pi * j / k + (0.9 if j % 2 else -0.9)
    height = 2.0 if j % 3 else -1.0
    if obj == "sphere":
        return [4 * np.cos(b), 4 * np.sin(b), height]
    if obj == "tile":
        return [2.5 * np.cos(b), 2.5 * np.sin(b), 2.5]
    return [4 * np.sin(b), height, 4 * np.cos(b)]


def highlight_lamp(obj: str, j: int, k: int, layout: str = "sweep") -> list:
    """``sweep`` (and ``globe``): lamp ``j`` where camera ``j`` sees its mirror reflection, at a
    point that moves over the object from capture to capture (a golden-angle spiral; the
    held-out lamp ``j == k`` at a point of its own), so each capture shows a highlight
    somewhere else."""
    c = np.array(camera(obj, j, k, HIGHLIGHT_CAMERAS[layout])["origin"], dtype=float)
    golden = np.pi * (3 - np.sqrt(5))
    rho, phi = np.sqrt((j + 0.5) / (k + 1)), j * golden
    if obj == "tile":                       # the mirror point t on the plane z = 0
        t = 0.9 * rho * np.array([np.cos(phi), np.sin(phi), 0.0])
        return [2 * t[0] - c[0], 2 * t[1] - c[1], c[2]]
    v = c / np.linalg.norm(c)               # a normal tilted from the view by up to 50 degrees
    a = np.cross(v, [0.3, 0.2, 1.0])
    if np.linalg.norm(a) < 0.3:             # a view within ~16 degrees of that axis (no sweep camera)
        a = np.cross(v, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(v, a)
    tilt = np.radians(50) * rho
    n = np.cos(tilt) * v + np.sin(tilt) * (np.cos(phi) * a + np.sin(phi) * b)
    lamp_dir = 2 * np.dot(n, v) * n - v
    return (n + 3.5 * lamp_dir).tolist()


#: ``patterns``: the bands' angular frequencies (radians of phase per radian of the angle to
#: the pattern's axis: periods of 1.05, 0.70 and 0.48 rad): a lobe as wide as one period
#: flattens them, a sharp one keeps them, so the contrast each texel reflects measures roughness
PATTERN_FREQUENCIES = (6.0, 9.0, 13.0)
PATTERN_SHARPNESS = 4.0
PATTERN_PEAK = 4.0


def pattern_environment(i: int, w: int = 128, h: int = 64) -> np.ndarray:
    """``patterns``: capture ``i``'s environment (``(h, w, 3)``, lat-long like
    :func:`environment`): bright bands, ``0.02 + PEAK exp(SHARPNESS (sin(f angle + 1.3 i) - 1))``
    with ``angle`` the angle to an axis that moves from the pole down a golden-angle spiral of
    16 points (capture 16 starts it again) and ``f`` cycling through
    :data:`PATTERN_FREQUENCIES`: a screen or a lit wall showing stripes, as Aittala et al.
    (2013) photograph materials under, so that every texel reflects some band in some capture.
    (Measured: far worse than ``sweep`` with softboxes; two 512-spp renders of the truth differ
    by an MSE of 2e-3 over the tile, results/svbrdf_fit.md.)"""
    th = (np.arange(h) + .5) / h * np.pi
    ph = (np.arange(w) + .5) / w * 2 * np.pi
    t, p = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    golden = np.pi * (3 - np.sqrt(5))
    z = 1 - 2 * (i % 16 + 0.5) / 16
    axis = np.array([np.sqrt(1 - z * z) * np.cos(i * golden), np.sqrt(1 - z * z) * np.sin(i * golden), z])
    f = PATTERN_FREQUENCIES[i % len(PATTERN_FREQUENCIES)]
    angle = np.arccos(np.clip(d @ axis, -1, 1))
    v = 0.02 + PATTERN_PEAK * np.exp(PATTERN_SHARPNESS * (np.sin(f * angle + 1.3 * i) - 1))
    return np.repeat(v[..., None], 3, -1).astype(np.float32)


def padded(env: np.ndarray):
    """``env`` as Mitsuba's ``envmap`` holds it (``data``: one wrapped column each side)."""
    return mi.TensorXf(np.ascontiguousarray(np.concatenate([env[:, -1:], env, env[:, :1]], 1)))


def captures(obj: str, k: int, layout: str = "ring") -> list:
    """``k`` captures: camera ``i`` and lamp ``L{i}`` (the environment always on); lamp
    ``L{k}`` is the held-out one. ``patterns``: every lamp off and the environment replaced by
    capture ``i``'s grating (:func:`pattern_environment`)."""
    if layout == "patterns":
        return [{"camera": camera(obj, i, k, layout), "lights": {f"L{j}": 0.0 for j in range(k + 1)},
                 "params": {"env.data": padded(pattern_environment(i))}} for i in range(k)]
    return [{"camera": camera(obj, i, k, layout), "lights": {f"L{j}": float(j == i) for j in range(k + 1)}}
            for i in range(k)]


def render_captures(scene, caps, spp: int, seed: int) -> list:
    """Mitsuba ``path`` renders of ``scene`` as each capture sees it."""
    from draaw_mi.fitting.captures import render_capture
    return [render_capture(scene, c, spp=spp, version="path", seed=seed + i) for i, c in enumerate(caps)]


def psnr(a, b) -> float:
    return float(-10 * np.log10(max(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2), 1e-12)))


def run_case(obj: str, k: int, n: int, res: int, args, env: str) -> list:
    truth = truth_maps(n) if args.truth == "procedural" else constant_maps(n)       # (scalar: as constant)
    desc = scene_description(obj, truth, env, res, k, args.layout, args.lamp)
    if args.truth == "scalar":
        desc = as_scalars(desc)
    ref_scene = draaw_mi.load_scene(desc)
    t = time.perf_counter()
    caps = captures(obj, k, args.layout)
    refs = render_captures(ref_scene, caps, args.ref_spp, 1000)
    held = [{"camera": camera(obj, k, k, HIGHLIGHT_CAMERAS.get(args.layout, "ring")),
             "lights": {f"L{j}": float(j == k) for j in range(k + 1)}}]
    held_truth = render_captures(ref_scene, held, 256, 77)[0]
    t_ref = time.perf_counter() - t
    rows = []
    observed = None
    truth_caps = None
    # one material as scalars: the fit is the same whatever the maps' method, so it runs once
    for method in (["scalars"] if args.truth == "scalar" else args.methods):
        start = truth if args.start == "truth" else (
            np.full((n, n, 3), 0.5, np.float32), np.full((n, n, 1), 0.5, np.float32),
            np.full((n, n, 1), STARTS[args.start][0], np.float32))
        d = scene_description(obj, start, env, res, k, args.layout, args.lamp)
        scene = draaw_mi.load_scene(as_scalars(d) if args.truth == "scalar" else d)
        t = time.perf_counter()
        pyramid = method in ("pyramid", "two-starts")
        run = fit_two_starts if method == "two-starts" else draaw_mi.fit
        r = run(scene, refs, PARAMS, captures=caps, spp=args.spp, iterations=args.iterations,
                batch=args.batch, loss=args.loss,
                maps=None if method == "scalars" else
                {"parametrisation": "pyramid" if pyramid else method, "tv": args.tv if pyramid else None,
                 "lr_scale": args.lr_scale if pyramid else None},
                lr=args.lr_texels if method == "texels" else args.lr,
                seed=args.seed, progress=not args.no_progress)
        seconds = time.perf_counter() - t
        if observed is None:
            observed = r.observed.get("obj.base_color")
        seen = observed if observed is not None else np.ones((n, n), bool)
        v = {p: np.broadcast_to(r.values[p], t.shape) for p, t in zip(PARAMS, truth)}
        relit = psnr(render_captures(scene, held, 256, 77)[0], held_truth)
        if args.capture_spp:
            if truth_caps is None:
                truth_caps = render_captures(ref_scene, caps, args.capture_spp, 500)
            # the same seeds as the truth's renders: their noise largely cancels in the difference
            fitted_caps = render_captures(scene, caps, args.capture_spp, 500)
            capture_psnr = float(np.mean([psnr(a, b) for a, b in zip(fitted_caps, truth_caps)]))
        else:
            capture_psnr = float("nan")
        rows.append({"object": obj, "captures": k, "texture": n, "image": res, "method": method,
                     "albedo_psnr": float(-10 * np.log10(np.mean((v["obj.base_color"] - truth[0])[seen] ** 2))),
                     "rough_mae": float(np.abs(v["obj.roughness"] - truth[1])[seen].mean()),
                     "metal_mae": float(np.abs(v["obj.metallic"] - truth[2])[seen].mean()),
                     "mean_fit": [float(v[p][seen].mean()) for p in PARAMS],
                     "relit_psnr": relit, "capture_psnr": capture_psnr, "seconds": seconds, "ref_seconds": t_ref,
                     "observed": float(seen.mean()),
                     "unexplained": [i for i, c in enumerate(r.captures) if not c["explained"]]})
        print(rows[-1], flush=True)
        if args.plots:
            from draaw_mi.fitting.map_outputs import plot_maps
            plot_maps(v, dict(zip(PARAMS, truth)), r.losses, r.observed,
                      path=os.path.join(args.plots, f"svbrdf_{obj}_{k}_{n}_{method}.png"))
    return rows


def map_option(items: list, number: bool):
    """``--lr-scale`` / ``--tv`` items as ``fit(maps=...)`` takes them: ``NAME=X`` items as a
    dict (``None`` for none), or with ``number`` one bare number as itself.

    >>> map_option(["metallic=5", "obj.roughness=2"], False), map_option(["0"], True), map_option([], True)
    ({'metallic': 5.0, 'obj.roughness': 2.0}, 0.0, None)
    """
    if number and len(items) == 1 and "=" not in items[0]:
        return float(items[0])
    return {k: float(v) for k, v in (item.split("=", 1) for item in items)} or None


def tv_text(tv) -> str:
    """``--tv`` as the table's header says it: one weight for every map, or entries per map
    over :data:`~draaw_mi.fitting.maps.TV_WEIGHTS` (the more specific name wins).

    >>> tv_text(None), tv_text(0.0)
    ("{'roughness': 0.003}", '0.0')
    >>> tv_text({"obj.roughness": 0.01})
    "{'obj.roughness': 0.01} over {'roughness': 0.003}"
    """
    if isinstance(tv, float):
        return str(tv)
    return f"{tv} over {TV_WEIGHTS}" if tv else str(TV_WEIGHTS)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", nargs="+", default=["sphere", "monkey", "tile"])
    ap.add_argument("--captures", nargs="+", type=int, default=[8])
    ap.add_argument("--textures", nargs="+", type=int, default=[64])
    ap.add_argument("--image", type=int, default=128)
    ap.add_argument("--layout", choices=LAYOUTS, default="ring", help="where the captures' cameras and lamps are")
    ap.add_argument("--lamp", choices=LAMPS, default="point", help="the captures' own lights")
    ap.add_argument("--truth", choices=("procedural", "constant", "scalar"), default="procedural",
                    help="the ground truth: procedural maps (smooth and sharp features), one material "
                         "as maps (constant), or one material fitted as three scalars (scalar)")
    ap.add_argument("--methods", nargs="+", default=["pyramid", "texels"],
                    choices=("pyramid", "two-starts", "texels"),
                    help="pyramid: fit() with its default maps; two-starts: fit_two_starts() (two fits of "
                         "--iterations, metallic from the start and from 0, merged, refined); texels: the "
                         "texel-by-texel fit")
    ap.add_argument("--start", choices=(*STARTS, "truth"), default="half",
                    help="the fit's first maps: 0.5 everywhere (half), the draaw material's defaults "
                         "(colour and roughness 0.5, metallic 0: default), or the ground truth (a "
                         "diagnostic: where the fit drifts from the truth, the captures' optimum is not the truth)")
    ap.add_argument("--iterations", type=int, default=300)
    ap.add_argument("--batch", type=int, default=2)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--capture-spp", type=int, default=0,
                    help="spp of the 'captures PSNR' column (0: not measured): the fitted maps' "
                         "renders of the captures against the truth's, with the same seeds. Low: the "
                         "optimiser stopped short; high while the maps are wrong: the captures cannot "
                         "tell them apart. Over whole images: the background, the same in both, raises it, so compare it between "
                         "fits of one object")
    ap.add_argument("--lr", type=float, default=0.05, help="the pyramid's lr (logit units)")
    ap.add_argument("--lr-texels", type=float, default=0.05, help="the texel-by-texel fit's lr (value units)")
    ap.add_argument("--lr-scale", nargs="+", default=[], metavar="NAME=X",
                    help="the pyramid's per-map learning rates, as maps={'lr_scale': ...} takes them, "
                         "over draaw_mi.fitting.maps.LR_SCALES (metallic=1 gives every map the same rate)")
    ap.add_argument("--loss", choices=LOSSES, default="l2", help="fit()'s loss")
    ap.add_argument("--tv", nargs="+", default=[], metavar="W | NAME=W",
                    help="the pyramid's total-variation prior, as maps={'tv': ...} takes it: one weight "
                         "for every map, or NAME=W items over draaw_mi.fitting.maps.TV_WEIGHTS (default "
                         "those alone; 0 turns the prior off)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plots", help="folder for a maps/truth/error figure per fit")
    ap.add_argument("--out", default=OUT)
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    for option, flag, number, example in (("lr_scale", "--lr-scale", False, "metallic=5"),
                                          ("tv", "--tv", True, "roughness=0.003")):
        items = getattr(args, option)
        try:
            setattr(args, option, map_option(items, number))
            MapOptions.parse({option: getattr(args, option)})
        except (ValueError, ParameterError) as e:
            ap.error(f"{flag} {' '.join(items)}: {e} ({'one NUMBER, or ' if number else ''}NAME=NUMBER items: "
                     f"{example})")
    if args.capture_spp < 0:
        ap.error(f"--capture-spp {args.capture_spp}: expected 0 (not measured) or a positive spp")
    if args.layout == "patterns" and args.lamp == "softbox":
        ap.error("--layout patterns takes --lamp point: switched-off softboxes are black panels that "
                 "would stand where each camera sees its highlight")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        env = environment(os.path.join(tmp, "env.exr"))
        for obj in args.objects:
            for k in args.captures:
                for n in args.textures:
                    rows += run_case(obj, k, n, args.image, args, env)
    lines = ["# SVBRDF fitting: maps from captures", "",
             f"Command (repository root): `.venv/bin/python benchmarks/svbrdf_fit.py {' '.join(argv or sys.argv[1:])}`",
             "", f"Recorded {time.strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} CPUs, variant "
             f"`{mi.variant()}`. Times are wall clock.", "",
             f"Fit: `draaw_mi.fit(scene, refs, {PARAMS}, captures=..., spp={args.spp}, "
             f"iterations={args.iterations}, batch={args.batch}, maps=...)` from "
             f"{'the truth' if args.start == 'truth' else STARTS[args.start][1]}: pyramid with "
             f"lr {args.lr} (logit units; per map x{ {**LR_SCALES, **(args.lr_scale or {})} }) and tv {tv_text(args.tv)}, texels with lr {args.lr_texels} (value units, today's "
             f"texel-by-texel fit); references `path` at {args.ref_spp} spp, max_depth 2, "
             f"gaussian filter. Captures: layout `{args.layout}`, lamps `{args.lamp}`, truth `{args.truth}`. "
             "Metrics over the observed texels; relit = a held-out camera and lamp, "
             "256 spp both, clipped to [0, 1]. Time = the whole fit() call. Captures PSNR (with "
             "--capture-spp): the fitted maps' renders of the captures against the truth's, the same seeds, "
             "mean over the captures, whole images.", "",
             "| object | captures | texture | image | method | albedo PSNR (dB) | roughness MAE | metallic MAE "
             "| relit PSNR (dB) | captures PSNR (dB) | fitted means (colour, r, m) | fit time (s) | observed | unexplained captures |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cap_psnr = "-" if np.isnan(r["capture_psnr"]) else f"{r['capture_psnr']:.1f}"
        lines.append(f"| {r['object']} | {r['captures']} | {r['texture']}² | {r['image']}² | {r['method']} | "
                     f"{r['albedo_psnr']:.1f} | {r['rough_mae']:.3f} | {r['metal_mae']:.3f} | {r['relit_psnr']:.1f} | {cap_psnr} | "
                     f"{', '.join(f'{x:.2f}' for x in r['mean_fit'])} | "
                     f"{r['seconds']:.0f} | {r['observed']:.0%} | {r['unexplained'] or '-'} |")
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
