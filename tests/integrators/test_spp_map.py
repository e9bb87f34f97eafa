"""One wavefront with a per-pixel sample count (draaw_mi/integrators/spp_map.py): counts set
each pixel's variance and keep its expectation, bad maps are refused, every sample finds its
pixel, and other path-replay integrators render maps too."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi  # noqa: F401
import mitsuba as mi

from draaw_mi.bench import reference_scenes as rs
from draaw_mi.integrators.spp_map import pixel_of_samples, render_spp_map


def _scene(res=8, spp=4):
    return mi.load_dict(rs.feature_scene(res=res, spp=spp, constant=True))


def test_spp_map_counts_set_the_variance():
    """Pixels with 16 samples have ~1/16 the variance of the same pixels with 1 sample (two
    maps with the halves swapped, so each pixel is compared with itself)."""
    scene = _scene(8)
    sensor = scene.sensors()[0]
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    counts = np.ones((8, 8), np.int64)
    counts[:, 4:] = 16
    n = 80                              # 8x8 renders: cheap; 40 left the z-test fragile
    stack = np.stack([render_spp_map(integ, scene, sensor, counts, seed=s) for s in range(n)])
    swapped = np.stack([render_spp_map(integ, scene, sensor, 17 - counts, seed=500 + s)
                        for s in range(n)])
    var = stack.var(0, ddof=1).sum(-1)
    var_sw = swapped.var(0, ddof=1).sum(-1)
    # left half: 1 sample in `stack`, 16 in `swapped`; right half the other way round
    left = var[:, :4].mean() / var_sw[:, :4].mean()
    right = var_sw[:, 4:].mean() / var[:, 4:].mean()
    # expected 16; the band is wide because the pixels' sample variances are heavy-tailed: over
    # six seed offsets the left ratio was 9.1-22.8 with a bootstrap SE of 1.2-6.7 (a +-20 % band
    # from a Gaussian SE fails there)
    assert 8.0 < left < 32.0 and 8.0 < right < 32.0, (left, right)
    # same expectation on both sides' pixels as a uniform 16-spp map (z-test of the means)
    uni = np.stack([render_spp_map(integ, scene, sensor, np.full((8, 8), 4), seed=100 + s)
                    for s in range(n)])
    se = np.sqrt(stack.var(0, ddof=1) / n + uni.var(0, ddof=1) / n)
    m = se > 1e-6
    z = (stack.mean(0) - uni.mean(0))[m] / se[m]
    assert np.mean(np.abs(z) > 3) < 0.03 and abs(z.mean()) < 0.3


@pytest.mark.parametrize("spp_map, what", [(np.ones((8, 6), int), r"shape \(8, 6\)"), (np.ones(48), r"shape \(48,\)"),
                                           (np.full((6, 8), 2.9), "values from 2.9 to 2.9"),
                                           (np.full((6, 8), -1), "values from -1 to -1"),
                                           (np.full((6, 8), np.nan), "values from nan"),
                                           (np.full((6, 8), np.inf), "values from inf")])
def test_a_spp_map_of_another_shape_or_of_fractions_is_refused(spp_map, what):
    """A transposed (W, H) or flat map was taken in the wrong pixel order, 2.9 as 2 samples;
    the error named no value."""
    d = rs.feature_scene(res=8, spp=4, constant=True)
    d["sensor"]["film"].update(width=8, height=6)
    scene = mi.load_dict(d)
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    with pytest.raises(ValueError, match=rf"render_spp_map: spp_map has {what}.*; expected \(6, 8\) whole counts"):
        render_spp_map(integ, scene, scene.sensors()[0], spp_map, 0)


def test_the_per_pixel_variance_is_unbiased():
    """render_spp_map's variance (the adaptive allocation's input, public) is the unbiased
    sample variance: at 2 samples per pixel its mean over seeds is the variance of 1-spp
    pixels over seeds (without the n/(n - 1) factor: half of it)."""
    scene = _scene(8)
    sensor = scene.sensors()[0]
    integ = mi.load_dict({"type": "draaw_v4", "max_depth": 3, "stratify": False})
    est = np.mean([render_spp_map(integ, scene, sensor, np.full((8, 8), 2), seed=s, moments=True)[1]
                   for s in range(150)], axis=0)
    pop = np.stack([render_spp_map(integ, scene, sensor, np.ones((8, 8), np.int64), seed=1000 + s)
                    for s in range(300)]).var(0, ddof=1)
    ratio = est.sum() / pop.sum()
    assert 0.8 < ratio < 1.25, ratio                    # (0.96 measured; 0.48 without it)


def test_every_sample_finds_its_pixel(monkeypatch):
    """``pixel_of_samples`` against ``np.repeat`` on 200 random count maps, through the block
    table (smallest count at least a third of the mean) and the full binary search (the
    rest). A table whose block is four times the smallest count (a sample four pixels past
    its block's, beyond two bisection steps) or a bisection that stops after one step
    misplaces samples here."""
    import drjit as dr
    rng = np.random.default_rng(0)
    searched = []
    search = dr.binary_search
    monkeypatch.setattr(dr, "binary_search", lambda *a: searched.append(1) or search(*a))
    tables = 0
    for _ in range(200):
        n, lo = int(rng.integers(1, 300)), int(rng.integers(1, 40))
        counts = rng.integers(lo, lo * int(rng.integers(1, 12)) + 1, n).astype(np.uint32)
        before = len(searched)
        pixel, starts = pixel_of_samples(dr.arange(mi.UInt32, int(counts.sum())), counts)
        tables += len(searched) == before
        assert (np.array(pixel) == np.repeat(np.arange(n), counts)).all(), counts
        assert (np.array(starts) == np.concatenate([[0], np.cumsum(counts)])).all()
    assert 20 < tables < 180, tables          # both ways taken


def test_spp_maps_render_with_other_path_replay_integrators():
    """``render_spp_map`` asks ``draaw_v4`` for path lengths and first-vertex light only where
    the integrator has them: Mitsuba's ``prb`` renders a map and its moments (lengths 1).
    Asking every integrator for first-vertex light (as when the flag was shadowed by the
    pixel-start helper of the same name, so every pass asked) fails here: ``prb`` has no
    ``last_first``."""
    scene = mi.load_dict(rs.cornell_draaw(res=8, spp=4))
    integ = mi.load_dict({"type": "prb", "max_depth": 3})
    counts = np.full((8, 8), 4)
    img = render_spp_map(integ, scene, scene.sensors()[0], counts, seed=1)
    mean, var, alpha, lengths = render_spp_map(integ, scene, scene.sensors()[0], counts, seed=1, moments=True)
    assert img.shape == (8, 8, 3) and np.isfinite(img).all() and img.mean() > 0
    assert np.isfinite(var).all() and (lengths == 1).all()
