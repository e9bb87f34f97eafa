"""Shared helpers for the draaw BSDF tests: vectorised BSDF queries, tiny Cornell boxes,
multi-seed renders and the per-pixel z-score comparison.

Imported by the ``test_draaw_*.py`` files next to it (pytest puts this folder on ``sys.path``).
"""
from __future__ import annotations

import numpy as np

import draaw_mi  # noqa: F401  (sets the variant, registers the 'draaw' BSDF)
import drjit as dr
import mitsuba as mi

# mi.cornell_box()'s 'white' reflectance
CORNELL_WHITE = [0.885809, 0.698859, 0.666422]
UP = mi.ScalarVector3f(0, 0, 1)


# ---------------------------------------------------------------------------- BSDF queries
def vec3(a) -> mi.Vector3f:
    a = np.asarray(a, dtype=np.float32)
    return mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])


def make_si(wi, uv=None) -> mi.SurfaceInteraction3f:
    """A vectorised SurfaceInteraction3f with local wi (N, 3) and an identity shading frame."""
    wi = np.asarray(wi, dtype=np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[0])
    si.wi = vec3(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float32)
        si.uv = mi.Point2f(uv[:, 0], uv[:, 1])
    return si


def direction(cos_theta, phi=0.0) -> np.ndarray:
    """Unit vectors (N, 3) with the given cos theta (may be <= 0) and azimuth."""
    c = np.atleast_1d(np.asarray(cos_theta, dtype=np.float64))
    phi = np.broadcast_to(np.asarray(phi, dtype=np.float64), c.shape)
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    return np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=-1)


def uniform_hemisphere(n, rng) -> np.ndarray:
    u = rng.random((n, 2))
    z = u[:, 0]
    return direction(z, 2 * np.pi * u[:, 1])


def color_np(c) -> np.ndarray:
    """mi.Color3f / Spectrum with N lanes -> (N, 3) numpy."""
    return np.array(c, dtype=np.float64).reshape(3, -1).T


def draaw(**kw) -> mi.BSDF:
    return mi.load_dict({"type": "draaw", **kw})


# ---------------------------------------------------------------------------- scenes
def cornell(res=32, max_depth=4, integrator="path", white=None, override=None, mats=None):
    """mi.cornell_box() at res x res with a box filter.

    white: BSDF dict replacing the shared 'white' material (all walls, boxes, light).
    override: BSDF dict given to large-box, small-box, floor and back (id 'mat').
    mats: explicit {shape: bsdf dict}.
    """
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=res, height=res, rfilter={"type": "box"})
    d["sensor"]["sampler"] = {"type": "independent", "sample_count": 16}
    d["integrator"] = {"type": integrator, "max_depth": max_depth}
    if white is not None:
        d["white"] = white
    if override is not None:
        d["mat"] = override
        for k in ("large-box", "small-box", "floor", "back"):
            d[k]["bsdf"] = {"type": "ref", "id": "mat"}
    for k, v in (mats or {}).items():
        d[k]["bsdf"] = v
    return mi.load_dict(d)


def render_stack(scene, seeds, spp) -> np.ndarray:
    """(K, H, W, 3) numpy stack of renders, one per seed."""
    out = []
    for s in seeds:
        img = mi.render(scene, spp=spp, seed=int(s))
        out.append(np.array(img, dtype=np.float64))
    return np.stack(out)


def zstats(a: np.ndarray, b: np.ndarray) -> dict:
    """Per-pixel Welch z-scores of mean(a) - mean(b) over independent renders (axis 0).

    frac4: fraction of pixel channels with |z| > 4; mean_z: their mean (0 for equal images);
    rel: relative difference of the image means; z_image: z-score of that difference.
    """
    k_a, k_b = a.shape[0], b.shape[0]
    diff = a.mean(0) - b.mean(0)
    se = np.sqrt(a.var(0, ddof=1) / k_a + b.var(0, ddof=1) / k_b)
    live = se > 0
    # channels with no variance in both stacks (e.g. black background) must agree exactly
    dead_mismatch = int(np.sum(np.abs(diff[~live]) > 1e-6))
    z = diff[live] / se[live]
    ga, gb = a.mean(axis=(1, 2, 3)), b.mean(axis=(1, 2, 3))
    z_image = (ga.mean() - gb.mean()) / np.sqrt(ga.var(ddof=1) / k_a + gb.var(ddof=1) / k_b)
    return {
        "frac4": float(np.mean(np.abs(z) > 4)),
        "mean_z": float(z.mean()),
        "max_abs_z": float(np.abs(z).max()),
        "n": int(z.size),
        "dead_mismatch": dead_mismatch,
        "rel": float(diff.mean() / b.mean()),
        "z_image": float(z_image),
    }
