"""Adaptive subsampling: coverage, exact bilinear fill, refinement at edges, tiny images."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.rendering.subsample import _grid, render_adaptive


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


def _pixel_centre_maps(scene):
    """Independent per-pixel maps at pixel centres: what is seen (0 sky, 1 floor, 2 sphere,
    told apart by the normal) and whether the point light at (2, 4, 3) is visible."""
    mis, (w, h) = scene.mi_scene, scene.resolution
    yy, xx = np.mgrid[0:h, 0:w]
    pos = mi.Point2f(mi.Float(((xx.ravel() + 0.5) / w).astype(np.float32)),
                     mi.Float(((yy.ravel() + 0.5) / h).astype(np.float32)))
    ray, _ = mis.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))
    si = mis.ray_intersect(ray)
    hit = np.array(si.is_valid()).reshape(h, w)
    floor = np.abs(np.array(si.n.y).reshape(h, w) - 1.0) < 1e-4
    seen = np.where(~hit, 0, np.where(floor, 1, 2))
    light = mi.Point3f(2.0, 4.0, 3.0)
    lit = ~np.array(mis.ray_test(si.spawn_ray_to(light), si.is_valid())).reshape(h, w) & hit
    return seen, lit


def _pair_coverage(labels, traced):
    """Fraction of horizontally/vertically adjacent pixel pairs with different labels of which
    at least one pixel was traced."""
    dx, dy = labels[:, 1:] != labels[:, :-1], labels[1:] != labels[:-1]
    cov = np.concatenate([(traced[:, 1:] | traced[:, :-1])[dx], (traced[1:] | traced[:-1])[dy]])
    return cov.mean(), cov.size


def test_edges_and_shadows_are_refined_to_pixels(tiny_scene, monkeypatch):
    from draaw_mi.rendering import subsample as adaptive
    real, calls = adaptive._sample_points, []

    def spy(scene, integrator, xs, ys, spp, seed):      # the pixels that are really traced
        calls.append((xs.copy(), ys.copy()))
        return real(scene, integrator, xs, ys, spp, seed)
    monkeypatch.setattr(adaptive, "_sample_points", spy)
    img, stats = render_adaptive(tiny_scene, block=8, spp=1, version="path")
    assert len(calls) == 1 and stats["levels"] == 4
    w, h = tiny_scene.resolution
    traced = np.zeros((h, w), bool)
    traced[calls[0][1], calls[0][0]] = True
    assert stats["traced"] == traced.sum() and 0.05 < stats["traced_fraction"] < 0.8
    seen, lit = _pixel_centre_maps(tiny_scene)
    # every silhouette (sky/floor/sphere boundary) is traced on at least one side
    cov, n = _pair_coverage(seen, traced)
    assert n > 40 and cov == 1.0, (cov, n)
    # shadow edges on the floor (the sphere's cast shadow): nearly all refined (a shadow edge
    # can cut a block's side between two agreeing corners; measured 0.92 / 0.96 per axis)
    cov, n = _pair_coverage(np.where(seen == 1, lit, -1), traced)
    assert n > 40 and cov >= 0.9, (cov, n)
    # and the sky far from any edge is interpolated, not traced
    assert traced[:2, :8].mean() < 0.2
    assert np.isfinite(np.array(img)).all() and (np.array(img).sum(axis=2) > 0).mean() > 0.95


@pytest.mark.parametrize("sampler", ["independent", "multijitter"])
def test_traced_pixels_have_the_expectation_of_a_full_render(sampler, monkeypatch):
    """The pixels that are traced (silhouettes and shadow edges, mostly) are the image's own
    pixels: over independent seeds their values have the expectation of Mitsuba's ``path``
    render of the whole image at the same pixels (box filter; per-pixel z-test with the
    suite's bounds). A sample position off by one pixel puts the edge pixels at |z| >> 3.
    With a stratifying scene sampler (multijitter), the traced pixels' samples are still
    uniform: its clone gave every lane sample 0 of one pattern (a skewed jitter)."""
    from conftest import tiny_description
    tiny_scene = draaw_mi.load_scene(tiny_description(sampler=sampler))
    from integrators_helpers import check_same_expectation

    from draaw_mi.rendering import subsample as adaptive
    real, calls = adaptive._sample_points, []
    monkeypatch.setattr(adaptive, "_sample_points",
                        lambda scene, integ, xs, ys, spp, seed: (calls.append((xs.copy(), ys.copy())),
                                                                 real(scene, integ, xs, ys, spp, seed))[1])
    seeds = range(10)
    stack = np.stack([np.array(render_adaptive(tiny_scene, block=8, spp=16, seed=s, version="path")[0])
                      for s in seeds])
    xs, ys = calls[0]
    assert all(np.array_equal(c[0], xs) and np.array_equal(c[1], ys) for c in calls)  # same pixels
    full = np.stack([np.array(draaw_mi.render(tiny_scene, version="path", spp=16, seed=100 + s, post=[]))
                     for s in seeds])
    assert len(xs) > 100
    check_same_expectation(stack[:, ys, xs][:, :, None], full[:, ys, xs][:, :, None])


@pytest.mark.parametrize("res", [(1, 1), (2, 2), (3, 5), (17, 9)])
def test_tiny_and_odd_images(res):
    scene = _plane_scene(res)
    img, stats = render_adaptive(scene, block=4, spp=1, version="path")
    assert np.array(img).shape == (res[1], res[0], 3)
    assert np.isfinite(np.array(img)).all() and (np.array(img) > 0).all()


def test_render_option_and_errors(tiny_scene):
    img, info = draaw_mi.render(tiny_scene, version="path", spp=1, adaptive=4, return_info=True)
    assert np.array(img).shape == (24, 32, 3) and info["adaptive"]["traced_fraction"] < 1.0
    for block in (6, 1):                     # (a block of 1 pixel interpolates nothing)
        with pytest.raises(draaw_mi.DraawError, match="power of two"):
            draaw_mi.render(tiny_scene, adaptive=block)
    with pytest.raises(draaw_mi.DraawError, match="not differentiable"):
        draaw_mi.render(tiny_scene, adaptive=8, params=tiny_scene.params)


def test_render_passes_its_options_to_adaptive(tiny_scene, capsys):
    """``render(adaptive=...)`` honours hide_emitters and integrator_options like any render
    (they were dropped: the sky stayed in the picture), shows its progress bar, and refuses
    the pass options it has no passes for."""
    top = lambda img: np.array(img)[0]                       # noqa: E731 - the sky row
    shown = draaw_mi.render(tiny_scene, version="v2", spp=4, adaptive=4, hide_emitters=False)
    hidden = draaw_mi.render(tiny_scene, version="v2", spp=4, adaptive=4, hide_emitters=True)
    np.testing.assert_allclose(top(shown), 0.2, atol=1e-5)   # the constant sky's radiance
    assert np.all(top(hidden) == 0.0)
    with pytest.raises(draaw_mi.RenderError, match="no option 'bogus'"):
        draaw_mi.render(tiny_scene, version="v2", adaptive=4, integrator_options={"bogus": 1})
    for option in ({"time_budget": 1.0}, {"pass_spp": 2}):
        with pytest.raises(draaw_mi.RenderError, match="one launch"):
            draaw_mi.render(tiny_scene, version="v2", adaptive=4, **option)
    draaw_mi.render(tiny_scene, version="v2", spp=2, adaptive=4, progress="lines")
    assert "2/2" in capsys.readouterr().err


def test_a_numpy_block_size_is_a_block_size(tiny_scene):
    """render(adaptive=np.int64(8)) was refused as "expected a power of two >= 2"."""
    a = np.array(draaw_mi.render(tiny_scene, version="path", spp=4, seed=2, adaptive=np.int64(8)))
    b = np.array(draaw_mi.render(tiny_scene, version="path", spp=4, seed=2, adaptive=8))
    assert np.array_equal(a, b)


@pytest.mark.parametrize("change, match", [
    ({"type": "thinlens", "aperture_radius": 0.3, "focus_distance": 1.0}, "has an aperture"),
    ({"film": {"crop_width": 16}}, "has a crop window")])
def test_cameras_adaptive_rays_cannot_follow_are_refused(change, match):
    """Its rays start at the aperture's centre and cover the whole film: a thin lens rendered
    pinhole-sharp (RMSE 0.98 against the plain render), a crop window came back whole."""
    d = mi.cornell_box()
    film = change.pop("film", {})
    d["sensor"].update(change)
    d["sensor"]["film"].update(width=32, height=32, rfilter={"type": "box"}, **film)
    scene = draaw_mi.load_scene(d)
    with pytest.raises(draaw_mi.RenderError, match=f"adaptive subsampling .*{match}"):
        draaw_mi.render(scene, version="path", spp=4, adaptive=2)
    with pytest.raises(draaw_mi.RenderError, match=f"render_adaptive: adaptive subsampling .*{match}"):
        render_adaptive(scene, block=2, spp=4, version="path")      # (the public function too)
