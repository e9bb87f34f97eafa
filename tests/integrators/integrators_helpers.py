"""Shared helpers of the integrator tests (scenes, renders, statistics, finite differences)."""
from __future__ import annotations

import numpy as np

import draaw_mi  # noqa: F401  (variant + plugins)
import drjit as dr
import mitsuba as mi

from draaw_mi.bench import reference_scenes as rs  # noqa: F401  (re-exported to the tests)


VERSIONS = ("draaw_v1", "draaw_v2", "draaw_v3", "draaw_v4")


def integrator(kind: str, **kw) -> mi.Integrator:
    d = {"type": kind, "max_depth": kw.pop("max_depth", 6)}
    d.update(kw)
    return mi.load_dict(d)


def render_np(scene, integ, spp: int, seed: int = 0) -> np.ndarray:
    img = mi.render(scene, integrator=integ, spp=spp, seed=seed)
    return np.array(img, dtype=np.float64)


def seed_stack(scene, integ, spp: int, seeds) -> np.ndarray:
    """(K, H, W, C) stack of independent renders."""
    return np.stack([render_np(scene, integ, spp, 1000 + 7919 * s) for s in seeds])


def zscores(stack_a: np.ndarray, stack_b: np.ndarray, floor: float = 1e-6) -> np.ndarray:
    """Per-pixel/channel z-scores of the difference of two seed stacks' means."""
    ka, kb = len(stack_a), len(stack_b)
    ma, mb = stack_a.mean(0), stack_b.mean(0)
    va = stack_a.var(0, ddof=1) / ka
    vb = stack_b.var(0, ddof=1) / kb
    se = np.sqrt(va + vb)
    mask = se > floor
    z = np.zeros_like(ma)
    z[mask] = (ma[mask] - mb[mask]) / se[mask]
    return z[mask]


def z_summary(z: np.ndarray) -> dict:
    return {"n": int(z.size), "frac_gt3": float(np.mean(np.abs(z) > 3)),
            "frac_gt2": float(np.mean(np.abs(z) > 2)), "mean": float(z.mean()),
            "std": float(z.std())}


def loss_of(img, weight=None) -> "mi.Float":
    """Mean of the image, or of ``image * weight`` (a fixed, detached weight image: still a
    linear function of the render, so AD and FD estimate the same derivative)."""
    return dr.mean(img if weight is None else img * weight, axis=None)


def highlight_weight(scene, spp: int = 256) -> "mi.TensorXf":
    """Squared normalised luminance of a ``path`` render: a fixed weight that emphasises the
    highlights, so that the loss sees light moving within the image (a normalised lobe's
    roughness hardly changes the image mean)."""
    img = render_np(scene, integrator("path", max_depth=4), spp, seed=4242)
    lum = img.mean(axis=2, keepdims=True)
    cap = np.percentile(lum, 90)              # visible emitters saturate instead of dominating
    w = (np.minimum(lum, cap) / cap) ** 2
    return mi.TensorXf(np.repeat(w, img.shape[2], axis=2).astype(np.float32))


def ad_gradient(scene, integ, key: str, spp: int, seed: int, weight=None) -> float:
    """d(loss)/d(param), summed over the parameter's channels (reverse mode)."""
    params = mi.traverse(scene)
    dr.enable_grad(params[key])
    dr.clear_grad(params[key])
    params.update()
    img = mi.render(scene, params, integrator=integ, spp=spp, seed=seed, seed_grad=seed + 1)
    dr.backward(loss_of(img, weight))
    g = dr.grad(params[key])
    out = float(np.sum(np.array(g)))
    dr.disable_grad(params[key])
    dr.clear_grad(params[key])
    params.update()
    return out


def forward_gradient(scene, integ, key: str, spp: int, seed: int) -> float:
    """d(mean image)/d(param) in forward mode, the tangent 1 on every channel."""
    params = mi.traverse(scene)
    dr.enable_grad(params[key])
    params.update()
    dr.set_grad(params[key], type(params[key])(1.0))
    img = mi.render(scene, params, integrator=integ, spp=spp, seed=seed)
    dr.forward_to(img)
    out = float(np.array(dr.mean(dr.grad(img), axis=None)).ravel()[0])
    dr.disable_grad(params[key])
    params.update()
    return out


def fd_gradient(scene, integ, key: str, h: float, spp: int, seed: int, weight=None) -> float:
    """Central difference (common random numbers) of the mean image, +h on every channel."""
    params = mi.traverse(scene)
    v0 = type(params[key])(params[key])
    vals = []
    for sgn in (1.0, -1.0):
        params[key] = v0 + sgn * h
        params.update()
        img = mi.render(scene, integrator=integ, spp=spp, seed=seed)
        vals.append(float(np.array(loss_of(img, weight)).ravel()[0]))
    params[key] = v0
    params.update()
    return (vals[0] - vals[1]) / (2 * h)


def ball_on_floor(ball_bsdf: dict, res: int = 12) -> mi.Scene:
    """A ball of ``ball_bsdf`` on a diffuse floor under a point light (box filter)."""
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene",
        "cam": {"type": "perspective", "fov": 45, "to_world": T().look_at(origin=[0, 1, 4], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}},
        "light": {"type": "point", "position": [0, 2, 1], "intensity": {"type": "rgb", "value": 10}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3), "bsdf": {"type": "diffuse"}},
        "ball": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "bsdf": ball_bsdf}})


def official_scene(name: str, res: int):
    """``scenes/<name>.toml`` through draaw_mi.load_scene at res x res (box filter). A loader
    failure fails the test: these tests are about the shipped scenes, not stand-ins."""
    import os
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return draaw_mi.load_scene(os.path.join(root, "scenes", f"{name}.toml"),
                               resolution=(res, res)).mi_scene


def check_same_expectation(a: np.ndarray, b: np.ndarray, max_frac3: float = 0.02,
                           max_mean: float = 0.25) -> dict:
    """Per-pixel z-test of two seed stacks; raises AssertionError with the summary."""
    s = z_summary(zscores(a, b))
    assert s["n"] > 0.3 * a[0].size, s
    assert s["frac_gt3"] <= max_frac3, s
    assert abs(s["mean"]) <= max_mean, s
    assert 0.7 <= s["std"] <= 1.4, s
    return s
