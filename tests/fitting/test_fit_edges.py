"""fit() and the post chain, edge cases from a review: the fit renders what render() renders
(the scene's post chain, hidden emitters and version); references that are not linear float
images or not the view's size are refused by name; fit's numeric options are checked; the
linear tone curve and edge norms stay finite; render() checks its chain before rendering."""
from __future__ import annotations

import os

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tomllib

import draaw_mi
from draaw_mi.errors import DraawError, ParameterError

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scenes")
P = ["target.roughness"]


def _scene(**render):
    with open(os.path.join(SCENES, "fit_sphere.toml"), "rb") as f:
        desc = tomllib.load(f)
    desc["render"].update({"resolution": [16, 16]}, **render)
    return desc


def _loss_at_truth(desc, **kw):
    """The fit's first loss with the parameters at the values the reference was made with."""
    scene = draaw_mi.load_scene(desc)
    ref = np.mean([np.array(draaw_mi.render(scene, spp=16, seed=100 + i)) for i in range(4)], axis=0)
    res = draaw_mi.fit(draaw_mi.load_scene(desc), ref, P, iterations=1, spp=16, lr=1e-9, progress=False, **kw)
    return float(res.history[0]["loss"])


@pytest.mark.parametrize("extra", [{"post": [{"type": "srgb"}]}, {"render": {"hide_emitters": True}}],
                         ids=["post", "hide_emitters"])
def test_the_fit_renders_what_render_renders(extra):
    """A reference rendered from the scene file (the README's workflow) is one the fit can
    render: at the true values its loss is the noise's, not a systematic difference (the srgb
    chain: 0.48 against 0.26; hidden emitters: 0.67)."""
    desc = _scene()
    if "post" in extra:
        desc["post"] = extra["post"]
    else:
        desc["render"].update(extra["render"])
    noise = _loss_at_truth(_scene())                  # the plain scene: noise only
    assert _loss_at_truth(desc) < 1.5 * noise + 1e-4
    if "post" in extra:                               # and post=[] still turns it off
        assert _loss_at_truth(desc, post=[]) > 1.5 * noise


def test_the_fit_takes_the_scenes_version_where_it_is_differentiable():
    res = draaw_mi.fit(draaw_mi.load_scene(_scene(version="v1")), np.zeros((16, 16, 3), np.float32), P,
                       iterations=1, spp=4, progress=False)
    assert res.version == "v1"
    res = draaw_mi.fit(draaw_mi.load_scene(_scene(version="path")), np.zeros((16, 16, 3), np.float32), P,
                       iterations=1, spp=4, progress=False)
    assert res.version == "v4"                         # path is not differentiable


@pytest.mark.parametrize("was_on", [False, True])
def test_the_fit_leaves_the_kernel_history_flag_as_it_found_it(was_on):
    """fit() records kernel compiles with Dr.Jit's kernel history; it turned the flag off
    afterwards, ending a caller's own kernel-history measurement around the fit."""
    old = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, was_on)
    try:
        res = draaw_mi.fit(draaw_mi.load_scene(_scene()), np.zeros((16, 16, 3), np.float32), P,
                           iterations=1, spp=1, progress=False)
        assert "kernel_compiles" in res.history[0]
        assert dr.flag(dr.JitFlag.KernelHistory) == was_on
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, old)


def test_an_8_bit_bitmap_reference_is_refused(tmp_path):
    from draaw_mi.fitting.reference import load_reference
    png = str(tmp_path / "ref.png")
    draaw_mi.write_png(png, np.full((4, 4, 3), 0.2, np.float32))
    with pytest.raises(ParameterError, match="component format"):       # (values of 0-255, no word)
        load_reference(mi.Bitmap(png))
    as_float = mi.Bitmap(png).convert(component_format=mi.Struct.Type.Float32, srgb_gamma=False)
    np.testing.assert_allclose(load_reference(as_float), load_reference(png), atol=1e-3)


@pytest.mark.parametrize("width,height", [(32, 8), (16, 8)], ids=["both", "height-only"])
def test_a_sensor_view_of_another_size_is_refused_by_name(width, height):
    """Both sides are compared: a sensor as wide as the references but of another height was
    taken (its pixels compared scrambled, or a raw Dr.Jit size error)."""
    sensor = mi.load_dict({"type": "perspective", "film": {"type": "hdrfilm", "width": width, "height": height}})
    with pytest.raises(DraawError, match=rf"views\[0\] is a sensor of {width}x{height} pixels; "
                                         r"expected the references' 16x16"):
        draaw_mi.fit(draaw_mi.load_scene(_scene()), np.zeros((16, 16, 3), np.float32), P, views=[sensor],
                     iterations=1, spp=1, progress=False)


@pytest.mark.parametrize("kw,match", [({"lr_final": -1.0}, "lr_final"), ({"lr_final": float("nan")}, "lr_final"),
                                      ({"beta_2": 1.0}, "beta_2"), ({"tol": float("nan")}, "tol"),
                                      ({"smooth": "yes"}, "smooth")])
def test_fit_options_are_checked(kw, match):
    with pytest.raises(ParameterError, match=match):
        draaw_mi.fit(_scene(), np.zeros((16, 16, 3), np.float32), P, iterations=1, spp=1, progress=False, **kw)


def test_references_are_named_in_their_errors():
    good = np.zeros((16, 16, 3), np.float32)
    bad = good.copy()
    bad[3, 5, 1] = np.inf
    bad[7, 2, 0] = np.nan
    views = [{"origin": [0, 0.7, 3.2], "target": [0, 0.5, 0]}, {"origin": [1, 0.7, 3.0], "target": [0, 0.5, 0]}]
    with pytest.raises(DraawError, match=r"references\[1\].*2 pixel\(s\) with NaN or Inf \(first at x=5, y=3\)"):
        draaw_mi.fit(_scene(), [good, bad], P, views=views, iterations=1, spp=1, progress=False)
    with pytest.raises(ParameterError, match="references is empty"):           # (IndexError)
        draaw_mi.fit(_scene(), [], P, iterations=1, spp=1, progress=False)


@pytest.mark.parametrize("gamma", [0.25, 0.015, 0.002, 1e-4])
def test_linear_tone_curve_is_finite_for_small_gamma(gamma):
    """x' = min((255 x)^e / 255, 1), e = 1 / (3 gamma): a step for small gamma (NaN on black
    pixels below 0.0196, OverflowError below 0.0026)."""
    from draaw_mi import post
    x = np.array([[[0.0, 0.001, 0.5]], [[0.0039, 0.004, 1e-30]]], np.float32)
    out = np.array(post.apply(x, [{"type": "linear", "gamma": gamma}]))
    e = 1.0 / (3.0 * gamma)
    with np.errstate(over="ignore", under="ignore"):
        ref = np.minimum(np.exp(e * np.log(np.maximum(x.astype(np.float64), 1e-300) * 255.0)) / 255.0, 1.0)
    ref[x <= 0] = 0.0
    assert np.all(np.isfinite(out))
    # float32: Dr.Jit's log2 is good to a few 1e-6 (measured), an error the exponent e
    # multiplies (dr.power, before, was as accurate where it was finite)
    np.testing.assert_allclose(out, ref, rtol=1e-5 + 4e-6 * e, atol=1e-30)


def test_edge_norm_gradient_is_right_for_bright_edges():
    from draaw_mi.post._util import safe_norm2
    for scale in (1.0, 1e20, 1e-20):
        gx, gy = mi.Float(2.0 * scale), mi.Float(1.0 * scale)
        dr.enable_grad(gx, gy)
        n = safe_norm2(gx, gy)
        dr.backward(n)
        g = [float(dr.grad(gx)[0]), float(dr.grad(gy)[0])]                # d|g| = g / |g|
        np.testing.assert_allclose(g, [2 / 5 ** 0.5, 1 / 5 ** 0.5], rtol=1e-5, err_msg=str(scale))


@pytest.fixture
def render_calls(monkeypatch):
    """The calls of ``mi.render`` while a test runs (a list that grows by one per call)."""
    calls = []
    real = mi.render
    monkeypatch.setattr(mi, "render", lambda *a, **k: calls.append(1) or real(*a, **k))
    return calls


def test_render_checks_its_post_chain_before_rendering(render_calls):
    scene = draaw_mi.load_scene(_scene())
    with pytest.raises(ParameterError, match="blom"):
        draaw_mi.render(scene, spp=1, post=[{"type": "blom"}])
    assert render_calls == []                         # (the error came after the whole render)


def test_render_refuses_a_function_as_post_chain_before_rendering(render_calls):
    from draaw_mi.errors import RenderError
    scene = draaw_mi.load_scene(_scene())
    with pytest.raises(RenderError, match="render: post=<function.*expected a chain"):
        draaw_mi.render(scene, spp=1, post=lambda img: img)
    assert render_calls == []                         # (a TypeError after the render)
    from draaw_mi import post
    chain = post.load_chain([{"type": "contrast", "amount": 0.0}])      # a Chain is a chain
    assert np.isfinite(np.array(draaw_mi.render(scene, spp=1, post=chain))).all()


@pytest.mark.parametrize("step, tol, expected", [(0.00025, 5e-3, True), (0.004, 0.1, False)])
def test_settled_bounds_the_drift_by_the_steps_of_one_eighth(step, tol, expected):
    """128 iterations at lr 0.01: one eighth (16 steps) may move the latent by up to 0.35 x
    16 x 0.01 = 0.056 between eighth-means. A drift of 0.004 is settled (a bound of 0.35 x
    0.01, without the eighth's length, called it unsettled), 0.064 is not."""
    from draaw_mi.fitting.result import settled
    hist = [{"loss": 1.0, "lr": 0.01, "values": {"m": 0.5 + step * i}, "latent": {"m": 0.5 + step * i}}
            for i in range(128)]
    assert settled(hist, tol) is expected


def test_a_map_with_one_channel_still_descending_is_not_settled():
    """A map's history holds six summary entries (channel means, mean deviations). One channel
    still descending (an XML diffuse map's blue mean at 0.28 of 0.20 after 40 iterations, the
    cosine decay slowing it) drifted 0.73 of its steps' path, yet the RMS over the six entries
    read 0.30, under the 0.35 bound: "converged". The largest entry's drift decides now."""
    import math
    from draaw_mi.fitting.result import settled
    n, hist = 40, []
    for i in range(n):
        lr = 0.0025 + 0.0475 * 0.5 * (1 + math.cos(math.pi * i / n))
        blue = -0.95 * (1 - math.exp(-i / 11))                      # (log space: 0.5 e^blue)
        latent = [0.0, -0.2 * (1 - math.exp(-i / 11)), blue, 0.0, 0.0, 0.0]
        hist.append({"loss": 1.0, "lr": lr, "latent": {"m": latent},
                     "values": {"m": [0.5, 0.46, 0.5 * math.exp(blue), 0.2, 0.15, 0.01]}})
    assert not settled(hist, 5e-3)
    for h in hist[-16:]:                                            # the same map, settled
        h["latent"] = hist[-17]["latent"]
        h["values"] = hist[-17]["values"]
    assert settled(hist, 5e-3)


def test_an_init_out_of_range_is_shown_as_given():
    """One number given for a textured base colour was reported as "an array of shape
    (4, 4, 3), all NaN"."""
    from conftest import tiny_description
    d = tiny_description(resolution=[8, 6])
    d["materials"]["ball"]["base_color"] = np.full((4, 4, 3), 0.5)
    for given, shown in ((float("nan"), "nan"), (-1.0, "-1.0")):
        with pytest.raises(ParameterError, match=rf"fit: init ball.base_color={shown}; expected values in \[0.0, 1.0\]"):
            draaw_mi.fit(draaw_mi.load_scene(d), np.zeros((6, 8, 3), np.float32), ["ball.base_color"],
                         iterations=1, spp=2, progress=False, init={"ball.base_color": given})


def test_an_init_of_the_wrong_type_or_count_names_the_parameter():
    """A string, a list of two for one number, two numbers for a colour or one too many for an
    SDF centre had failed inside the fit's first render, with Dr.Jit's words ("Could not
    construct from sequence", "dr.while_loop(): encountered an exception"); one number for a
    colour starts it grey."""
    from conftest import tiny_description
    d = tiny_description(resolution=[8, 6])
    scene = draaw_mi.load_scene(d)
    ref = np.zeros((6, 8, 3), np.float32)
    bad = [("ball.roughness", "0.5", r"ball.roughness='0.5' \(a str\); expected a number"),
           ("ball.roughness", [0.2, 0.3], r"ball.roughness=\[0.2, 0.3\] \(2 numbers\); expected a number"),
           ("ball.base_color", [0.1, 0.2], r"\(2 numbers\); expected one number or 3 \(a value per channel\)"),
           ("ball.base_color", {"r": 1}, r"\(a dict\); expected one number or 3")]
    for name, value, message in bad:
        with pytest.raises(ParameterError, match=rf"fit: init {message}" if message.startswith("ball") else message):
            draaw_mi.fit(scene, ref, [name], iterations=1, spp=2, progress=False, init={name: value})
    result = draaw_mi.fit(scene, ref, ["ball.base_color"], iterations=1, spp=2, progress=False,
                          init={"ball.base_color": 0.25}, lr=1e-9)
    assert np.allclose(result.history[0]["values"]["ball.base_color"], [0.25, 0.25, 0.25], atol=1e-6)


def test_a_vector_init_takes_its_count_of_numbers_and_no_grey():
    """A point (an SDF object's centre) takes exactly its three numbers, in order; one number is
    not spread over it as over a colour."""
    import mitsuba as mi
    from draaw_mi.fitting.start import value_start
    like = mi.Point3f(0.0, 0.0, 0.0)
    assert np.allclose(np.array(value_start("sdf.a.center", (1, 2, 3.5), like)).ravel(), [1, 2, 3.5])
    assert type(value_start("sdf.a.center", np.array([1.0, 2.0, 3.0]), like)) is mi.Point3f
    for value in (0.5, [1, 2], [1, 2, 3, 4]):
        with pytest.raises(ParameterError, match=r"fit: init sdf.a.center=.*; expected 3 numbers"):
            value_start("sdf.a.center", value, like)
    # two points: as rows of three numbers, as Dr.Jit holds them (channel by channel) or flat,
    # the channels of each point stay together (they were read across points)
    two = mi.Point3f([0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    for value in ([[1, 2, 3], [4, 5, 6]], mi.Point3f([1, 4], [2, 5], [3, 6]), [1, 2, 3, 4, 5, 6]):
        assert np.array(value_start("p", value, two)).T.tolist() == [[1, 2, 3], [4, 5, 6]], value


def _plain_scene(bsdf: dict) -> "draaw_mi.DraawScene":
    T = mi.ScalarTransform4f
    return draaw_mi.load_scene({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "gaussian"}},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "obj": {"type": "sphere", "bsdf": bsdf},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}})


def test_a_mitsuba_materials_parameters_keep_their_range():
    """roughplastic's diffuse_reflectance and roughconductor's alpha_u had no range: fitted
    towards a black reference (darker than the plastic's specular alone) the colour went to
    -0.19, and alpha_u below 0; both are projected now (alpha_u in log space, as alpha)."""
    from draaw_mi.fitting.params import range_for, space_for
    assert range_for("obj.bsdf.alpha_u.value") == (1e-3, 1.0) and space_for("obj.bsdf.alpha_v.value") == "log"
    assert range_for("obj.bsdf.specular_transmittance.value") == (0.0, 1.0)
    s = _plain_scene({"type": "roughplastic", "alpha": 0.3,
                      "diffuse_reflectance": {"type": "rgb", "value": [0.05, 0.05, 0.05]}})
    key = next(k for k in s.params.keys() if "diffuse_reflectance" in k)
    res = draaw_mi.fit(s, np.zeros((16, 16, 3), np.float32), [key], iterations=12, spp=4, lr=0.05,
                       progress=False, version="prb")
    assert min(min(h["values"][key]) for h in res.history) >= 0.0


def test_a_non_finite_pixel_leaves_the_running_mean_as_it_was():
    """With smooth on, one NaN pixel entered the running mean of renders and stayed: every
    later loss NaN, the fit never settled."""
    from draaw_mi.fitting.problem import PassLoss
    ref = mi.TensorXf(np.full((2, 2, 3), 0.5, np.float32))
    mean = mi.TensorXf(np.full((2, 2, 3), 0.4, np.float32))
    bad = np.full((2, 2, 3), 0.6, np.float32)
    bad[1, 1, 0] = np.nan
    _, (_, mean) = PassLoss("l2", "fixed", 1.0, smooth=True)(mi.TensorXf(bad), ref, None, mean, 0.5)
    got = mean.numpy()
    assert np.all(np.isfinite(got)) and got[1, 1, 0] == pytest.approx(0.4) and got[0, 0, 0] == pytest.approx(0.5)
    good = mi.TensorXf(np.full((2, 2, 3), 0.6, np.float32))
    value, _ = PassLoss("l2", "fixed", 1.0, smooth=True)(good, ref, None, mean, 0.5)
    assert np.isfinite(float(value[0]))


def test_an_interrupted_fit_of_a_resized_copy_leaves_its_iterate_in_the_callers_scene(monkeypatch):
    """Ctrl-C in a fit whose references are smaller than the scene's film (the fit renders a
    copy) left the caller's scene at its start values; the end of a fit had copied them."""
    from draaw_mi.fitting import fitter
    orig = fitter.history_entry

    def interrupting(problem, s, opt, it, *a):
        if it == 3:
            raise KeyboardInterrupt
        return orig(problem, s, opt, it, *a)

    monkeypatch.setattr(fitter, "history_entry", interrupting)
    scene = draaw_mi.load_scene(_scene())                         # 16 x 16
    start = float(np.array(scene.params[scene.key("target.roughness")])[0])
    with pytest.raises(KeyboardInterrupt):
        draaw_mi.fit(scene, np.zeros((8, 8, 3), np.float32), P, iterations=10, spp=1, lr=0.1, progress=False)
    assert float(np.array(scene.params[scene.key("target.roughness")])[0]) != pytest.approx(start)


def test_the_two_starts_merge_takes_the_largest_seed():
    """fit() takes seeds up to 2^32 - 1, but the merge of fit_two_starts rendered seed + i +
    SECOND_RENDER unmasked: a nanobind TypeError after both fits had run."""
    from draaw_mi.fitting.captures import render_capture
    from draaw_mi.fitting.two_starts import _captures_error
    scene = draaw_mi.load_scene(_scene(resolution=[8, 8]))
    caps = [{"camera": None, "lights": {}, "params": {}}]
    ref = np.full((8, 8, 3), 0.2, np.float32)
    assert np.isfinite(_captures_error(scene, {"target.roughness": 0.4}, caps, [ref], [None], "v4", 1, 0xFFFFFFFF))
    with pytest.raises(ParameterError, match=r"render_capture: seed=-1; expected an integer"):
        render_capture(scene, {}, spp=1, seed=-1)


@pytest.mark.parametrize("kw, match", [
    ({"params": {"target.roughness": 0.9}}, r"params=\{'target.roughness': 0.9\}; expected a name or a list "
                                            r"of names \(start values go in init=\)"),
    ({"params": 3}, r"params=3; expected a name or a list of names"),
    ({"max_depth": "4"}, r"max_depth='4'; expected an integer >= -1"),
    ({"max_depth": True}, r"max_depth=True"),
    ({"max_depth": 2.7}, r"max_depth=2.7"),
    ({"references": np.zeros((2, 16, 16, 3), np.float32)}, r"shape \(2, 16, 16, 3\).*one reference per view"),
    ({"references": [[0.1, 0.2], [0.3]]}, r"references\[0\]: reference of shape \(2,\)"),
    ({"references": None, "captures": [{"reference": np.zeros((16, 16, 3), np.float32),
                                        "camera": {"origin": "x"}}]}, r"fit: captures\[0\]\.camera\.origin"),
])
def test_what_fit_is_given_is_checked_by_name(kw, match):
    """A dict of params dropped its values silently, an int raised a bare TypeError; max_depth
    of any type passed; a stacked array of references named to_numpy; a capture's camera was
    named views[0]."""
    args = {"references": np.zeros((16, 16, 3), np.float32), "params": P}
    args.update(kw)
    with pytest.raises(DraawError, match=match):
        draaw_mi.fit(_scene(), args.pop("references"), args.pop("params"), iterations=1, spp=1,
                     progress=False, **args)


def test_a_16_bit_png_reference_keeps_its_precision(tmp_path):
    """matplotlib's reader cut a 16-bit RGB PNG to 8 bits (40000 / 65535 read 0.6118 for 0.6104);
    grey kept its 16 bits."""
    from draaw_mi.fitting.reference import load_reference
    for fmt, arr in (("Y", np.full((4, 4), 40000, np.uint16)), ("RGB", np.full((4, 4, 3), 40000, np.uint16)),
                     ("RGBA", np.full((4, 4, 4), 40000, np.uint16))):
        path = str(tmp_path / f"r_{fmt}.png")
        mi.Bitmap(arr, pixel_format=getattr(mi.Bitmap.PixelFormat, fmt)).write(path)
        got = load_reference(path, encoded=True)
        assert got.shape == (4, 4, 3)
        np.testing.assert_allclose(got, 40000 / 65535, rtol=1e-6, err_msg=fmt)


def test_a_fits_views_stand_in_the_scene_cameras_medium():
    """A view made from a camera table had no medium: inside the scene camera's fog it rendered
    the scene as if the fog were not there (once V1-V4 took each sensor's own medium)."""
    from draaw_mi.fitting.views import view_sensors
    T = mi.ScalarTransform4f
    scene = draaw_mi.load_scene({
        "type": "scene", "fog": {"type": "homogeneous", "sigma_t": 0.5, "albedo": 0.0},
        "sensor": {"type": "perspective", "fov": 40, "medium": {"type": "ref", "id": "fog"},
                   "to_world": T().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}},
        "ball": {"type": "sphere"}, "light": {"type": "constant"}})
    (view,) = view_sensors(scene, [{"origin": [0, 1, 5], "target": [0, 0, 0]}])
    assert view.get_medium() is not None
    own = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "draaw_v4", "max_depth": 3}), spp=8))
    seen = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "draaw_v4", "max_depth": 3}),
                              sensor=view, spp=8))
    assert seen.mean() < 0.2 and own.mean() < 0.2          # (0.88 without the fog)


def _fog_scene(albedo, sigma_t=1.0):
    T = mi.ScalarTransform4f
    return draaw_mi.load_scene({
        "type": "scene", "fog": {"type": "homogeneous", "sigma_t": sigma_t, "albedo": albedo},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": T().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}},
        "box": {"type": "cube", "interior": {"type": "ref", "id": "fog"}, "bsdf": {"type": "null"}},
        "light": {"type": "constant"}})


@pytest.mark.parametrize("part", ["albedo", "sigma_t"])
def test_a_medium_albedo_or_density_started_at_0_is_warned_about(part):
    """Their gradient is exactly 0 there (a real collision with sigma_s = 0 ends the path; with
    sigma_t = 0 no collision is sampled), so a fit from 0 keeps them at 0: said in a warning,
    which says what to do (the fit's later "zero gradient" warning asked whether the parameter
    was visible). The gradient is measured at both starts: 0 at 0, not at 0.05."""
    name = f"fog.{part}.value"
    scene_at = (lambda v: _fog_scene(v)) if part == "albedo" else (lambda v: _fog_scene(0.8, v))
    ref = np.full((8, 8, 3), 0.3, np.float32)
    with pytest.warns(RuntimeWarning, match=rf"fit: {name} starts at 0 everywhere, where its gradient is "
                                            rf"exactly 0 .*init=\{{'{name}': 0.05\}}"):
        r = draaw_mi.fit(scene_at(0.0), ref, [name], iterations=1, spp=4, progress=False)
    assert np.all(np.array(r.values[name]) == 0.0)                      # (the fit kept it)
    grads = {}
    for start in (0.0, 0.05):
        scene = scene_at(start)
        key = scene.key(name)
        p = scene.params
        dr.enable_grad(p[key])
        p.update()
        img = mi.render(scene.mi_scene, p, integrator=mi.load_dict({"type": "draaw_v4", "max_depth": 4}), spp=16)
        dr.backward(dr.mean(img, axis=None))
        grads[start] = float(np.abs(np.array(dr.grad(p[key]))).sum())
    assert grads[0.0] == 0.0 and grads[0.05] > 1e-3, grads
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        draaw_mi.fit(scene_at(0.0), ref, [name], init={name: 0.05}, iterations=1, spp=4, progress=False)


def _blend_scene(weight):
    T = mi.ScalarTransform4f
    return draaw_mi.load_scene({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}},
        "ball": {"type": "sphere", "bsdf": {"type": "blendbsdf", "weight": weight,
                                            "a": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.9, 0.1, 0.1]}},
                                            "b": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.1, 0.1, 0.9]}}}},
        "light": {"type": "constant"}})


def test_a_blend_weight_is_fitted_within_0_and_1():
    """Mitsuba's blendbsdf clips its weight: a fit towards 1 went on to 1.32 (every value past
    1 renders alike, Adam's momentum kept pushing), one towards 0 to -0.30, and init 2.0 was
    taken. The weight is now projected onto [0, 1]; a start on a bound, where its gradient is
    0, is warned of."""
    ref = np.array(draaw_mi.render(_blend_scene(1.0), version="v4", spp=16, seed=1))
    r = draaw_mi.fit(_blend_scene(0.6), ref, ["ball.bsdf.weight"], iterations=30, spp=8, lr=0.2, progress=False)
    w = float(np.ravel(r.values["ball.bsdf.weight"])[0])
    assert 0.85 < w <= 1.0, w
    with pytest.raises(ParameterError, match=r"init ball.bsdf.weight=2.0; expected values in \[0.0, 1.0\]"):
        draaw_mi.fit(_blend_scene(0.6), ref, ["ball.bsdf.weight"], init={"ball.bsdf.weight": 2.0}, iterations=1,
                     progress=False)
    with pytest.warns(RuntimeWarning, match=r"ball.bsdf.weight starts at 0, where Mitsuba's blendbsdf clips"):
        draaw_mi.fit(_blend_scene(0.0), ref, ["ball.bsdf.weight"], iterations=1, spp=2, progress=False)
    with pytest.raises(draaw_mi.SceneError, match=r"weight"):
        bad = {"render": {"resolution": [4, 4]}, "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
               "materials": {"m": {"type": "blendbsdf", "weight": 1.5, "a": {"type": "diffuse"},
                                   "b": {"type": "diffuse"}}},
               "shapes": [{"type": "sphere", "material": "m"}], "lights": [{"type": "constant"}]}
        draaw_mi.load_scene(bad)


def _black_ball(**material):
    return draaw_mi.load_scene({
        "render": {"resolution": [8, 8], "max_depth": 4, "filter": "box"},
        "camera": {"origin": [0, 1, 4], "target": [0, 0.3, 0], "fov": 40},
        "materials": {"m": {"base_color": [0, 0, 0], "roughness": 0.4, **material},
                      "g": {"base_color": [0.5, 0.5, 0.5], "roughness": 0.8}},
        "shapes": [{"name": "ball", "type": "sphere", "material": "m", "center": [0, 0.5, 0], "radius": 0.5},
                   {"name": "floor", "type": "rectangle", "material": "g", "rotate": {"axis": [1, 0, 0], "angle": -90},
                    "scale": 4.0}],
        "lights": [{"name": "key", "type": "area", "position": [1, 3, 2], "target": [0, 0, 0], "size": [1, 1],
                    "intensity": 10}, {"name": "sky", "type": "constant", "intensity": 0.2}]})


@pytest.mark.parametrize("material, warned", [({"metallic": 1.0}, True), ({"specular": 0.0}, True),
                                              ({"metallic": 0.0}, False)])
def test_a_black_base_color_whose_bsdf_is_0_is_warned_about(material, warned):
    """At base_color 0 with metallic 1 (or specular 0) the draaw BSDF is 0 (f90 = min(1, 50 f0)):
    path replay stops there and the base colour's gradient misses the light it would reflect
    (V3 read 0.0 against 0.05 by finite differences). Measured here on V3: the gradient at 0
    is far below the one at 1e-3, where AD and FD agree. A dielectric of specular 0.5 keeps its
    specular lobe (f > 0): not warned."""
    import warnings
    ref = np.full((8, 8, 3), 0.2, np.float32)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        draaw_mi.fit(_black_ball(**material), ref, ["m.base_color"], version="v3", iterations=1, spp=2, progress=False)
    said = [str(w.message) for w in seen if "at exactly 0 on a material of" in str(w.message)]
    assert len(said) == (1 if warned else 0), said
    if not warned:
        return
    grads = []
    for c in (0.0, 1e-3):
        scene = _black_ball(**material)
        x = mi.Color3f(c)
        dr.enable_grad(x)
        scene.params["m.base_color.value"] = x
        scene.params.update()
        dr.backward(dr.mean(draaw_mi.render(scene, version="v3", spp=64, seed=0, params=scene.params), axis=None))
        grads.append(float(np.array(dr.grad(x)).sum()))
    assert grads[0] < 0.85 * grads[1], grads


def test_a_roughplastic_alpha_fit_is_warned_of_its_partial_gradient():
    """Mitsuba 3.9.1's roughplastic differentiates its alpha in part only: prb's gradient of an
    image's mean -0.0062 against -0.080 by finite differences (measured here too, below: under
    a fifth). A roughconductor's alpha is differentiated whole: not warned."""
    import warnings
    T = mi.ScalarTransform4f

    def scene(kind):
        return draaw_mi.load_scene({
            "type": "scene",
            "sensor": {"type": "perspective", "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}},
            "ball": {"type": "sphere", "bsdf": {"type": kind, "alpha": 0.4}},
            "light": {"type": "point", "position": [2, 2, 3], "intensity": {"type": "rgb", "value": [20, 20, 20]}},
            "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.2, 0.2, 0.2]}}})
    ref = np.full((8, 8, 3), 0.2, np.float32)
    for kind, warned in (("roughplastic", True), ("roughconductor", False)):
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            draaw_mi.fit(scene(kind), ref, ["ball.bsdf.alpha"], iterations=1, spp=2, progress=False)
        said = [str(w.message) for w in seen if "differentiates only in part" in str(w.message)]
        assert len(said) == (1 if warned else 0), (kind, said)
    s = scene("roughplastic")
    p, key = s.params, s.key("ball.bsdf.alpha")
    integ = mi.load_dict({"type": "prb", "max_depth": 3})
    ad, fd = [], []
    for seed in range(3):
        p[key] = 0.4
        dr.enable_grad(p[key])
        p.update()
        dr.backward(dr.mean(mi.render(s.mi_scene, p, integrator=integ, spp=32, seed=seed), axis=None))
        ad.append(float(np.array(dr.grad(p[key])).ravel()[0]))
        dr.disable_grad(p[key])
        v = []
        for a in (0.41, 0.39):
            p[key] = a
            p.update()
            v.append(float(np.array(mi.render(s.mi_scene, integrator=integ, spp=32, seed=seed)).mean()))
        fd.append((v[0] - v[1]) / 0.02)
    assert np.mean(fd) < 0 and abs(np.mean(ad)) < 0.2 * abs(np.mean(fd)), (ad, fd)
