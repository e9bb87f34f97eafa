"""The texture-map latent of fit() (draaw_mi.fitting.maps) and the map outputs
(draaw_mi.fitting.map_outputs), against closed forms and finite differences; no renders."""
from __future__ import annotations

import numpy as np
import pytest

from draaw_mi.errors import ParameterError
from draaw_mi.fitting.map_outputs import map_errors, plot_maps, save_maps
from draaw_mi.fitting.maps import (
    LR_SCALES,
    TV_WEIGHTS,
    MapLatent,
    MapOptions,
    MapSet,
    fill_unobserved,
    pyramid_sizes,
    upsample_matrix,
)


def test_upsampling_reproduces_a_linear_ramp_between_the_edge_texels():
    """Bilinear on texel centres: a ramp sampled at the coarse centres upsamples to the ramp at
    the fine centres (the clamped half-texel at each edge aside). Catches an off-by-half-texel
    (align-corners) matrix, which shifts the ramp by a quarter of a coarse texel."""
    n_in, n_out = 8, 32
    a = upsample_matrix(n_out, n_in)
    coarse = (np.arange(n_in) + 0.5) / n_in
    fine = (np.arange(n_out) + 0.5) / n_out
    inner = (fine > coarse[0]) & (fine < coarse[-1])
    np.testing.assert_allclose((a @ coarse)[inner], fine[inner], atol=1e-12)
    np.testing.assert_allclose(a.sum(axis=1), 1.0)                 # a partition of unity


def test_latent_gradients_match_finite_differences():
    """The chain rule through the sigmoid, the pyramid's upsampling (its transpose) and the TV
    prior: each level's analytic gradient against central differences of
    ``loss(value(levels)) + prior``. Catches a missing sigmoid derivative, an untransposed
    upsampling, a TV gradient of the wrong sign."""
    rng = np.random.default_rng(3)
    start = rng.uniform(0.2, 0.8, (8, 12, 2))
    target = rng.uniform(0.0, 1.0, (8, 12, 2))
    m = MapLatent(start, 0.1, 0.9, tv=0.3)
    for lv in m.levels:
        lv += rng.normal(0, 0.3, lv.shape)

    def objective():
        v = m.value(np.float64)
        return 0.5 * np.sum((v - target) ** 2) + m.prior(v)[0]

    v = m.value(np.float64)
    grads = m.gradients(v - target)
    assert len(grads) == 2 and grads[0].shape == (4, 6, 2)
    h = 1e-6
    for level, g in enumerate(grads):
        for idx in [(0, 0, 0), (1, 2, 1), (g.shape[0] - 1, g.shape[1] - 1, 0)]:
            keep = m.levels[level][idx]
            m.levels[level][idx] = keep + h
            up = objective()
            m.levels[level][idx] = keep - h
            down = objective()
            m.levels[level][idx] = keep
            assert g[idx] == pytest.approx((up - down) / (2 * h), rel=1e-6, abs=1e-10), (level, idx)


def test_a_map_converges_to_its_target_in_range_and_stays_there():
    """Adam on the pyramid drives ``0.5 |T - target|^2`` to zero, the texels in range all the
    way, including targets at the range's ends (0 and 1: the sigmoid reaches within 1e-4)."""
    rng = np.random.default_rng(0)
    target = rng.uniform(0.0, 1.0, (16, 16, 3))
    target[:4] = 0.0
    target[-4:] = 1.0
    m = MapLatent(np.full((16, 16, 3), 0.5), 0.0, 1.0)
    for _ in range(400):
        m.step(m.value() - target, 0.1)
        v = m.value()
        assert v.min() >= 0.0 and v.max() <= 1.0
    assert np.abs(m.value() - target).mean() < 0.01


@pytest.mark.parametrize("start", [0.0, 1.0])
def test_a_map_that_starts_at_a_bound_leaves_it_when_the_gradient_points_inside(start):
    """Metallic's default is 0, a bound: its latent starts clamped at -LOGIT_MAX. A clamped
    latent passed no gradient at all, so a map started at 0 (or driven to a bound on the way)
    never left it (a fit from metallic 0 ended with every metal patch at 0). A gradient that
    points outside moves nothing, not even the latent beyond the clamp: had it grown there, the
    first inward steps would only walk it back (passing every gradient: no texel moved by 1e-3
    in 30 inward steps; 0.04 in 20 with the rule)."""
    m = MapLatent(np.full((16, 16, 1), start), 0.0, 1.0)
    target = np.full((16, 16, 1), 0.6)
    outside = np.full((16, 16, 1), -1.0 if start == 1.0 else 1.0)    # descent pushes beyond the bound
    levels = [lv.copy() for lv in m.levels]
    for _ in range(20):
        m.step(outside, 0.1)
    assert np.abs(m.value() - start).max() < 2e-4
    assert all(np.array_equal(a, b) for a, b in zip(levels, m.levels))   # not even the latent
    for _ in range(20):
        m.step(m.value() - target, 0.1)
    assert np.abs(m.value() - start).min() > 0.01                   # it answers at once
    for _ in range(380):
        m.step(m.value() - target, 0.1)
    assert np.abs(m.value() - target).mean() < 0.01


@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan, 1e30, -1e30])
def test_a_map_stays_finite_and_in_range_under_wild_gradients(bad):
    """What a black or saturated photo, or a firefly, can feed the map: infinite, NaN or huge
    gradients. The texels stay finite and inside [lo, hi]; a NaN/Inf entry counts as 0."""
    m = MapLatent(np.full((8, 8, 1), 0.3), 0.0, 1.0)
    g = np.zeros((8, 8, 1))
    g[2:5, 2:5] = bad
    for _ in range(50):
        m.step(g, 0.5)
    v = m.value()
    assert np.all(np.isfinite(v)) and v.min() >= 0.0 and v.max() <= 1.0
    if not np.isfinite(bad):
        np.testing.assert_allclose(v, 0.3, atol=1e-6)      # NaN/Inf: no step at all
        assert not m.seen.any()


def test_seen_texels_are_those_a_gradient_reached():
    m = MapLatent(np.full((4, 4, 3), 0.5), 0.0, 1.0)
    g = np.zeros((4, 4, 3))
    g[1, 2, 0] = 1e-9
    m.step(g, 0.01)
    assert m.seen.sum() == 1 and m.seen[1, 2]


def test_fill_continues_a_smooth_map_into_unseen_texels():
    """Pull-push fill of a linear ramp with a hole keeps the ramp's values near the hole (within
    the ramp's change over the hole), and leaves the seen texels as they were."""
    y, x = np.mgrid[0:16, 0:16]
    ramp = (0.02 * x + 0.01 * y)[..., None]
    seen = np.ones((16, 16), bool)
    seen[6:10, 6:10] = False
    out = fill_unobserved(np.where(seen[..., None], ramp, 7.0), seen)
    np.testing.assert_array_equal(out[seen], ramp[seen])
    assert np.abs(out[~seen] - ramp[~seen]).max() < 0.12          # the ramp rises 0.12 over the hole
    assert np.abs(out[~seen] - 7.0).min() > 6                    # nothing of the start is left


def test_pyramid_sizes_and_options_are_checked():
    assert pyramid_sizes(128, 64)[0] == (8, 4) and pyramid_sizes(128, 64)[-1] == (128, 64)
    assert MapOptions.parse(None).parametrisation == "pyramid"
    assert MapOptions.parse("texels").parametrisation == "texels"
    with pytest.raises(ParameterError, match="parametrisation='wavelets'"):
        MapOptions.parse({"parametrisation": "wavelets"})
    with pytest.raises(ParameterError, match="tv=-1"):
        MapOptions.parse({"tv": -1})
    with pytest.raises(ParameterError, match="key\\(s\\) smooth"):
        MapOptions.parse({"smooth": 1})
    for bad in ({"metallic": 0.0}, {"metallic": float("inf")}, {"metallic": True}, {3: 1.0}, [("metallic", 2.0)]):
        with pytest.raises(ParameterError, match="lr_scale"):
            MapOptions.parse({"lr_scale": bad})
    with pytest.raises(ParameterError, match="with parametrisation='texels'; expected it with 'pyramid' only"):
        MapOptions.parse({"parametrisation": "texels", "lr_scale": {"metallic": 2.0}})
    for bad in ({"roughness": -1.0}, {"roughness": float("nan")}, {"roughness": "0.1"}, {"roughness": True},
                "0.1", [0.1], True, np.bool_(True), -0.5):
        with pytest.raises(ParameterError, match="maps tv"):
            MapOptions.parse({"tv": bad})
    assert MapOptions.parse({"tv": np.float32(0.01)}).tv_for("obj.metallic.data") == pytest.approx(0.01)
    for bad in ({"roughness": 0.1}, 0.1):
        with pytest.raises(ParameterError, match="with parametrisation='texels'; expected it with 'pyramid' only"):
            MapOptions.parse({"parametrisation": "texels", "tv": bad})
    for bad in ("x", [1.0], {"metallic": 2.0}):
        with pytest.raises(ParameterError, match="lr_scale=.* with parametrisation='texels'"):
            MapOptions.parse({"parametrisation": "texels", "lr_scale": bad})
    for none in (0.0, {"roughness": 0.0}, None):       # no prior asked for: nothing to refuse
        assert MapOptions.parse({"parametrisation": "texels", "tv": none}).tv_for("obj.roughness.data") == 0.0
    starts = {"obj.metallic.data": (np.full((4, 4, 1), 0.5), 0.0, 1.0)}
    with pytest.raises(ParameterError, match="lr_scale names 'metalic', which no fitted map has; expected one of "
                                             "metallic, obj.metallic, obj.metallic.data"):
        MapSet(starts, MapOptions.parse({"lr_scale": {"metalic": 1.0}}))
    with pytest.raises(ParameterError, match="tv names 'roughness', which no fitted map has"):
        MapSet(starts, MapOptions.parse({"tv": {"roughness": 0.01}}))


def test_the_smoothness_prior_is_on_for_roughness_maps_only_unless_the_user_says():
    """Each map's TV weight: by default :data:`TV_WEIGHTS` (roughness), a number for every map,
    a dict over the defaults (most specific name first, 0 turns one off). And the prior acts
    through ``MapSet.step``: with no image gradient, one step smooths a noisy roughness map (its
    TV energy falls) and leaves the colour where it was. Catches ``MapSet`` handing every map
    the option as given (``None``: no prior anywhere), ``tv_for`` ignoring :data:`TV_WEIGHTS` or
    a dict's entries, and a step that drops the prior's gradient."""
    rng = np.random.default_rng(0)
    starts = {"obj.base_color.data": rng.uniform(0.3, 0.7, (8, 8, 3)),
              "obj.roughness.data": rng.uniform(0.3, 0.7, (8, 8, 1)),
              "obj.metallic.data": np.full((8, 8, 1), 0.5)}

    def weights(maps):
        ms = MapSet({k: (v, 0.0, 1.0) for k, v in starts.items()}, MapOptions.parse(maps))
        return {k.split(".")[1]: ms.latents[k].tv for k in starts}, ms

    w, ms = weights(None)
    assert w == {"base_color": 0.0, "roughness": TV_WEIGHTS["roughness"], "metallic": 0.0} and w["roughness"] > 0
    assert weights({"tv": 0.0})[0] == {"base_color": 0.0, "roughness": 0.0, "metallic": 0.0}
    assert weights({"tv": 0.01})[0] == {"base_color": 0.01, "roughness": 0.01, "metallic": 0.01}
    assert weights({"tv": {"metallic": 0.02}})[0] == {"base_color": 0.0, "roughness": TV_WEIGHTS["roughness"],
                                                     "metallic": 0.02}
    assert weights({"tv": {"obj.roughness": 0.0, "roughness": 0.5}})[0]["roughness"] == 0.0
    rough, colour = ms.latents["obj.roughness.data"], ms.latents["obj.base_color.data"]
    before, colour_before = rough.prior()[0], colour.value()
    ms.step(0.05)                                  # the gradients are zero: the prior alone
    assert rough.prior()[0] < 0.9 * before, (rough.prior()[0], before)
    assert np.array_equal(colour.value(), colour_before)


def test_each_map_steps_at_its_own_scale_of_the_learning_rate():
    """Adam's first step moves every latent by ``lr`` times its scale, whatever the gradient's
    size: with one gradient for all three maps, metallic's latents move ``LR_SCALES`` times as
    far as the colour's, roughness's as far as the colour's, and a user's ``lr_scale`` replaces
    the default. Catches ``MapSet.step`` dropping the scale (every map at the common rate) or
    ``scale_for`` not matching the ``.data`` keys (metallic at 1)."""
    starts = {"obj.base_color.data": np.full((8, 8, 3), 0.5), "obj.roughness.data": np.full((8, 8, 1), 0.5),
              "obj.metallic.data": np.full((8, 8, 1), 0.5)}

    def moved(options):
        ms = MapSet({k: (v, 0.0, 1.0) for k, v in starts.items()}, options)
        for k, v in starts.items():
            ms.grads[k][:] = 1e-3                        # the same gradient on every texel
        ms.step(0.01)
        return {k.split(".")[1]: float(np.abs(ms.latents[k].latent()).mean()) for k in starts}

    d = moved(MapOptions())
    assert d["base_color"] > 0 and np.isclose(d["roughness"], d["base_color"], rtol=1e-6)
    assert np.isclose(d["metallic"], LR_SCALES["metallic"] * d["base_color"], rtol=1e-6), d
    own = moved(MapOptions.parse({"lr_scale": {"metallic": 1.0, "obj.roughness": 3.0}}))
    assert np.isclose(own["metallic"], own["base_color"], rtol=1e-6), own
    assert np.isclose(own["roughness"], 3.0 * own["base_color"], rtol=1e-6), own
    # the most specific name wins: the scene key over the fit name over the parameter
    o = MapOptions.parse({"lr_scale": {"metallic": 2.0, "obj.metallic": 3.0, "obj.roughness.data": 4.0,
                                       "roughness": 0.5}})
    assert (o.scale_for("obj.metallic.data"), o.scale_for("obj.roughness.data")) == (3.0, 4.0)


def test_maps_are_saved_as_exr_and_8_and_16_bit_pngs(tmp_path):
    """EXR keeps the values (float32); the PNGs hold a colour map sRGB-encoded and a data map as
    it is, at 8 and 16 bits (the 16-bit file's IHDR says 16 and its values round-trip to 1/65535)."""
    import draaw_mi
    from draaw_mi.io import srgb_encode
    colour = np.random.default_rng(1).uniform(0, 1, (6, 5, 3)).astype(np.float32)
    rough = np.linspace(0, 1, 30, dtype=np.float32).reshape(6, 5, 1)
    files = save_maps({"m.base_color": colour, "m.roughness": rough, "m.scale": 0.5}, str(tmp_path))
    names = sorted(p.replace(str(tmp_path) + "/", "") for p in files)
    assert names == ["m.base_color.16bit.png", "m.base_color.exr", "m.base_color.png",
                     "m.roughness.16bit.png", "m.roughness.exr", "m.roughness.png"]
    np.testing.assert_array_equal(draaw_mi.read_exr(str(tmp_path / "m.roughness.exr"))[..., :1], rough)
    import matplotlib.image
    png16 = tmp_path / "m.roughness.16bit.png"
    assert open(png16, "rb").read()[24] == 16                        # IHDR bit depth
    np.testing.assert_allclose(matplotlib.image.imread(str(png16)), rough[..., 0], atol=1 / 65535)
    png8 = matplotlib.image.imread(str(tmp_path / "m.base_color.png"))[..., :3]
    np.testing.assert_allclose(png8, srgb_encode(colour), atol=1 / 255 + 1e-6)


def test_map_errors_count_observed_texels_only():
    truth = {"m.metallic": np.zeros((2, 2, 1))}
    fitted = {"m.metallic": np.array([[[0.1], [0.1]], [[1.0], [1.0]]])}
    seen = {"m.metallic": np.array([[True, True], [False, False]])}
    assert map_errors(fitted, truth, seen)["m.metallic"]["mae"] == pytest.approx(0.1)
    assert map_errors(fitted, truth)["m.metallic"]["mae"] == pytest.approx(0.55)
    with pytest.raises(ParameterError, match="'m.roughness', which was not fitted"):
        map_errors(fitted, {"m.roughness": np.zeros((2, 2, 1))})


def test_plot_maps_shows_fit_truth_error_and_loss(tmp_path):
    v = {"m.base_color": np.full((4, 4, 3), 0.4, np.float32), "m.roughness": np.full((4, 4, 1), 0.2, np.float32)}
    fig = plot_maps(v, truth=v, losses=[1.0, 0.5, 0.25], path=str(tmp_path / "maps.png"))
    assert len(fig.axes) == 3 * 3 + 2                 # 3 rows of 3 (maps, maps, loss) + 2 colour bars
    assert [a.get_title() for a in fig.axes[:3]] == ["m.base_color: fitted", "truth", "|error| (unobserved: blank)"]
    assert (tmp_path / "maps.png").stat().st_size > 0
    with pytest.raises(ParameterError, match="no texture maps"):
        plot_maps({"m.roughness": 0.3})


@pytest.mark.parametrize("truth", [np.zeros((8, 8, 3)), np.zeros((4, 4, 1)), np.zeros((2, 2))])
def test_a_truth_of_another_shape_is_named_with_both_shapes(truth, tmp_path):
    """A bare numpy reshape error ("cannot reshape array of size 192 into shape (2,2,3)")."""
    values = {"m.base_color": np.zeros((2, 2, 3))}
    shape = str(tuple(truth.shape)).replace("(", r"\(").replace(")", r"\)")
    with pytest.raises(ParameterError, match=rf"map_errors: the truth of m\.base_color has shape {shape}; "
                                             r"the fitted map has \(2, 2, 3\)"):
        map_errors(values, {"m.base_color": truth})
    with pytest.raises(ParameterError, match=rf"plot_maps: the truth of m\.base_color has shape {shape}"):
        plot_maps(values, {"m.base_color": truth}, path=str(tmp_path / "p.png"))


def test_a_grey_truth_may_leave_out_its_channel():
    fit = np.array([[0.5, 0.5], [0.25, 1.0]]).reshape(2, 2, 1)
    truth = np.array([[0.0, 0.5], [0.25, 0.5]])                # texel by texel: 0.5, 0, 0, 0.5
    errs = map_errors({"m.roughness": fit}, {"m.roughness": truth})
    assert errs["m.roughness"]["mae"] == pytest.approx(0.25)
    assert errs["m.roughness"]["psnr"] == pytest.approx(-10 * np.log10(0.125))   # mse 0.5 / 4
