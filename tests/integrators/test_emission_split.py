"""Emission splitting in draaw_v4 (``integrators/emission_split.py``): the emission of a light
seen directly, estimated in its edge pixels from stratified extra camera rays. It must keep
the expectation of Mitsuba's ``path``, lower the variance of those pixels, carry emitter
gradients, and add nothing to the kernels of scenes that show no emitting surface."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

from integrators_helpers import ad_gradient, dr, fd_gradient, forward_gradient, integrator, mi, rs, seed_stack

from draaw_mi.integrators import emission_split


def cornell(res: int, look_down: bool = False):
    d = rs.cornell_draaw(res=res, spp=4)
    if look_down:                        # the same box, the camera looking at the floor
        d["sensor"]["to_world"] = mi.ScalarTransform4f().look_at(
            origin=[0, 0.9, 0.5], target=[0, -1, 0.2], up=[0, 0, -1])
    return mi.load_dict(d)


@pytest.fixture(scope="module")
def box32():
    return cornell(32)


def light_edges(scene) -> np.ndarray:
    """Pixels partly covered by the light, from Mitsuba's own ``path`` at max_depth 1
    (emission seen directly) and 1024 spp: neither dark nor fully lit."""
    img = np.array(mi.render(scene, integrator=mi.load_dict({"type": "path", "max_depth": 1}),
                             spp=1024, seed=5))[..., :3].mean(-1)
    full = img.max()
    return (img > 0.03 * full) & (img < 0.97 * full)


def test_edge_pixels_keep_their_expectation(box32):
    """The light's edge pixels, where every extra ray lands, against ``path``: the summed
    mean of those pixels agrees within 4 standard errors. A pixel mapping off by one, a
    flipped axis or an emission counted twice moves it by tens of errors."""
    edges = light_edges(box32)
    assert edges.sum() >= 8, edges.sum()
    n = 48
    v4 = seed_stack(box32, integrator("draaw_v4", max_depth=3), 4, range(n))[..., :3]
    ref = seed_stack(box32, integrator("path", max_depth=3), 4, range(1000, 1000 + n))[..., :3]
    a, b = v4[:, edges].sum(axis=(1, 2)), ref[:, edges].sum(axis=(1, 2))
    se = np.sqrt(a.var(ddof=1) / n + b.var(ddof=1) / n)
    assert abs(a.mean() - b.mean()) <= 4 * se, (a.mean(), b.mean(), se)
    assert se < 0.05 * b.mean(), se              # the test can see a 20 % error


@pytest.mark.parametrize("max_depth, wall_z", [(3, -1.0), (2, -0.62)])
def test_edge_pixels_of_a_sphere_light_keep_their_expectation(max_depth, wall_z):
    """A round light (edges at every angle: the box light's are along the pixel axes, which
    hid split rays taking only the diagonal cells) before a wall, against ``path``; with
    max_depth 2 and the wall near, the edge pixels' light found by BSDF sampling after the
    first bounce counts too (dropped there, the edge pixels came out darker by 6 standard
    errors)."""
    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "cam": {"type": "perspective", "fov": 40, "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}},
        "light": {"type": "sphere", "radius": 0.6, "center": [0.1, 0.05, 0],
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 4.0}}},
        "wall": {"type": "rectangle", "to_world": T().translate([0, 0, wall_z]).scale(3),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.8}}}})
    edges = light_edges(scene)
    assert edges.sum() >= 12, edges.sum()
    n = 40
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=max_depth, adaptive=False), 64, range(n))[..., :3]
    ref = seed_stack(scene, integrator("path", max_depth=max_depth), 64, range(1000, 1000 + n))[..., :3]
    a, b = v4[:, edges].sum(axis=(1, 2)), ref[:, edges].sum(axis=(1, 2))
    se = np.sqrt(a.var(ddof=1) / n + b.var(ddof=1) / n)
    assert abs(a.mean() - b.mean()) <= 4 * se, (a.mean(), b.mean(), se)
    z = (v4.mean(0) - ref.mean(0)) / (np.sqrt(v4.var(0, ddof=1) / n + ref.var(0, ddof=1) / n) + 1e-9)
    assert np.mean(np.abs(z[edges]) > 3) < 0.05, np.abs(z[edges]).max()


def test_edge_pixels_are_much_less_noisy(box32):
    edges = light_edges(box32)
    seeds = range(24)
    on = seed_stack(box32, integrator("draaw_v4", max_depth=3), 2, seeds)[..., :3]
    off = seed_stack(box32, integrator("draaw_v4", max_depth=3, emission_split=1), 2, seeds)[..., :3]
    var_on, var_off = on[:, edges].var(axis=0, ddof=1).mean(), off[:, edges].var(axis=0, ddof=1).mean()
    assert var_on < var_off / 4, (var_on, var_off)
    # away from the light (two pixels and more) nothing changes but the random numbers
    lit = light_edges(box32) | (np.array(mi.render(
        box32, integrator=mi.load_dict({"type": "path", "max_depth": 1}), spp=64, seed=2))[..., :3].sum(-1) > 0)
    near = lit.copy()
    for dy in (-2, -1, 0, 1, 2):
        for dx in (-2, -1, 0, 1, 2):
            near |= np.roll(np.roll(lit, dy, 0), dx, 1)
    rest = ~near
    ratio = on[:, rest].var(axis=0, ddof=1).mean() / off[:, rest].var(axis=0, ddof=1).mean()
    assert 0.8 < ratio < 1.25, ratio


def kernels(scene, integ, spp: int = 4) -> list[int]:
    """Operation counts of the JIT kernels of a primal render after a first one (which also
    projects the emitters' bounds for the split, once per camera)."""
    dr.eval(mi.render(scene, integrator=integ, spp=spp, seed=1))
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        dr.eval(mi.render(scene, integrator=integ, spp=spp, seed=0))
        dr.sync_thread()
        return [k["operation_count"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


@pytest.mark.parametrize("case", ["light out of view", "hide_emitters", "thin lens"])
def test_no_split_code_where_no_light_is_seen(case):
    if case == "light out of view":
        scene, props = cornell(16, look_down=True), {}
    elif case == "hide_emitters":
        scene, props = cornell(16), {"hide_emitters": True}
    else:                                # rays through a lens: a pixel's probes say nothing
        d = rs.cornell_draaw(res=16, spp=4)
        d["sensor"].update(type="thinlens", aperture_radius=0.05, focus_distance=3.9)
        d["sensor"]["film"]["rfilter"] = {"type": "gaussian"}
        scene, props = mi.load_dict(d), {}
    said = pytest.warns(RuntimeWarning, match="emission splitting is off: the camera samples a lens") \
        if case == "thin lens" else contextlib.nullcontext()
    with said:                           # (what stays off is said once per render)
        on = kernels(scene, integrator("draaw_v4", max_depth=4, **props))
        off = kernels(scene, integrator("draaw_v4", max_depth=4, emission_split=1, **props))
    assert on == off, (on, off)
    # nor is an edge map built for frozen recordings of it
    assert integrator("draaw_v4", max_depth=4, **props).freeze_state(scene)[1] is None


@pytest.mark.parametrize("rfilter", ["box", "gaussian"])
def test_split_code_where_a_light_is_seen(rfilter):
    d = rs.cornell_draaw(res=16, spp=4)
    d["sensor"]["film"]["rfilter"] = {"type": rfilter}
    scene = mi.load_dict(d)
    on = kernels(scene, integrator("draaw_v4", max_depth=4))
    off = kernels(scene, integrator("draaw_v4", max_depth=4, emission_split=1))
    # the edge map is made once per camera, not per render (other filters than box: one
    # small kernel adds the emission's own block to the film's, film_splat.with_emission)
    assert len(on) == len(off) + (rfilter != "box"), (on, off)
    assert max(on) > max(off)                # the extra rays in the render kernel
    edges = integrator("draaw_v4", max_depth=4).freeze_state(scene)[1]
    assert edges is not None and dr.any(edges)      # frozen recordings get the map


def test_emitter_rect_holds_the_light(box32):
    rect = emission_split.emitter_rect(box32, box32.sensors()[0])
    lit = np.array(mi.render(box32, integrator=mi.load_dict({"type": "path", "max_depth": 1}),
                             spp=64, seed=1))[..., :3].sum(-1) > 0
    ys, xs = np.nonzero(lit)
    x0, y0, x1, y1 = rect
    assert x0 <= xs.min() and xs.max() < x1 and y0 <= ys.min() and ys.max() < y1, (rect, xs, ys)
    assert (x1 - x0) * (y1 - y0) < 0.25 * 32 * 32, rect         # tight, not the whole film
    down = cornell(32, look_down=True)
    assert emission_split.emitter_rect(down, down.sensors()[0]) is None


def test_emitter_rect_in_a_crop_window_is_in_film_coordinates():
    """The sensor projects points into its crop window; the rectangle is in film coordinates
    (the edge map and the split rays use them). Read as film coordinates, a crop window's
    projections fell left of the window and no light in it was ever split (a lost gain)."""
    d = rs.cornell_draaw(res=32, spp=4)
    full = mi.load_dict(d)
    d["sensor"]["film"].update(crop_offset_x=12, crop_offset_y=1, crop_width=8, crop_height=6)
    crop = mi.load_dict(d)
    x0, y0, x1, y1 = emission_split.emitter_rect(full, full.sensors()[0])
    assert emission_split.emitter_rect(crop, crop.sensors()[0]) == (max(x0, 12), max(y0, 1), min(x1, 20), min(y1, 7))


def test_a_light_thinner_than_a_pixel_is_found():
    """At 16x16 the Cornell box's light is a strip less than a pixel tall, between two rows of
    pixel corners: the half-pixel probe lattice still finds it, and only where it is."""
    scene = cornell(16)
    sensor = scene.sensors()[0]
    edges = np.array(emission_split.edge_map(scene, sensor, emission_split.emitter_rect(scene, sensor),
                                             mi.RayFlags.ShadingFrame)).reshape(16, 16)
    lit = np.array(mi.render(scene, integrator=mi.load_dict({"type": "path", "max_depth": 1}),
                             spp=256, seed=3))[..., :3].sum(-1) > 0
    assert edges.sum() >= 3, edges.sum()
    assert lit[edges].all()


def probe_kernels(fn) -> tuple:
    """``fn()``'s result and the hashes of the JIT kernels it launched."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()
        out = fn()
        return out, {k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT}
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def test_edge_map_follows_the_camera(box32):
    """A moved camera gets its own edge map (the cache key follows the camera), made by the
    same kernels (the moved rectangle reaches the probes as data, not as constants that
    compile a new kernel for every camera of a preview's orbit or a batch's path)."""
    integ = integrator("draaw_v4", max_depth=3)
    sensor = box32.sensors()[0]
    params = mi.traverse(box32)
    old = mi.Transform4f(params["sensor.to_world"])

    def moved(dx):
        params["sensor.to_world"] = mi.Transform4f().translate([dx, 0.0, 0.0]) @ old
        params.update()
        rect = emission_split.emitter_rect(box32, sensor)
        return rect, probe_kernels(lambda: np.array(integ.edge_map(box32, sensor)))

    try:
        rect1, (map1, k1) = moved(0.15)
        rect2, (map2, k2) = moved(0.3)
        assert rect1 != rect2 and map1.any() and (map2 != map1).any()
        assert k2 and k2 <= k1, (k1, k2)
        fresh = emission_split.edge_map(box32, sensor, rect2, mi.RayFlags.ShadingFrame)
        assert (map2 == np.array(fresh)).all()
    finally:
        params["sensor.to_world"] = old
        params.update()


def test_light_gradient_through_the_split_rays(box32):
    """d(mean image)/d(light radiance) where the light is seen (32x32: the light is two pixel
    rows, all edge pixels, and about half of the derivative; a split that drops their
    derivative is far off), reverse mode against finite differences, and forward mode
    against reverse mode."""
    scene = box32
    key = "light.emitter.radiance.value"
    integ = integrator("draaw_v4", max_depth=2)
    n = 6
    ad = np.array([ad_gradient(scene, integ, key, 64, s) for s in range(n)])
    fd = np.array([fd_gradient(scene, integ, key, 0.5, 256, 10 + s) for s in range(n)])
    se = np.sqrt(ad.var(ddof=1) / n + fd.var(ddof=1) / n)
    assert abs(ad.mean() - fd.mean()) <= 3 * se + 1e-7, (ad, fd, se)
    assert se < 0.05 * abs(fd.mean()), (se, fd)
    fwd = [forward_gradient(scene, integ, key, 64, s) for s in range(n)]
    se_f = np.sqrt(np.var(fwd, ddof=1) / n + ad.var(ddof=1) / n)
    assert abs(np.mean(fwd) - ad.mean()) <= 3 * se_f + 1e-7, (fwd, ad)


def test_bad_ray_counts_are_refused():
    from draaw_mi.errors import ParameterError
    with pytest.raises((ParameterError, RuntimeError), match="emission_split=2"):
        integrator("draaw_v4", emission_split=2)


def test_doctests():
    import doctest
    res = doctest.testmod(emission_split)
    assert res.attempted >= 2 and res.failed == 0, res
