"""render() options users rely on: the scene's ``[[post]]`` chain and ``post=``, ``aovs=``
(values and EXR channel names), ``hide_emitters`` and ``integrator_options``.

References: numpy formulas (the post filter, ray-plane distances), Mitsuba's ``path`` and
integrators built directly with ``mi.load_dict``.
"""
from __future__ import annotations

import math
import re
import os

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import DraawError

from conftest import SCENES, tiny_description

CHAIN = [{"type": "contrast", "contrast": 1.5, "pivot": 0.3}]


def _contrast(c):
    return (c - 0.3) * 1.5 + 0.3


def test_scene_post_chain_is_applied_and_can_be_overridden():
    desc = tiny_description()
    desc["post"] = CHAIN
    scene = draaw_mi.load_scene(desc)
    plain = np.array(draaw_mi.render(scene, version="path", spp=4, seed=1, post=[]))
    with_chain = np.array(draaw_mi.render(scene, version="path", spp=4, seed=1))
    assert np.abs(with_chain - plain).max() > 0.05
    assert np.allclose(with_chain, _contrast(plain), atol=1e-5)
    other = [{"type": "contrast", "contrast": 0.5, "pivot": 0.0}]
    overridden = np.array(draaw_mi.render(scene, version="path", spp=4, seed=1, post=other))
    assert np.allclose(overridden, 0.5 * plain, atol=1e-5)


def _facing_plane(res=(9, 7), dist=3.0, fov=30.0):
    return draaw_mi.load_scene({
        "render": {"resolution": list(res), "max_depth": 3, "filter": "box"},
        "camera": {"origin": [0, 0, dist], "target": [0, 0, 0], "up": [0, 1, 0], "fov": fov},
        "materials": {"m": {"base_color": [0.6, 0.3, 0.1], "roughness": 0.8}},
        "shapes": [{"type": "rectangle", "material": "m", "scale": 20}],
        "lights": [{"type": "constant", "intensity": 1.0}],
    })


@pytest.mark.parametrize("version", ["v1", "v4"])
def test_aovs_values_and_exr_channels(tmp_path, version):
    w, h, dist, fov = 9, 7, 3.0, 30.0
    scene = _facing_plane((w, h), dist, fov)
    img, info = draaw_mi.render(scene, version=version, spp=64, seed=2, aovs=["depth", "normal", "albedo"],
                                return_info=True)
    img = np.array(img)
    names = info["channels"]
    assert names == ["R", "G", "B", "depth.Z", "N.X", "N.Y", "N.Z", "albedo.R", "albedo.G", "albedo.B"]
    assert img.shape == (h, w, len(names))
    path = str(tmp_path / "a.exr")
    draaw_mi.write_exr(path, img, channels=names)
    back, back_names = draaw_mi.read_exr(path, with_names=True)
    for i, n in enumerate(names):                    # every channel is in the EXR under its name
        assert np.array_equal(back[..., back_names.index(n)], img[..., i]), n
    by = {n: img[..., i] for i, n in enumerate(names)}
    depth = by["depth.Z"]
    # ray-plane distance through the pixel centre (fov along x), measured, as in Mitsuba's
    # ``aov`` integrator, from where the camera ray starts: on the near-clip plane (0.01); the
    # box-filtered mean over the pixel differs from the centre value only to second order
    t = math.tan(math.radians(fov) / 2)
    x = (2 * (np.arange(w) + 0.5) / w - 1) * t
    y = (1 - 2 * (np.arange(h) + 0.5) / h) * t * h / w
    expected = (dist - 0.01) * np.sqrt(1 + x[None, :] ** 2 + y[:, None] ** 2)
    assert np.allclose(depth, expected, rtol=2e-3), (depth - expected)
    normal = np.stack([by["N.X"], by["N.Y"], by["N.Z"]], -1)
    albedo = np.stack([by["albedo.R"], by["albedo.G"], by["albedo.B"]], -1)
    assert np.allclose(normal, [0, 0, 1], atol=1e-5)
    assert np.allclose(albedo, [0.6, 0.3, 0.1], atol=1e-5)


def test_hide_emitters_matches_mitsuba_path(tiny_scene):
    ours = np.array(draaw_mi.render(tiny_scene, version="path", spp=8, seed=3, hide_emitters=True))
    ref = np.array(mi.render(tiny_scene.mi_scene, integrator=mi.load_dict(
        {"type": "path", "max_depth": 4, "hide_emitters": True}), spp=8, seed=3))
    assert np.array_equal(ours, ref)
    shown = np.array(draaw_mi.render(tiny_scene, version="v4", spp=8, seed=3))
    hidden = np.array(draaw_mi.render(tiny_scene, version="v4", spp=8, seed=3, hide_emitters=True))
    sky = np.all(np.abs(shown - 0.2) < 1e-6, axis=2)          # pixels that see only the sky (0.2)
    assert sky.sum() > 20
    assert np.all(hidden[sky] == 0)
    # V4 with hidden emitters has path's expectation pixel by pixel (seed stacks; the sky
    # still lights the scene): |z| above 4 in at most 1 % of the values, mean z near 0
    path = mi.load_dict({"type": "path", "max_depth": 4, "hide_emitters": True})
    a = np.stack([np.array(mi.render(tiny_scene.mi_scene, integrator=path, spp=16, seed=100 + k)) for k in range(8)])
    b = np.stack([np.array(draaw_mi.render(tiny_scene, version="v4", spp=16, seed=200 + k, hide_emitters=True,
                                           post=[])) for k in range(8)])
    se = np.sqrt(a.var(0, ddof=1) / 8 + b.var(0, ddof=1) / 8)
    varies = se > 1e-6
    z = (a.mean(0) - b.mean(0))[varies] / se[varies]
    assert z.size > 0.5 * a[0].size
    assert np.mean(np.abs(z) > 4) <= 0.01 and abs(z.mean()) < 4 * z.std() / np.sqrt(z.size), (z.mean(), z.std())


def test_integrator_options_reach_the_integrator(tiny_scene):
    ours = np.array(draaw_mi.render(tiny_scene, version="v2", spp=4, seed=5, integrator_options={"scatter": 0}))
    ref = np.array(mi.render(tiny_scene.mi_scene, integrator=mi.load_dict(
        {"type": "draaw_v2", "max_depth": 4, "scatter": 0}), spp=4, seed=5))
    default = np.array(draaw_mi.render(tiny_scene, version="v2", spp=4, seed=5))
    assert np.array_equal(ours, ref) and not np.allclose(ours, default)
    with pytest.raises(draaw_mi.DraawError, match="scatter"):
        draaw_mi.render(tiny_scene, version="v2", integrator_options={"scatter": -1})


@pytest.mark.parametrize("kwargs, match", [
    ({"hide_emitters": "false"}, "hide_emitters='false'; expected True or False"),
    ({"hide_emitters": 0}, "hide_emitters=0; expected True or False"),
    ({"time_budget": True}, "time_budget=True; expected a positive number"),
    ({"time_budget": float("nan")}, "time_budget=nan; expected a positive number"),
    ({"integrator_options": [("rr_depth", 3)]}, r"integrator_options=\[\('rr_depth', 3\)\]; expected a dict")])
def test_option_types_are_checked_before_rendering(tiny_scene, kwargs, match):
    """The string "false" hid the lights (any truthy value did), time_budget=True rendered for
    one second, a list of options raised Python's "argument after ** must be a mapping"."""
    with pytest.raises(draaw_mi.RenderError, match=match):
        draaw_mi.render(tiny_scene, version="v4", spp=1, **kwargs)
    assert np.array_equal(np.array(draaw_mi.render(tiny_scene, version="v4", spp=2, seed=1,
                                                   hide_emitters=np.bool_(True))),
                          np.array(draaw_mi.render(tiny_scene, version="v4", spp=2, seed=1,
                                                   hide_emitters=True)))


def test_misspelt_integrator_options_and_aovs_name_the_fix(tiny_scene):
    """An option the integrator does not take, AOVs asked of Mitsuba's ``path``: one line that
    says what to do (Mitsuba's text was ``- float "sdf_epsilonn": 0.01`` and ``- string
    "aovs": "depth"``)."""
    with pytest.raises(draaw_mi.RenderError, match="no option 'sdf_epsilonn'; did you mean 'sdf_epsilon'"):
        draaw_mi.render(tiny_scene, version="v4", spp=1, integrator_options={"sdf_epsilonn": 0.01})
    with pytest.raises(draaw_mi.RenderError, match="no option 'rr_dept'; did you mean 'rr_depth'"):
        draaw_mi.render(tiny_scene, version="v4", spp=1, integrator_options={"rr_dept": 3})
    with pytest.raises(draaw_mi.RenderError, match="AOVs .depth. come from the draaw versions"):
        draaw_mi.render(tiny_scene, version="path", spp=1, aovs=["depth"])


def test_aovs_given_as_one_string_are_one_name(tiny_scene):
    """``aovs="depth"`` and ``aovs="all"`` (as the docstring writes them) are names, not lists
    of characters (``aovs entry 'a' is unknown``)."""
    one = draaw_mi.render(tiny_scene, version="v4", spp=1, seed=2, aovs="depth", return_info=True)[1]
    assert one["channels"] == ["R", "G", "B", "depth.Z"]
    every = draaw_mi.render(tiny_scene, version="v4", spp=1, seed=2, aovs="all", return_info=True)[1]
    assert len(every["channels"]) == 11


def test_a_scenes_own_aovs_are_dropped_with_a_warning_for_mitsubas_integrators():
    """A scene that asks for AOVs still renders with ``--version path`` (colour only, and
    says so) instead of failing with no way to drop them from the command line."""
    desc = tiny_description(aovs=["depth"])
    scene = draaw_mi.load_scene(desc)
    with pytest.warns(RuntimeWarning, match="renders colour only"):
        img = np.array(draaw_mi.render(scene, version="path", spp=2, seed=1, post=[]))
    ref = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "path", "max_depth": 4}),
                             spp=2, seed=1))
    assert np.array_equal(img, ref)


@pytest.mark.parametrize("version", ["path", "prb", "volpath"])
def test_mitsubas_integrators_refuse_sdf_objects(version):
    """[[sdf]] objects are traced inside v1..v4 only: Mitsuba's integrators rendered the scene
    without them (the floor alone) and exited 0."""
    scene = draaw_mi.load_scene(os.path.join(SCENES, "sdf_csg.toml"), resolution=(16, 12))
    with pytest.raises(draaw_mi.RenderError, match=r"\[\[sdf\]\] objects, which Mitsuba's"):
        draaw_mi.render(scene, version=version, spp=1)
    assert np.array(draaw_mi.render(scene, version="v4", spp=1)).mean() > 0


def test_path_refuses_media_and_volpath_renders_them():
    scene = draaw_mi.load_scene(os.path.join(SCENES, "smoke.toml"), resolution=(16, 12))
    for version in ("path", "prb"):
        with pytest.raises(draaw_mi.RenderError, match="participating media, which Mitsuba's"):
            draaw_mi.render(scene, version=version, spp=1)
    got = np.array(draaw_mi.render(scene, version="volpath", spp=1, seed=0, post=[]))
    ref = np.array(mi.render(scene.mi_scene, spp=1, seed=0, integrator=mi.load_dict(
        {"type": "volpath", "max_depth": scene.settings["max_depth"]})))
    assert np.isfinite(got).all() and got.mean() > 0 and np.allclose(got, ref, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ["sdf_csg.toml", "smoke.toml"])
def test_adaptive_subsampling_refuses_what_its_corner_rays_cannot_see(name):
    """Adaptive subsampling interpolates between corner samples whose signatures (camera,
    shadow and mirror rays) see meshes only: SDF objects and smoke became smears."""
    with pytest.raises(draaw_mi.RenderError, match="adaptive subsampling cannot see"):
        draaw_mi.render(os.path.join(SCENES, name), spp=2, resolution=(16, 16), adaptive=8)


def test_a_graded_go_draaw_version_without_its_grade_says_so():
    """``V4-Log`` renders what ``V4`` renders; its Log grade is the post filter ``log``. The
    name was taken without a word, the image left ungraded."""
    import warnings
    scene = draaw_mi.load_scene(tiny_description())
    with pytest.warns(RuntimeWarning, match=r"'V4-Log' renders linear light, as 'draaw_v4'.*post filter 'log'"):
        graded = np.array(draaw_mi.render(scene, version="V4-Log", spp=2, seed=1))
    assert np.array_equal(graded, np.array(draaw_mi.render(scene, version="v4", spp=2, seed=1)))
    with pytest.warns(RuntimeWarning, match="post filter 'linear'"):
        draaw_mi.render(scene, version="v2-linear-texture", spp=1)
    with pytest.warns(RuntimeWarning, match="post filter 'log'"):      # (resolved as V4-Log: said too)
        draaw_mi.render(scene, version="V4_Log", spp=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        draaw_mi.render(scene, version="V4-Log", spp=1, post=[{"type": "log"}])
        draaw_mi.render(scene, version="V4-Optim-V2", spp=1)           # not a graded name


def test_a_differentiable_render_refuses_aovs_and_other_params(tiny_scene):
    """``render(scene, params=p, aovs=["depth"])`` then ``dr.backward`` died in Mitsuba's
    adjoint pass (ImageBlock.put: incompatible arguments); a dict of values for ``params``
    died in mi.render ("should be an instance of mi.SceneParameters")."""
    import drjit as dr
    p = tiny_scene.params
    with pytest.raises(draaw_mi.RenderError, match=r"render: AOVs \(depth\) are not differentiable; drop "
                                                   r"params= or pass aovs=\[\]"):
        draaw_mi.render(tiny_scene, spp=1, params=p, aovs=["depth"])
    with pytest.raises(draaw_mi.RenderError, match=r"render: params of type dict; expected the scene's parameters"):
        draaw_mi.render(tiny_scene, spp=1, params={"ball.roughness.value": 0.5})
    # another scene's parameters (the scene loaded again) took no gradient, without a word
    again = draaw_mi.load_scene(tiny_description())
    with pytest.raises(draaw_mi.RenderError, match=r"render: params belong to another scene"):
        draaw_mi.render(tiny_scene, spp=1, params=again.params)
    draaw_mi.render(tiny_scene, spp=1, params=mi.traverse(tiny_scene.mi_scene))     # its own objects
    key = tiny_scene.key("ball.roughness")
    x = type(p[key])(p[key])
    dr.enable_grad(x)
    p[key] = x
    p.update()
    img = draaw_mi.render(tiny_scene, spp=2, params=p, aovs=[])        # what the message says works
    dr.backward(dr.mean(img, axis=None))
    assert np.isfinite(dr.grad(x)).all() and dr.grad(x)[0] != 0
    dr.disable_grad(x)


def test_a_render_with_nan_values_says_which_parameter_made_them(tiny_scene):
    """A NaN colour set through scene.params rendered 2,541 NaN values without a word (only
    ``info["non_finite"]`` counted them); the warning names the value a scene file refuses."""
    p = tiny_scene.params
    key = tiny_scene.key("ball.base_color")
    assert tiny_scene.out_of_range() == []
    old = type(p[key])(p[key])
    p[key] = mi.Color3f(float("nan"))
    p.update()
    try:
        assert tiny_scene.out_of_range() == [f"out_of_range: {key}=[nan, nan, nan]; expected finite "
                                             "numbers (in float32, |x| <= 3.4e38)"]
        with pytest.warns(draaw_mi.NonFiniteWarning, match=rf"are NaN or inf; {re.escape(key)}=\[nan, nan, nan\]"):
            _, info = draaw_mi.render(tiny_scene, spp=1, return_info=True)
        assert info["non_finite"] > 0
        p[tiny_scene.key("ground.roughness")] = mi.Float(-0.5)              # a range, not NaN
        assert any("ground.roughness.value=-0.5; expected a number in [0.0, 1.0]" in m
                   for m in tiny_scene.out_of_range())
    finally:
        p[key] = old
        p[tiny_scene.key("ground.roughness")] = mi.Float(0.9)
        p.update()


def _roughness_map_scene():
    d = tiny_description(resolution=[16, 12])
    d["materials"]["ball"]["roughness"] = np.random.default_rng(4).random((4, 6))
    return draaw_mi.load_scene(d)


@pytest.mark.parametrize("version", ["v4", "path"])
def test_a_nan_texel_set_through_params_is_said_by_the_render(version):
    """A NaN texel of a roughness map set through scene.params renders finite but wrong pixels (V4
    darker, some black) and said nothing; the render names the map, the count and the texel,
    every render until the map is mended, and a good map renders without a word."""
    import warnings
    scene = _roughness_map_scene()
    key = scene.key("ball.roughness")
    good = np.array(scene.params[key])
    bad = good.copy()
    bad[1, 2, 0] = np.nan
    scene.params[key] = mi.TensorXf(bad)
    scene.params.update()
    assert scene.out_of_range() == [f"out_of_range: {key}: 1 texel value(s) outside [0, 1] (the first, nan, "
                                    "at [1, 2, 0]); expected finite values in [0, 1]"]
    for _ in range(2):
        with pytest.warns(RuntimeWarning, match=rf"render: the {version} render of .* used {re.escape(key)}: 1 "
                                                r"texel value\(s\) outside \[0, 1\] \(the first, nan, at \[1, 2, 0\]\)"):
            image, info = draaw_mi.render(scene, version=version, spp=2, post=[], return_info=True)
        assert info["non_finite"] == 0 and np.isfinite(np.array(image)).all()
    scene.params[key] = mi.TensorXf(good)
    scene.params.update()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        draaw_mi.render(scene, version=version, spp=2, post=[])


def test_a_render_reads_back_only_the_values_set_since_the_last_one(monkeypatch):
    """Each render checks the values whose Dr.Jit variables changed since they were last found
    fine (reading every map back before every render would cost more than a small render):
    everything at the first render, none after it, then only the one key set, whichever
    traversal set it; out_of_range() itself reads the whole scene."""
    from draaw_mi.scene import draaw_scene
    scene = _roughness_map_scene()
    checked = []
    real = draaw_scene.DraawScene.check_value
    monkeypatch.setattr(draaw_scene.DraawScene, "check_value",
                        lambda self, who, name, key, value: (checked.append(key), real(self, who, name, key, value)))
    draaw_mi.render(scene, spp=1, post=[])
    assert scene.key("ball.roughness") in checked and len(checked) > 10
    checked.clear()
    draaw_mi.render(scene, spp=1, post=[])
    assert checked == []
    key = scene.key("ground.roughness")
    scene.params[key] = mi.Float(0.5)
    scene.params.update()
    draaw_mi.render(scene, spp=1, post=[])
    assert checked == [key]
    draaw_mi.render(scene, spp=1, post=[])
    assert checked == [key]
    own = mi.traverse(scene.mi_scene)                 # a traversal of the user's own
    own[key] = mi.Float(0.6)
    own.update()
    draaw_mi.render(scene, spp=1, post=[])
    assert checked == [key, key]
    checked.clear()
    assert scene.out_of_range() == [] and scene.key("ball.roughness") in checked and len(checked) > 10


@pytest.mark.parametrize("route", ["traverse", "copy", "keep"])
def test_a_nan_texel_set_through_any_traversal_is_said(route):
    """``mi.traverse(scene.mi_scene)`` and ``scene.params.copy()`` (which render(params=) takes)
    reach the same textures as ``scene.params``: a NaN texel set through them is said too, also
    after ``scene.params.keep()`` (the optimisation tutorials' way) dropped the map's key."""
    scene = _roughness_map_scene()
    key = scene.key("ball.roughness")
    draaw_mi.render(scene, spp=1, post=[])
    if route == "keep":
        scene.params.keep([scene.key("ground.roughness")])
    p = scene.params.copy() if route == "copy" else mi.traverse(scene.mi_scene)
    bad = np.array(p[key])
    bad[0, 0, 0] = np.nan
    p[key] = mi.TensorXf(bad)
    p.update()
    with pytest.warns(RuntimeWarning, match=rf"used {re.escape(key)}: 1 texel value\(s\) outside \[0, 1\]"):
        draaw_mi.render(scene, spp=1, post=[])


def test_a_copy_at_another_resolution_checks_only_what_its_scene_had_not(monkeypatch):
    """``render(scene, resolution=...)`` renders a reloaded copy with the scene's values carried
    over: what the scene had found fine is not read back again (a 2048^2 map took 0.2 s a
    render), a NaN texel set since is found in the copy."""
    from draaw_mi.scene import draaw_scene
    scene = _roughness_map_scene()
    draaw_mi.render(scene, spp=1, post=[])
    checked = []
    real = draaw_scene.DraawScene.check_value
    monkeypatch.setattr(draaw_scene.DraawScene, "check_value",
                        lambda self, who, name, key, value: (checked.append(key), real(self, who, name, key, value)))
    draaw_mi.render(scene, spp=1, post=[], resolution=(8, 6))
    assert checked == []
    key = scene.key("ball.roughness")
    bad = np.array(scene.params[key])
    bad[0, 1, 0] = np.nan
    scene.params[key] = mi.TensorXf(bad)
    scene.params.update()
    with pytest.warns(RuntimeWarning, match=rf"used {re.escape(key)}: 1 texel value\(s\) outside \[0, 1\]"):
        draaw_mi.render(scene, spp=1, post=[], resolution=(8, 6))
    assert checked == [key]


def test_a_value_set_twice_between_renders_is_still_checked():
    """A single value set twice between two renders, the second time out of range, is said at
    every render until it is mended (a wrong value is never recorded as found fine), and the
    good value after it renders without a word. (Single values are told by their numbers: by
    their variable indices, a phase g past its bound once passed unread.)"""
    import warnings
    scene = _roughness_map_scene()
    key = scene.key("constant_light1.radiance")
    draaw_mi.render(scene, spp=1, post=[])
    for _ in range(4):
        scene.params[key] = mi.Color3f(0.3)
        scene.params.update()
        scene.params[key] = mi.Color3f(0.2, -0.1, 0.2)
        scene.params.update()
        with pytest.warns(RuntimeWarning, match=rf"used {re.escape(key)}=\[0\.2.*expected values >= 0"):
            draaw_mi.render(scene, spp=1, post=[])
        with pytest.warns(RuntimeWarning, match=rf"used {re.escape(key)}=\[0\.2.*expected values >= 0"):
            draaw_mi.render(scene, spp=1, post=[])                      # (still wrong: said again)
        scene.params[key] = mi.Color3f(0.2)
        scene.params.update()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            draaw_mi.render(scene, spp=1, post=[])


def test_a_map_set_again_and_again_between_renders_is_still_checked():
    """The same for a roughness map, set 0-3 times with good texels and then with a NaN one
    between renders: without the map last found fine held, 9 of 40 such renders said nothing."""
    import warnings
    scene = _roughness_map_scene()
    key = scene.key("ball.roughness")
    good = np.array(scene.params[key])
    bad = good.copy()
    bad[1, 1, 0] = np.nan
    draaw_mi.render(scene, spp=1, post=[])
    for i in range(16):
        for _ in range(i % 4):
            scene.params[key] = mi.TensorXf(good)
            scene.params.update()
        scene.params[key] = mi.TensorXf(bad)
        scene.params.update()
        with pytest.warns(RuntimeWarning, match=rf"used {re.escape(key)}: 1 texel value"):
            draaw_mi.render(scene, spp=1, post=[])
        scene.params[key] = mi.TensorXf(good)
        scene.params.update()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            draaw_mi.render(scene, spp=1, post=[])


@pytest.mark.parametrize("freeze", [True, False])
def test_a_single_value_set_to_two_values_is_named_when_the_render_fails(freeze, monkeypatch):
    """A roughness set through scene.params to ``mi.Float([0.2, 0.3])`` failed inside Dr.Jit
    ("dr.while_loop(): encountered an exception", "size of output variable r2153 is 2 (must be
    1)") and, recorded, left the recording failed for good (traced from then on): the error
    names the value, and the value put back renders as before, replayed."""
    from draaw_mi.rendering import session as S
    monkeypatch.setattr(S, "FREEZE", freeze)
    scene = draaw_mi.load_scene(tiny_description(resolution=[12, 8]))
    before = np.array(draaw_mi.render(scene, version="v4", spp=2, seed=1, post=[]))
    p = scene.params
    key = scene.key("ball.roughness")
    old = type(p[key])(p[key])
    p[key] = mi.Float([0.2, 0.3])
    p.update()
    assert scene.widened_values() == [f"{key} holds 2 values"]
    with pytest.raises(draaw_mi.RenderError, match=rf"render of .*: {re.escape(key)} holds 2 values; expected one"):
        draaw_mi.render(scene, version="v4", spp=2, seed=1, post=[])
    p[key] = old
    p.update()
    assert scene.widened_values() == []
    for _ in range(2):                   # (a changed value records anew, up to twice)
        again = np.array(draaw_mi.render(scene, version="v4", spp=2, seed=1, post=[]))
        assert np.array_equal(again, before)
    calls = []
    real = mi.render
    monkeypatch.setattr(mi, "render", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    draaw_mi.render(scene, version="v4", spp=2, seed=1, post=[])
    assert len(calls) == (0 if freeze else 1)        # replayed: the recording did not fail


def test_a_curves_arrays_are_not_taken_for_widened_values(tmp_path):
    """A curve's control points and segment indices are wide by design: they were named as
    widened single values, and every failed render of such a scene was blamed on them (the
    recorder's retry and fallback skipped). Shapes are left out, and only a failure that speaks
    of sizes is explained so."""
    from draaw_mi.rendering.frozen import widened_error
    (tmp_path / "curve.txt").write_text("-1 0 0 0.1\n-0.3 0.5 0 0.1\n0.3 0.5 0 0.1\n1 0 0 0.1\n")
    d = {"type": "scene", "integrator": {"type": "path"},
         "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 8, "height": 8},
                    "to_world": mi.ScalarTransform4f().look_at([0, 0.5, 4], [0, 0.5, 0], [0, 1, 0])},
         "c": {"type": "linearcurve", "filename": str(tmp_path / "curve.txt")},
         "e": {"type": "constant"}}
    scene = draaw_mi.load_scene(d)
    assert "c.control_points" in scene.params.keys()
    assert scene.widened_values() == []
    assert widened_error(scene, RuntimeError("jit_llvm_compile(): out of memory")) is None
    # a widened value, and a failure that is not about sizes: not explained as one
    tiny = draaw_mi.load_scene(tiny_description(resolution=[8, 6]))
    p = tiny.params
    p[tiny.key("ball.roughness")] = mi.Float([0.2, 0.3])
    p.update()
    assert widened_error(tiny, RuntimeError("jit_llvm_compile(): out of memory")) is None
    assert widened_error(tiny, RuntimeError("size of output variable r1 is 2 (must be 1)")) is not None


@pytest.mark.parametrize("rgba", [False, True], ids=["rgb", "rgba"])
def test_a_post_chain_treats_the_colour_alike_with_or_without_aovs(rgba):
    """apply_post told colour from AOVs by the channel count: an RGB film with a depth AOV had
    its depth read as alpha (srgb divided the colour by it: 0.56 for 0.75), an RGBA film with an
    AOV its alpha passed over (the colour encoded premultiplied)."""
    T = mi.ScalarTransform4f
    film = {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "gaussian"}}
    if rgba:
        film["pixel_format"] = "rgba"
    scene = draaw_mi.load_scene({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "film": film,
                   "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": 4}},
        "sphere": {"type": "sphere", "bsdf": {"type": "diffuse"}},
        "light": {"type": "point", "position": [0, 0, 4], "intensity": {"type": "rgb", "value": 20}}})
    chain = [{"type": "srgb"}]
    plain, info = draaw_mi.render(scene, version="v4", spp=4, seed=0, post=chain, return_info=True)
    with_aov, info_aov = draaw_mi.render(scene, version="v4", spp=4, seed=0, aovs=["depth"], post=chain,
                                         return_info=True)
    colour = 4 if rgba else 3
    assert info_aov["channels"][:colour] == info["channels"] and info_aov["channels"][colour] == "depth.Z"
    np.testing.assert_allclose(np.array(with_aov)[..., :colour], np.array(plain), atol=1e-5)


@pytest.mark.parametrize("kw, match", [
    ({"denoise": "no"}, r"render: denoise='no'; expected True or False"),
    ({"return_info": "yes"}, r"render: return_info='yes'; expected True or False"),
    ({"aovs": [1]}, r"render: aovs=\[1\]; expected a list of AOV names"),
    ({"aovs": ["dpth"]}, r"dpth"),
])
def test_renders_flags_and_aov_names_are_checked(kw, match):
    """denoise='no' denoised (a biased image), return_info took any truthy value, and an AOV
    that is not a string raised a bare TypeError from str.join."""
    with pytest.raises(DraawError, match=match):
        draaw_mi.render(draaw_mi.load_scene(tiny_description(resolution=[8, 8])), spp=1, **kw)


def test_aov_names_in_a_numpy_array_are_names():
    _, info = draaw_mi.render(draaw_mi.load_scene(tiny_description(resolution=[8, 8])), spp=1,
                              aovs=np.array(["depth"]), return_info=True)
    assert info["channels"][-1] == "depth.Z"
