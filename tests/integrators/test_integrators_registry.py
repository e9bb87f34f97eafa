"""Registration, version names, parameter validation, feature detection and AOV names."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import mitsuba as mi
from draaw_mi.errors import ParameterError, RenderError
from draaw_mi.integrators.features import BLACK_SURFACE_PREFIX
from draaw_mi.integrators import (FEATURE_NAMES, PLUGINS, VERSION_ALIASES, detect_features,
                                  register, resolve_version)
from draaw_mi.bench import reference_scenes as rs


@pytest.mark.parametrize("plugin", PLUGINS)
def test_plugin_loads_and_prints(plugin):
    integ = mi.load_dict({"type": plugin, "max_depth": 5})
    assert plugin.replace("draaw_v", "DraawV") in type(integ).__name__
    assert "max_depth=5" in str(integ)
    assert integ.aov_names() == []


def test_register_is_idempotent():
    register()
    register()
    draaw_mi.register_plugins()
    assert mi.load_dict({"type": "draaw_v4"}) is not None


@pytest.mark.parametrize("name,plugin", [
    ("V1", "draaw_v1"), ("V2", "draaw_v2"), ("V2M", "draaw_v3"), ("V4", "draaw_v4"),
    ("v3", "draaw_v3"), ("draaw_v2", "draaw_v2"), ("DRAAW-V4", "draaw_v4"),
    ("V4-Log-Optim", "draaw_v4"), ("V2-Linear", "draaw_v3"), (" path ", "path"), ("prb", "prb"),
])
def test_resolve_version(name, plugin):
    assert resolve_version(name) == plugin


def test_every_alias_resolves_to_a_plugin():
    for alias, plugin in VERSION_ALIASES.items():
        assert resolve_version(alias) == plugin
        assert plugin in PLUGINS + ("path", "prb", "volpath", "prbvolpath", "scene")


@pytest.mark.parametrize("bad", ["v5", "pth", "", "V3X"])
def test_resolve_version_error_names_value_and_valid_names(bad):
    with pytest.raises(RenderError) as e:
        resolve_version(bad)
    msg = str(e.value)
    assert repr(bad) in msg and "v4" in msg and "path" in msg and "VERSION_ALIASES" in msg
    assert len(msg) < 300                  # the names users pick from, not all 35 aliases


def test_resolve_version_suggests():
    with pytest.raises(RenderError, match="did you mean 'path'"):
        resolve_version("pth")


@pytest.mark.parametrize("plugin,props,match", [
    ("draaw_v4", {"max_depth": -2}, "max_depth=-2"),
    ("draaw_v4", {"rr_depth": 0}, "rr_depth=0"),
    ("draaw_v4", {"rr_min": 0.0}, "rr_min"),
    ("draaw_v3", {"distribution": "ggxx"}, "did you mean 'ggx'"),
    ("draaw_v3", {"glossy_alpha": 2.0}, "glossy_alpha"),
    ("draaw_v2", {"scatter": -1}, "scatter=-1"),
    ("draaw_v1", {"scatter": -3}, "scatter=-3"),
    ("draaw_v1", {"aovs": "deph"}, "did you mean 'depth'"),
    ("draaw_v2", {"aovs": "depth, normals"}, "normals"),
    # (bool("false") is True: adaptive sampling stayed on, constant-sky NEE went on)
    ("draaw_v4", {"adaptive": "false"}, "adaptive='false'; expected a boolean"),
    ("draaw_v4", {"constant_env_nee": "no"}, "constant_env_nee='no'; expected a boolean"),
    ("draaw_v4", {"emission_split": 4.7}, "emission_split=4.7; expected an integer"),   # (cut to 4)
    ("draaw_v4", {"emission_split": True}, "emission_split=True; expected an integer"),
    ("draaw_v4", {"rr_min": "0.5"}, "rr_min='0.5'; expected a number"),
    ("draaw_v3", {"glossy_alpha": True}, "glossy_alpha=True; expected a number"),
    # (inf roulettes every path at rr_min; scatter 256 took 86 s to compile a 4x4 render)
    ("draaw_v4", {"rr_threshold": float("inf")}, r"rr_threshold=inf; expected a finite value > 0"),
    ("draaw_v1", {"scatter": 65}, r"scatter=65; expected an integer in \[0, 64\]"),
])
def test_bad_parameters_raise(plugin, props, match):
    with pytest.raises((ParameterError, RuntimeError), match=match):
        mi.load_dict({"type": plugin, **props})


def test_aov_names():
    integ = mi.load_dict({"type": "draaw_v4", "aovs": "albedo, depth"})
    assert integ.aov_names() == ["depth.Z", "albedo.R", "albedo.G", "albedo.B"]
    integ = mi.load_dict({"type": "draaw_v1", "aovs": "all"})
    assert integ.aov_names() == ["depth.Z", "depth_log.Z", "N.X", "N.Y", "N.Z",
                                 "albedo.R", "albedo.G", "albedo.B"]
    # ("all" beside another name was refused: "aovs entry 'all' is unknown; did you mean 'all'?")
    assert mi.load_dict({"type": "draaw_v4", "aovs": "all, depth"}).aov_names() == integ.aov_names()


def _scene(**extra):
    d = rs.cornell_draaw(res=8, spp=1)
    d.update(extra)
    return mi.load_dict(d)


def test_detect_features_cornell():
    f = detect_features(_scene())
    assert tuple(f) == FEATURE_NAMES
    assert all(isinstance(v, bool) for v in f.values())
    assert f["area_lights"] and f["hittable_lights"] and f["draaw_materials"]
    for k in ("point_lights", "spot_lights", "envmap", "constant_env", "environment",
              "delta_lights", "textures", "normal_maps", "delta_bsdfs", "other_glossy", "anisotropic",
              "media", "aovs", "null_surfaces", "black_surfaces"):
        assert not f[k], k


def test_detect_features_emitters_and_materials():
    T = mi.ScalarTransform4f
    env = mi.Bitmap(np.full((8, 16, 3), 0.5, np.float32))

    def tex():
        return mi.TensorXf(np.full((4, 4, 3), 0.5, np.float32))
    f = detect_features(_scene(
        pt={"type": "point", "position": [0, 0.5, 0]},
        spot={"type": "spot", "to_world": T().look_at([0, 0.9, 0], [0, 0, 0], [0, 0, 1])},
        sun={"type": "directional", "direction": [0, -1, 0]},
        sky={"type": "envmap", "bitmap": env},
        glass={"type": "sphere", "radius": 0.1, "bsdf": {"type": "dielectric"}},
        metal={"type": "sphere", "radius": 0.1, "center": [0, -0.5, 0],
               "bsdf": {"type": "roughconductor", "alpha_u": 0.1, "alpha_v": 0.3}},
        tex={"type": "sphere", "radius": 0.1, "center": [0.5, 0, 0],
             "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "data": tex()}}},
        nm={"type": "sphere", "radius": 0.1, "center": [-0.5, 0, 0],
            "bsdf": {"type": "draaw", "normalmap": {"type": "bitmap", "data": tex(), "raw": True}}},
        fog={"type": "sphere", "radius": 0.1, "center": [0, 0.5, 0], "bsdf": {"type": "null"},
             "interior": {"type": "homogeneous", "sigma_t": 1.0}},
        lamp={"type": "sphere", "radius": 0.05, "center": [0.5, 0.5, 0], "emitter": {"type": "area"},
              "bsdf": {"type": "diffuse", "id": BLACK_SURFACE_PREFIX + "lamp", "reflectance": 0.0}},
        integrator={"type": "draaw_v4", "aovs": "depth"},
    ))
    for k in FEATURE_NAMES:
        if k not in ("constant_env", "sdf"):       # sdf: only draaw_mi scenes with [[sdf]]
            assert f[k], k
    assert not f["constant_env"] and not f["sdf"]


def test_detect_features_constant_env_only():
    d = {"type": "scene", "sky": {"type": "constant"},
         "ball": {"type": "sphere", "bsdf": {"type": "diffuse"}}}
    f = detect_features(mi.load_dict(d))
    assert f["constant_env"] and f["environment"] and f["hittable_lights"]
    assert f["other_materials"] and not f["draaw_materials"] and not f["area_lights"]


@pytest.mark.parametrize("bsdf, glossy", [
    ({"type": "roughconductor", "alpha": 0.1}, True),
    ({"type": "principled", "roughness": 0.3}, True),
    ({"type": "twosided", "bsdf": {"type": "roughplastic"}}, True),
    ({"type": "conductor"}, False),                   # a delta lobe: delta_bsdfs
    ({"type": "diffuse"}, False),
    ({"type": "draaw", "roughness": 0.1}, False),     # draaw lobes are V3's own business
])
def test_detect_other_glossy(bsdf, glossy):
    f = detect_features(mi.load_dict({"type": "scene", "ball": {"type": "sphere", "bsdf": bsdf}}))
    assert f["other_glossy"] is glossy


def test_a_normal_map_alone_is_no_texture_and_a_null_surface_is_named():
    """A draaw BSDF with only a normal map is SpatiallyVarying, and ``textures`` was on with
    it (V1 and V2, which ignore normal maps, then traced uv and dp/du). A ``null`` BSDF keeps
    ``delta_bsdfs`` and ``other_materials`` on (V3 and V4 cross it as a delta event of another
    BSDF: without them a null sphere renders 22 % dark) and is named ``null_surfaces``."""
    nm = mi.TensorXf(np.full((2, 2, 3), 0.5, np.float32))
    f = detect_features(_scene(nm={"type": "sphere", "radius": 0.1, "bsdf": {
        "type": "draaw", "normalmap": {"type": "bitmap", "data": nm, "raw": True}}}))
    assert f["normal_maps"] and not f["textures"]
    f = detect_features(_scene(veil={"type": "sphere", "radius": 0.1, "bsdf": {"type": "null"}}))
    assert f["null_surfaces"] and f["delta_bsdfs"] and f["other_materials"]


def test_a_toml_area_lights_surface_is_black_not_another_material():
    """A TOML scene's area light gets draaw-mi's black surface: ``black_surfaces``, not
    ``other_materials`` (which would put every other-BSDF branch into V1..V3); a ``diffuse`` of
    reflectance 0 of the user's own stays another material (only the id says black)."""
    import draaw_mi
    from conftest import tiny_description
    d = tiny_description()
    d["lights"] = [{"type": "area", "position": [0, 3, 0], "target": [0, 0, 0], "size": [0.5, 0.5]}]
    f = draaw_mi.load_scene(d).features()
    assert f["black_surfaces"] and not f["other_materials"] and f["draaw_materials"]
    own = detect_features(_scene(dark={"type": "sphere", "radius": 0.1,
                                       "bsdf": {"type": "diffuse", "reflectance": 0.0}}))
    assert own["other_materials"] and not own["black_surfaces"]
