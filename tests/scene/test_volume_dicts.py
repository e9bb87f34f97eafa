"""``[[volumes]]`` in scene files, the smoke medium dict against closed-form transmittance,
``draaw-mi info`` and bad inputs (one SceneError line, CLI exit 2)."""
from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

import draaw_mi
import mitsuba as mi

from draaw_mi import SceneError
from draaw_mi.media import VoxelGrid, write_vol
from draaw_mi.media.mitsuba_dicts import smoke_shape

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GO_DRAAW = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "go-draaw"))


def ortho_scene(shape_dict, res=(6, 4)):
    """Orthographic camera looking down -z over [-1, 1]^2, constant white environment."""
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "volpath", "max_depth": 4},
        "sensor": {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": res[0], "height": res[1], "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent"}},
        "env": {"type": "constant", "radiance": 1.0},
        "smoke": shape_dict})


def test_smoke_medium_orientation_and_scale_match_closed_form_transmittance():
    # density varies along x (image columns) and z (the viewing axis); nearest filtering
    nx, ny, nz = 6, 4, 5
    dx = np.linspace(0.2, 1.2, nx)[:, None, None]
    dz = np.linspace(0.5, 1.5, nz)[None, None, :]
    dens = np.broadcast_to(dx * dz, (nx, ny, nz)).astype(np.float32)
    g = VoxelGrid.from_arrays(density=dens, bbox_min=(-1, -1, -0.5), bbox_max=(1, 1, 0.5))
    scene = ortho_scene(smoke_shape(g, scale=2.0, filter_type="nearest", albedo=0.0))
    img = np.array(mi.render(scene, spp=4096, seed=0))[..., 0]
    tau = 2.0 * (dx[:, 0, 0] * dz.sum() * (1.0 / nz))              # per column, cell length 0.2
    expected = np.exp(-tau)
    got = img.mean(axis=0)                                        # average the 4 rows
    # delta-tracking estimate of a Bernoulli(T): standard error sqrt(T(1-T)/(4096*4))
    se = np.sqrt(expected * (1 - expected) / (4096 * 4))
    assert np.all(np.abs(got - expected) < 5 * se + 1e-4), (got, expected)


def test_smoke_scene_loads_reports_and_renders(tmp_path):
    s = draaw_mi.load_scene(os.path.join(ROOT, "scenes", "smoke.toml"), resolution=(16, 12), spp=4)
    summ = s.summary()
    vols = {v["name"]: v for v in summ["volumes"]}
    assert vols["plume"]["mode"] == "smoke" and vols["plume"]["cells"] > 1000
    assert vols["blocks"]["voxels"] == 20 and vols["blocks"]["faces"] == 72
    assert summ["features"]["media"]
    keys = mi.traverse(s.mi_scene).keys()
    assert "plume.interior_medium.sigma_t.data" in keys and "blocks.face_color" in keys
    img = np.array(draaw_mi.render(s, version="volpath", spp=4, seed=0))
    assert np.all(np.isfinite(img)) and img.mean() > 0.01
    out = subprocess.run([sys.executable, "-m", "draaw_mi_cli", "info", os.path.join(ROOT, "scenes", "smoke.toml")],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "volume: plume: smoke 32x48x32" in out.stdout and "volume: blocks: solid 3x3x3, 20 voxels" in out.stdout


def base_desc(**vol):
    v = {"name": "v", "mode": "smoke", "density": [[[1.0, 2.0]], [[0.5, 0.0]]], "bounds": [[-1, -1, -1], [1, 1, 1]]}
    v.update(vol)
    return {"render": {"resolution": [8, 8], "spp": 1},
            "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]},
            "shapes": [{"type": "sphere", "radius": 0.1, "center": [0, 0, -3]}],
            "lights": [{"type": "constant", "intensity": 1.0}],
            "volumes": [v]}


@pytest.mark.parametrize("vol, match", [
    ({"g": 1.0}, r"volumes\[0\]\.g.*g in \[-0\.999, 0\.999\]"),
    ({"g": -1.5}, r"g in \[-0\.999, 0\.999\]"),
    ({"g": 0.99999999}, r"volumes\[0\]\.g: 0\.99999999; .*g in \[-0\.999, 0\.999\]"),   # 1 in float32
    ({"g": 0.9999}, r"volumes\[0\]\.g: 0\.9999; .*g in \[-0\.999, 0\.999\]"),  # a near-delta lobe
    ({"density_scale": 1e39}, r"volumes\[0\]\.density_scale: 1e\+39 is beyond float32"),
    ({"density": [[[1e38, 1.0]]], "density_scale": 10.0}, r"density 1e\+38 is 1e\+39, beyond float32"),
    ({"density": [[[1.0, -2.0]]]}, r"volumes\[0\].*density\[0, 0, 1\] = -2"),
    ({"density": [[[1.0, float("nan")]]]}, r"density.*nan"),
    ({"bounds": [[0, 0, 0], [1, 0, 1]]}, r"volumes\[0\]\.bounds.*empty"),
    ({"density": [[[1.0, 2.0]]], "occupied": [[[1], [1]]]}, r"shape"),
    ({"mode": "fog"}, r"mode.*solid, smoke"),
    # GO-Draaw's 0-255 colour copied over: a solid voxel reflected 256x the light arriving
    ({"mode": "solid", "density": None, "occupied": [[[1, 1]]], "color": [255, 128, 0]},
     r"volumes\[0\]\.color: \[255, 128, 0\]; expected values in \[0, 1\] \(GO-Draaw's 0-255"),
    ({"material": "x"}, r"mode = solid volumes only"),
    ({"densty": 1}, r"did you mean 'density'"),
    ({"density": None, "procedural": {"type": "plume", "seed": "x"}}, r"procedural\.seed: 'x' is not a number"),
    ({"density": None, "procedural": {"type": "plume", "resolution": [8.5, 8, 8]}},
     r"procedural\.resolution\[0\]: 8\.5 is not an integer"),
    ({"density": None, "procedural": {"type": "plume", "resolution": [8, 8]}}, r"list of 3 integers"),
    ({"density": None, "procedural": {"type": "plume", "resolution": 4800}}, r"4800 is out of range"),
    # within 1024 per axis but too many cells: 1024^3 had died in numpy's allocator (~72 GB)
    ({"density": None, "procedural": {"type": "plume", "resolution": [1024, 1024, 128]}},
     r"procedural\.resolution: \(1024, 1024, 128\) is 134,217,728 cells \(~8\.99 GB .* at most 67,108,864"),
    # keys that were taken and ignored: a second grid beside a procedural one, a mesh's
    # voxelisation settings on a grid that is no mesh
    ({"procedural": {"type": "plume"}}, r"one of 'file', 'procedural' or inline arrays, not procedural and density"),
    ({"resolution": 32}, r"volumes\[0\]\.resolution: 'resolution' sets how a mesh 'file' is voxelised"),
    ({"density": None, "procedural": {"type": "plume"}, "fill": "solid"},
     r"\.fill: .*no mesh file; a procedural grid's size is procedural\.resolution"),
])
def test_bad_volume_entries_are_one_scene_error(vol, match):
    desc = base_desc(**vol)
    v = desc["volumes"][0]
    for key in [k for k, value in v.items() if value is None]:
        del v[key]                                  # (None: the entry has no such key)
    with pytest.raises(SceneError, match=match) as e:
        draaw_mi.load_scene(desc)
    assert "\n" not in str(e.value)
    assert str(e.value).count("volumes[0]") == 1     # one location (g named it twice)


def test_a_mesh_voxelised_past_the_cell_limit_is_a_scene_error(tmp_path):
    """resolution = 1024 passes the per-axis bound but is 2^30 cells (~72 GB): refused by name
    before voxelising (it had died in numpy's allocator)."""
    import trimesh
    trimesh.creation.box().export(tmp_path / "box.obj")
    desc = base_desc(mode="solid", file=str(tmp_path / "box.obj"), resolution=1024)
    del desc["volumes"][0]["density"]
    with pytest.raises(SceneError, match=r"volumes\[0\]\.resolution: \(1024, 1024, 1024\) is 1,073,741,824 "
                                         r"cells \(~71\.9 GB .* expected at most 67,108,864 cells"):
        draaw_mi.load_scene(desc)


def test_truncated_vol_file_is_a_scene_error_and_cli_exit_2(tmp_path):
    p = tmp_path / "d.vol"
    write_vol(p, np.ones((4, 4, 4, 1), np.float32), (0, 0, 0), (1, 1, 1))
    p.write_bytes(p.read_bytes()[:-7])
    desc = base_desc(file=str(p))
    del desc["volumes"][0]["density"]
    with pytest.raises(SceneError, match=r"volumes\[0\].*truncated"):
        draaw_mi.load_scene(desc)
    import json
    scene_file = tmp_path / "bad.json"
    scene_file.write_text(json.dumps(desc))
    out = subprocess.run([sys.executable, "-m", "draaw_mi_cli", "info", str(scene_file)],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("draaw-mi: error:") and "truncated" in lines[0]


def test_a_vol_with_an_empty_header_box_loads_at_the_entrys_bounds(tmp_path):
    """Mitsuba ignores a .vol's header box: with 'bounds' the entry places the grid, and a
    file whose header box is empty loads (it had been refused before 'bounds' applied)."""
    import struct
    vals = np.arange(1, 9, dtype="<f4")
    (tmp_path / "flat.vol").write_bytes(struct.pack("<3sBiiiii6f", b"VOL", 3, 1, 2, 2, 2, 1, *[0.0] * 6)
                                        + vals.tobytes())
    desc = base_desc(file=str(tmp_path / "flat.vol"))
    del desc["volumes"][0]["density"]
    s = draaw_mi.load_scene(desc)
    assert s.summary()["volumes"][0]["bounds"] == [[-1, -1, -1], [1, 1, 1]]
    data = np.array(mi.traverse(s.mi_scene)["v.interior_medium.sigma_t.data"])
    assert np.array_equal(data.reshape(-1), vals)
    del desc["volumes"][0]["bounds"]
    with pytest.raises(SceneError, match=r"volumes\[0\]: VoxelGrid.from_vol\(.*flat\.vol'\): the file's header box .* is "
                                         r"empty.*give the grid's bounds"):
        draaw_mi.load_scene(desc)


def test_a_colour_vol_as_a_volumes_file_is_one_error_in_the_scenes_terms(tmp_path):
    """A 3-channel .vol (save_vol(what='smoke_color')) as a [[volumes]] file: the entry has no
    'what', so VoxelGrid.from_vol's hint to read it with what='smoke_color' cannot be
    followed; the error names the entry's file, its channels and what to give instead.
    from_vol's new arguments are keywords: from_vol(path, 3) is still the seed."""
    g = VoxelGrid.from_arrays(density=np.ones((2, 2, 2)), smoke_color=np.full((2, 2, 2, 3), 0.5),
                              bbox_min=(-1, -1, -1), bbox_max=(1, 1, 1))
    g.save_vol(str(tmp_path / "c.vol"), what="smoke_color")
    desc = base_desc(file=str(tmp_path / "c.vol"))
    del desc["volumes"][0]["density"]
    with pytest.raises(SceneError, match=r"^<dict>: volumes\[0\]\.file: '.*c\.vol' has 3 channels; a \[\[volumes\]\] "
                                         r"\.vol file is the density, 1 channel .*VoxelGrid\.save"):
        draaw_mi.load_scene(desc)
    assert VoxelGrid.from_vol(str(tmp_path / "c.vol"), 3, what="smoke_color").smoke_color.shape == (2, 2, 2, 3)


def test_npz_and_vol_sources_give_the_same_medium(tmp_path):
    rng = np.random.default_rng(0)
    g = VoxelGrid.from_arrays(density=rng.random((4, 3, 5)), bbox_min=(-1, -1, -1), bbox_max=(1, 1, 1))
    g.save(tmp_path / "g.npz")
    g.save_vol(str(tmp_path / "g.vol"))
    datas = []
    for name in ("g.npz", "g.vol"):
        desc = base_desc(file=name)
        del desc["volumes"][0]["density"], desc["volumes"][0]["bounds"]
        s = draaw_mi.load_scene(desc | {}) if False else None
        from draaw_mi.scene.loading import from_description
        s = from_description(desc, "<t>", str(tmp_path), {})
        datas.append(np.array(mi.traverse(s.mi_scene)["v.interior_medium.sigma_t.data"]))
    assert np.array_equal(datas[0], datas[1])
    assert np.allclose(datas[0][..., 0], g.density.transpose(2, 1, 0))


@pytest.mark.skipif(not os.path.isdir(GO_DRAAW), reason=f"GO-Draaw data not found at {GO_DRAAW}")
def test_mesh_source_voxelises_go_draaw_monkey(tmp_path):
    desc = base_desc(mode="solid", file=os.path.join(GO_DRAAW, "monkey.obj"), resolution=24, color=[0.7, 0.5, 0.2])
    del desc["volumes"][0]["density"], desc["volumes"][0]["bounds"]
    s = draaw_mi.load_scene(desc)
    v = s.summary()["volumes"][0]
    assert v["mode"] == "solid" and v["voxels"] > 500 and v["faces"] > v["voxels"]


def test_a_mesh_as_smoke_is_its_voxels_at_density_scale(tmp_path):
    """``mode = "smoke"`` with a mesh (no density of its own): each voxel the mesh fills is
    smoke of density ``density_scale`` (it was refused: "no density > 0"). The medium's grid
    equals an independent voxelisation of the same mesh."""
    import trimesh
    from draaw_mi.media import VoxelGrid
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    mesh.export(tmp_path / "ball.obj")
    desc = base_desc(mode="smoke", file=str(tmp_path / "ball.obj"), resolution=12, fill="solid",
                     density_scale=4.0)
    del desc["volumes"][0]["density"], desc["volumes"][0]["bounds"]
    s = draaw_mi.load_scene(desc)
    ref = VoxelGrid.from_mesh(mesh, resolution=12, fill="solid")
    v = s.summary()["volumes"][0]
    assert v["mode"] == "smoke" and v["cells"] == int(ref.occupied.sum()) > 100 and v["max_sigma_t"] == 4.0
    grid = np.array(s.params["v.interior_medium.sigma_t.data"])[..., 0]        # (z, y, x)
    np.testing.assert_array_equal(grid, ref.occupied.transpose(2, 1, 0).astype(np.float32))
    assert np.isfinite(np.array(draaw_mi.render(s, version="v4", spp=2))).all()


@pytest.mark.parametrize("key,good,bad,match", [
    ("plume.interior_medium.phase_function.g", 0.3, 1.5, r"g in \[-0\.999, 0\.999\]"),
    ("plume.interior_medium.scale", 2.0, -5.0, r"density scale >= 0"),
    ("plume.interior_medium.albedo.value.value", [0.9, 0.9, 0.9], [1.2, 0.5, 0.5], r"values in \[0, 1\]"),
])
def test_medium_values_set_after_loading_are_checked_as_in_scene_files(tmp_path, key, good, bad, match):
    """A medium's g, density scale and albedo, set by a preview or a batch override, are held
    to the ranges of a scene file's [[volumes]] table (a g of 1.5 rendered negative pixels,
    exit 0); the good value passes the same checks."""
    from draaw_mi import ParameterError, batch
    from draaw_mi.rendering.preview import Preview
    scene_file = os.path.join(ROOT, "scenes", "smoke.toml")
    pv = Preview(draaw_mi.load_scene(scene_file, resolution=(8, 6)), freeze=False)
    pv.update({key: good})
    with pytest.raises(ParameterError, match=r"Preview.update: " + key.replace(".", r"\.") + ".*" + match):
        pv.update({key: bad})
    doc = {"output": "{job}/{frame:04d}.exr",
           "jobs": [{"name": "m", "scene": scene_file, "resolution": [8, 6], "spp": 1, "frames": 2,
                     "params": {key: {"values": [good, bad]}}}]}
    with pytest.raises(SceneError, match=r"frame 1.*" + match):
        batch.load(doc, out=str(tmp_path))
    doc["jobs"][0]["params"][key]["values"] = [good, good]
    batch.load(doc, out=str(tmp_path))


def test_a_camera_inside_a_smoke_box_is_refused():
    """It rendered as if the smoke were absent (density 1e6 gave the no-smoke image: the
    sensor's medium was not set). So did one on the box's face, or closer to it than its near
    clip (its rays started inside without crossing the face); one just beyond loads."""
    desc = base_desc(density_scale=1e6)
    desc["camera"] = {"origin": [0, 0, 0.5], "target": [0, 0, -3]}
    with pytest.raises(SceneError, match=r"camera: the camera at \[0\.0, 0\.0, 0\.5\] is inside smoke "
                                         r"volume 'v'.*move it outside") as e:
        draaw_mi.load_scene(desc)
    assert "\n" not in str(e.value)
    for z in (1.0, 1.005):                       # the face, and within the near clip (0.01)
        desc["camera"] = {"origin": [0, 0, z], "target": [0, 0, -3]}
        with pytest.raises(SceneError, match=r"within its near clip \(0\.011\d*\) of it"):
            draaw_mi.load_scene(desc)
    desc["camera"] = {"origin": [0, 0, 1.02], "target": [0, 0, -3]}
    sc = draaw_mi.load_scene(desc)
    assert sc.info["volumes"][0]["name"] == "v"
    # and it sees the smoke: density 1e6 in front of the sky
    assert float(np.array(draaw_mi.render(sc, version="v4", spp=1)).max()) < 1e-3


def test_a_batch_camera_path_through_a_smoke_box_is_a_bad_manifest(tmp_path, capsys):
    import tomli_w
    from draaw_mi.cli import main
    scene = tmp_path / "smoke.toml"
    scene.write_bytes(tomli_w.dumps(base_desc()).encode())
    doc = {"output": "out/{frame:04d}.exr",
           "jobs": [{"scene": str(scene), "frames": 3, "camera": {"look_at": [
               {"origin": [0, 0, 4], "target": [0, 0, 0]}, {"origin": [0, 0, 0.2], "target": [0, 0, -3]}]}}]}
    path = tmp_path / "m.toml"
    path.write_bytes(tomli_w.dumps(doc).encode())
    assert main(["batch", str(path), "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "frame 2" in err and "inside smoke volume 'v'" in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("as_jit", [False, True])
def test_a_preview_camera_moved_into_a_smoke_box_is_refused(as_jit):
    """The scene file's camera is checked at load and a batch path's per frame; a preview's
    (the tuner's orbit) was not, and rendered the smoke as absent around it."""
    import mitsuba as mi
    from draaw_mi.errors import ParameterError
    from draaw_mi.rendering.preview import Preview
    pv = Preview(draaw_mi.load_scene(base_desc()), version="v2", freeze=False, seed=1)
    inside = mi.ScalarTransform4f().look_at(origin=[0.2, 0.0, 0.5], target=[0, 0, -3], up=[0, 1, 0])
    outside = mi.ScalarTransform4f().look_at(origin=[0.2, 0.0, 2.5], target=[0, 0, -3], up=[0, 1, 0])
    wrap = mi.Transform4f if as_jit else (lambda t: t)
    with pytest.raises(ParameterError, match=r"the camera at \[0\.2, 0\.0, 0\.5\] is inside smoke "
                                             r"volume 'v'.*\(sensor\.to_world\)"):
        pv.update({"sensor.to_world": wrap(inside)})
    pv.update({"sensor.to_world": wrap(outside)})
    assert pv.step() is not None and pv.error is None


def two_smoke_slabs(b_lo_z: float) -> dict:
    """Black smoke slabs a (z in [-1, 0], sigma_t 0.2) and b (z from ``b_lo_z`` to 1, sigma_t
    0.4) before a white sky, seen along -z from afar with a 2-degree view (every camera ray
    crosses both slabs, within 3e-4 of their thickness)."""
    def slab(name, scale, z0, z1):
        return {"name": name, "mode": "smoke", "density": [[[1.0]]], "density_scale": scale,
                "albedo": [0.0, 0.0, 0.0], "bounds": [[-1, -1, z0], [1, 1, z1]]}
    desc = base_desc()
    desc["camera"] = {"origin": [0, 0, 40], "target": [0, 0, 0], "fov": 2.0}
    desc["shapes"][0]["center"] = [5, 5, -3]                 # out of view
    desc["volumes"] = [slab("a", 0.2, -1.0, 0.0), slab("b", 0.4, b_lo_z, 1.0)]
    return desc


def test_overlapping_smoke_boxes_are_refused():
    """Each smoke box is a null cube around its medium: where two overlap a ray carries one
    medium, and none after leaving the inner box (volpath and every version showed the sky
    brighter through the overlap than through either box)."""
    with pytest.raises(SceneError, match=r"volumes\[1\]\.bounds: smoke volume 'b' .* overlaps smoke volume 'a'"
                                         r".*merge them into one grid, or move them apart"):
        draaw_mi.load_scene(two_smoke_slabs(-0.5))
    desc = two_smoke_slabs(-0.5)
    desc["volumes"][1]["mode"] = "solid"                     # smoke beside a solid grid is fine
    del desc["volumes"][1]["density_scale"], desc["volumes"][1]["albedo"], desc["volumes"][1]["density"]
    desc["volumes"][1]["occupied"] = [[[1]]]
    draaw_mi.load_scene(desc)


def test_smoke_boxes_that_touch_up_to_rounding_are_accepted():
    """A face at 0.1 + 0.2 = 0.30000000000000004 against one at 0.3: touching, not overlapping."""
    desc = two_smoke_slabs(0.3)
    desc["volumes"][0]["bounds"][1][2] = 0.1 + 0.2
    draaw_mi.load_scene(desc)


@pytest.mark.parametrize("version", ["v1", "v2", "v3", "v4"])
def test_smoke_boxes_that_touch_add_up(version):
    """Slabs sharing the face z = 0: a ray leaves one medium for the other, so the sky shows
    through exp(-(0.2 + 0.4)) = 0.549 (the closed form; with either slab lost 0.67 or 0.82).
    Tolerance: 4 standard errors of the Bernoulli escape count of V3/V4's 4096 samples
    (V1/V2 march the uniform slabs exactly)."""
    scene = draaw_mi.load_scene(two_smoke_slabs(0.0))
    img = np.array(draaw_mi.render(scene, version, spp=64, seed=3), dtype=np.float64)[..., :3]
    p = np.exp(-0.6)
    assert abs(img.mean() - p) < 4 * np.sqrt(p * (1 - p) / (64 * 64)), img.mean()


def test_a_mesh_source_is_placed_at_its_bounds_whole(tmp_path):
    """``bounds`` places a voxelised mesh in the world as it places every other source (it
    was the voxelisation window in the mesh's coordinates: a world box away from the mesh
    cropped it to a piece, or to nothing). The grid equals the voxelisation without bounds;
    the smoke's box is the bounds."""
    import trimesh
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    mesh.export(tmp_path / "ball.obj")
    box = [[2.0, 0.0, -0.8], [3.6, 1.6, 0.8]]
    desc = base_desc(mode="smoke", file=str(tmp_path / "ball.obj"), resolution=12, fill="solid",
                     density_scale=4.0, bounds=box)
    del desc["volumes"][0]["density"]
    s = draaw_mi.load_scene(desc)
    ref = VoxelGrid.from_mesh(mesh, resolution=12, fill="solid")
    grid = np.array(s.params["v.interior_medium.sigma_t.data"])[..., 0]        # (z, y, x)
    np.testing.assert_array_equal(grid, ref.occupied.transpose(2, 1, 0).astype(np.float32))
    shape = next(sh for sh in s.mi_scene.shapes() if sh.id() == "v")
    bb = shape.bbox()
    np.testing.assert_allclose([list(bb.min), list(bb.max)], box, atol=1e-5)


@pytest.mark.parametrize("resolution", [np.int64(8), (np.int32(8), 8, np.int64(8)), [8, 8, 8]])
def test_plume_takes_numpy_integers(resolution):
    """plume(np.int64(8)) raised a bare "'numpy.int64' object is not iterable"."""
    from draaw_mi.media.procedural import plume
    assert np.array_equal(plume(resolution, seed=3), plume(8, seed=3))


@pytest.mark.parametrize("resolution", [8.0, (8.5, 8, 8), (8, 8), True, "8"])
def test_plume_refuses_a_resolution_that_is_not_whole_numbers(resolution):
    """A float side was truncated ((8.5, 8, 8) made an 8^3 grid) or a bare TypeError."""
    from draaw_mi.errors import ParameterError
    from draaw_mi.media.procedural import plume
    with pytest.raises(ParameterError, match=r"plume: resolution .*; expected an integer or \(nx, ny, nz\)"):
        plume(resolution)


@pytest.mark.parametrize("resolution", [(0, 8, 8), (8, 0, 8), 0])
def test_plume_refuses_a_resolution_with_an_empty_side(resolution):
    """A side of 0 cells makes no grid: one ParameterError naming the resolution (it was
    numpy's "zero-size array to reduction operation maximum")."""
    from draaw_mi.errors import ParameterError
    from draaw_mi.media.procedural import plume
    with pytest.raises(ParameterError, match=r"plume: resolution " + re.escape(repr(resolution))):
        plume(resolution)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_plume_fades_towards_the_top(seed):
    """The column is scaled by (1 - y) / 0.35 over the top 35 % of the box: at the top layer
    of 32 (y = 1 - 1/64) that is 0.045 of the unfaded column, so its density stays under a
    tenth of the middle layer's (measured: 0.047 against 0.824 at seed 0; with the fade gone
    the top layer held the maximum, 1)."""
    from draaw_mi.media.procedural import plume
    d = plume((32, 32, 32), seed=seed)
    top, middle = d[:, -1, :].max(), d[:, 16, :].max()
    assert middle > 0.3, middle
    assert top < 0.1 * middle, (top, middle)


def test_plume_is_seeded():
    """The seed picks the noise and the drift: the same seed gives the same array, another
    seed another one (every seed gave seed 0's plume)."""
    from draaw_mi.media.procedural import plume
    a = plume(16, seed=1)
    np.testing.assert_array_equal(a, plume(16, seed=1))
    largest_change = float(np.abs(a - plume(16, seed=2)).max())
    assert largest_change > 0.1, largest_change


def test_volpath_is_refused_a_smoke_it_would_not_finish():
    """One voxel of sigma_t 1e30: Mitsuba's volpath steps by one global majorant and ran for
    more than 10 minutes at 8x8 pixels (SIGTERM did not stop it); v1..v4 render it at once."""
    desc = base_desc(density=[[[0.0, 0.0]], [[0.0, 1e30]]])
    scene = draaw_mi.load_scene(desc)
    with pytest.raises(draaw_mi.RenderError, match=r"'volpath' about 3.5e\+30 steps a ray \(at most 1e\+06\); pick v1..v4"):
        draaw_mi.render(scene, version="volpath", spp=1)
    assert np.isfinite(np.array(draaw_mi.render(scene, version="v4", spp=1))).all()
    ok = draaw_mi.load_scene(base_desc())                      # sigma_t 2: about 7 steps a ray
    assert np.isfinite(np.array(draaw_mi.render(ok, version="volpath", spp=1))).all()
