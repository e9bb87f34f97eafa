"""``draaw_v4``'s path reuse among 2x2 pixel tiles (``draaw_mi.integrators.pixel_reuse``):
``path``'s expectation per pixel under the suite's filters, lower variance where light arrives
after a bounce, passes of a bounded size, and no code where the scene has nothing to share."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from integrators_helpers import check_same_expectation, integrator, render_np, seed_stack

from draaw_mi.bench import suite as ss
from draaw_mi.integrators import pixel_reuse


# the suite's scenes with Lambertian surfaces: box (doorway, glossy_diffuse), tent
# (mitsuba_cbox, as shipped), gaussian (spot_and_area, whose normal-mapped diffuse panel is
# re-evaluated); ``on`` shares their draaw and other BSDFs too (reconnection.py)
@pytest.mark.parametrize("name", ["doorway", "mitsuba_cbox", "spot_and_area", "glossy_diffuse"])
def test_shared_paths_keep_paths_expectation(name):
    scene = ss.load(name, 10)
    depth = ss.max_depth(name)
    K, spp = 24, 512
    ref = seed_stack(scene, integrator("path", max_depth=depth, hide_emitters=True), spp, range(K))
    v4 = integrator("draaw_v4", max_depth=depth, hide_emitters=True, pixel_reuse="on", guiding="off")
    assert v4.reuse_table(scene, scene.sensors()[0], spp) is not None
    st = seed_stack(scene, v4, spp, range(300, 300 + K))
    assert np.isfinite(st).all()
    check_same_expectation(ref, st, max_frac3=0.03, max_mean=0.35)


def test_a_guided_render_that_shares_keeps_its_expectation():
    """The glossy panel guided, shared (its tiles' densities the guided mixture's) and not:
    the same expectation per pixel. (Against ``path``, guided or not, one nearly black pixel
    beside the panel differs by z 6 in 96 renders: ``path`` all but never finds the light
    there, 4e-6 against V4's 4e-5.)"""
    scene = ss.load("glossy_diffuse", 10)
    K, spp = 24, 512
    ref = seed_stack(scene, integrator("draaw_v4", max_depth=6, pixel_reuse="off", guiding="on"), spp, range(K))
    v4 = integrator("draaw_v4", max_depth=6, pixel_reuse="on", guiding="on")
    st = seed_stack(scene, v4, spp, range(300, 300 + K))
    assert np.isfinite(st).all()
    check_same_expectation(ref, st, max_frac3=0.03, max_mean=0.35)


def _doorway(width, height, rfilter="box"):
    d = ss.build("doorway", 16)
    d["sensor"]["film"].update(width=width, height=height, rfilter={"type": rfilter})
    return mi.load_dict(d)


def test_odd_films_in_passes_keep_paths_expectation(monkeypatch):
    """A film of odd size (tiles cut at its right and bottom edges), a gaussian filter, and
    the render in four passes (the parts of one stratified pattern)."""
    monkeypatch.setattr(pixel_reuse, "PASS_LANES", 9 * 7 * 64)
    scene = _doorway(9, 7, "gaussian")
    K, spp = 24, 256
    ref = seed_stack(scene, integrator("path"), spp, range(K))
    st = seed_stack(scene, integrator("draaw_v4", pixel_reuse="on"), spp, range(300, 300 + K))
    assert np.isfinite(st).all()
    check_same_expectation(ref, st, max_frac3=0.03, max_mean=0.35)


@pytest.mark.parametrize("stratify", [True, False])
def test_passes_take_the_parts_of_one_pattern_or_their_own_seeds(monkeypatch, stratify):
    """A render of 64 spp in passes of 16: with V4's stratified sampler each pass draws the
    next quarter of the one 64-sample pattern; with independent samples each its own seed."""
    from draaw_mi.integrators import film_splat
    seen, real = [], film_splat.splat_pass

    def spy(integ, scene, sensor, seed, spp, splat, own_emission):
        out = real(integ, scene, sensor, seed, spp, splat, own_emission)
        seen.append((integ._strata_part if stratify else seed, spp, integ._reuse_layout.lanes))
        return out

    monkeypatch.setattr(film_splat, "splat_pass", spy)
    monkeypatch.setattr(pixel_reuse, "PASS_LANES", 16 * 16 * 16)
    scene = _doorway(16, 16)
    img = render_np(scene, integrator("draaw_v4", pixel_reuse="on", stratify=stratify, adaptive=False), 64, 5)
    assert np.isfinite(img).all()
    lanes = 16 * 16 * 16
    if stratify:
        assert seen == [((64, 0), 16, lanes), ((64, 16), 16, lanes), ((64, 32), 16, lanes), ((64, 48), 16, lanes)]
    else:
        assert [s[1:] for s in seen] == [(16, lanes)] * 4 and len({s[0] for s in seen}) == 4


def test_sharing_lowers_the_doorways_variance():
    """The doorway's light arrives after a bounce: the tile's four samples of it take its
    per-pixel variance to about a third (measured 0.35x at 128^2; 0.6x allows for 8 renders)."""
    scene = _doorway(32, 32)
    on = seed_stack(scene, integrator("draaw_v4", pixel_reuse="on"), 16, range(8))
    off = seed_stack(scene, integrator("draaw_v4", pixel_reuse="off"), 16, range(8))
    ratio = on.var(0, ddof=1).mean() / off.var(0, ddof=1).mean()
    assert ratio < 0.6, ratio


@pytest.mark.parametrize("bsdf, expected", [
    ({"type": "diffuse"}, True),
    ({"type": "diffuse", "reflectance": {"type": "checkerboard"}}, True),
    ({"type": "twosided", "bsdf": {"type": "diffuse"}}, True),
    ({"type": "twosided", "bsdf": {"type": "diffuse"}, "bsdf2": {"type": "roughplastic"}}, False),
    ({"type": "normalmap", "bsdf": {"type": "diffuse"},
      "normalmap": {"type": "bitmap", "raw": True, "bitmap": mi.Bitmap(np.full((2, 2, 3), 0.5, np.float32))}}, False),
    ({"type": "bumpmap", "bsdf": {"type": "diffuse"}, "arg": {"type": "checkerboard"}}, False),
    ({"type": "roughplastic"}, False),
    ({"type": "draaw", "roughness": 1.0, "metallic": 0.0}, False),
])
def test_only_lambertian_surfaces_share_as_lambertian(bsdf, expected):
    # (a normal or bump map has its nested diffuse's flags, but reflects nothing below its
    # perturbed horizon: the light it reflects depends on where it is seen from)
    assert pixel_reuse.is_lambertian(mi.load_dict(bsdf)) is expected
    assert pixel_reuse.share_code(mi.load_dict(bsdf)) == (pixel_reuse.LAMBERTIAN if expected else pixel_reuse.REEVALUATED)


@pytest.mark.parametrize("bsdf", [{"type": "dielectric"}, {"type": "conductor"}, {"type": "plastic"},
                                  {"type": "blendbsdf", "weight": 0.5, "a": {"type": "diffuse"}, "b": {"type": "conductor"}}])
def test_bsdfs_with_delta_lobes_do_not_share(bsdf):
    assert pixel_reuse.share_code(mi.load_dict(bsdf)) == 0


def _delta_room():
    """Glass and a mirror under an area light: no surface but the light's shares."""
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "to_world": T().look_at(origin=[0, 1, 3], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3), "bsdf": {"type": "conductor"}},
        "ball": {"type": "sphere", "radius": 0.5, "bsdf": {"type": "dielectric"}},
        "light": {"type": "rectangle", "to_world": T().translate([0, 2, 0]).rotate([1, 0, 0], 90).scale(0.5),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 10.0}}}})


def test_lights_alone_give_nothing_to_share():
    assert pixel_reuse.share_table(_delta_room().shapes()) is None
    table = pixel_reuse.share_table(ss.load("doorway", 8).shapes())
    assert table is not None and table.lambertian_surfaces and dr.any(table.codes == pixel_reuse.LAMBERTIAN)
    metals = pixel_reuse.share_table(ss.load("metals", 8).shapes())    # draaw materials
    assert metals is not None and metals.reevaluates and metals.lambertian_only() is None


def _kernel_ops(scene, integ, spp=16):
    mi.render(scene, integrator=integ, spp=spp, seed=1)       # traced and compiled
    dr.kernel_history()
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        img = mi.render(scene, integrator=integ, spp=spp, seed=2)
        dr.eval(img)
        return sorted(k["operation_count"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT)


def test_no_sharing_code_where_the_scene_has_nothing_to_share():
    room = _delta_room()
    assert _kernel_ops(room, integrator("draaw_v4", max_depth=5, pixel_reuse="on")) == \
        _kernel_ops(room, integrator("draaw_v4", max_depth=5, pixel_reuse="off"))
    doorway = _doorway(16, 16)
    assert _kernel_ops(doorway, integrator("draaw_v4", pixel_reuse="on")) != \
        _kernel_ops(doorway, integrator("draaw_v4", pixel_reuse="off"))


def test_no_reconnection_code_where_every_shared_bsdf_is_lambertian(monkeypatch):
    """A scene whose surfaces are all Mitsuba's diffuse keeps the Lambertian loop state and
    passes: with the table claiming a re-evaluated BSDF, the same render has more code."""
    scene = _floor_and_wall({"type": "point", "position": [0, 1, 0.5], "intensity": 5.0})
    lean = _kernel_ops(scene, integrator("draaw_v4", pixel_reuse="on"))
    real = pixel_reuse.ShareTable.__init__

    def claims(self, codes, lambertian_surfaces):
        real(self, codes, lambertian_surfaces)
        self.reevaluates = True

    monkeypatch.setattr(pixel_reuse.ShareTable, "__init__", claims)
    assert sum(_kernel_ops(scene, integrator("draaw_v4", pixel_reuse="on"))) > sum(lean)


def test_auto_shares_where_the_light_arrives_after_a_bounce():
    """``auto``: the doorway (indirect share about 0.45) and Mitsuba's Cornell box (0.23)
    share in a render of 128^2 x 64, and at 256^2 x 16; the spot beside an area light (0.09)
    does not, and no scene does in a render of fewer than 2^20 samples."""
    for name, expected in (("doorway", True), ("mitsuba_cbox", True), ("spot_and_area", False)):
        scene = ss.load(name, 128)
        v4 = integrator("draaw_v4", max_depth=ss.max_depth(name), guiding="off")
        sensor = scene.sensors()[0]
        assert (v4.reuse_table(scene, sensor, 64) is not None) is expected, name
        assert v4.reuse_table(scene, sensor, 16) is None, name
        if expected:          # (unguided: Lambertian second vertices only)
            assert not v4.reuse_table(scene, sensor, 64).reevaluates, name
    scene = ss.load("doorway", 256)
    assert integrator("draaw_v4").reuse_table(scene, scene.sensors()[0], 16) is not None


def test_gradient_passes_do_not_share():
    """A differentiable render's image shares; its gradient pass samples as before (the
    layout is only set around uniform primal passes): the same gradient as without sharing."""
    grads = []
    for mode in ("on", "off"):
        scene = _doorway(16, 16)
        params = mi.traverse(scene)
        key = next(k for k in params.keys() if k.endswith("reflectance.value") and dr.all(params[k] > 0, axis=None))
        dr.enable_grad(params[key])
        params.update()
        img = mi.render(scene, params, integrator=integrator("draaw_v4", pixel_reuse=mode), spp=16, seed=3)
        dr.backward(dr.mean(img, axis=None))
        grads.append(np.array(dr.grad(params[key])))
    assert np.isfinite(grads[0]).all() and np.abs(grads[0]).sum() > 0
    # (equal up to the order of the gradient's atomic sums over two threads)
    np.testing.assert_allclose(grads[0], grads[1], rtol=1e-5)


def test_a_panel_seen_edge_on_shares_each_side_with_its_own():
    """A two-sided panel seen edge-on, lit on one side only: the floor's tiles astride its
    line see the panel's lit face from one side and its dark face from the other, and each
    side's light is shared only with the pixels on that side."""
    T = mi.ScalarTransform4f
    white = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.8}}}
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": T().look_at(origin=[0, 1.5, 4], target=[0, 0.3, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 10, "height": 10, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3), "bsdf": white},
        "panel": {"type": "rectangle", "bsdf": white,
                  "to_world": T().translate([0, 1.5, 0]).rotate([0, 1, 0], 90).scale([3, 1.5, 1])},
        "lamp": {"type": "rectangle", "to_world": T().translate([1.5, 2.5, 0]).rotate([1, 0, 0], 90).scale(0.3),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 40.0}}},
    })
    K, spp = 24, 512
    ref = seed_stack(scene, integrator("path", max_depth=4), spp, range(K))
    st = seed_stack(scene, integrator("draaw_v4", max_depth=4, pixel_reuse="on"), spp, range(300, 300 + K))
    check_same_expectation(ref, st, max_frac3=0.03, max_mean=0.35)


def _floor_and_wall(light: dict):
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene", "light": light,
        "sensor": {"type": "perspective", "to_world": T().look_at(origin=[0, 1, 3], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3), "bsdf": {"type": "diffuse"}},
        "wall": {"type": "rectangle", "to_world": T().translate([0, 1, -1]).scale(3), "bsdf": {"type": "diffuse"}}})


def test_a_sky_is_left_unshared_and_a_lamp_is_not():
    """Under a constant sky the light after a bounce is smooth and sharing adds variance (the
    balance heuristic's sum of four pixels' samples): ``auto`` leaves it; a point light's
    light after a bounce is shared, with less variance."""
    sky = _floor_and_wall({"type": "constant", "radiance": 1.0})
    lamp = _floor_and_wall({"type": "point", "position": [0, 1, 0.5], "intensity": 5.0})
    assert pixel_reuse.sky_only(sky) and not pixel_reuse.sky_only(lamp)
    var = {}
    for name, scene in (("sky", sky), ("lamp", lamp)):
        for mode in ("on", "off"):
            var[name, mode] = seed_stack(scene, integrator("draaw_v4", pixel_reuse=mode), 64, range(12)).var(0, ddof=1).mean()
    assert var["sky", "on"] > 1.05 * var["sky", "off"], var     # (1.13x measured)
    assert var["lamp", "on"] < 0.7 * var["lamp", "off"], var


def test_info_says_whether_v4_shares(capsys):
    from draaw_mi.cli import main
    cbox = ss.os.path.join(ss.ROOT, "scenes", "mitsuba_cbox.xml")
    assert main(["info", cbox, "-D", "res=128", "-D", "spp=64"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.strip().startswith("v4 reuse:"))
    assert "2x2 pixel tiles share" in line and "auto: 2" in line, line      # (23 % after a bounce)
    assert main(["info", cbox, "-D", "res=128", "-D", "spp=16"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.strip().startswith("v4 reuse:"))
    assert line.strip() == "v4 reuse: off (auto: renders of 2^20 samples or more)", line


def test_auto_leaves_images_above_1024_squared_unshared():
    """A pass keeps one sample of every pixel: ``auto`` shares up to 2^20 pixels (a 1024^2
    render peaks at 1.8x ``path``'s memory; 2048^2 would add 0.6 GiB), ``on`` above too."""
    scene = _doorway(1024, 1025)
    sensor = scene.sensors()[0]
    table, why = integrator("draaw_v4", guiding="off").reuse_decision(scene, sensor, 64)
    assert table is None and why.startswith("auto: images up to 2^20 pixels"), why
    assert integrator("draaw_v4", pixel_reuse="on").reuse_table(scene, sensor, 64) is not None


def test_auto_reconnects_glossy_second_vertices_in_guided_renders_only():
    """The glossy panel (its light after the first bounce: 100 %) renders guided, and its
    draaw floor and panel share there, in images up to 2^19 pixels; unguided, ``auto`` shares
    Lambertian BSDFs only (its wall), and the metal spheres (no Lambertian surface) not at all."""
    scene = ss.load("glossy_diffuse", 128)
    sensor = scene.sensors()[0]
    v4 = integrator("draaw_v4", max_depth=6)
    assert not v4.reuse_table(scene, sensor, 64).reevaluates
    v4._guide = v4.guides.guide(v4, scene, v4.selection_key(scene))
    assert v4._guide is not None
    table, why = v4.reuse_decision(scene, sensor, 64)
    assert table.reevaluates and "guided" in why, why
    # above 2^19 pixels the re-evaluation's memory (about 330 bytes a lane) is not spent
    d = ss.build("glossy_diffuse", 16)
    d["sensor"]["film"].update(width=1024, height=513)
    big = mi.load_dict(d)
    v4 = integrator("draaw_v4", max_depth=6)
    v4._guide = v4.guides.guide(v4, big, v4.selection_key(big))
    assert v4._guide is not None
    table, why = v4.reuse_decision(big, big.sensors()[0], 64)
    assert table is not None and not table.reevaluates, why
    metals = ss.load("metals", 128)
    table, why = integrator("draaw_v4", max_depth=5, guiding="off").reuse_decision(metals, metals.sensors()[0], 64)
    assert table is None and "Lambertian" in why, why
    assert integrator("draaw_v4", max_depth=5, pixel_reuse="on").reuse_table(metals, metals.sensors()[0], 64).reevaluates


@pytest.mark.parametrize("sampler", ["ldsampler", "stratified", "multijitter"])
def test_a_scenes_own_sampler_that_rounds_its_count_shares_the_lanes_it_takes(monkeypatch, sampler):
    """Passes of 3 spp, which these samplers round up (to 4 or 6): each pass's tiles are laid
    out by the count its sampler takes."""
    d = ss.build("doorway", 8)
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 12}
    scene = mi.load_dict(d)
    monkeypatch.setattr(pixel_reuse, "PASS_LANES", 8 * 8 * 3)
    img = render_np(scene, integrator("draaw_v4", pixel_reuse="on"), 12, 1)
    assert np.isfinite(img).all() and img.mean() > 0


def test_a_drjit_seed_renders_in_passes(monkeypatch):
    monkeypatch.setattr(pixel_reuse, "PASS_LANES", 8 * 8 * 4)
    scene = _doorway(8, 8)
    v4 = integrator("draaw_v4", pixel_reuse="on", stratify=False, adaptive=False)
    img = np.array(mi.render(scene, integrator=v4, spp=16, seed=mi.UInt32(3)))
    assert np.isfinite(img).all() and img.mean() > 0
    assert pixel_reuse.pass_seed(mi.UInt32(3), 2)[0] != 3


def test_auto_keeps_a_scenes_own_sampler_unshared():
    d = ss.build("doorway", 128)
    d["sensor"]["sampler"] = {"type": "ldsampler", "sample_count": 64}
    scene = mi.load_dict(d)
    table, why = integrator("draaw_v4", guiding="off").reuse_decision(scene, scene.sensors()[0], 64)
    assert table is None and "ldsampler" in why, why


@pytest.mark.parametrize("name, guided", [("doorway", False), ("glossy_diffuse", True)])
def test_a_scenes_first_render_shares_after_its_pilot(monkeypatch, name, guided):
    """A scene's first render (one ``draaw-mi render``): adaptive sampling's pilot decides on
    guiding, then the rest of each pixel's samples (60 of 64) render uniformly, guided or not,
    and share: the render is 64 spp, as large as ``auto`` asks."""
    from draaw_mi.integrators import film_splat
    calls = []
    real = film_splat.splat_pass

    def spy(integ, *a, **k):
        calls.append((a[3], integ._guide is not None))
        return real(integ, *a, **k)

    monkeypatch.setattr(film_splat, "splat_pass", spy)
    scene = ss.load(name, 128)
    img = render_np(scene, integrator("draaw_v4", max_depth=ss.max_depth(name)), 64, 1)
    assert np.isfinite(img).all() and sum(c[0] for c in calls) == 60, calls
    assert all(c[1] is guided for c in calls), calls


def _room(extra=None, camera=None):
    T = mi.ScalarTransform4f
    white = {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.7}}}
    d = {"type": "scene",
         "sensor": camera or {"type": "perspective", "fov": 60,
                              "to_world": T().look_at(origin=[0, 1, 2.5], target=[0, 1.2, 0], up=[0, 1, 0])},
         "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(2), "bsdf": white},
         "ceiling": {"type": "rectangle", "to_world": T().translate([0, 2, 0]).rotate([1, 0, 0], 90).scale(2), "bsdf": white},
         "back": {"type": "rectangle", "to_world": T().translate([0, 1, -1]).scale(2), "bsdf": white},
         "light": {"type": "rectangle", "to_world": T().translate([0, 1.99, 0]).rotate([1, 0, 0], 90).scale(0.6),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 10.0}}}}
    d["sensor"]["film"] = {"type": "hdrfilm", "width": 12, "height": 12, "rfilter": {"type": "box"}}
    d.update(extra or {})
    return mi.load_dict(d)


@pytest.mark.parametrize("case", ["light in view", "black texels"])
def test_black_first_vertices_leave_their_tiles_unbiased(case):
    """A first vertex that reflects nothing (a light's default black BSDF seen directly; a black
    texel) stops its path: its density must not count in its tile's balance heuristic, which
    darkened the light's neighbours (z -10) and a checkerboard wall's white texels (z -20)."""
    if case == "light in view":
        scene = _room()
    else:
        T = mi.ScalarTransform4f
        checker = {"type": "diffuse", "reflectance": {
            "type": "checkerboard", "color0": {"type": "rgb", "value": 0.0},
            "color1": {"type": "rgb", "value": 0.8}, "to_uv": T().scale([4, 4, 1])}}
        scene = _room({"back": {"type": "rectangle", "to_world": T().translate([0, 1, -1]).scale(1), "bsdf": checker}},
                      {"type": "perspective", "fov": 40,
                       "to_world": T().look_at(origin=[0, 0.8, 3.5], target=[0, 0.8, -1], up=[0, 1, 0])})
    K, spp = 24, 64
    ref = seed_stack(scene, integrator("path"), spp, range(K))
    st = seed_stack(scene, integrator("draaw_v4", pixel_reuse="on"), spp, range(600, 600 + K))
    check_same_expectation(ref, st, max_frac3=0.03, max_mean=0.35)


def test_the_indirect_share_is_measured_once_for_sharing_and_guiding(monkeypatch):
    """Where guiding has not decided, ``auto`` sharing measures the scene's indirect share
    with guiding's pilot, once: later renders and guiding's own decision take that value."""
    from draaw_mi.integrators import guiding
    calls, real = [], guiding.indirect_share
    monkeypatch.setattr(guiding, "indirect_share", lambda *a, **k: calls.append(1) or real(*a, **k))
    scene = ss.load("doorway", 128)
    v4 = integrator("draaw_v4")
    for _ in range(2):
        assert v4.reuse_table(scene, scene.sensors()[0], 64) is not None
    key = v4.selection_key(scene)
    assert v4.guides.share(key) is None               # (guiding has not decided)
    v4.guides.guide(v4, scene, key)
    assert calls == [1] and v4.guides.share(key) == pytest.approx(0.45, abs=0.05)
