"""Media inputs from a review: numpy scalars are numbers; values float32 cannot hold, NaN or
negative densities and albedos above 1 are refused by name, before they render NaN; V1/V2
stay finite under an infinite density that reaches them anyway."""
from __future__ import annotations

import re

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
import media_scenes as ms
from draaw_mi.errors import ParameterError
from draaw_mi.media.mitsuba_dicts import check_g, smoke_medium

SMOKE = "scenes/smoke.toml"


def test_numpy_scalars_are_numbers():
    assert check_g(np.float32(0.5)) == 0.5                   # (refused)
    assert smoke_medium(ms.grid("uniform", 4), scale=np.float32(2.0))["scale"] == 2.0


@pytest.mark.parametrize("kw,match", [
    ({"g_phase": 0.99999999}, r"g=0\.99999999"),            # 1 in float32: the hg plugin failed
    ({"g_phase": 0.9995}, r"g=0\.9995; expected a Henyey-Greenstein g in \[-0\.999, 0\.999\]"),
    ({"scale": 1e39}, r"scale=1e\+39"),
    ({"scale": 2e38}, r"scale=2e\+38 times the densest voxel.*beyond float32"),   # x density 2: inf
    ({"albedo": [0.5, 0.5]}, r"albedo=\[0\.5, 0\.5\]"),       # (a numpy broadcast error)
])
def test_smoke_medium_refuses_what_float32_or_mitsuba_cannot_take(kw, match):
    with pytest.raises(ParameterError, match="smoke_medium: " + match):
        smoke_medium(ms.grid("uniform", 4), **kw)


def test_a_scale_beyond_float32_is_refused_on_an_empty_grid_too():
    """The scale's own bound: on an all-zero grid the densest-voxel product (0) cannot catch it."""
    g = ms.grid("uniform", 4)
    g.density[:] = 0.0
    with pytest.raises(ParameterError, match=r"smoke_medium: scale=1e\+39; expected a finite value >= 0"):
        smoke_medium(g, scale=1e39)


def test_a_medium_albedo_grid_above_one_is_refused():
    """An albedo grid (``*.albedo.data``) set through the preview: values above 1 are no albedo."""
    from draaw_mi.materials import check_value
    key = "smoke.interior_medium.albedo.data"
    check_value("Preview.update", key, key, np.full((2, 2, 2, 3), 0.9))
    with pytest.raises(ParameterError, match=r"albedo.data: 24 value\(s\) outside \[0, 1\]"):
        check_value("Preview.update", key, key, np.full((2, 2, 2, 3), 1.2))


@pytest.mark.parametrize("change,match", [(lambda a: np.where(a == a.max(), np.nan, a), "nan"),
                                          (lambda a: a - 0.5, r"-0\.5"),
                                          (lambda a: a * 0 + 1e39, r"1e\+39")])
@pytest.mark.parametrize("legacy", [False, "1.13"])
def test_a_medium_grid_set_through_the_preview_is_checked(change, match, legacy):
    """The first bad value is named as a plain number whatever numpy's print options (under
    ``legacy='1.13'``, which some library set in the suite, it read 9.9999999999999994e+38;
    otherwise ``np.float64(1e+39)``)."""
    scene = draaw_mi.load_scene(SMOKE, resolution=(8, 6))
    key = next(k for k in scene.params.keys() if k.endswith("interior_medium.sigma_t.data"))
    grid = np.array(scene.params[key], np.float64)
    scene.check_value("Preview.update", key, key, grid)       # as it is: fine
    with np.printoptions(legacy=legacy), pytest.raises(
            ParameterError, match=rf"Preview\.update: {key}: \d+ value\(s\) outside.*\(the first, ({match}), at"):
        scene.check_value("Preview.update", key, key, change(grid))


@pytest.mark.parametrize("version", ["draaw_v1", "draaw_v2"])
def test_the_march_stays_finite_under_an_infinite_density(version):
    d = ms.base({"type": version}, 8)
    shape = ms.smoke_shape(ms.grid("uniform", 4))
    shape["interior"]["scale"] = 1e39                          # past the checks: inf in float32
    d["smoke"] = shape
    img = np.array(mi.render(mi.load_dict(d), spp=4))
    assert np.all(np.isfinite(img)), int(np.sum(~np.isfinite(img)))   # (402 of 768 NaN)
    # (black is right here: the box fills the view and volpath renders it black at 1e30 too)


def test_voxel_grid_inputs_are_named():
    from draaw_mi.media import VoxelGrid
    with pytest.raises(ParameterError, match="from_arrays: density is a ragged nested list"):
        VoxelGrid.from_arrays(density=[[[1, 2], [3]]])          # (numpy's 'inhomogeneous shape')
    g = ms.grid("uniform", 4)
    assert g.index_of((np.nan, 0, 0)) is None                  # (-9223372036854775808, 1, 1)
    assert g.index_of((0.1, 0.1, 0.1)) == (2, 2, 2)


def test_solid_voxels_take_the_colour_parameter_of_their_bsdf():
    from draaw_mi.media import VoxelGrid
    from draaw_mi.media.faces import solid_meshes
    g = VoxelGrid.from_arrays(occupied=np.ones((2, 1, 1), bool), color=[0.8, 0.2, 0.1])
    for kind, key in (("plastic", "diffuse_reflectance"), ("roughplastic", "diffuse_reflectance"),
                      ("diffuse", "reflectance"), ("conductor", "specular_reflectance")):  # (plastic: 'unreferenced')
        meshes = solid_meshes(g, {"type": kind}, group_by="color")
        assert len(meshes) == 1, kind
        p = mi.traverse(next(iter(meshes.values())).bsdf())
        np.testing.assert_allclose(np.array(p[f"{key}.value"]).ravel(), [0.8, 0.2, 0.1], rtol=1e-6, err_msg=kind)
    with pytest.raises(ParameterError, match="material type 'dielectric' has no colour parameter"):
        solid_meshes(g, {"type": "dielectric"}, group_by="color")


def test_a_medium_inside_a_shapegroup_is_refused_by_v3_v4_and_seen_by_v1_v2():
    """A smoke-filled sphere placed by an instance: V3/V4's media table walked scene.shapes()
    (the instance only) and rendered it empty (1.0 against volpath's 0.16); they now refuse
    it by name. V1/V2 find media at their hits: the same image as without the group. Such
    scenes are not frozen (a recording of media aborts Dr.Jit 1.5)."""
    from draaw_mi.rendering.frozen import freeze_supported
    T = mi.ScalarTransform4f
    sphere = {"type": "sphere", "radius": 0.5, "bsdf": {"type": "null"},
              "interior": {"type": "homogeneous", "sigma_t": 4.0, "albedo": 0.5}}
    base = {"type": "scene", "e": {"type": "constant"},
            "sensor": {"type": "perspective", "fov": 30, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}}
    plain = mi.load_dict(dict(base, s=sphere))
    grouped = mi.load_dict(dict(base, grp={"type": "shapegroup", "s": sphere},
                                inst={"type": "instance", "shapegroup": {"type": "ref", "id": "grp"}}))
    assert not freeze_supported(grouped)
    solid = dict(sphere, bsdf={"type": "diffuse"})                  # an instance without media
    del solid["interior"]
    assert freeze_supported(mi.load_dict(dict(base, grp={"type": "shapegroup", "s": solid},
                                              inst={"type": "instance", "shapegroup": {"type": "ref", "id": "grp"}})))
    for v in ("draaw_v3", "draaw_v4"):
        with pytest.raises(RuntimeError) as info:
            mi.render(grouped, integrator=mi.load_dict({"type": v}), spp=4)
        assert "inside a shapegroup (s) is not supported" in repr(info.value.__cause__)
    for v in ("draaw_v1", "draaw_v2"):
        a, b = (np.array(mi.render(s, integrator=mi.load_dict({"type": v}), spp=16, seed=1)) for s in (plain, grouped))
        assert np.allclose(a, b, atol=1e-6) and a[4, 4, 0] < 0.5          # the medium darkens the centre


@pytest.mark.parametrize("version", ["v1", "v2", "v3", "v4"])
def test_a_density_pushed_below_zero_through_params_is_no_medium(version):
    """An optimiser step can take a density grid below 0 (scene.params are not checked as
    they are set). sigma_t and sigma_s are read as at least 0 (volume_tracking.coefficients),
    so the render is the empty medium's, pixel for pixel with the same seed; V1/V2's march
    had read exp(+0.5 dt) transmittances and negative scattering (pixels from -3.5 to 4.3,
    mean -0.31, against 0 to 0.24). The render says which value a scene file would refuse."""
    import warnings
    scene = draaw_mi.load_scene(SMOKE, resolution=(12, 9))
    key = next(k for k in scene.params.keys() if k.endswith("interior_medium.sigma_t.data"))
    shape = np.array(scene.params[key]).shape
    images = []
    for value in (0.0, -0.5):
        scene.params[key] = mi.TensorXf(np.full(shape, value, np.float32))
        scene.params.update()
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            images.append(np.array(draaw_mi.render(scene, version=version, spp=4, seed=3, post=[]))[..., :3])
        assert [str(w.message) for w in said if w.category is RuntimeWarning] == (
            [] if value == 0 else [f"render: the {version} render of scenes/smoke.toml used {key}: "
                                   f"{np.prod(shape)} value(s) outside [0, 3.40282e+38] (the first, -0.5, at "
                                   "[0, 0, 0, 0]); expected densities in [0, 3.40282e+38]; its pixels are not to "
                                   "be trusted (set through scene.params: scene.out_of_range() lists what a scene "
                                   "file would refuse)"])
    empty, negative = images
    assert negative.min() >= 0.0
    np.testing.assert_allclose(negative, empty, atol=1e-6)


@pytest.mark.parametrize("what, value, match", [
    ("scale", -2.0, r"plume\.interior_medium\.scale = -2\.0; expected a finite density scale >= 0"),
    ("scale", float("nan"), r"plume\.interior_medium\.scale = nan; expected a finite density scale"),
    ("data", float("nan"), r"plume\.interior_medium\.sigma_t\.data\[0, 0, 1, 0\] = nan \(1 non-finite "
                           r"value\(s\), \[z, y, x, channel\]\); expected finite densities"),
    ("data", float("inf"), r"plume\.interior_medium\.sigma_t\.data\[0, 0, 1, 0\] = inf"),
])
def test_a_scale_below_zero_or_a_non_finite_density_set_through_params_is_refused(what, value, match):
    """A scale of -2 rendered V4 as if no smoke (every sigma_t read as 0) while volpath
    rendered 0.163 for 0.300; a NaN density voxel rendered as no smoke there too: V3/V4 refuse
    them by key and voxel when the media are read (a density below 0 stays no medium)."""
    scene = draaw_mi.load_scene(SMOKE, resolution=(12, 9))
    prefix = next(k for k in scene.params.keys() if k.endswith("interior_medium.scale"))[:-len("scale")]
    if what == "scale":
        scene.params[prefix + "scale"] = value
    else:
        data = np.array(scene.params[prefix + "sigma_t.data"])
        data[0, 0, 1, 0] = value
        scene.params[prefix + "sigma_t.data"] = mi.TensorXf(data)
    scene.params.update()
    for version in ("v3", "v4"):
        with pytest.raises(Exception) as info:
            draaw_mi.render(scene, version=version, spp=2, post=[])
        err = info.value if isinstance(info.value, ParameterError) else info.value.__cause__
        assert isinstance(err, ParameterError), repr(info.value)
        assert re.search(r"draaw_v3/draaw_v4: " + match, str(err)), str(err)


def test_a_phase_g_set_past_its_bound_through_params_is_said_by_the_render():
    """g = 1.2 (Mitsuba's hg: a negative lobe) renders finite but negative pixels: the render
    says which value did it; a g inside [-0.999, 0.999] renders without a word."""
    import warnings
    scene = draaw_mi.load_scene(SMOKE, resolution=(12, 9))
    key = next(k for k in scene.params.keys() if k.endswith("phase_function.g"))
    for g in (0.5, -0.999, 0.999):      # (the bound itself, read back as float32 0.99900001)
        scene.params[key] = g
        scene.params.update()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            draaw_mi.render(scene, version="v4", spp=2, post=[])
    scene.params[key] = 1.2
    scene.params.update()
    with pytest.warns(RuntimeWarning, match=rf"render: the v4 render of .* used {key}=1\.2.*g in "
                                            r"\[-0\.999, 0\.999\]"):
        image = np.array(draaw_mi.render(scene, version="v4", spp=2, post=[]))
    assert np.isfinite(image).all()
