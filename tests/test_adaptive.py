"""Adaptive subsampling: coverage, exact bilinear fill, refinement at edges, tiny images."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
from draaw_mi.adaptive import _grid, render_adaptive


def _plane_scene(res=(40, 33)):
    """A diffuse plane filling the view under a constant sky: every corner agrees."""
    return draaw_mi.load_scene({
        "render": {"resolution": list(res), "max_depth": 2},
        "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "fov": 30},
        "materials": {"m": {"base_color": [0.5, 0.4, 0.3], "specular": 0.0, "roughness": 1.0}},
        "shapes": [{"type": "rectangle", "material": "m", "scale": 10}],
        "lights": [{"type": "constant", "intensity": 1.0}],
    })


def test_uniform_region_is_interpolated_exactly():
    scene = _plane_scene()
    img, stats = render_adaptive(scene, block=8, spp=4, version="path", seed=3)
    img = np.array(img)
    w, h = scene.resolution
    gx, gy = _grid(w, 8), _grid(h, 8)
    assert stats["traced"] == len(gx) * len(gy)            # only the level-0 corners are traced
    corners = img[np.ix_(gy, gx)]
    # rebuild the bilinear interpolation independently with numpy
    ref = np.zeros_like(img)
    for j in range(len(gy) - 1):
        for i in range(len(gx) - 1):
            x0, x1, y0, y1 = gx[i], gx[i + 1], gy[j], gy[j + 1]
            fx = (np.arange(x0, x1 + 1) - x0) / (x1 - x0)
            fy = (np.arange(y0, y1 + 1) - y0) / (y1 - y0)
            c = corners[j:j + 2, i:i + 2]
            top = c[0, 0] * (1 - fx[:, None]) + c[0, 1] * fx[:, None]
            bot = c[1, 0] * (1 - fx[:, None]) + c[1, 1] * fx[:, None]
            ref[y0:y1 + 1, x0:x1 + 1] = top[None] * (1 - fy[:, None, None]) + bot[None] * fy[:, None, None]
    assert np.allclose(img, ref, atol=1e-6)
    # and it agrees with the real render up to noise (a flat, evenly lit plane)
    full = np.array(draaw_mi.render(scene, version="path", spp=64))
    assert abs(img.mean() - full.mean()) < 0.02 * full.mean()


def test_edges_and_shadows_are_refined_to_pixels(tiny_scene):
    img, stats = render_adaptive(tiny_scene, block=8, spp=1, version="path")
    assert 0.05 < stats["traced_fraction"] < 1.0 and stats["levels"] == 4
    assert np.isfinite(np.array(img)).all()
    # every pixel is covered: the sphere scene is lit everywhere by the sky
    assert (np.array(img).sum(axis=2) > 0).mean() > 0.95


@pytest.mark.parametrize("res", [(1, 1), (2, 2), (3, 5), (17, 9)])
def test_tiny_and_odd_images(res):
    scene = _plane_scene(res)
    img, stats = render_adaptive(scene, block=4, spp=1, version="path")
    assert np.array(img).shape == (res[1], res[0], 3)
    assert np.isfinite(np.array(img)).all() and (np.array(img) > 0).all()


def test_render_option_and_errors(tiny_scene):
    img, info = draaw_mi.render(tiny_scene, version="path", spp=1, adaptive=4, return_info=True)
    assert np.array(img).shape == (24, 32, 3) and info["adaptive"]["traced_fraction"] < 1.0
    with pytest.raises(draaw_mi.DraawError, match="power of two"):
        draaw_mi.render(tiny_scene, adaptive=6)
    with pytest.raises(draaw_mi.DraawError, match="not differentiable"):
        draaw_mi.render(tiny_scene, adaptive=8, params=tiny_scene.params)
