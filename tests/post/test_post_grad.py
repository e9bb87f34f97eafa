"""Gradients: Dr.Jit reverse mode against central differences of the float64 reference, the
straight-through quantiser, and render → chain → loss through Mitsuba's ``prb``."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi.post as post
from post_helpers import CASES, hdr_image, ref

GRAD_CASES = [(name, params) for name, cases in CASES.items() if name != "color_mapping"
              for params in cases[:2]]


def _vjp(fn, img, weights):
    """∂/∂img Σ weights · fn(img) by dr.backward."""
    x = mi.TensorXf(img)
    dr.enable_grad(x)
    y = fn(x)
    dr.backward(dr.sum(y.array * mi.Float(weights.ravel())))
    g = dr.grad(x).numpy()
    assert np.all(np.isfinite(g))
    return g


@pytest.mark.parametrize("name,params", GRAD_CASES,
                         ids=[f"{n}-{i % 2}" for i, (n, _) in enumerate(GRAD_CASES)])
def test_gradient_matches_finite_differences(name, params):
    img = hdr_image(seed=5, lo=0.05)            # away from 0 where the tone curves are steep
    rng = np.random.default_rng(6)
    w = rng.standard_normal(img.shape).astype(np.float32)
    v = rng.standard_normal(img.shape)
    g = _vjp(lambda x: getattr(post, name)(x, **params), img, w)
    ad = float((g.astype(np.float64) * v).sum())

    a = img.astype(np.float64)
    h = 1e-6

    def loss(z):
        return float((getattr(ref, name)(z, **params) * w).sum())
    fd = (loss(a + h * v) - loss(a - h * v)) / (2 * h)
    scale = float(np.abs(g * v).sum()) + 1e-12
    assert abs(ad - fd) <= 1e-4 * scale, f"{name}{params}: AD {ad:.6g} vs FD {fd:.6g}"


@pytest.mark.parametrize("params", [{}, {"levels": (3, 5, 200), "amount": 0.4, "multipass": 3}])
def test_color_mapping_gradient_is_straight_through(params):
    img = hdr_image(seed=7)
    w = np.random.default_rng(8).standard_normal(img.shape).astype(np.float32)
    g = _vjp(lambda x: post.color_mapping(x, **params), img, w)
    np.testing.assert_allclose(g, w, rtol=1e-6, atol=1e-7)


def test_gradient_flows_through_rgba_and_chain():
    img = hdr_image(seed=9, channels=4)
    w = np.random.default_rng(10).standard_normal(img.shape).astype(np.float32)
    chain = [{"type": "lighten", "strength": 1.0}, {"type": "contrast", "contrast": 2.0}]
    g = _vjp(lambda x: post.apply(x, chain), img, w)
    np.testing.assert_allclose(g[..., :3], w[..., :3] * 4.0, rtol=1e-6)   # d/dc 2·(2c-.5)+.5
    np.testing.assert_array_equal(g[..., 3], w[..., 3])                  # alpha: identity


def _tiny_scene():
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "prb", "max_depth": 3},
        "sensor": {
            "type": "perspective", "fov": 40,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0],
                                                       up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": 16, "height": 12, "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": 4},
        },
        "plane": {"type": "rectangle",
                  "bsdf": {"type": "diffuse",
                           "reflectance": {"type": "rgb", "value": [0.6, 0.4, 0.3]}}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.5}},
    })


def test_render_chain_loss_backpropagates():
    """render (prb) → post chain → loss: the reflectance gradient matches central differences."""
    scene = _tiny_scene()
    params = mi.traverse(scene)
    key = "plane.bsdf.reflectance.value"
    chain = post.load_chain([
        {"type": "contrast", "contrast": 1.3},
        {"type": "bloomV2", "params": {"amount": 0.5, "BloomSpread": 1.5}, "clamp": False},
        {"type": "sharpen", "amount": 0.5},
        {"type": "CRT", "Radius": 4, "clamp": False, "amount": 0.5},
        {"type": "srgb"},
    ])

    def loss_of(image):
        return dr.mean(dr.square(image.array - 0.5), axis=None)

    value = mi.Color3f(params[key])
    dr.enable_grad(params[key])
    params.update()
    loss = loss_of(chain(mi.render(scene, params, spp=4, seed=1)))
    dr.backward(loss)
    grad = dr.grad(params[key])
    g = np.array([grad[i][0] for i in range(3)])
    assert np.all(np.isfinite(g)) and np.all(g != 0)

    h = 1e-2
    fd = []
    for i in range(3):
        vals = []
        for sgn in (1, -1):
            v = mi.Color3f(value)
            v[i] = v[i] + sgn * h
            params[key] = v
            params.update()
            vals.append(loss_of(chain(mi.render(scene, params, spp=4, seed=1))).item())
        fd.append((vals[0] - vals[1]) / (2 * h))
    np.testing.assert_allclose(g, fd, rtol=2e-2)


@pytest.mark.parametrize("scale", [1e19, 1e30, 1e36])
def test_edge_gradients_of_bright_images_are_those_of_dim_ones(scale):
    """edge_detection is homogeneous of degree 1 (the image plus Sobel magnitudes), so its
    gradient does not depend on the image's scale. Through the magnitude's 1/m^2 it did: past
    1e30 the edge term's share underflowed and the gradient was the identity's."""
    img = hdr_image(seed=9, shape=(5, 6), lo=0.05, hi=1.0)
    w = np.random.default_rng(10).standard_normal(img.shape).astype(np.float32)
    g1 = _vjp(post.edge_detection, img, w)
    gs = _vjp(post.edge_detection, (img.astype(np.float64) * scale).astype(np.float32), w)
    assert np.abs(g1 - w).max() > 0.1                        # the edges do contribute
    np.testing.assert_allclose(gs, g1, rtol=1e-4, atol=1e-5)
