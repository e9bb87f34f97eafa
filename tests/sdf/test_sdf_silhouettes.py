"""Boundary gradients of SDF shape parameters (draaw_mi.sdf.silhouette,
draaw_mi.integrators.silhouettes): whole-image gradients (every pixel, outlines and shadow edges
included) against central finite differences with common random numbers, and the band's parts
against closed forms.

The scenes keep to what the band covers: objects are black, or white and diffuse under a
constant sky, or shaded, away from the floor and from lights at the camera. Not covered, and
so not here: the crease of a sharp edge or operator (its shading or material jump: a black
slab with a grey crater cut by a subtraction gives AD 0.027 against FD 0.070), an object
touching a mesh, a point light at the camera (its shadow edges lie on the outlines: counted
twice), outlines met by bounce rays."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi
import drjit as dr
import mitsuba as mi
from draaw_mi.sdf import Sphere
from draaw_mi.sdf.silhouette import Band, closest_approach, inside_ray, kernel
from draaw_mi.sdf.tracer import TracerOptions, march

from sdf_helpers import base_description

RES = (32, 24)
SEEDS = 12


class One:
    """A one-root stand-in for an SDFScene (distance + boxes)."""
    def __init__(self, node):
        self.node = node

    def distance(self, p):
        return self.node.distance(p)

    def bboxes(self):
        return [self.node.bbox()]


def _scene(sdf, light=(2.0, 4.0, 3.0), floor=True, sky=False, sun=False):
    """Black sky above a floor wide enough that every outline has it behind (a mesh edge
    behind an outline puts a jump inside the band, and the FD secant over it is no derivative)."""
    d = base_description(RES)
    d["camera"] = {"origin": [0.0, 2.5, 5.0], "target": [0.0, 0.6, 0.0], "fov": 38}
    d["shapes"] = d["shapes"][:1] if floor else []
    if floor:
        d["shapes"][0]["scale"] = 10.0
    d["render"]["max_depth"] = 2
    d["materials"]["black"] = {"type": "diffuse", "reflectance": [0.0, 0.0, 0.0]}
    d["materials"]["white"] = {"type": "diffuse", "reflectance": [0.8, 0.8, 0.8]}
    d["lights"] = [{"type": "point", "position": list(light), "intensity": 30.0}]
    if sky:
        d["lights"] = [{"type": "constant", "intensity": 1.0}]
    if sun:
        d["lights"] = [{"type": "directional", "direction": [-0.3, -0.6, -1.0], "intensity": 3.0}]
    d["sdf"] = sdf
    return draaw_mi.load_scene(d)


def _loss(img):
    return dr.sum(img[..., :3], axis=None) / (RES[0] * RES[1])


def ad_fd(scene, key, comp, h, version, seeds=SEEDS, spp=32, options=None):
    """Per-seed AD (backward) and central-FD derivatives of the image mean."""
    params = draaw_mi.sdf.parameters(scene)
    v0 = params[key]
    base = [float(c[0]) for c in (v0.x, v0.y, v0.z)] if comp is not None else float(v0[0])
    ad, fd = [], []
    for seed in range(seeds):
        val = params[key]
        dr.enable_grad(val)
        img = draaw_mi.render(scene, version=version, spp=spp, seed=seed, params=params, post=[],
                              integrator_options=options)
        dr.backward(_loss(img))
        g = np.array(dr.grad(val)).ravel()
        ad.append(float(g[comp] if comp is not None else g[0]))
        dr.disable_grad(val)
        vals = []
        for sgn in (1.0, -1.0):
            if comp is not None:
                v = list(base)
                v[comp] += sgn * h
            else:
                v = base + sgn * h
            params[key] = v
            vals.append(_loss(draaw_mi.render(scene, version=version, spp=spp, seed=seed, post=[])).item())
        params[key] = base
        fd.append((vals[0] - vals[1]) / (2 * h))
    return np.array(ad), np.array(fd)


def _se(a):
    return a.std(ddof=1) / np.sqrt(len(a))


def check(ad, fd):
    """AD within 4 standard errors of FD (the boundary pass has its own seeds: the two
    estimates' errors are independent), and FD standing out of its own noise."""
    assert np.all(np.isfinite(ad)), ad
    se = np.hypot(_se(ad), _se(fd))
    assert abs(fd.mean()) > 4 * _se(fd), ("FD not above its noise", fd)
    z = (ad.mean() - fd.mean()) / se
    assert abs(z) <= 4.0, (ad.mean(), fd.mean(), se, z)
    return z


BALL = [{"type": "sphere", "name": "ball", "material": "black", "center": [0.0, 1.0, 0.0], "radius": 0.7}]
BOX = [{"type": "box", "name": "blk", "material": "black", "center": [0, 0.6, 0], "size": [1.2, 1.0, 0.9],
        "rotate": {"axis": [0, 1, 0], "angle": 35}}]
BLOB = [{"type": "sphere", "name": "a", "material": "black", "center": [-0.45, 0.8, 0], "radius": 0.55},
        {"type": "sphere", "name": "b", "material": "black", "center": [0.45, 0.8, 0], "radius": 0.55},
        {"type": "smooth_union", "name": "u", "children": ["a", "b"], "k": 0.4}]
CARVED = [{"type": "box", "name": "slab", "material": "black", "center": [0, 0.7, 0], "size": [1.4, 0.9, 0.8]},
          {"type": "sphere", "name": "bite", "material": "black", "center": [0.75, 0.7, 0.1], "radius": 0.4},
          {"type": "subtraction", "name": "cut", "children": ["slab", "bite"]}]
MOVED = [{"type": "sphere", "name": "core", "material": "black", "center": [0, 0, 0], "radius": 0.6,
          "translate": [0.1, 0.9, 0.0]}]
WHITE = [{"type": "sphere", "name": "ball", "material": "white", "center": [0.0, 1.0, 0.0], "radius": 0.8}]
SHADED = [{"type": "sphere", "name": "ball", "material": "ball", "center": [0.0, 1.0, 0.0], "radius": 0.8}]

# name: (sdf, scene options, key, component, FD step, version); the bug each catches is in
# its comment (besides a wrong band kernel or a missing camera pass, which fail them all)
CASES = {
    # outline against a lit floor + its shadow on the floor: shadow-ray term's sign or factor
    "ball_radius_shadow": (BALL, {}, "sdf.ball.radius", None, 0.02, "v4"),
    # a moving centre: dm/dpi taken at the closest point, not at the ray's hit
    "ball_centre_x": (BALL, {}, "sdf.ball.center", 0, 0.02, "v3"),
    # a sharp primitive's size: closest approach to an edge, grazing hits on a face
    "box_size": (BOX, {}, "sdf.blk.size", 0, 0.03, "v4"),
    # a smooth operator's k: the neck's outline and self-occlusion (a minimum before a hit)
    "blob_k": (BLOB, {}, "sdf.u.k", None, 0.03, "v4"),
    # a sharp operator: the outline of a subtraction, the bite's radius (V4; V2's every-light
    # loop in the slow form)
    "subtraction_radius": (CARVED, {}, "sdf.bite.radius", None, 0.03, "v4"),
    "subtraction_radius_v2": (CARVED, {}, "sdf.bite.radius", None, 0.03, "v2"),
    # a transformed node's translation: shadow term on V1's every-emitter light loop
    "translate_y": (MOVED, {}, "sdf.core_xf.translate", 1, 0.02, "v1"),
    # the outline alone, against a sky (no floor): L_in and L_out both from sample()
    "white_ball_sky": (WHITE, {"sky": True, "floor": False}, "sdf.ball.radius", None, 0.02, "v4"),
    # a shaded ball under a sun: interior (re-attachment) plus outline, L_in at the outline limit
    "shaded_ball_sun": (SHADED, {"sun": True, "floor": False}, "sdf.ball.radius", None, 0.02, "v4"),
}


# at 32x24 a pixel is 0.13 scene units: the default band (one pixel) is a third of the bite's
# radius, where the notch's outline bends (band 1: AD 0.0125 vs FD 0.0084; band 0.25: 0.0079)
BAND = {"subtraction_radius": 0.25, "subtraction_radius_v2": 0.25}


# three more cases, run by `make test-all` (subtraction_radius_v2: 23 s)
SLOW = ("ball_centre_x", "white_ball_sky", "subtraction_radius_v2")


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW else c for c in CASES])
def test_whole_image_gradient_matches_fd(case):
    sdf, opts, key, comp, h, version = CASES[case]
    ad, fd = ad_fd(_scene(sdf, **opts), key, comp, h, version,
                   options={"sdf_band": BAND[case]} if case in BAND else None)
    check(ad, fd)


def test_without_the_boundary_terms_the_gradient_is_wrong():
    """``sdf_silhouettes = false`` leaves the interior terms: on a black ball (no interior
    term) the gradient is then 0 where finite differences see the outline and the shadow."""
    ad, fd = ad_fd(_scene(BALL), "sdf.ball.radius", None, 0.02, "v4", seeds=4,
                   options={"sdf_silhouettes": False})
    assert np.all(ad == 0.0), ad
    assert abs(fd.mean()) > 8 * _se(fd), fd


def test_forward_mode_equals_backward_mode():
    scene = _scene(BALL)
    params = draaw_mi.sdf.parameters(scene)
    val = params["sdf.ball.radius"]
    dr.enable_grad(val)
    img = draaw_mi.render(scene, version="v4", spp=16, seed=3, params=params, post=[])
    dr.backward(_loss(img))
    back = float(dr.grad(val)[0])
    dr.disable_grad(val)
    val = params["sdf.ball.radius"]
    dr.enable_grad(val)
    img = draaw_mi.render(scene, version="v4", spp=16, seed=3, params=params, post=[])
    dr.set_grad(val, 1.0)
    dr.forward_to(img)
    fwd = float(np.array(dr.grad(img))[..., :3].sum()) / (RES[0] * RES[1])
    assert back != 0.0
    assert fwd == pytest.approx(back, rel=1e-4)


def test_primal_renders_trace_no_boundary_code():
    """The band exists only inside the gradient passes: a primal render after a gradient one
    has no ``sdf_band`` and gives the same image as before it (no state left behind)."""
    scene = _scene(BALL)
    before = np.array(draaw_mi.render(scene, version="v4", spp=4, seed=0, post=[]))
    params = draaw_mi.sdf.parameters(scene)
    dr.enable_grad(params["sdf.ball.radius"])
    dr.backward(_loss(draaw_mi.render(scene, version="v4", spp=4, seed=0, params=params, post=[])))
    dr.disable_grad(params["sdf.ball.radius"])
    integ = mi.load_dict({"type": "draaw_v4"})
    assert integ.sdf_band is None
    after = np.array(draaw_mi.render(scene, version="v4", spp=4, seed=0, post=[]))
    assert np.array_equal(before, after)


def test_gradient_passes_at_new_radii_compile_no_new_kernel():
    """The band's ray count changes with the radius; the adjoint of the gather that spreads
    their values back over the image's rays wrote into an array of that count, which Dr.Jit
    expands per thread with the count as a literal: each new value compiled a new kernel
    (a 60-step fit: 34 compiles). Gradient passes at 0.62, 0.66 and 0.70 launch only the
    kernels that the pass at 0.58 launched (compared by their code's hash, so that a kernel
    cache on disk does not hide one)."""
    scene = _scene(BALL)
    params = draaw_mi.sdf.parameters(scene)
    flag = dr.flag(dr.JitFlag.KernelHistory)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        seen = []
        for radius in (0.58, 0.62, 0.66, 0.70):
            params["sdf.ball.radius"] = radius
            params.update()
            val = params["sdf.ball.radius"]
            dr.kernel_history()                                  # (cleared)
            dr.enable_grad(val)
            dr.backward(_loss(draaw_mi.render(scene, version="v4", spp=4, seed=0, params=params, post=[])))
            grad = dr.grad(val)
            dr.eval(grad)
            dr.disable_grad(val)
            dr.sync_thread()
            assert float(grad[0]) != 0.0
            seen.append({(k["hash"], k["operation_count"]) for k in dr.kernel_history()
                         if k["type"] == dr.KernelType.JIT})
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, flag)
    for radius, kernels in zip((0.62, 0.66, 0.70), seen[1:]):
        assert kernels <= seen[0], (radius, sorted(n for _, n in kernels - seen[0]))


# --------------------------------------------------------------------------- the band's parts
def test_closest_approach_of_a_sphere_is_the_lines_distance():
    """Rays passing a sphere: m = distance from the centre to the line - R (closed form), at
    the foot of the perpendicular; rays that hit report a hit and no passed minimum."""
    sdf = One(Sphere((0.0, 0.0, 0.0), 0.5))
    b = np.array([0.52, 0.55, 0.6, 0.8, 0.3, 0.0], dtype=np.float32)     # impact parameters
    o = mi.Point3f(mi.Float(b), mi.Float(0.0), mi.Float(-3.0))
    d = mi.Vector3f(0.0, 0.0, 1.0)
    hit, t, m, found = closest_approach(sdf, o, d, mi.Float(dr.inf), mi.Bool(True), TracerOptions(), 0.4)
    hit, t, m, found = (np.array(x) for x in (hit, t, m, found))
    miss = b > 0.5
    assert np.all(hit == ~miss) and np.all(found == miss)
    # less the hit band, 1e-5 (1 + t) at most here
    np.testing.assert_allclose(m[miss], b[miss] - 0.5, rtol=2e-3, atol=5e-5)
    np.testing.assert_allclose(t[miss], 3.0, atol=0.06)


def test_a_ray_leaving_a_surface_has_no_minimum_there():
    """A shadow ray spawned on a sphere's surface, away from it: |f| only grows (the surface
    it leaves must not count as a passed minimum: every lit point would be in the band)."""
    sdf = One(Sphere((0.0, 0.0, 0.0), 0.5))
    o = mi.Point3f(0.5, 0.0, 0.0)
    d = dr.normalize(mi.Vector3f([1.0, 0.05, 0.2], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]))
    _, _, _, found = closest_approach(sdf, o, d, mi.Float(dr.inf), mi.Bool(True), TracerOptions(), 0.1)
    assert not np.any(np.array(found))


def test_inside_ray_grazes_the_surface_just_inside_the_outline():
    sdf = One(Sphere((0.0, 0.0, 0.0), 0.5))
    o = mi.Point3f(mi.Float([0.51, 0.53]), mi.Float(0.0), mi.Float(-3.0))
    d = mi.Vector3f(0.0, 0.0, 1.0)
    _, t, m, _ = closest_approach(sdf, o, d, mi.Float(dr.inf), mi.Bool(True), TracerOptions(), 0.1)
    eps = mi.Float(0.05)
    d_in, ok = inside_ray(sdf, o, d, t, m, eps, TracerOptions())
    assert np.all(np.array(ok))
    t_hit, hit, _ = march(sdf, o, d_in, mi.Float(dr.inf), mi.Bool(True), TracerOptions())
    assert np.all(np.array(hit))
    p = o + d_in * t_hit
    # hit near the outline: the normal is nearly perpendicular to the ray (grazing)
    cos = np.abs(np.array(dr.dot(dr.normalize(mi.Vector3f(p)), d_in)))
    assert np.all(cos < 0.05), cos


def test_kernel_weights_cancel_the_bands_first_order():
    """k integrates 1 to 1 and m to 0 over the band, whatever its width; 0 outside."""
    for eps in (0.01, 0.3):
        m = np.linspace(0.0, 2 * eps, 200001)
        k = np.array(kernel(mi.Float(m.astype(np.float32)), mi.Float(eps)))
        assert np.trapezoid(k, m) == pytest.approx(1.0, abs=2e-3)
        assert np.trapezoid(k * m, m) == pytest.approx(0.0, abs=2e-3 * eps)
        assert np.all(k[m > eps * 1.001] == 0.0)


def test_band_width_follows_the_pixel_footprint():
    scene = _scene(BALL)
    sensor = scene.mi_scene.sensors()[0]
    band = Band.of_sensor(sensor, 1.0)
    # a 38-degree camera, 32 pixels wide: one pixel subtends 2 tan(19 deg) / 32 radians
    assert band.angle == pytest.approx(2 * np.tan(np.radians(19)) / 32, rel=0.02)
    dist = np.linalg.norm(np.array([0.0, 2.5, 0.0]) - np.array(list(band.origin)))
    assert dist == pytest.approx(5.0, abs=0.02)            # the camera (rays start at its near clip)
    assert float(band.epsilon(mi.Point3f(0.0, 2.5, 0.0))[0]) == pytest.approx(dist * band.angle, rel=1e-4)
    with pytest.raises(draaw_mi.errors.ParameterError, match="width"):
        Band(0.0, (0, 0, 0), 0.01, 0.0)


def test_bad_band_option_is_refused_by_name():
    with pytest.raises(Exception, match="sdf_band"):
        mi.load_dict({"type": "draaw_v4", "sdf_band": 20.0})
    with pytest.raises(Exception, match="sdf_silhouettes"):
        mi.load_dict({"type": "draaw_v4", "sdf_silhouettes": "yes"})
