"""Hard cases (anchors.md §3.2, design.md §8): every version renders finite images and finite
gradients with grazing cameras, roughness/metallic at 0 and 1, a light touching surfaces,
degenerate triangles (zero area, repeated vertices, recomputed vertex normals of
degenerate faces) and a camera
inside an object; with Dr.Jit's fast-math on and off."""
from __future__ import annotations

import numpy as np
import pytest

from integrators_helpers import VERSIONS, ad_gradient, dr, integrator, mi, render_np, rs

T = mi.ScalarTransform4f

OBJ = """\
v -1 0 -1
v 1 0 -1
v 1 0 1
v 0 0.5 0
v 0 0.5 0
v 2 0.5 0
v 0.5 1 0.5
f 1 2 3
f 4 5 6
f 4 6 4
f 7 7 7
f 1 3 7
"""

CAMERAS = {
    "normal": T().look_at(origin=[0.0, 1.5, 4.0], target=[0.0, 0.3, 0.0], up=[0, 1, 0]),
    # grazing: just above the floor, looking along it
    "grazing": T().look_at(origin=[-2.9, 1e-3, 0.0], target=[3.0, 0.0, 0.0], up=[0, 1, 0]),
    # inside the closed metal cube
    "inside": T().look_at(origin=[1.2, 0.35, -0.6], target=[0.0, 0.35, 0.0], up=[0, 1, 0]),
}


def hard_scene(tmp_path, camera: str) -> dict:
    obj = tmp_path / "degenerate.obj"
    obj.write_text(OBJ)
    d = {
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 60.0, "to_world": CAMERAS[camera],
                   "film": {"type": "hdrfilm", "width": 12, "height": 12,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3.0),
                  "bsdf": rs.draaw([0.7, 0.7, 0.7], roughness=0.0, metallic=1.0)},
        "rough": {"type": "sphere", "center": [-0.8, 0.5, 0.0], "radius": 0.5,
                  "bsdf": rs.draaw([0.8, 0.4, 0.2], roughness=1.0, metallic=0.0, specular=1.0)},
        "mirrorish": {"type": "sphere", "center": [0.0, 0.4, 1.0], "radius": 0.4,
                      "bsdf": rs.draaw([0.9, 0.9, 0.9], roughness=0.0, metallic=0.0,
                                       specular=1.0, reflection=1.0)},
        "box": {"type": "cube", "to_world": T().translate([1.2, 0.35, -0.6]).scale(0.35),
                "bsdf": rs.draaw([0.5, 0.6, 0.7], roughness=1.0, metallic=1.0,
                                 two_sided=True)},
        "degenerate": {"type": "obj", "filename": str(obj), "face_normals": False,
                       "to_world": T().translate([0.0, 0.01, -1.5]),
                       "bsdf": rs.draaw([0.6, 0.6, 0.6], roughness=0.5)},
        # an area light lying on the floor (coplanar, touching) and one touching the sphere
        "floor_light": {"type": "rectangle",
                        "to_world": T().translate([1.5, 0.0, 1.2]).rotate([1, 0, 0], -90).scale(0.3),
                        "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [5, 5, 5]}}},
        "light": {"type": "rectangle",
                  "to_world": T().translate([-0.8, 1.0, 0.0]).rotate([1, 0, 0], 90).scale(0.4),
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [10, 9, 8]}}},
        "pt": {"type": "point", "position": [0.0, 0.4, 0.6],   # inside the mirror sphere's skin
               "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
    }
    return d


@pytest.fixture(params=list(CAMERAS))
def camera(request):
    return request.param


@pytest.mark.parametrize("kind", VERSIONS)
def test_images_finite(tmp_path, camera, kind):
    scene = mi.load_dict(hard_scene(tmp_path, camera))
    for depth in (1, 2, 6):
        img = render_np(scene, integrator(kind, max_depth=depth, aovs="all"), 16)
        assert np.isfinite(img).all(), (kind, camera, depth)
        assert (img[..., :3] >= 0).all()


@pytest.mark.parametrize("kind", VERSIONS)
@pytest.mark.parametrize("key", ["floor.bsdf.roughness.value", "rough.bsdf.roughness.value",
                                 "floor.bsdf.metallic.value", "mirrorish.bsdf.base_color.value",
                                 "box.bsdf.specular.value", "light.emitter.radiance.value"])
def test_gradients_finite(tmp_path, kind, key):
    scene = mi.load_dict(hard_scene(tmp_path, "normal"))
    g = ad_gradient(scene, integrator(kind, max_depth=5), key, 16, 0)
    assert np.isfinite(g), (kind, key, g)


@pytest.mark.parametrize("fast_math", [True, False])
def test_finite_with_and_without_fast_math(tmp_path, fast_math):
    old = dr.flag(dr.JitFlag.FastMath)
    dr.set_flag(dr.JitFlag.FastMath, fast_math)
    try:
        for camera in ("normal", "grazing"):
            scene = mi.load_dict(hard_scene(tmp_path, camera))
            for kind in VERSIONS:
                img = render_np(scene, integrator(kind, max_depth=4), 16)
                assert np.isfinite(img).all(), (kind, camera, fast_math)
                g = ad_gradient(scene, integrator(kind, max_depth=4),
                                "floor.bsdf.roughness.value", 16, 1)
                assert np.isfinite(g), (kind, camera, fast_math)
    finally:
        dr.set_flag(dr.JitFlag.FastMath, old)


def test_camera_inside_closed_object_sees_its_inside(tmp_path):
    """Inside the two-sided metal box every camera ray hits the box: alpha is 1."""
    d = hard_scene(tmp_path, "inside")
    d["sensor"]["film"]["pixel_format"] = "rgba"
    scene = mi.load_dict(d)
    for kind in VERSIONS:
        img = render_np(scene, integrator(kind), 16)
        assert np.isfinite(img).all()
        assert np.allclose(img[..., 3], 1.0), kind


def test_v3_stops_a_path_whose_throughput_is_zero(monkeypatch):
    """``max_depth = -1`` inside a closed diffuse shell: V3 bounced on after the throughput
    underflowed to 0 (28 s for an 8x8 image that 1024 bounces render identically). Counted in
    an evaluated loop, whose body runs once per bounce: albedo 0.3 underflows float32 after
    about 90 bounces (0.3^86 < 1.4e-45), which took 146 BSDF evaluations here; without the stop
    the loop never ends (cut at 400)."""
    import draaw_mi
    from draaw_mi.integrators import v3
    d = {"render": {"resolution": [4, 4], "spp": 1, "max_depth": -1, "filter": "box"},
         "camera": {"origin": [0, 0, 0], "target": [0, 0, -1]},
         "materials": {"m": {"base_color": [0.3] * 3, "roughness": 1.0, "metallic": 0.0, "specular": 0.0}},
         "shapes": [{"type": "sphere", "name": "shell", "material": "m", "center": [0, 0, 0], "radius": 2.0}],
         "lights": [{"type": "point", "position": [0.3, 0.5, 0.2], "intensity": 3.0}]}
    scene = draaw_mi.load_scene(d)
    calls = [0]
    original = v3.DraawV3Integrator._eval

    def counted(self, *args, **kwargs):
        calls[0] += 1
        if calls[0] > 400:
            raise RuntimeError("V3 kept bouncing paths of zero throughput")
        return original(self, *args, **kwargs)
    monkeypatch.setattr(v3.DraawV3Integrator, "_eval", counted)
    dr.set_flag(dr.JitFlag.SymbolicLoops, False)
    try:
        img = np.array(mi.render(scene.mi_scene, integrator=mi.load_dict({"type": "draaw_v3", "max_depth": -1}), spp=1, seed=0))
    finally:
        dr.set_flag(dr.JitFlag.SymbolicLoops, True)
    assert 20 < calls[0] <= 400 and np.isfinite(img).all() and img.mean() > 0
