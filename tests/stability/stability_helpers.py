"""Shared machinery of the stability suite: tiny renders with gradients, fast-math toggling."""
from __future__ import annotations

import contextlib

import drjit as dr
import mitsuba as mi
import numpy as np

import draaw_mi

VERSIONS = ("v1", "v2", "v3", "v4")
RES = (8, 8)


@contextlib.contextmanager
def fast_math(on: bool):
    old = dr.flag(dr.JitFlag.FastMath)
    dr.set_flag(dr.JitFlag.FastMath, on)
    try:
        yield
    finally:
        dr.set_flag(dr.JitFlag.FastMath, old)


def render_with_gradient(scene, version: str, key: str | None, spp: int = 4, seed: int = 0):
    """(image, gradient) of the image mean w.r.t. ``key`` (gradient None when key is None)."""
    if key is None:
        return np.array(draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[])), None
    p = scene.params
    dr.enable_grad(p[key])
    p.update()
    try:
        img = draaw_mi.render(scene, version=version, spp=spp, seed=seed, params=p, post=[])
        dr.backward(dr.mean(img, axis=None))
        grad = np.array(dr.grad(p[key]))
        return np.array(img), grad
    finally:
        dr.clear_grad(p[key])
        dr.disable_grad(p[key])
        p.update()


def assert_finite(img, grad=None, what=""):
    assert np.isfinite(img).all(), f"{what}: non-finite image values ({np.sum(~np.isfinite(img))} of {img.size})"
    if grad is not None:
        assert np.isfinite(grad).all(), f"{what}: non-finite gradient {grad}"


def scene(shapes, lights, materials=None, camera=None, res=RES, max_depth=4):
    return draaw_mi.load_scene({
        "render": {"resolution": list(res), "max_depth": max_depth, "filter": "box"},
        "camera": camera or {"origin": [0, 1, 4], "target": [0, 0.5, 0], "fov": 45},
        "materials": materials or {"m": {"base_color": [0.7, 0.6, 0.5], "roughness": 0.4, "metallic": 0.3}},
        "shapes": shapes, "lights": lights,
    })


def bsdf_si(n: int, wi: np.ndarray):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(wi[:, 0], wi[:, 1], wi[:, 2])
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    si.uv = mi.Point2f(0.5, 0.5)
    return si
