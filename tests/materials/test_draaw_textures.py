"""Textured parameters and normal maps of the draaw BSDF, and the errors bad parameter values
raise (design.md §3).

Arrays reach the plugin as ``mi.TensorXf`` (a plain numpy array cannot be stored in
``mi.Properties``; draaw_mi's scene loader converts numpy arrays, tested below too).
"""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import drjit as dr
import mitsuba as mi
from draaw_mi.errors import ParameterError
from draaw_mi.materials.draaw_bsdf import DraawBSDF

from _draaw_helpers import color_np, cornell, draaw, make_si, uniform_hemisphere, vec3

CTX = mi.BSDFContext()
MAT = {"base_color": [0.8, 0.5, 0.3], "roughness": 0.4, "metallic": 0.3, "specular": 0.6}


def _tensor(a):
    return mi.TensorXf(np.ascontiguousarray(np.asarray(a, dtype=np.float32)))


def _render(material, spp=8, seed=5, res=32):
    """Cornell box, `path`, depth 3, the draaw material on boxes, floor and back wall."""
    scene = cornell(res, 3, override={"type": "draaw", **material})
    img = np.array(mi.render(scene, spp=spp, seed=seed))
    assert np.all(np.isfinite(img))
    return img


@pytest.fixture(scope="module")
def reference_image():
    return _render(MAT)


# ---------------------------------------------------------------------------- bitmaps
@pytest.mark.parametrize("name", ["base_color", "roughness", "metallic", "specular"])
def test_constant_bitmap_renders_like_the_constant(name, reference_image):
    value = MAT[name]
    shape = (5, 7, 3) if name == "base_color" else (5, 7)
    arr = np.broadcast_to(np.asarray(value, dtype=np.float32), shape)
    img = _render(dict(MAT, **{name: _tensor(arr)}))
    np.testing.assert_allclose(img, reference_image, rtol=1e-5, atol=1e-6)


def test_bitmap_lookup_at_texel_centres():
    """uv (u, v) reads texel [row = v H, col = u W], as Mitsuba's bitmap does; colour data are
    used as given (linear), scalar data raw."""
    rng = np.random.default_rng(1)
    h, w = 3, 4
    base = rng.random((h, w, 3)).astype(np.float32)
    rough = rng.random((h, w)).astype(np.float32)
    b = draaw(base_color=_tensor(base), roughness=_tensor(rough))
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    uv = np.stack([(cols.ravel() + 0.5) / w, (rows.ravel() + 0.5) / h], axis=-1)
    si = make_si(np.tile([0.0, 0.0, 1.0], (h * w, 1)), uv=uv)
    np.testing.assert_allclose(color_np(b.eval_attribute("base_color", si)), base.reshape(-1, 3), rtol=1e-5)
    np.testing.assert_allclose(np.array(b.eval_attribute_1("roughness", si)), rough.ravel(), rtol=1e-5)
    assert mi.has_flag(b.flags(), mi.BSDFFlags.SpatiallyVarying)
    assert not mi.has_flag(draaw(**MAT).flags(), mi.BSDFFlags.SpatiallyVarying)


def test_varying_bitmaps_change_the_render_and_are_differentiable(reference_image):
    checker = (np.indices((8, 8)).sum(axis=0) % 2).astype(np.float32)
    base = np.stack([0.2 + 0.7 * checker, 0.5 * np.ones((8, 8)), 0.9 - 0.7 * checker], -1)
    rough = 0.1 + 0.8 * checker
    img = _render(dict(MAT, base_color=_tensor(base), roughness=_tensor(rough)))
    assert np.abs(img - reference_image).mean() > 1e-3

    scene = cornell(32, 3, integrator="prb",
                    override={"type": "draaw", **dict(MAT, base_color=_tensor(base), roughness=_tensor(rough))})
    p = mi.traverse(scene)
    for key in ("mat.base_color.data", "mat.roughness.data"):
        assert key in p.keys() and not (p.flags(key) & mi.ParamFlags.NonDifferentiable)
        dr.enable_grad(p[key])
    p.update()
    dr.backward(dr.mean(mi.render(scene, p, spp=16, seed=2), axis=None))
    for key in ("mat.base_color.data", "mat.roughness.data"):
        g = np.array(dr.grad(p[key]))
        assert np.all(np.isfinite(g)) and np.abs(g).max() > 0, key


def test_numpy_arrays_through_the_scene_loader(tiny_desc):
    """draaw_mi.load_scene turns numpy arrays in a description into bitmap parameters."""
    rng = np.random.default_rng(4)
    tiny_desc["materials"]["ball"]["base_color"] = rng.random((4, 6, 3))
    tiny_desc["materials"]["ball"]["roughness"] = rng.random((4, 6))
    tiny_desc["materials"]["ball"]["metallic"] = np.full((2, 2), 0.5)
    scene = draaw_mi.load_scene(tiny_desc)
    bsdfs = [str(sh.bsdf()) for sh in scene.mi_scene.shapes()]
    assert any("base_color=bitmap(6x4x3)" in s and "roughness=bitmap(6x4x1)" in s
               and "metallic=bitmap(2x2x1)" in s for s in bsdfs), bsdfs
    img = mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "path", "max_depth": 3}), spp=4)
    assert np.all(np.isfinite(np.array(img)))


# ---------------------------------------------------------------------------- normal maps
FLAT = [
    ({"normalmap": [0.5, 0.5, 1.0]}, "unsigned constant"),
    ({"normalmap": _tensor(np.tile([0.5, 0.5, 1.0], (4, 4, 1)))}, "unsigned bitmap"),
    ({"normalmap": [0.0, 0.0, 1.0], "normalmap_encoding": "signed"}, "signed constant"),
    ({"normalmap": _tensor(np.tile([0.0, 0.0, 1.0], (4, 4, 1))), "normalmap_encoding": "signed"}, "signed bitmap"),
]


@pytest.mark.parametrize("extra", [f[0] for f in FLAT], ids=[f[1] for f in FLAT])
def test_flat_normal_map_is_a_no_op(extra, reference_image):
    rng = np.random.default_rng(2)
    wi, wo = uniform_hemisphere(4096, rng), uniform_hemisphere(4096, rng)
    si = make_si(wi, uv=rng.random((4096, 2)))
    a = color_np(draaw(**MAT, **extra).eval(CTX, si, vec3(wo)))
    b = color_np(draaw(**MAT).eval(CTX, si, vec3(wo)))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(_render(dict(MAT, **extra)), reference_image, rtol=1e-5, atol=1e-6)


def test_a_normal_map_file_is_read_as_data(tmp_path):
    """A PNG normal map holds directions, not colours: read without the sRGB curve. Decoded,
    a flat map's 128 became 0.22 and tilted every normal by about 30 degrees. Reference: the
    same texel given as a constant."""
    path = str(tmp_path / "flat.png")
    mi.Bitmap(np.full((4, 4, 3), [128, 128, 255], np.uint8)).write(path)
    rng = np.random.default_rng(3)
    wi, wo = uniform_hemisphere(4096, rng), uniform_hemisphere(4096, rng)
    si = make_si(wi, uv=rng.random((4096, 2)))
    a = color_np(draaw(**MAT, normalmap=path).eval(CTX, si, vec3(wo)))
    b = color_np(draaw(**MAT, normalmap=[128 / 255, 128 / 255, 1.0]).eval(CTX, si, vec3(wo)))
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)


def _tilted_frame(n):
    n = np.asarray(n, dtype=np.float64)
    n = n / np.linalg.norm(n)
    t = np.array([1.0, 0.0, 0.0]) - n * n[0]
    t /= np.linalg.norm(t)
    return np.stack([t, np.cross(n, t), n])          # rows: tangent, bitangent, normal


@pytest.mark.parametrize("n_signed", [[0.36, 0.1, 0.93], [-0.5, 0.3, 0.81], [0.0, -0.7, 0.71]])
def test_tilted_normal_map_rotates_the_shading_frame(n_signed):
    """Tilted map == the plain BSDF evaluated in the rotated frame (tangent x - n n.x), for
    both encodings, and == Mitsuba's `normalmap` adapter around the plain BSDF (with its
    flip_invalid_normals and shadow-terminator extras off)."""
    rng = np.random.default_rng(3)
    n = 4096
    wi, wo = uniform_hemisphere(n, rng), uniform_hemisphere(n, rng)
    si = make_si(wi)
    si.dp_du = mi.Vector3f(1, 0, 0)
    unsigned = (np.asarray(n_signed) + 1.0) / 2.0
    signed_b = draaw(**MAT, normalmap=_tensor(np.tile(n_signed, (2, 2, 1))), normalmap_encoding="signed")
    unsigned_b = draaw(**MAT, normalmap=_tensor(np.tile(unsigned, (2, 2, 1))))
    a = color_np(signed_b.eval(CTX, si, vec3(wo)))
    b = color_np(unsigned_b.eval(CTX, si, vec3(wo)))
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)

    R = _tilted_frame(n_signed)
    wi_l, wo_l = wi @ R.T, wo @ R.T
    manual = color_np(draaw(**MAT).eval(CTX, make_si(wi_l), vec3(wo_l)))
    np.testing.assert_allclose(a, manual, rtol=1e-3, atol=1e-5)
    assert np.all(a[(wi_l[:, 2] <= 0) | (wo_l[:, 2] <= 0)] == 0)

    adapter = mi.load_dict({"type": "normalmap", "flip_invalid_normals": False, "use_shadowing_function": False,
                            "normalmap": {"type": "bitmap", "raw": True,
                                          "data": _tensor(np.tile(unsigned, (2, 2, 1)))},
                            "bsdf": {"type": "draaw", **MAT}})
    c = color_np(adapter.eval(CTX, si, vec3(wo)))
    np.testing.assert_allclose(b, c, rtol=1e-4, atol=1e-6)
    pdf_b = np.array(unsigned_b.pdf(CTX, si, vec3(wo)))
    pdf_c = np.array(adapter.pdf(CTX, si, vec3(wo)))
    np.testing.assert_allclose(pdf_b, pdf_c, rtol=1e-4, atol=1e-6)


def test_tilted_normal_map_changes_the_render(reference_image):
    rng = np.random.default_rng(6)
    nm = rng.normal(size=(16, 16, 3)) * [0.4, 0.4, 0.1] + [0.0, 0.0, 1.0]
    nm /= np.linalg.norm(nm, axis=-1, keepdims=True)
    nm[0, 0] = 0.0                       # a zero texel (falls back to the geometric normal)
    nm[0, 1] = [1.0, 0.0, 0.0]           # a texel lying in the surface
    nm[0, 2] = [0.0, 0.0, -1.0]          # one pointing into the surface
    img = _render(dict(MAT, normalmap=_tensor(nm), normalmap_encoding="signed", two_sided=True))
    assert np.abs(img - reference_image).mean() > 1e-3
    img_u = _render(dict(MAT, normalmap=_tensor(np.clip((nm + 1.0) / 2.0, 0, 1))))
    assert np.abs(img_u - reference_image).mean() > 1e-3


# ---------------------------------------------------------------------------- bad values
def _nan_tensor():
    a = np.full((2, 2, 3), 0.5, dtype=np.float32)
    a[1, 0, 2] = np.nan
    return _tensor(a)


BAD = [
    # (properties, strings the message must contain)
    ({"roughness": 1.5}, ["roughness", "1.5"]),
    ({"roughness": -0.1}, ["roughness", "-0.1"]),
    ({"metallic": float("nan")}, ["metallic", "nan"]),
    ({"specular": float("inf")}, ["specular", "inf"]),
    ({"reflection": 2.0}, ["reflection", "2"]),
    ({"direct_to_scatter": -1.0}, ["direct_to_scatter", "-1"]),
    ({"base_color": [1.0, -0.5, 0.0]}, ["base_color", "-0.5"]),
    ({"base_color": _nan_tensor()}, ["base_color", "nan"]),
    ({"roughness": _tensor(np.array([[0.2, 1.25]]))}, ["roughness", "1.25"]),
    ({"metallic": _tensor(np.array([[-0.5, 0.2]]))}, ["metallic", "-0.5"]),
    ({"roughness": True}, ["roughness", "True"]),
    ({"roughness": "no/such/roughness.png"}, ["roughness", "no/such/roughness.png"]),
    ({"base_color": "missing_base.exr"}, ["base_color", "missing_base.exr"]),
    ({"roughness": [0.1, 0.2, 0.3]}, ["roughness", "0.1"]),
    ({"normalmap": _tensor(np.zeros((2, 2, 2)))}, ["normalmap", "(2, 2, 2)"]),
    ({"normalmap_encoding": "sined"}, ["normalmap_encoding", "sined"]),
    ({"normalmap_encoding": 1}, ["normalmap_encoding", "1"]),
    ({"alpha_min": 0.0}, ["alpha_min", "0"]),
    ({"alpha_min": 0.5}, ["alpha_min", "0.5"]),
    ({"alpha_min": "tiny"}, ["alpha_min", "tiny"]),
    ({"two_sided": "yes"}, ["two_sided", "yes"]),
]


@pytest.mark.parametrize("props,needles", BAD, ids=[f"{list(b[0])[0]}={b[1][1]}" for b in BAD])
def test_bad_value_error_names_parameter_and_value(props, needles):
    """Through mi.load_dict Mitsuba wraps the plugin's ParameterError in a RuntimeError whose
    text carries it; draaw_mi's scene loader unwraps it again."""
    with pytest.raises(RuntimeError) as info:
        mi.load_dict({"type": "draaw", **props})
    msg = str(info.value)
    assert "ParameterError" in msg, msg
    line = msg[msg.rindex("ParameterError"):]
    for needle in needles:
        assert needle in line, (needle, line)


@pytest.mark.parametrize("name,value", [("roughness", 1.5), ("metallic", -1.0), ("normalmap_encoding", "x"),
                                        ("alpha_min", 1.0), ("two_sided", 1)])
def test_direct_construction_raises_parameter_error(name, value):
    props = mi.Properties("draaw")
    props[name] = value
    with pytest.raises(ParameterError, match=name):
        DraawBSDF(props)


def test_nested_texture_with_out_of_range_values_is_rejected():
    with pytest.raises(RuntimeError, match=r"ParameterError: .*roughness=1\.7"):
        mi.load_dict({"type": "draaw", "roughness": {"type": "uniform", "value": 1.7}})


def test_values_outside_reflectance_range_are_accepted_where_allowed():
    """base_color has no upper bound (emissive-looking albedo is the user's call) and a signed
    constant normal map may have negative components: both load and evaluate finitely."""
    rng = np.random.default_rng(8)
    wi, wo = uniform_hemisphere(256, rng), uniform_hemisphere(256, rng)
    for kw in ({"base_color": [2.0, 1.0, 0.5]}, {"base_color": 1.5},
               {"normalmap": [-0.3, 0.2, 0.9], "normalmap_encoding": "signed"}):
        b = draaw(**kw)
        v = color_np(b.eval(CTX, make_si(wi), vec3(wo)))
        assert np.all(np.isfinite(v)) and v.max() > 0, kw


def test_a_texture_file_name_is_checked_and_found_beside_an_xml_scene(tmp_path, monkeypatch):
    """A file name was not range-checked (a NaN roughness file rendered NaN; the same file in a
    nested bitmap table is refused) and was looked up in the working directory only, not in
    the XML scene's folder where Mitsuba's own bitmap finds it."""
    bad = np.full((4, 4, 3), 0.5, np.float32)
    bad[0, 0] = np.nan
    mi.Bitmap(bad).write(str(tmp_path / "bad.exr"))
    monkeypatch.chdir(tmp_path)
    for name in ("roughness", "base_color", "metallic"):
        with pytest.raises(RuntimeError, match=rf"ParameterError: .*{name}=nan \(texture values\) is not finite"):
            mi.load_dict({"type": "draaw", name: "bad.exr"})
    (tmp_path / "xd").mkdir()
    mi.Bitmap(np.full((4, 4, 1), 0.3, np.float32)).write(str(tmp_path / "xd" / "rough.exr"))
    (tmp_path / "xd" / "s.xml").write_text('<scene version="3.0.0"><bsdf type="draaw" id="b">'
                                          '<string name="roughness" value="rough.exr"/></bsdf></scene>')
    monkeypatch.chdir("/")
    params = mi.traverse(mi.load_file(str(tmp_path / "xd" / "s.xml")))
    np.testing.assert_allclose(np.array(params["b.roughness.data"]).ravel(), 0.3)


@pytest.mark.parametrize("texel", [[0.3, 0.2, -0.5], [0.0, 0.0, 0.0]])
def test_a_normal_map_texel_below_the_surface_falls_back_to_the_normal(texel):
    """A texel pointing below the surface (or of zero length) cannot be a shading normal: the
    BSDF evaluates as without the map (it was black: every direction below that frame)."""
    rng = np.random.default_rng(4)
    wi, wo = uniform_hemisphere(64, rng), uniform_hemisphere(64, rng)
    mapped = draaw(base_color=0.6, roughness=0.4, normalmap=texel, normalmap_encoding="signed")
    plain = draaw(base_color=0.6, roughness=0.4)
    a, b = (color_np(m.eval(CTX, make_si(wi), vec3(wo))) for m in (mapped, plain))
    assert b.max() > 0 and np.allclose(a, b, rtol=1e-5, atol=1e-7)


def _png8(path, value, channels=1):
    """An 8-bit sRGB-tagged PNG (what an image editor writes) of one value."""
    from PIL import Image
    arr = np.full((4, 4, channels), value, np.uint8)
    Image.fromarray(arr[..., 0] if channels == 1 else arr, "L" if channels == 1 else "RGB").save(path)
    return str(path)


@pytest.mark.parametrize("name, value, channels", [("roughness", 102, 1), ("metallic", 102, 1),
                                                   ("normalmap", (128, 128, 255), 3)])
def test_a_nested_bitmap_of_a_data_parameter_must_be_raw(tmp_path, name, value, channels):
    """A Mitsuba ``bitmap`` nested for a data parameter (XML ``<texture type="bitmap">``, a
    dict) is sRGB-decoded by Mitsuba unless raw: roughness 0.4 was looked up as 0.133 and a
    flat normal map tilted 39 degrees, silently. Without raw it is refused, naming the
    parameter and the fix; with raw it loads and reads the file's 0.4; a colour parameter's
    bitmap is decoded as a colour should be."""
    path = _png8(tmp_path / f"{name}.png", value if channels == 1 else np.array(value), channels)
    with pytest.raises(RuntimeError, match=rf"ParameterError: draaw BSDF: {name}: a bitmap texture of 8-bit texels "
                                             r"\(.*\.png\) read without raw.*<boolean name=\"raw\" value=\"true\"/>"):
        mi.load_dict({"type": "draaw", name: {"type": "bitmap", "filename": path}})
    xml = (f'<bsdf version="3.0.0" type="draaw"><texture type="bitmap" name="{name}">'
           f'<string name="filename" value="{path}"/></texture></bsdf>')
    with pytest.raises(RuntimeError, match=rf"ParameterError: draaw BSDF: {name}: a bitmap texture of 8-bit"):
        mi.load_string(xml)
    b = mi.load_dict({"type": "draaw", name: {"type": "bitmap", "filename": path, "raw": True}})
    if channels == 1:                    # (looked up as 102/255 = 0.4, not 0.133)
        si = make_si([[0.0, 0.0, 1.0]], uv=[[0.5, 0.5]])
        assert float(np.array(b.eval_attribute_1(name, si))[0]) == pytest.approx(value / 255, abs=1e-6)
    mi.load_dict({"type": "draaw", "base_color": {"type": "bitmap", "filename": _png8(tmp_path / "c.png", 188, 3)}})


def test_a_nested_half_float_exr_of_a_data_parameter_needs_no_raw(tmp_path):
    """Mitsuba never decodes an EXR; its half floats were refused as if they were a 16-bit PNG's."""
    path = str(tmp_path / "rough_half.exr")
    mi.Bitmap(np.full((4, 4, 1), 0.4, np.float16)).write(path)
    b = mi.load_dict({"type": "draaw", "roughness": {"type": "bitmap", "filename": path}})
    si = make_si([[0.0, 0.0, 1.0]], uv=[[0.5, 0.5]])
    assert float(np.array(b.eval_attribute_1("roughness", si))[0]) == pytest.approx(0.4, abs=1e-3)


@pytest.mark.parametrize("name, table, match", [
    ("roughness", {"color0": float("nan"), "color1": 0.5}, r"roughness=nan \(texture's color0\.value\) is not finite"),
    ("metallic", {"color0": 7.0, "color1": 0.5}, r"metallic=7 \(texture's color0\.value\) is above 1\.0"),
    ("metallic", {"color0": 0.5, "color1": -3.0}, r"metallic=-3 \(texture's color1\.value\) is below 0\.0"),
])
def test_a_nested_checkerboards_values_are_range_checked(name, table, match):
    """A texture that is not a bitmap (a checkerboard) holds its values as ``color0.value``
    and ``color1.value``: each is held to the parameter's range (a NaN roughness and a
    metallic of 7 and -3 loaded without a word)."""
    with pytest.raises(RuntimeError, match="ParameterError: draaw BSDF: " + match):
        mi.load_dict({"type": "draaw", name: {"type": "checkerboard", **table}})
    mi.load_dict({"type": "draaw", name: {"type": "checkerboard", "color0": 0.2, "color1": 0.9}})
