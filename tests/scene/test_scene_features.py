"""Scene-file features against closed forms: spot, directional, envmap, disk and sphere area
lights, ``emission`` on shapes, ``matrix`` transforms, bare ``.ply``/``.glb`` meshes, MTL
``map_Kd`` and image-file textures (base colour sRGB-decoded, roughness/metallic raw).

The light tests look at a Lambertian floor (draaw with specular = metallic = 0, exactly
Lambert) at max_depth 2 (direct light only): its radiance is ``albedo / pi * E`` with ``E`` the
irradiance of the light, known in closed form at the points checked.
"""
from __future__ import annotations

import math
import re

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import SceneError

ALBEDO = np.array([0.6, 0.5, 0.4])


def _floor_scene(lights, res=(15, 15), max_depth=2, extra_shapes=(), camera=None):
    return draaw_mi.load_scene({
        "render": {"resolution": list(res), "max_depth": max_depth, "filter": "box"},
        "camera": camera or {"origin": [0, 4, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30},
        "materials": {"lambert": {"base_color": ALBEDO.tolist(), "specular": 0.0, "metallic": 0.0}},
        "shapes": [{"type": "rectangle", "name": "floor", "material": "lambert", "scale": 50,
                    "rotate": {"axis": [1, 0, 0], "angle": -90}}] + list(extra_shapes),
        "lights": lights,
    })


def _hit_points(scene, sub: int = 0):
    """World positions seen through the pixel centres (Mitsuba ray casts), (H, W, 3); with
    ``sub``, through ``sub`` x ``sub`` points of each pixel, (H, W, sub * sub, 3)."""
    mis, (w, h) = scene.mi_scene, scene.resolution
    k = max(sub, 1)
    yy, xx = np.mgrid[0:h * k, 0:w * k]
    pos = mi.Point2f(mi.Float(((xx.ravel() + 0.5) / (w * k)).astype(np.float32)),
                     mi.Float(((yy.ravel() + 0.5) / (h * k)).astype(np.float32)))
    ray, _ = mis.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))
    si = mis.ray_intersect(ray)
    assert np.array(si.is_valid()).all()
    p = np.stack([np.array(si.p.x), np.array(si.p.y), np.array(si.p.z)], -1).reshape(h, k, w, k, 3)
    p = p.transpose(0, 2, 1, 3, 4).reshape(h, w, k * k, 3)
    return p if sub else p[:, :, 0]


def _render(scene, spp, seed=0):
    return np.array(draaw_mi.render(scene, version="path", spp=spp, seed=seed), dtype=np.float64)


def test_spot_light_cone_and_falloff():
    h, intensity = 2.0, 10.0
    scene = _floor_scene([{"type": "spot", "position": [0, h, 0], "target": [0, 0, 0], "intensity": intensity,
                           "cutoff_angle": 30.0, "beam_width": 20.0}])
    img, p = _render(scene, 64), _hit_points(scene)
    cos = h / np.sqrt(p[..., 0] ** 2 + h ** 2 + p[..., 2] ** 2)
    angle = np.degrees(np.arccos(cos))
    expected = ALBEDO / math.pi * (intensity * cos ** 3 / h ** 2)[..., None]     # E = I cos / r^2
    inner, outer = angle < 15.0, angle > 36.0          # clear of the cone's edge by a pixel
    assert inner.sum() >= 9 and outer.sum() >= 9
    assert np.allclose(img[inner], expected[inner], rtol=0.02)
    assert np.all(img[outer] == 0)
    # between beam_width and cutoff_angle the intensity falls linearly in the angle (Mitsuba's
    # spot: (cutoff - theta) / (cutoff - beam_width)): each pixel touching the band against
    # that law averaged over 8x8 points of its footprint (a pixel spans several degrees and the
    # ramp has kinks at 20 and 30 degrees); 256 spp: the estimate's noise is about 1 %
    p8 = _hit_points(scene, sub=8)
    cos8 = h / np.sqrt(p8[..., 0] ** 2 + h ** 2 + p8[..., 2] ** 2)
    ramp8 = np.clip((30.0 - np.degrees(np.arccos(cos8))) / (30.0 - 20.0), 0.0, 1.0)
    values = ALBEDO / math.pi * (intensity * cos8 ** 3 / h ** 2 * ramp8)[..., None]     # (H, W, 64, 3)
    law = values.mean(axis=2)
    band = (angle > 18.0) & (angle < 32.0) & (law[..., 0] > 0.01)
    assert band.sum() >= 9
    img256 = _render(scene, 256)
    # the only noise is where in the pixel each of the 256 samples lands: 4 of its standard errors
    se = values.std(axis=2) / np.sqrt(256)
    assert np.all(np.abs(img256[band] - law[band]) <= 4 * se[band] + 2e-3 * law[band])
    hard = ALBEDO / math.pi * (intensity * cos8 ** 3 / h ** 2 * (np.degrees(np.arccos(cos8)) < 30)).mean(axis=2)[..., None]
    assert np.abs(img256[band] / hard[band] - 1).max() > 0.2       # (a hard-edged cone fails this)


def test_directional_light_irradiance():
    d = np.array([1.0, -2.0, 0.5])
    scene = _floor_scene([{"type": "directional", "direction": d.tolist(), "intensity": 3.0,
                           "color": [1.0, 0.5, 0.25]}])
    img = _render(scene, 4)
    cos = 2.0 / np.linalg.norm(d)
    assert np.allclose(img, ALBEDO / math.pi * 3.0 * np.array([1.0, 0.5, 0.25]) * cos, rtol=1e-4)


def test_envmap_light_is_read_and_scaled(tmp_path):
    c = np.array([0.3, 0.5, 0.7], np.float32)
    draaw_mi.write_exr(str(tmp_path / "env.exr"), np.broadcast_to(c, (8, 16, 3)).copy())
    scene = _floor_scene([{"type": "envmap", "file": str(tmp_path / "env.exr"), "intensity": 2.0}], res=(8, 8))
    img = _render(scene, 256)
    # a uniform environment over the upper hemisphere: E = pi L, radiance = albedo L
    assert np.allclose(img.mean(axis=(0, 1)), ALBEDO * c * 2.0, rtol=0.01)
    assert np.abs(img - ALBEDO * c * 2.0).max() < 0.1 * (ALBEDO * c * 2.0).max()       # per pixel: noise


@pytest.mark.parametrize("shape", ["disk", "disk_size", "sphere"])
def test_area_lights_irradiance_below_them(shape):
    """Point below the light's centre at distance h: a facing disk of radius R gives
    E = pi L R^2 / (h^2 + R^2); a sphere of radius R gives E = pi L (R / h)^2."""
    h, r, radiance = 2.0, 0.4, 5.0
    light = {"type": "area", "shape": shape.split("_")[0], "position": [0, h, 0], "intensity": radiance}
    if shape != "sphere":
        light["target"] = [0, 0, 0]
    light.update({"size": [2 * r, 2 * r]} if shape == "disk_size" else {"radius": r})
    scene = _floor_scene([light], res=(9, 9),
                         camera={"origin": [0, 3, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 8})
    img, p = _render(scene, 1024), _hit_points(scene)
    assert np.linalg.norm(p[4, 4]) < 0.01                        # the centre pixel sees (0, 0, 0)
    e = math.pi * radiance * (r * r / (h * h + r * r) if shape != "sphere" else (r / h) ** 2)
    assert np.allclose(img[4, 4], ALBEDO / math.pi * e, rtol=0.02)


@pytest.mark.parametrize("shape, extra, match", [
    ("disk", {"radius": 0.0}, "radius"),
    ("disk", {"radius": 0.3, "size": [1.0, 1.0]}, "not both"),
    ("rectangle", {"radius": 0.3}, "rectangle area light has no 'radius'.*'size'"),
    ("sphere", {"size": [1.0, 1.0]}, "sphere area light has no 'size'.*'radius'"),
])
def test_an_area_light_refuses_a_size_its_shape_does_not_take(shape, extra, match):
    """A key that sizes another shape was accepted and ignored: a disk of radius 0.1, 2 or 0
    lit the scene as the default one of radius 0.5."""
    light = {"type": "area", "shape": shape, "position": [0, 2, 0], "target": [0, 0, 0], **extra}
    with pytest.raises(SceneError, match=match):
        _floor_scene([light], res=(8, 8))


@pytest.mark.parametrize("key, value", [("target", [0, 0, 0]), ("up", [0, 0, 1])])
def test_a_sphere_area_light_refuses_a_direction(key, value):
    """A sphere shines all around: its 'target' and 'up' were accepted and changed nothing."""
    light = {"type": "area", "shape": "sphere", "position": [0, 2, 0], "radius": 0.3, key: value}
    with pytest.raises(SceneError, match=f"lights\\[0\\]\\.{key}.*sphere area light .*no '{key}'"):
        _floor_scene([light], res=(8, 8))



@pytest.mark.parametrize("shape", ["rectangle", "disk", "sphere"])
def test_an_area_light_needs_a_position(shape):
    """An area light without 'position' sat at the origin, in this floor: a black image."""
    with pytest.raises(SceneError, match=rf"^<dict>: lights\[0\]: an area light needs 'position' \(the centre of its {shape}\)$"):
        _floor_scene([{"type": "area", "shape": shape, "intensity": 5.0}], res=(8, 8))


def _toml(folder, text):
    (folder / "s.toml").write_text(text)
    return folder / "s.toml"


def test_a_missing_envmap_says_where_it_was_looked_for(tmp_path):
    """The error named the file as written, not the path it was looked for at (beside the
    scene file)."""
    path = str(tmp_path / "nope.exr")
    with pytest.raises(SceneError, match=r"lights\[0\].file: environment map 'nope.exr' does not exist "
                                         rf"\(looked for '{re.escape(path)}'\)"):
        draaw_mi.load_scene(str(_toml(tmp_path, '[[shapes]]\ntype = "sphere"\n'
                                                 '[[lights]]\ntype = "envmap"\nfile = "nope.exr"\n')))


def test_emission_on_shapes():
    scene = _floor_scene([], max_depth=1, extra_shapes=[
        {"type": "sphere", "name": "glow", "center": [0, 0.5, 0], "radius": 0.5, "emission": [2.0, 1.0, 0.5],
         "emission_color": [1.0, 1.0, 2.0]}])
    img = _render(scene, 4)
    assert np.allclose(img[7, 7], [2.0, 1.0, 1.0], atol=1e-5)        # inside the sphere's image
    assert np.all(img[0, 0] == 0)                                     # the floor does not glow


def test_matrix_transform_is_row_major_world_matrix():
    m = [[2, 0, 0, 1], [0, 3, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]
    scene = draaw_mi.load_scene({"shapes": [{"type": "rectangle", "name": "r", "matrix": m}],
                                 "lights": [{"type": "constant"}],
                                 "camera": {"origin": [0, 0, 10], "target": [0, 0, 0]}})
    bb = scene.mi_scene.shapes()[0].bbox()
    assert np.allclose(np.array(bb.min), [-1, -1, 3]) and np.allclose(np.array(bb.max), [3, 5, 3])


@pytest.mark.parametrize("suffix", [".ply", ".glb"])
def test_bare_mesh_files(tmp_path, suffix):
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=[1.0, 2.0, 3.0])
    box.apply_translation([0.5, 1.0, -2.0])
    path = str(tmp_path / f"box{suffix}")
    box.export(path)
    scene = draaw_mi.load_scene(path, resolution=(16, 16), spp=4)
    meshes = [s for s in scene.mi_scene.shapes() if s.is_mesh() and s.emitter() is None]
    assert len(meshes) == 1 and meshes[0].face_count() == 12
    bb = meshes[0].bbox()
    assert np.allclose(np.array(bb.min), box.bounds[0], atol=1e-5)
    assert np.allclose(np.array(bb.max), box.bounds[1], atol=1e-5)
    img = _render(scene, 4)
    assert np.isfinite(img).all() and (img.sum(axis=2) > 0).mean() > 0.05      # framed and lit
    # the same box 100x larger is framed and lit alike: the light at the camera follows the
    # size (intensity ~ distance^2), so the image is the same up to noise
    box.apply_scale(100.0)
    box.export(path)
    big = _render(draaw_mi.load_scene(path, resolution=(16, 16), spp=4), 4)
    assert big.mean() == pytest.approx(img.mean(), rel=0.1)


def _png(path, rgb8):
    import matplotlib.image
    matplotlib.image.imsave(str(path), np.broadcast_to(np.array(rgb8, np.uint8), (4, 4, 3)).copy())


def _decode(v8):
    x = np.asarray(v8, float) / 255
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _attribute(scene, shape_index=0, name="base_color"):
    bsdf = scene.mi_scene.shapes()[shape_index].bsdf()
    si = dr_zeros_si()
    if name == "base_color":
        return np.array(bsdf.eval_attribute(name, si)).ravel()
    return float(np.array(bsdf.eval_attribute_1(name, si)).ravel()[0])


def dr_zeros_si():
    import drjit as dr
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.uv = mi.Point2f(0.5, 0.5)
    return si


def test_image_textures_decode_colour_and_keep_data_raw(tmp_path):
    _png(tmp_path / "base.png", [200, 100, 50])
    _png(tmp_path / "rough.png", [128, 128, 128])
    _png(tmp_path / "metal.png", [64, 64, 64])
    scene = _floor_scene([{"type": "constant", "intensity": 1.0}], res=(6, 6))
    desc = {"materials": {"tex": {"base_color": "base.png", "roughness": "rough.png", "metallic": "metal.png",
                                  "specular": 0.0}},
            "shapes": [{"type": "rectangle", "material": "tex", "scale": 50,
                        "rotate": {"axis": [1, 0, 0], "angle": -90}}],
            "lights": [{"type": "constant", "intensity": 1.0}],
            "render": {"resolution": [6, 6], "max_depth": 2},
            "camera": {"origin": [0, 4, 4], "target": [0, 0, 0]}}
    import json
    (tmp_path / "s.json").write_text(json.dumps(desc))
    scene = draaw_mi.load_scene(str(tmp_path / "s.json"))
    assert np.allclose(_attribute(scene), _decode([200, 100, 50]), atol=1e-4)        # sRGB-decoded
    assert _attribute(scene, name="roughness") == pytest.approx(128 / 255, abs=1e-4)   # raw
    assert _attribute(scene, name="metallic") == pytest.approx(64 / 255, abs=1e-4)     # raw
    # rendered: Lambert part under a uniform sky of 1 = base (1 - metallic) (no Fresnel: specular 0,
    # but metallic gives F0 = lerp(0, base, m), so compare with metallic 0 instead)
    desc["materials"]["tex"]["metallic"] = 0.0
    (tmp_path / "s.json").write_text(json.dumps(desc))
    img = _render(draaw_mi.load_scene(str(tmp_path / "s.json")), 256)
    assert np.allclose(img.mean(axis=(0, 1)), _decode([200, 100, 50]), rtol=0.02)


@pytest.mark.parametrize("table, key, colour", [
    ({"type": "thindielectric"}, "specular_transmittance", True),
    ({"type": "roughdielectric"}, "specular_transmittance", True),
    ({"type": "roughconductor"}, "specular_reflectance", True),
    ({"type": "roughconductor"}, "alpha", False),
])
def test_image_files_of_other_mitsuba_bsdfs_decode_colours_and_keep_data_raw(tmp_path, key, table, colour):
    """A PNG transmittance was read raw (only four reflectance names were decoded), so the
    same image made a glass's tint lighter than a reflectance's. Mitsuba's ``bitmap`` decodes
    sRGB where ``raw`` is false (it keeps 8-bit data and decodes on lookup); the texture of
    the loaded BSDF is compared with one made from the file by hand."""
    from draaw_mi.scene.context import BuildContext
    from draaw_mi.scene.material_dicts import material_dict
    from draaw_mi.scene.schema import Where
    _png(tmp_path / "t.png", [200, 100, 50])
    out = material_dict("m", dict(table, **{key: "t.png"}), BuildContext(str(tmp_path), str(tmp_path), "s.toml"),
                       Where("materials.m"))
    assert out[key] == {"type": "bitmap", "filename": str(tmp_path / "t.png"), "raw": not colour}
    tex = mi.load_dict(out[key])
    si = dr_zeros_si()
    value = np.array(tex.eval(si)).ravel()
    expect = _decode([200, 100, 50]) if colour else np.array([200, 100, 50]) / 255
    assert np.allclose(value, expect, atol=2e-3), (value, expect)
    mi.load_dict(out)                                      # the BSDF takes it


def test_mtl_map_kd_texture_is_srgb_decoded(tmp_path):
    _png(tmp_path / "kd.png", [200, 100, 50])
    (tmp_path / "m.mtl").write_text("newmtl tex\nKd 1 1 1\nmap_Kd kd.png\n")
    (tmp_path / "m.obj").write_text(
        "mtllib m.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "usemtl tex\nf 1/1 4/4 3/3\nf 1/1 3/3 2/2\n")
    scene = draaw_mi.load_scene(str(tmp_path / "m.obj"), resolution=(8, 8), spp=4)
    mesh = next(i for i, s in enumerate(scene.mi_scene.shapes()) if s.is_mesh() and s.emitter() is None)
    assert np.allclose(_attribute(scene, mesh), _decode([200, 100, 50]), atol=2e-3)


def _tinted_quad(path, factor, rgb8):
    """A uv-mapped quad .glb whose PBR material has ``baseColorFactor`` ``factor`` and a 4x4
    ``baseColorTexture`` of the 8-bit sRGB colour ``rgb8``."""
    trimesh = pytest.importorskip("trimesh")
    from PIL import Image
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial
    image = Image.fromarray(np.broadcast_to(np.array(rgb8, np.uint8), (4, 4, 3)).copy())
    quad = trimesh.Trimesh([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], [[0, 3, 2], [0, 2, 1]],
                           visual=TextureVisuals(uv=[[0, 0], [1, 0], [1, 1], [0, 1]],
                                                 material=PBRMaterial(baseColorFactor=factor,
                                                                      baseColorTexture=image)),
                           process=False)
    quad.export(str(path))
    return str(path)


def test_gltf_base_colour_is_the_factor_times_the_decoded_texture(tmp_path):
    """(defect: the baseColorFactor was dropped when a baseColorTexture was present: a white
    texture tinted (0.2, 1, 1) came out white). The factor is linear: it scales the sRGB-decoded
    texture, not the 8-bit values."""
    from draaw_mi.scene.meshes import load_mesh_parts
    from draaw_mi.scene.schema import Where
    white = _tinted_quad(tmp_path / "tint.glb", [0.2, 1, 1, 1], [255, 255, 255])
    (part,) = load_mesh_parts(white, Where("x"))
    assert np.allclose(part.material["base_color"].mean((0, 1)), [0.2, 1, 1], atol=1e-3)
    grey = _tinted_quad(tmp_path / "grey.glb", [0.2, 1, 0.5, 1], [128, 128, 128])
    (part,) = load_mesh_parts(grey, Where("x"))
    want = np.array([0.2, 1, 0.5]) * _decode(128)
    assert np.allclose(part.material["base_color"].mean((0, 1)), want, atol=2e-3)
    # and in the scene's BSDF (the texture stays a bitmap: the uvs map it)
    scene = draaw_mi.load_scene(grey, resolution=(8, 8), spp=4)
    mesh = next(i for i, s in enumerate(scene.mi_scene.shapes()) if s.is_mesh() and s.emitter() is None)
    assert np.allclose(_attribute(scene, mesh), want, atol=2e-3)


def test_info_reports_aovs_a_scene_asks_for():
    """A scene whose [render] table asks for AOVs showed "aovs" among the features that are
    off (`draaw-mi info`): the flag looked at the loaded scene's integrator only."""
    from conftest import tiny_description
    assert draaw_mi.load_scene(tiny_description(aovs=["depth"])).features()["aovs"] is True
    assert draaw_mi.load_scene(tiny_description()).features()["aovs"] is False


def test_light_defaults_follow_mitsuba_and_point_down():
    """A spot light without beam_width takes Mitsuba's own default (3/4 of the cutoff: 15 of
    20 degrees), and an area light without a target faces down (-y), lighting the floor below
    it, not the ceiling."""
    from conftest import tiny_description
    d = tiny_description()
    d["lights"] = [{"type": "spot", "name": "s", "position": [0, 3, 0], "target": [0, 0, 0], "cutoff_angle": 20.0},
                   {"type": "area", "name": "a", "position": [0, 2, 0], "intensity": 5.0}]
    scene = draaw_mi.load_scene(d)
    spots = [e for e in scene.mi_scene.emitters() if e.class_name() == "SpotLight"]
    mitsuba_default = mi.load_dict({"type": "spot", "cutoff_angle": 20.0})
    beam = lambda e: str(e).split("beam_width = ")[1].split(",")[0]      # noqa: E731
    assert len(spots) == 1 and beam(spots[0]) == beam(mitsuba_default) == "[15]"
    (area,) = [s for s in scene.mi_scene.shapes() if s.emitter() is not None]
    ps = area.sample_position(0.0, mi.Point2f(0.5, 0.5))
    assert np.allclose(np.array(ps.n).ravel(), [0.0, -1.0, 0.0], atol=1e-6)


def test_a_material_no_shape_uses_is_left_out_and_info_says_so(tmp_path, capsys):
    """Dr.Jit's BSDF calls trace every live BSDF: an unused textured, normal-mapped material
    put its code into every kernel (tests/integrators/test_integrators_kernels.py counts it)
    while info said textures and normal maps were off. It is left out, and info names it."""
    import json

    from conftest import tiny_description

    from draaw_mi.cli import main
    d = tiny_description()
    d["materials"]["extra"] = {"base_color": [[[0.9, 0.2, 0.1], [0.1, 0.2, 0.9]]] * 2,
                               "normalmap": [[[0.6, 0.5, 0.9], [0.4, 0.5, 0.9]]] * 2}
    s = draaw_mi.load_scene(d)
    assert s.info["unused_materials"] == ["extra"] and s.info["materials"] == ["ball", "ground"]
    assert not any(k.startswith("extra.") for k in s.params.keys())
    assert sum(sh.bsdf() is not None for sh in s.mi_scene.shapes()) == 2
    f = s.features()
    assert not f["textures"] and not f["normal_maps"]
    p = tmp_path / "scene.json"
    p.write_text(json.dumps(d))
    assert main(["info", str(p)]) == 0
    assert "unused: extra (no shape uses them: left out of the scene)" in capsys.readouterr().out
    # a [[volumes]] material is copied into the voxel meshes: left out, but not unused
    d["volumes"] = [{"name": "vox", "mode": "solid", "occupied": [[[1]]], "bounds": [[1, 0, 0], [1.5, 0.5, 0.5]],
                     "material": "extra"}]
    d["materials"]["extra"] = {"roughness": 0.3}
    with_volume = draaw_mi.load_scene(d)
    assert with_volume.info["unused_materials"] == [] and with_volume.info["volume_materials"] == ["extra"]
    # a parameter of either is said to be left out, not a misspelling of another material's
    with pytest.raises(draaw_mi.SceneError, match=r"no parameter 'extra.roughness': material 'extra' is "
                                                  r"copied into the voxels"):
        with_volume.key("extra.roughness")
    with pytest.raises(draaw_mi.SceneError, match=r"no parameter 'extra.roughness': material 'extra' is used "
                                                  r"by no shape, so it is left out"):
        s.key("extra.roughness")
    p.write_text(json.dumps(d))
    assert main(["info", str(p)]) == 0
    assert "volumes: extra (copied into the volumes' voxels)" in capsys.readouterr().out


@pytest.mark.parametrize("shape, key", [
    ({"type": "sphere", "scale": [1, 3, 1]}, "scale"),
    ({"type": "sphere", "matrix": [[1, 0, 0, 0], [0, 2, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, "matrix"),
    ({"type": "cylinder", "scale": [1, 3, 1], "rotate": {"axis": [1, 0, 0], "angle": 45}}, "scale"),
    ({"type": "cylinder", "p1": [1, 0, 0], "scale": [1, 1, 3]}, "scale"),
])
def test_a_sphere_or_cylinder_stretched_unevenly_is_refused(shape, key):
    """Such a shape loaded as a round one (only Mitsuba's log said so)."""
    with pytest.raises(SceneError, match=rf"<dict>: shapes\[0\]\.{key}: .* stretches {shape['type']} "
                                         rf"'{shape['type']}0' unevenly.*as a mesh"):
        draaw_mi.load_scene({"render": {"resolution": [8, 8]}, "shapes": [shape]})


@pytest.mark.parametrize("shape", [
    {"type": "sphere", "scale": 2, "rotate": {"axis": [1, 1, 0], "angle": 33}},
    {"type": "cylinder", "scale": [2, 2, 5], "rotate": {"axis": [1, 0, 0], "angle": 45}},
    {"type": "cylinder", "p1": [1, 0, 0], "scale": [4, 1, 1]},          # (along its axis)
    # (round to what files write: a rotation to 4 decimals, a scale off by 1e-5)
    {"type": "sphere", "matrix": [[1.4142, -1.4142, 0, 0], [1.4142, 1.4142, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]},
    {"type": "sphere", "scale": [2, 2, 2.00002]},
])
def test_a_sphere_or_cylinder_scaled_evenly_loads(shape):
    # (a rotation axis of any length is a unit one: Mitsuba's rotate stretched by its length)
    scene = draaw_mi.load_scene({"render": {"resolution": [8, 8]}, "shapes": [shape]})
    box = scene.mi_scene.shapes()[0].bbox()
    if shape["type"] == "sphere":
        assert np.allclose(box.min, [-2, -2, -2], atol=1e-4) and np.allclose(box.max, [2, 2, 2], atol=1e-4)
