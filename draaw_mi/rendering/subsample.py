"""Adaptive subsampling with bilinear interpolation (the second thesis' §3.4 speed-up), wavefront style.

The image is covered by blocks of ``block`` × ``block`` pixels whose corners are pixel
centres. A block whose four corners *agree* — the same primary shape, the same visibility of
every light (towards a fixed point on it) and the same shape along the mirror direction — is
filled by bilinear interpolation of its corners' radiance; a block whose corners disagree is
split into four and its new corners are examined, down to single pixels.

How it runs (no per-pixel Python):

1. Level by level, the *signatures* of the corner points still unknown are traced in one small
   Dr.Jit launch (a camera ray, one shadow ray per light, one mirror ray); the agree/split
   decisions are vectorised numpy on the level's regular grid of blocks.
2. One integrator launch computes the radiance of every pixel that was a corner at some level
   (the compacted list of pixels to trace).
3. One Dr.Jit kernel over all pixels fills the rest: each pixel finds the coarsest agreeing
   block that contains it and interpolates its four corners.

It is biased by design: inside agreeing blocks it blurs texture, soft shadows and glossy
highlights, and at low spp it turns per-pixel noise into smooth blobs. ``draaw-mi bench``
reports its speed-up and its error against ground truth.

>>> import draaw_mi
>>> scene = draaw_mi.load_scene("scenes/cornell.toml", resolution=(32, 32))
>>> img, stats = render_adaptive(scene, block=8, spp=1, version="path")
>>> img.shape, 0.0 < stats["traced_fraction"] < 1.0
((32, 32, 3), True)
"""
from __future__ import annotations

import numbers

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import RenderError
from .film_colour import film_colour_names
from .session import holding, session_of


def _jit(array_type, values: np.ndarray):
    """A Dr.Jit array made from ``values`` via a 64-byte aligned buffer. Dr.Jit maps numpy
    memory; its alignment varies between allocations and is baked into the kernel (``align 1``
    vs ``align 64`` loads), so unaligned inputs would cost a recompile on many calls."""
    values = np.ascontiguousarray(values)
    buf = np.empty(values.nbytes + 64, np.uint8)
    offset = (-buf.ctypes.data) % 64
    aligned = buf[offset:offset + values.nbytes].view(values.dtype)
    aligned[...] = values.ravel()
    return array_type(aligned)


def _sample_points(scene, integrator, xs: np.ndarray, ys: np.ndarray, spp: int, seed: int) -> mi.Float:
    """Radiance at pixels (xs, ys), ``spp`` jittered samples each, one launch: a flat
    (w * h * 3) Dr.Jit array with the traced pixels filled in (zeros elsewhere)."""
    mis = scene.mi_scene
    sensor = mis.sensors()[0]
    w, h = scene.resolution
    n = len(xs)
    idx = dr.arange(mi.UInt32, n)
    if spp > 1:
        idx = dr.repeat(idx, spp)
    px = dr.gather(mi.Float, _jit(mi.Float, xs.astype(np.float32)), idx)
    py = dr.gather(mi.Float, _jit(mi.Float, ys.astype(np.float32)), idx)
    # independent samples: the scene's sampler, cloned, stratifies over its own sample count,
    # not over these lanes (else every lane takes sample 0 of a multijitter pattern: a skewed
    # jitter, pixel means 13 sigma off on a 300-seed test)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(dr.opaque(mi.UInt32, seed), n * spp)
    with dr.suspend_grad():
        jitter = sampler.next_2d()
        pos = mi.Point2f((px + jitter.x) / w, (py + jitter.y) / h)
        ray, weight = sensor.sample_ray(0.0, sampler.next_1d(), pos, mi.Point2f(0.5))
        if isinstance(integrator, mi.ad.integrators.common.ADIntegrator):
            L, _, _, _ = integrator.sample(dr.ADMode.Primal, mis, sampler, ray, None, None, mi.Bool(True))
        else:
            L, _, _ = integrator.sample(mis, sampler, ray, None, mi.Bool(True))
        L = mi.Color3f(L * weight)
        if spp > 1:
            L = dr.block_sum(L, spp) / spp
        pix = _jit(mi.UInt32, (ys * w + xs).astype(np.uint32))
        image = dr.zeros(mi.Float, w * h * 3)
        dr.eval(L)                           # once, not once per scattered channel
        for c in range(3):
            dr.scatter(image, L[c], pix * 3 + c)
        dr.eval(image)
    return image


def _signatures(scene, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """One int64 per pixel centre packing: primary shape (16 bits), shape along the mirror
    direction (16 bits), and the visibility of each emitter (32 bits; more lights are folded)."""
    mis = scene.mi_scene
    sensor = mis.sensors()[0]
    w, h = scene.resolution
    with dr.suspend_grad():
        pos = mi.Point2f((_jit(mi.Float, xs.astype(np.float32)) + 0.5) / w,
                         (_jit(mi.Float, ys.astype(np.float32)) + 0.5) / h)
        ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))
        si = mis.ray_intersect(ray)
        hit = si.is_valid()
        shape = dr.select(hit, dr.reinterpret_array(mi.UInt32, si.shape), 0)
        vis = mi.UInt32(0)
        for k, em in enumerate(mis.emitters()):
            ds, _ = em.sample_direction(si, mi.Point2f(0.5, 0.5), hit)
            ok = hit & (ds.pdf > 0) & (dr.dot(ds.d, si.n) > 0)
            blocked = mis.ray_test(si.spawn_ray_to(ds.p), ok)
            vis = vis ^ dr.select(ok & ~blocked, mi.UInt32(1 << (k % 32)), 0)
        refl = ray.d - 2 * dr.dot(ray.d, si.sh_frame.n) * si.sh_frame.n          # mirror direction
        si2 = mis.ray_intersect(si.spawn_ray(refl), hit)
        second = dr.select(hit & si2.is_valid(), dr.reinterpret_array(mi.UInt32, si2.shape), 0)
        ids = (shape & 0xFFFF) | ((second & 0xFFFF) << 16)
        dr.eval(ids, vis)
    return (np.array(ids, dtype=np.int64) << 32) | np.array(vis, dtype=np.int64)


def _grid(n_pixels: int, step: int) -> np.ndarray:
    """Corner coordinates of a level: 0, step, 2 step, ... clamped to the last pixel."""
    n_cells = max(1, -(-(n_pixels - 1) // step))
    return np.minimum(np.arange(n_cells + 1) * step, n_pixels - 1)


def check_adaptive_camera(scene) -> None:
    """Refuse what adaptive subsampling's rays cannot follow: a film that is not R, G, B,
    a camera with an aperture, a crop window."""
    sensor = scene.mi_scene.sensors()[0]
    film = sensor.film()
    colour = film_colour_names(film)
    if colour != ["R", "G", "B"]:       # (an rgba film's alpha would be dropped)
        raise RenderError(f"render_adaptive: adaptive subsampling renders R, G, B; the film of {scene.source} "
                          f"stores {', '.join(colour)}: set its pixel_format to rgb, or drop adaptive=")
    # its rays go through pixel centres of the whole film with the aperture's centre: a
    # thin lens would render pinhole-sharp, a crop window come back as the whole film
    if sensor.needs_aperture_sample():
        raise RenderError(f"render_adaptive: adaptive subsampling traces pinhole rays; the camera of {scene.source} "
                          "has an aperture (thinlens): drop adaptive=")
    if tuple(film.crop_size()) != tuple(film.size()) or any(int(v) for v in film.crop_offset()):
        raise RenderError(f"render_adaptive: adaptive subsampling renders the whole film; the film of {scene.source} "
                          "has a crop window: drop adaptive= or the crop")


def render_adaptive(scene, block: int = 8, spp: int = 1, seed: int = 0, version: str = "v4",
                    max_depth: int | None = None, integrator=None):
    """Render ``scene`` with adaptive subsampling; returns ((H, W, 3) mi.TensorXf, stats dict).
    ``integrator``: a made one (e.g. hiding emitters) instead of ``version`` / ``max_depth``.

    ``stats``: ``traced`` (pixels traced), ``traced_fraction``, ``levels``, ``cells_interpolated``.
    """
    if isinstance(block, bool) or not isinstance(block, numbers.Integral) or block < 2 or block & (block - 1):
        raise RenderError(f"render: adaptive={block!r}; expected a power of two >= 2 (block size in pixels)")
    block = int(block)                  # (numpy integers too, as render's other counts)
    check_adaptive_camera(scene)
    session = session_of(scene)
    if integrator is None:
        integrator = session.integrator(version, scene.settings["max_depth"] if max_depth is None else max_depth)
    with holding(scene):
        return _render(scene, block, spp, seed, integrator)


def _render(scene, block: int, spp: int, seed: int, integrator):
    """:func:`render_adaptive` once its arguments are checked (under the scene's lock)."""
    w, h = scene.resolution
    traced = np.zeros((h, w), bool)
    sig = np.zeros((h, w), np.int64)
    agree_maps = []                                   # per level: (step, agree mask of cells)
    if w >= 2 and h >= 2:
        step = block
        active = None
        while step >= 1:
            gx, gy = _grid(w, step), _grid(h, step)
            ny, nx = len(gy) - 1, len(gx) - 1
            if active is None:
                active = np.ones((ny, nx), bool)
            # corner points of active cells that are not known yet
            pts = np.zeros((ny + 1, nx + 1), bool)
            pts[:-1, :-1] |= active
            pts[:-1, 1:] |= active
            pts[1:, :-1] |= active
            pts[1:, 1:] |= active
            py, px = np.nonzero(pts)
            X, Y = gx[px], gy[py]
            new = ~traced[Y, X]
            if new.any():
                xs, ys = X[new], Y[new]
                sig[ys, xs] = _signatures(scene, xs, ys)
                traced[ys, xs] = True
            g = sig[np.ix_(gy, gx)]
            same = (g[:-1, :-1] == g[:-1, 1:]) & (g[:-1, :-1] == g[1:, :-1]) & (g[:-1, :-1] == g[1:, 1:])
            agree = active & same
            agree_maps.append((step, agree))
            split = active & ~same
            if step == 1 or not split.any():
                break
            step //= 2
            ny2, nx2 = len(_grid(h, step)) - 1, len(_grid(w, step)) - 1
            active = np.repeat(np.repeat(split, 2, axis=0), 2, axis=1)[:ny2, :nx2]
            if active.shape != (ny2, nx2):          # odd trailing cells: pad with False
                pad = np.zeros((ny2, nx2), bool)
                pad[:active.shape[0], :active.shape[1]] = active
                active = pad
    else:
        traced[:] = True
    ys, xs = np.nonzero(traced)
    value = _sample_points(scene, integrator, xs, ys, spp, seed)
    out = _fill(value, traced, agree_maps, w, h)
    cells = int(sum(a.sum() for _, a in agree_maps))
    return out, {"traced": int(traced.sum()), "traced_fraction": float(traced.mean()),
                 "levels": len(agree_maps), "cells_interpolated": cells}


def _fill(vals: mi.Float, traced: np.ndarray, agree_maps, w: int, h: int) -> mi.TensorXf:
    """Dr.Jit kernel over all pixels: traced pixels keep their value, the others take the
    bilinear interpolation of the coarsest agreeing cell that contains them."""
    if traced.all():
        return mi.TensorXf(vals, (h, w, 3))
    idx = dr.arange(mi.UInt32, w * h)
    x, y = idx % w, idx // w
    out = mi.Color3f(dr.gather(mi.Float, vals, idx * 3 + 0), dr.gather(mi.Float, vals, idx * 3 + 1),
                     dr.gather(mi.Float, vals, idx * 3 + 2))
    done = _jit(mi.Bool, traced.ravel())
    for step, agree in agree_maps:
        nyc, nxc = agree.shape
        i = dr.minimum(x // step, nxc - 1)
        j = dr.minimum(y // step, nyc - 1)
        ok = ~done & dr.gather(mi.Bool, _jit(mi.Bool, agree.ravel()), j * nxc + i)
        x0, y0 = i * step, j * step
        x1, y1 = dr.minimum(x0 + step, w - 1), dr.minimum(y0 + step, h - 1)
        fx = mi.Float(x - x0) / mi.Float(dr.maximum(x1 - x0, 1))
        fy = mi.Float(y - y0) / mi.Float(dr.maximum(y1 - y0, 1))

        def corner(cx, cy):
            base = (cy * w + cx) * 3
            return mi.Color3f(dr.gather(mi.Float, vals, base, ok), dr.gather(mi.Float, vals, base + 1, ok),
                              dr.gather(mi.Float, vals, base + 2, ok))
        top = dr.lerp(corner(x0, y0), corner(x1, y0), fx)
        bottom = dr.lerp(corner(x0, y1), corner(x1, y1), fx)
        out = dr.select(ok, dr.lerp(top, bottom, fy), out)
        done |= ok
    flat = dr.ravel(out)
    dr.eval(flat)
    return mi.TensorXf(flat, (h, w, 3))
