"""Sphere tracing inside the integrators: ray hits against closed forms; an SDF sphere / box
renders the same image as Mitsuba's ``sphere`` / ``cube`` (per-pixel z-test over independent
seeds, with its shadow on a mesh floor and a mesh occluding part of it); feature gating."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import drjit as dr
import mitsuba as mi
from draaw_mi.sdf import Box, Sphere
from draaw_mi.sdf.scene import SDFScene
from draaw_mi.sdf.tracer import TracerOptions, march

from sdf_helpers import base_description, check_same_expectation, kernel_ops, render_np, seed_stack, twin_scenes

RNG = np.random.default_rng(7)


def _rays(n=4000):
    o = RNG.uniform(-3, 3, size=(n, 3))
    o[:, 2] = RNG.uniform(3, 5, size=n)
    target = RNG.uniform(-1.2, 1.2, size=(n, 3))
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o, d


def _march_np(node, o, d, **opts):
    sdf = SDFScene([node], ["m"])
    P = mi.Point3f(*(o[:, i].astype(np.float32) for i in range(3)))
    D = mi.Vector3f(*(d[:, i].astype(np.float32) for i in range(3)))
    t, hit, steps = march(sdf, P, D, mi.Float(np.inf), mi.Bool(True), TracerOptions(**opts))
    return np.array(t), np.array(hit), np.array(steps)


@pytest.mark.parametrize("relaxation", [1.0, 1.6, 1.9])
def test_ray_sphere_hits(relaxation):
    c, r = np.array([0.2, -0.1, 0.3]), 0.9
    o, d = _rays()
    b = np.sum((o - c) * d, 1)
    disc = b * b - (np.sum((o - c) ** 2, 1) - r * r)
    t_ref = -b - np.sqrt(np.maximum(disc, 0))
    t, hit, _ = _march_np(Sphere(c, r), o, d, relaxation=relaxation)
    clear = np.abs(disc) > 1e-3                     # not grazing
    assert np.array_equal(hit[clear], (disc > 0)[clear])
    both = hit & (disc > 0) & clear
    assert both.sum() > 500
    # stops short of the surface, within the hit tolerance |f| < 1e-5 (1 + t) + 1e-6 max|p|
    p = o[both] + t[both, None] * d[both]
    tol = 1e-5 * (1 + t[both]) + 1e-6 * np.abs(p).max(1) + 2e-6
    assert np.all(t[both] <= t_ref[both] + 2e-6)
    assert np.all(np.abs(np.linalg.norm(p - c, axis=1) - r) <= tol)
    np.testing.assert_allclose(t[both], t_ref[both], atol=2e-3)


@pytest.mark.parametrize("relaxation", [1.0, 1.5, 1.9])
def test_ray_box_hits(relaxation):
    """Also over-relaxed: a relaxed step through a face lands inside, and without a side
    check the march went on to the back face (683 of 4000 rays at 1.9)."""
    c, size = np.array([0.1, 0.0, -0.2]), np.array([1.6, 1.0, 1.2])
    lo, hi = c - size / 2, c + size / 2
    o, d = _rays()
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    tn = np.max(np.minimum(t1, t2), 1)
    tf = np.min(np.maximum(t1, t2), 1)
    ref_hit = tn < tf
    t, hit, _ = _march_np(Box(c, size), o, d, relaxation=relaxation)
    clear = np.abs(tf - tn) > 1e-2                 # away from edges and corners
    assert np.array_equal(hit[clear], ref_hit[clear])
    both = hit & ref_hit & clear
    assert both.sum() > 500
    assert np.all(t[both] <= tn[both] + 2e-6)
    p = o[both] + t[both, None] * d[both]              # on the surface within the tolerance
    q = np.abs(p - c) - size / 2
    dist = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)
    assert np.all(np.abs(dist) <= 1e-5 * (1 + t[both]) + 1e-6 * np.abs(p).max(1) + 2e-6)
    np.testing.assert_allclose(t[both], tn[both], atol=5e-3)     # grazing: error = eps / cos
    np.testing.assert_allclose(np.median(np.abs(t[both] - tn[both])), 0, atol=1e-4)


@pytest.mark.parametrize("relaxation", [1.5, 1.9])
def test_over_relaxed_rays_head_on_stop_at_the_front_face(relaxation):
    # rays along -z onto a unit box's face z = 0.5 from 1000 distances: every relaxed step
    # that passes the face lands inside (833 of 1000 went on to the back face at 1.5)
    oz = np.linspace(2.0, 5.0, 1000)
    o = np.stack([np.full_like(oz, 0.1), np.full_like(oz, 0.2), oz], 1)
    d = np.tile([0.0, 0.0, -1.0], (1000, 1))
    t, hit, _ = _march_np(Box((0, 0, 0), (1, 1, 1)), o, d, relaxation=relaxation)
    assert hit.all()
    z = oz - t
    assert np.all(np.abs(z - 0.5) <= 1e-4), (z.min(), z.max())       # (float32 o and t)


def test_over_relaxation_pays_for_rays_spawned_on_a_surface():
    # rays leaving a sphere's surface (1e-6 inside: in the hit band) at shallow angles to a
    # floor: relaxation was turned off by their first step (118 steps against 73 from 1e-6
    # outside, plain tracing 116)
    from draaw_mi.sdf import Plane, union
    n = 500
    ang = np.radians(np.linspace(2, 10, n))
    d = np.stack([np.cos(ang), -np.sin(ang), np.zeros(n)], 1)
    node = union(Sphere((0, 0, 0), 1.0), Plane((0, 1, 0), -1.0))
    o = np.tile([1.0 - 1e-6, 0.0, 0.0], (n, 1))
    t1, h1, s1 = _march_np(node, o, d, relaxation=1.0)
    t2, h2, s2 = _march_np(node, o, d, relaxation=1.6)
    assert h1.all() and h2.all()
    np.testing.assert_allclose(t2, 1.0 / np.sin(ang), rtol=2e-3)     # (hit band / sin a)
    assert s2.mean() < 0.75 * s1.mean(), (s1.mean(), s2.mean())


def test_over_relaxation_same_hits_fewer_steps_at_shallow_angles():
    """Over-relaxation pays off where plain tracing crawls (shallow angles: the distance
    shrinks by (1 - sin a) per step); it must find the same hits everywhere."""
    from draaw_mi.sdf import Plane
    n = 2000
    ang = np.radians(RNG.uniform(2, 10, n))
    phi = RNG.uniform(0, 2 * np.pi, n)
    d = np.stack([np.cos(ang) * np.cos(phi), -np.sin(ang), np.cos(ang) * np.sin(phi)], 1)
    o = np.tile([0.0, 1.0, 0.0], (n, 1))
    plane = Plane((0, 1, 0), 0.0)
    t1, h1, s1 = _march_np(plane, o, d, relaxation=1.0)
    t2, h2, s2 = _march_np(plane, o, d, relaxation=1.6)
    assert h1.all() and h2.all()
    t_ref = 1.0 / np.sin(ang)
    np.testing.assert_allclose(t2, t_ref, rtol=2e-3)
    assert s2.mean() < 0.75 * s1.mean(), (s1.mean(), s2.mean())
    o, d = _rays()                                 # head-on rays at a sphere: same hits
    _, h1, _ = _march_np(Sphere((0, 0, 0), 1.0), o, d, relaxation=1.0)
    _, h2, _ = _march_np(Sphere((0, 0, 0), 1.0), o, d, relaxation=1.6)
    assert np.array_equal(h1, h2)


def test_iteration_cap_is_a_miss():
    o = np.array([[0.99, 0.0, 5.0]])                 # near-grazing: needs many steps
    d = np.array([[0.0, 0.0, -1.0]])
    _, hit, steps = _march_np(Sphere((0, 0, 0), 1.0), o, d, max_steps=3)
    assert not hit[0] and steps[0] == 3
    _, hit, _ = _march_np(Sphere((0, 0, 0), 1.0), o, d)
    assert hit[0]


@pytest.mark.parametrize("version", ["v3", "v4"])
@pytest.mark.parametrize("kind", ["sphere", "box"])
def test_same_image_as_mitsuba_shape(version, kind):
    """8 + 8 independent seeds of 16 spp; z-scores of the per-pixel mean differences."""
    ref, sdf = twin_scenes(kind)
    a = seed_stack(ref, version, 16, range(8))
    b = seed_stack(sdf, version, 16, range(100, 108))
    assert np.all(np.isfinite(b))
    check_same_expectation(a, b)
    # the SDF is really visible, shadowed and occluded: not a blank image
    assert b.mean(0).std() > 0.02


def test_two_objects_with_equal_materials_are_both_drawn():
    """Two SDF spheres whose material slots are equal (two names, one value; GO-Draaw's sphere
    lists, whose spheres share the default colour, make such slots): the same image as two
    Mitsuba spheres. Mitsuba's mesh merging once fused the slots' proxy shapes and the tracer
    drew neither (the floor alone, no error)."""
    import copy

    from sdf_helpers import base_description
    a = base_description()
    a["materials"]["twin"] = dict(a["materials"]["ball"])
    b = copy.deepcopy(a)
    balls = [{"type": "sphere", "name": f"ball{i}", "material": m, "center": [x, 0.45, 0.0],
              "radius": 0.45} for i, (x, m) in enumerate(((-0.6, "ball"), (0.7, "twin")))]
    a["shapes"] += balls
    b["sdf"] = copy.deepcopy(balls)
    ref, sdf = draaw_mi.load_scene(a), draaw_mi.load_scene(b)
    check_same_expectation(seed_stack(ref, "v4", 16, range(8)), seed_stack(sdf, "v4", 16, range(100, 108)))


@pytest.mark.parametrize("version", ["v1", "v4"])
def test_albedo_aov_of_two_sdf_objects_is_each_ones_material(version):
    """Two SDF spheres of two materials: the albedo AOV (traced without random numbers, so
    the material of the larger blend weight) shows each sphere's own base colour, pixel for
    pixel as two Mitsuba spheres do (the smaller weight's gave the other sphere's colour)."""
    import copy
    a = base_description(res=(16, 12))
    a["shapes"] = a["shapes"][:1]                           # the floor alone
    b = copy.deepcopy(a)
    balls = [{"type": "sphere", "name": "left", "material": "ball", "center": [-0.7, 0.6, 0.0], "radius": 0.6},
             {"type": "sphere", "name": "right", "material": "blocker", "center": [0.7, 0.6, 0.0], "radius": 0.6}]
    a["shapes"] += copy.deepcopy(balls)
    b["sdf"] = balls
    ref, sdf = (np.array(draaw_mi.render(draaw_mi.load_scene(d), version=version, spp=1, seed=0, post=[],
                                         aovs="albedo"))[..., 3:6] for d in (a, b))
    colours = {tuple(c) for c in np.round(ref.reshape(-1, 3).astype(np.float64), 3)}
    assert {(0.8, 0.3, 0.2), (0.2, 0.4, 0.7)} <= colours            # both spheres show
    assert np.allclose(sdf, ref, atol=1e-5)


def test_albedo_aov_of_a_smooth_blend_is_the_blend_the_path_shades_in_every_version():
    """A smooth union of a red and a green diffuse sphere under a sky, direct light only: a
    path shades a blend point with one material picked by the blend weights, so the beauty's
    red share r / (r + g) is the red material's weight w (the sky's visibility is common to
    both). The albedo AOV must be that blend, 0.9 (w, 1 - w, 0), and the same in every
    version: V1-V3 took the path's random material (0.9 or 0 per sample), V4 the larger
    weight's (a hard seam across the blend)."""
    desc = {"render": {"resolution": [24, 16], "max_depth": 2, "filter": "box"},
            "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 34},
            "materials": {"red": {"type": "diffuse", "reflectance": [0.9, 0.0, 0.0]},
                          "green": {"type": "diffuse", "reflectance": [0.0, 0.9, 0.0]}},
            "sdf": [{"type": "sphere", "name": "a", "material": "red", "center": [-0.5, 0, 0], "radius": 0.55},
                    {"type": "sphere", "name": "b", "material": "green", "center": [0.5, 0, 0], "radius": 0.55},
                    {"type": "smooth_union", "name": "u", "children": ["a", "b"], "k": 0.5}],
            "lights": [{"type": "constant", "intensity": 1.0}]}
    scene = draaw_mi.load_scene(desc)

    def albedo(version, spp, seed):
        img = draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[], aovs="albedo")
        return np.array(img, dtype=np.float64)[..., 3:6]

    one = {v: albedo(v, 1, 0) for v in ("v1", "v2", "v3", "v4")}
    for v in ("v1", "v2", "v3"):
        assert np.allclose(one[v], one["v4"], atol=1e-6), v
    a = albedo("v4", 64, 2)                        # averaged over the pixel, as the beauty is
    inside = np.abs(a.sum(-1) - 0.9) < 1e-4        # every sample on the union (w + (1 - w) = 1)
    w = a[..., 0] / 0.9
    zone = inside & (w > 0.1) & (w < 0.9)
    assert zone.sum() >= 30                        # a blend, not a seam
    assert np.all(a[..., 2] == 0)
    beauty = render_np(scene, "v4", 1024, 1)
    share = beauty[..., 0] / np.maximum(beauty[..., 0] + beauty[..., 1], 1e-12)
    # the share's noise: the red pick is a Bernoulli(w) per visible sample
    tol = 5 * np.sqrt(np.clip(w * (1 - w), 0.0, None) / 1024) + 0.01
    assert np.all(np.abs(share - w)[zone] <= tol[zone]), np.abs(share - w)[zone].max()


def test_same_image_under_area_light_v4():
    ref, sdf = twin_scenes("sphere", light="area")
    check_same_expectation(seed_stack(ref, "v4", 16, range(8)), seed_stack(sdf, "v4", 16, range(100, 108)))


@pytest.mark.parametrize("version", [pytest.param("v1", marks=pytest.mark.slow), "v2"])
def test_legacy_versions_match_mitsuba_shape(version):
    """V1/V2 shade SDF points through the same hooks (same seeds: nearly the same image)."""
    ref, sdf = twin_scenes("sphere")
    a = seed_stack(ref, version, 16, range(4))
    b = seed_stack(sdf, version, 16, range(4))
    assert np.abs(a.mean(0) - b.mean(0)).mean() < 2e-3


def test_scene_without_sdf_compiles_no_sdf_code(monkeypatch):
    """No [[sdf]]: the tracer is never called while the kernel is traced, and the kernel is
    smaller than the SDF twin's by the tracer's ops."""
    ref, sdf = twin_scenes("sphere")
    n_sdf = kernel_ops(lambda: draaw_mi.render(sdf, version="v4", spp=4, seed=3, post=[]))

    def boom(*a, **k):
        raise AssertionError("SDF code traced for a scene without SDFs")
    import draaw_mi.sdf.integration as integ
    import draaw_mi.sdf.tracer as tracer
    monkeypatch.setattr(tracer, "march", boom)
    monkeypatch.setattr(integ, "march", boom)
    monkeypatch.setattr(integ.SDFHook, "__init__", boom)
    counts = {}
    for v in ("v1", "v2", "v3", "v4"):
        counts[v] = kernel_ops(lambda: draaw_mi.render(ref, version=v, spp=4, seed=3, post=[]))
    assert not ref.features()["sdf"] and sdf.features()["sdf"]
    assert n_sdf > counts["v4"] + 100, (n_sdf, counts)


def test_tracer_options_validated():
    from draaw_mi.errors import ParameterError
    with pytest.raises((ParameterError, RuntimeError), match="sdf_relaxation"):
        mi.load_dict({"type": "draaw_v4", "sdf_relaxation": 2.5})
    with pytest.raises(ParameterError, match="hit_epsilon"):
        TracerOptions(hit_epsilon=1e-3)
    integ = mi.load_dict({"type": "draaw_v3", "sdf_epsilon": 2e-5, "sdf_max_steps": 64})
    assert integ.sdf_tracer.max_steps == 64


@pytest.mark.parametrize("value", [64.7, 0.5, float("inf")])
def test_a_fractional_max_steps_is_refused_by_name(value):
    """``int()`` truncated sdf_max_steps = 64.7 to 64 without a word (inf: an OverflowError)."""
    d = base_description((8, 8))
    d["sdf"] = [{"type": "sphere", "name": "ball", "material": "ball", "center": [0, 0.8, 0], "radius": 0.8}]
    scene = draaw_mi.load_scene(d)
    with pytest.raises(draaw_mi.RenderError,
                       match=rf"draaw_v2: sdf_max_steps={value!r}; expected a whole number >= 1"):
        draaw_mi.render(scene, version="v2", spp=1, integrator_options={"sdf_max_steps": value})
    integ = mi.load_dict({"type": "draaw_v2", "sdf_max_steps": 64.0})      # a whole float is taken
    assert integ.sdf_tracer.max_steps == 64 and type(integ.sdf_tracer.max_steps) is int


_ = dr


def test_relaxed_step_does_not_skip_a_surface_just_before_tmax():
    """A mesh just behind the SDF surface (tmax slightly beyond the hit): the relaxed march
    must not overshoot tmax and report a miss (regression: 0.3 % false misses in sdf_csg)."""
    o, d = _rays(2000)
    c, r = np.zeros(3), 1.0
    b = np.sum((o - c) * d, 1)
    disc = b * b - (np.sum((o - c) ** 2, 1) - r * r)
    t_ref = np.where(disc > 1e-3, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    sdf = SDFScene([Sphere(c, r)], ["m"])
    P = mi.Point3f(*(o[:, i].astype(np.float32) for i in range(3)))
    D = mi.Vector3f(*(d[:, i].astype(np.float32) for i in range(3)))
    tmax = mi.Float((t_ref + 0.05).astype(np.float32))
    _, hit, _ = march(sdf, P, D, tmax, mi.Bool(True), TracerOptions(relaxation=1.9))
    assert np.array(hit)[np.isfinite(t_ref)].all()


def test_far_ray_entering_a_tight_box_hits_the_front_face():
    """The box's bounding box touches its faces; with a coarse epsilon the entry point is in
    the hit band. Only rays *starting* in the band are disarmed (regression: such camera
    rays went through the front face and hit the back face)."""
    o = np.tile([0.05, 0.1, 8.0], (64, 1)) + RNG.uniform(-0.2, 0.2, (64, 3)) * [1, 1, 0]
    d = np.tile([0.0, 0.0, -1.0], (64, 1))
    t, hit, _ = _march_np(Box((0, 0, 0), (1, 1, 1)), o, d, hit_epsilon=5e-5)
    assert hit.all()
    np.testing.assert_allclose(t, o[:, 2] - 0.5, atol=1e-3)


@pytest.mark.parametrize("version", ["v1", "v2", "v3"])
def test_a_closed_sdf_sphere_keeps_the_sky_out(version):
    """Camera and floor inside a closed SDF sphere (radius 20), lit only by a constant sky:
    no light gets in. Shadow rays to the sky stopped at Mitsuba's finite ``ds.dist`` (twice
    the mesh scene's radius, about 9 here), short of the sphere: image mean 0.22."""
    desc = base_description(res=(16, 12))
    desc["shapes"] = desc["shapes"][:1]
    desc["lights"] = [{"type": "constant", "intensity": 1.0}]
    desc["sdf"] = [{"type": "sphere", "name": "shell", "material": "blocker", "center": [0.0, 0.5, 0.0],
                    "radius": 20.0}]
    img = render_np(draaw_mi.load_scene(desc), version, 4, 0)
    assert np.isfinite(img).all()
    assert img.mean() < 5e-3, img.mean()     # (residue: rays that exhaust their steps at the shell)


@pytest.mark.parametrize("version", ["v1", "v2", "v3", "v4"])
def test_sdf_objects_beyond_the_far_clip_are_not_drawn(version):
    """A ball 4.2 from the camera under a white sky and nothing else: with ``far_clip = 3``
    every pixel is the sky, as for a Mitsuba sphere (the march ignored the camera ray's
    ``maxt`` and drew it); with ``far_clip = 6`` it is drawn."""
    def image(far_clip, sdf=True):
        desc = base_description(res=(12, 9))
        desc["shapes"] = []
        desc["lights"] = [{"type": "constant", "intensity": 1.0}]
        desc["camera"]["far_clip"] = far_clip
        ball = {"type": "sphere", "name": "obj", "material": "ball", "center": [0.0, 0.8, 0.0], "radius": 0.8}
        desc["sdf" if sdf else "shapes"] = [ball]
        return render_np(draaw_mi.load_scene(desc), version, 4, 0)

    with pytest.warns(RuntimeWarning, match="beyond its far_clip 3"):         # (said at load)
        assert np.all(image(3.0, sdf=False) == 1.0)                 # Mitsuba's own sphere
    with pytest.warns(RuntimeWarning, match="beyond its far_clip 3"):
        assert np.all(image(3.0) == 1.0)
    assert (image(6.0) < 0.99).mean() > 0.2


def test_a_let_go_sdf_scene_leaves_the_registry_and_a_live_one_still_renders():
    """Each loaded SDF scene's registry entry goes with the scene (the registry held every
    SDFScene, its nodes and Dr.Jit arrays, for the life of the process); the scene kept alive
    renders the image it rendered before the others went; the ``mi_scene`` of a let-go scene
    is refused by name rather than rendered without its SDF objects."""
    import gc
    import re

    from draaw_mi.errors import SceneError
    from draaw_mi.sdf.scene import REGISTRY
    desc = base_description(res=(12, 9))
    desc["sdf"] = [{"type": "sphere", "name": "obj", "material": "ball", "center": [0.0, 0.8, 0.0], "radius": 0.8}]
    live = draaw_mi.load_scene(desc)
    before = render_np(live, "v4", 2, 0)
    tokens = []
    for _ in range(3):
        scene = draaw_mi.load_scene(desc)
        tokens.append(scene.info["sdf"].token)
        orphan = scene.mi_scene
        del scene
    gc.collect()
    assert not [t for t in tokens if t in REGISTRY]
    assert live.info["sdf"].token in REGISTRY
    np.testing.assert_array_equal(render_np(live, "v4", 2, 0), before)
    assert (before[..., :3] != render_np(draaw_mi.load_scene(base_description(res=(12, 9))), "v4", 2, 0)[..., :3]).any()
    # the message names the call, the object and what to do (it had named sdf.find and a proxy id)
    keep = r"; keep scene = draaw_mi.load_scene\(\.\.\.\) and render it"
    with pytest.raises(SceneError, match=r"^draaw_mi.render / load_scene of an mi.Scene: the SDF object 'obj' "
                       r"of this mi.Scene was freed with the DraawScene that loaded it.*" + keep):
        draaw_mi.render(orphan, version="v4", spp=1)
    with pytest.raises(RuntimeError) as raised:            # (Dr.Jit's custom op wraps it)
        mi.render(orphan, integrator=mi.load_dict({"type": "draaw_v4"}), spp=1)
    assert isinstance(raised.value.__cause__, SceneError)
    assert re.match(r"mi.render of an mi_scene with a draaw integrator: the SDF object 'obj' .*" + keep,
                    str(raised.value.__cause__))


@pytest.mark.parametrize("opts,match", [
    ({"sdf_max_steps": 2**31}, r"sdf_max_steps=2147483648; expected a whole number >= 1 and <= 2147483647"),
    ({"sdf_max_steps": 10**10}, r"sdf_max_steps=10000000000; expected a whole number >= 1 and <= 2147483647"),
    ({"sdf_relaxation": True}, r"sdf_relaxation=True; expected a number in \[1, 2\)"),
    ({"sdf_epsilon": True}, r"sdf_epsilon=True; expected a number in \(0, 5e-5\]"),
])
def test_tracer_options_beyond_32_bits_or_bools_are_refused_by_name(opts, match):
    """sdf_max_steps above 2^32 - 1 passed the check and failed deep in Dr.Jit ("Could not
    initialize element with a value of type 'int'"); sdf_relaxation = True rendered as 1."""
    d = base_description((8, 8))
    d["sdf"] = [{"type": "sphere", "name": "ball", "material": "ball"}]
    scene = draaw_mi.load_scene(d)
    with pytest.raises(draaw_mi.RenderError, match=rf"draaw_v2: {match}"):
        draaw_mi.render(scene, version="v2", spp=1, integrator_options=opts)
    from draaw_mi.errors import ParameterError
    for kw in ({"relaxation": True}, {"hit_epsilon": True}, {"max_steps": 2**31}):
        with pytest.raises(ParameterError, match=f"{next(iter(kw))}="):
            TracerOptions(**kw)
    assert TracerOptions(max_steps=2**31 - 1).max_steps == 2**31 - 1
