"""The draaw BSDF's plugin interface: traverse() keys and flags, params.update(), attributes,
flags and to_string/repr (design.md §3, §7; guide §2, §7)."""
from __future__ import annotations

import re

import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

from draaw_mi.errors import ParameterError

from _draaw_helpers import color_np, cornell, draaw, make_si

PARAMS = ["base_color", "roughness", "metallic", "specular", "reflection", "direct_to_scatter"]
MAT = {"base_color": [0.8, 0.5, 0.3], "roughness": 0.4, "metallic": 0.3, "specular": 0.6,
       "reflection": 0.25, "direct_to_scatter": 0.75}


def test_traverse_exposes_every_parameter_as_differentiable():
    p = mi.traverse(draaw(**MAT))
    assert sorted(p.keys()) == sorted(f"{n}.value" for n in PARAMS)
    for key in p.keys():
        assert not (p.flags(key) & mi.ParamFlags.NonDifferentiable), key
    np.testing.assert_allclose(np.array(p["base_color.value"]).ravel(), MAT["base_color"], rtol=1e-6)
    for n in PARAMS[1:]:
        assert p[f"{n}.value"][0] == pytest.approx(MAT[n])


def test_traverse_exposes_normalmap_and_bitmaps():
    nm = mi.TensorXf(np.tile(np.float32([0.5, 0.5, 1.0]), (2, 2, 1)))
    p = mi.traverse(draaw(roughness=mi.TensorXf(np.full((3, 2), 0.4, np.float32)), normalmap=nm))
    assert "roughness.data" in p.keys() and "normalmap.data" in p.keys()
    for key in ("roughness.data", "normalmap.data"):
        assert not (p.flags(key) & mi.ParamFlags.NonDifferentiable), key


@pytest.fixture(scope="module")
def scene():
    return cornell(32, 3, override={"type": "draaw", **MAT})


@pytest.mark.parametrize("name,new,literal", [("base_color", [0.3, 0.6, 0.9], False),
                                              ("roughness", 0.9, False), ("metallic", 0.9, False),
                                              ("specular", 0.0, False), ("roughness", 0.7, True),
                                              ("base_color", [0.2, 0.4, 0.6], True)])
def test_update_changes_the_render_without_recompiling(scene, name, new, literal):
    """``literal``: the value set as Python numbers (as the tuner's sliders do); the BSDF's
    ``parameters_changed`` must make it opaque, or each new value would compile new kernels."""
    p = mi.traverse(scene)
    key = f"mat.{name}.value"
    old = type(p[key])(p[key])
    before = np.array(mi.render(scene, spp=8, seed=1))
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        if literal:
            p[key] = mi.Color3f(*new) if name == "base_color" else new
        else:
            p[key] = mi.Color3f(*new) if name == "base_color" else dr.opaque(mi.Float, new)
        p.update()
        after = np.array(mi.render(scene, spp=8, seed=1))
        history = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        p[key] = old
        p.update()
    assert np.all(np.isfinite(after))
    assert np.abs(after - before).mean() > 1e-4, name
    # parameter values live in arrays: the render kernel is the cached one (anchors A12)
    render_kernel = max(history, key=lambda k: k["operation_count"])
    assert render_kernel["cache_hit"], "updating a material value recompiled the render kernel"
    restored = np.array(mi.render(scene, spp=8, seed=1))
    np.testing.assert_array_equal(restored, before)


@pytest.mark.parametrize("name", ["reflection", "direct_to_scatter"])
def test_legacy_knobs_update_through_traverse(scene, name):
    """reflection / direct_to_scatter only matter to the V1/V2 integrators; here they must be
    updatable and readable back through eval_attribute."""
    p = mi.traverse(scene)
    key = f"mat.{name}.value"
    old = type(p[key])(p[key])
    p[key] = dr.opaque(mi.Float, 0.6)
    p.update()
    bsdf = [sh.bsdf() for sh in scene.shapes() if "DraawBSDF" in str(sh.bsdf())][0]
    si = make_si(np.array([[0.0, 0.0, 1.0]]))
    assert bsdf.eval_attribute_1(name, si)[0] == pytest.approx(0.6)
    p[key] = old
    p.update()


def _lanes(a, n=4):
    """Constant textures return width-1 arrays (Dr.Jit broadcasts them); compare per lane."""
    return np.broadcast_to(a, (n,) + a.shape[1:])


def test_eval_attribute_returns_the_values():
    b = draaw(**MAT)
    si = make_si(np.tile([0.0, 0.0, 1.0], (4, 1)))
    for name in ("base_color", "albedo"):
        assert b.has_attribute(name)
        np.testing.assert_allclose(_lanes(color_np(b.eval_attribute(name, si))), [MAT["base_color"]] * 4, rtol=1e-6)
        np.testing.assert_allclose(_lanes(color_np(b.eval_attribute_3(name, si))), [MAT["base_color"]] * 4, rtol=1e-6)
    lum = 0.2126 * 0.8 + 0.7152 * 0.5 + 0.0722 * 0.3
    np.testing.assert_allclose(np.array(b.eval_attribute_1("base_color", si)), lum, rtol=1e-5)
    for name in PARAMS[1:]:
        assert b.has_attribute(name)
        np.testing.assert_allclose(np.array(b.eval_attribute_1(name, si)), MAT[name], rtol=1e-6)
        np.testing.assert_allclose(_lanes(color_np(b.eval_attribute(name, si))), [[MAT[name]] * 3] * 4, rtol=1e-6)
    assert not b.has_attribute("reflectance")
    assert not b.has_attribute("no_such_thing")
    np.testing.assert_array_equal(color_np(b.eval_attribute("no_such_thing", si)), 0.0)
    # diffuse reflectance = base_color * (1 - metallic)
    np.testing.assert_allclose(_lanes(color_np(b.eval_diffuse_reflectance(si))),
                               [np.array(MAT["base_color"]) * 0.7] * 4, rtol=1e-6)


def test_eval_attribute_through_a_scene_intersection(scene):
    """The albedo AOV path: eval_attribute on the BSDFPtr of a real intersection."""
    ray = mi.Ray3f(mi.Point3f(-0.6, 0.0, 0.6), mi.Vector3f(0.0, -1.0, 0.0))     # onto the floor
    si = scene.ray_intersect(ray)
    assert si.is_valid()[0]
    bsdf = si.bsdf()
    assert bsdf.has_attribute("base_color")[0]
    np.testing.assert_allclose(color_np(bsdf.eval_attribute("base_color", si))[0], MAT["base_color"], rtol=1e-6)


def test_flags():
    f = draaw(**MAT).flags()
    for flag in (mi.BSDFFlags.DiffuseReflection, mi.BSDFFlags.GlossyReflection, mi.BSDFFlags.FrontSide):
        assert mi.has_flag(f, flag)
    for flag in (mi.BSDFFlags.BackSide, mi.BSDFFlags.Delta, mi.BSDFFlags.Transmission, mi.BSDFFlags.SpatiallyVarying):
        assert not mi.has_flag(f, flag)
    assert mi.has_flag(draaw(two_sided=True).flags(), mi.BSDFFlags.BackSide)
    b = draaw()
    assert b.component_count() == 2
    assert mi.has_flag(b.flags(0), mi.BSDFFlags.DiffuseReflection)
    assert mi.has_flag(b.flags(1), mi.BSDFFlags.GlossyReflection)


def test_to_string_and_repr(scene):
    b = draaw(**MAT, normalmap=[0.5, 0.5, 1.0], two_sided=True)
    s = str(b)
    assert s.startswith("DraawBSDF[") and repr(b) == s
    for piece in ("base_color=(0.8, 0.5, 0.3)", "roughness=0.4", "metallic=0.3", "specular=0.6",
                  "reflection=0.25", "direct_to_scatter=0.75", "normalmap=(0.5, 0.5, 1) (unsigned)",
                  "two_sided=True"):
        assert piece in s, (piece, s)
    bitmap = draaw(base_color=mi.TensorXf(np.zeros((3, 5, 3), np.float32)))
    assert "base_color=bitmap(5x3x3)" in str(bitmap)
    assert "DraawBSDF[" in str(scene)           # printing a whole scene works too


def test_instance_dict_holds_only_traversable_values():
    """dr.freeze traverses a Python plugin's instance ``__dict__`` on every frozen render, at
    about 3 us per plain Python value: plain options live in slots, constants are bare Dr.Jit
    arrays (benchmarks/results/render_overhead.md)."""
    for b in (draaw(**MAT), draaw(**MAT, normalmap=[0.5, 0.5, 1.0], two_sided=True, alpha_min=0.01)):
        for name, value in vars(b).items():
            assert isinstance(value, mi.Texture) or dr.is_array_v(value), (name, value)
        assert b.two_sided in (False, True) and b.alpha_min > 0     # still readable
    b = draaw(**MAT)
    assert isinstance(b.roughness, mi.Float) and isinstance(b.base_color, mi.Color3f)
    assert b.normalmap is None and "normalmap" not in vars(b)
    bitmap = draaw(roughness=mi.TensorXf(np.full((3, 2), 0.4, np.float32)))
    assert isinstance(bitmap.roughness, mi.Texture)             # spatially varying: a texture


@pytest.mark.parametrize("key", ["ball.base_color.value", "sky.radiance.value", "lamp.intensity.value",
                                 "sun.irradiance.value"])
def test_check_value_refuses_a_negative_colour_or_light_value(key):
    """A colour, radiance, point/spot intensity or irradiance below 0 is refused (the preview
    and the batch check their overrides with it; -5 rendered negative light); 0 is taken."""
    from draaw_mi.errors import ParameterError
    from draaw_mi.materials import check_value
    with pytest.raises(ParameterError, match=r"expected values >= 0"):
        check_value("demo", key, key, [1.0, -5.0, 1.0])
    check_value("demo", key, key, [0.0, 0.0, 0.0])


@pytest.mark.parametrize("key, lo, hi", [("ball.roughness.data", "0", "1"),
                                         ("ball.base_color.data", "0", "3.4e38"),
                                         ("ball.normalmap.data", "-1.01", "1.01"),
                                         ("sky.data", "-3.4e38", "3.4e38")])
def test_check_value_refuses_a_texture_with_a_nan_texel(key, lo, hi):
    """Every texture's texels are checked (a normal map's and an environment map's were not):
    finite, in the parameter's range; the first bad texel is named."""
    from draaw_mi.materials import check_value
    texels = np.full((3, 4, 3), 0.5)
    check_value("demo", key, key, texels)
    texels[2, 1, 0] = np.nan
    with pytest.raises(ParameterError, match=rf"demo: {re.escape(key)}: 1 texel value\(s\) outside "
                                             rf"\[{re.escape(lo)}, {re.escape(hi)}\] \(the first, nan, at \[2, 1, 0\]\)"):
        check_value("demo", key, key, texels)


def test_check_value_holds_a_normal_map_to_its_range():
    """A normal map's texels and constant (``--set``, the preview, a batch, ``out_of_range``)
    within [-1.01, 1.01], as a scene file has them (the encoding is not known here: the signed
    one's range, with the loader's slack); a 1e30 texel rendered black patches."""
    from draaw_mi.materials import check_value
    flat = np.full((2, 2, 3), [0.5, 0.5, 1.0])
    check_value("demo", "m.normalmap", "m.normalmap.data", flat)
    check_value("demo", "m.normalmap", "m.normalmap.value", [-1.0, 0.0, 1.005])
    with pytest.raises(ParameterError, match=r"demo: m\.normalmap: 12 texel value\(s\) outside "
                                             r"\[-1\.01, 1\.01\]"):
        check_value("demo", "m.normalmap", "m.normalmap.data", np.full((2, 2, 3), 1e30))
    with pytest.raises(ParameterError, match=r"demo: m\.normalmap=\[2\.0, 2\.0, 2\.0\]; expected normal-map "
                                             r"components in \[-1\.01, 1\.01\]"):
        check_value("demo", "m.normalmap", "m.normalmap.value", [2.0, 2.0, 2.0])


@pytest.mark.parametrize("key, value, match", [
    ("m.roughness.color0.value", 7.0, r"m\.roughness\.color0\.value=7\.0; expected a number in \[0\.0, 1\.0\]"),
    ("m.metallic.color1.value", -3.0, r"m\.metallic\.color1\.value=-3\.0; expected a number in \[0\.0, 1\.0\]"),
    ("m.roughness.color0.value", float("nan"), r"expected finite numbers"),
    ("m.base_color.color0.value", [0.5, -1.0, 0.5], r"expected values >= 0"),
])
def test_check_value_of_a_nested_textures_value_is_its_parameters(key, value, match):
    """A checkerboard's colour in a draaw parameter (``m.roughness.color0.value``) is held to
    that parameter's range: the parameter is the first known name of the key, not the one
    before ``value`` (``color0``, which is no parameter: 7 was let through)."""
    from draaw_mi.materials import check_value
    with pytest.raises(ParameterError, match=match):
        check_value("demo", key, key, value)
    check_value("demo", key, key, [0.3, 0.3, 0.3] if "base_color" in key else 0.3)


@pytest.mark.parametrize("key, value, match", [
    ("metal.alpha.value", -0.3, r"metal\.alpha=-0\.3; expected a number in \[0, inf\)"),
    ("pr.sheen.value", 3.0, r"pr\.sheen=3\.0; expected a number in \[0, 1\]"),
    ("glass.eta", 0.0, r"glass\.eta=0\.0; expected a number in \(0, inf\)"),
    ("white.reflectance.value", [-0.5, -0.5, -0.5], r"white\.reflectance=\[-0\.5, -0\.5, -0\.5\]; expected values >= 0"),
])
def test_check_value_holds_mitsubas_own_bsdfs_to_a_scene_files_ranges(key, value, match):
    """A batch override (or the preview's) of a plain Mitsuba BSDF's alpha, principled weight,
    eta or reflectance was taken as given, though a scene file refuses it: a diffuse
    reflectance of -0.5 rendered negative pixels."""
    from draaw_mi.materials import check_value
    name = key.removesuffix(".value")
    with pytest.raises(ParameterError, match=match):
        check_value("demo", name, key, value)
    check_value("demo", name, key, [0.5, 0.5, 0.5] if isinstance(value, list) else 0.5)

