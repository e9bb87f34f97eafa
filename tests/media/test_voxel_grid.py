"""VoxelGrid: construction, validation, editing (GO-Draaw semantics, quirks fixed), picking,
files (voxelising meshes: test_voxelize.py). References are independent: analytic ray/box
intersections, Mitsuba's own ``.vol`` reader."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi  # noqa: F401
import mitsuba as mi

from draaw_mi import IOFailure, ParameterError
from draaw_mi.media import VoxelGrid, read_vol, write_vol

GO_DRAAW = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared",
                                         "data", "go-draaw"))


def random_grid(seed=0, shape=(7, 5, 6), p=0.15):
    rng = np.random.default_rng(seed)
    return VoxelGrid.from_arrays(occupied=rng.random(shape) < p, bbox_min=(-1, -0.5, 0),
                                 bbox_max=(2, 1.5, 1.2), seed=seed)


def reference_pick(g: VoxelGrid, o, d):
    """First occupied cell by intersecting the ray with every occupied cell's box."""
    best, best_t = None, np.inf
    size = g.cell_size
    for idx in np.argwhere(g.occupied):
        lo = g.bbox_min + idx * size
        hi = lo + size
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo - o) / d, (hi - o) / d
        t0 = np.nanmax(np.minimum(ta, tb))
        t1 = np.nanmin(np.maximum(ta, tb))
        if t1 >= max(t0, 0) and t1 > t0 + 1e-9 and max(t0, 0) < best_t:
            best, best_t = tuple(int(v) for v in idx), max(t0, 0)
    return best


# --------------------------------------------------------------------------- validation
def test_validation_errors_name_the_field():
    with pytest.raises(ParameterError, match=r"density\[0, 1, 0\] = -1"):
        VoxelGrid.from_arrays(density=np.array([[[0], [-1.0]]]))
    with pytest.raises(ParameterError, match="density.*nan"):
        VoxelGrid.from_arrays(density=np.full((2, 2, 2), np.nan))
    with pytest.raises(ParameterError, match="density has shape"):
        VoxelGrid.from_arrays(occupied=np.zeros((2, 2, 2)), density=np.zeros((2, 2, 3)))
    with pytest.raises(ParameterError, match="color has shape"):
        VoxelGrid.from_arrays(occupied=np.zeros((2, 2, 2)), color=np.zeros((2, 3, 2, 3)))
    with pytest.raises(ParameterError, match="empty"):
        VoxelGrid.empty(4, bbox_min=(0, 0, 0), bbox_max=(1, 0, 1))
    with pytest.raises(ParameterError, match="resolution"):
        VoxelGrid.empty((4, 0, 4))
    with pytest.raises(ParameterError, match="randomness"):
        VoxelGrid.empty(2).paint((1, 0, 0), randomness=-1)


def test_a_grid_too_large_for_memory_is_refused_with_its_size():
    """Past limits.MAX_GRID_CELLS (2^26) a grid is refused before anything is allocated, with
    the estimated memory (numpy had said 'Unable to allocate 909 TiB', or died at 1024^3)."""
    from draaw_mi.limits import MAX_GRID_CELLS
    from draaw_mi.media.procedural import plume
    with pytest.raises(ParameterError, match=r"VoxelGrid.empty: resolution \(100000, 100000, 100000\) is "
                                             r"1,000,000,000,000,000 cells \(~6\.7e\+07 GB"):
        VoxelGrid.empty(100000)
    with pytest.raises(ParameterError, match=r"VoxelGrid.empty: resolution \(512, 512, 257\) is .* expected at "
                                             r"most 67,108,864 cells"):
        VoxelGrid.empty((512, 512, 257))
    with pytest.raises(ParameterError, match=r"VoxelGrid.from_arrays: arrays of shape \(67108865, 1, 1\) is"):
        VoxelGrid.from_arrays(density=np.broadcast_to(np.float32(0), (MAX_GRID_CELLS + 1, 1, 1)))
    with pytest.raises(ParameterError, match=r"plume: resolution \(4096, 4096, 8\) is"):
        plume((4096, 4096, 8))
    assert VoxelGrid.empty((MAX_GRID_CELLS // 4, 2, 2), seed=1).shape == (MAX_GRID_CELLS // 4, 2, 2)


# --------------------------------------------------------------------------- picking
def test_pick_matches_exact_ray_box_reference():
    rng = np.random.default_rng(3)
    g = random_grid()
    hits = 0
    for _ in range(300):
        o = rng.uniform(-3, 4, 3)
        target = rng.uniform(g.bbox_min, g.bbox_max)
        d = target - o
        ref = reference_pick(g, o, d)
        assert g.pick(o, d) == ref, (o, d)
        hits += ref is not None
    assert hits > 100


def test_pick_from_inside_and_along_cell_planes():
    g = VoxelGrid.empty((4, 4, 4), (0, 0, 0), (4, 4, 4))
    g.occupied[3, 2, 2] = True
    assert g.pick((0.5, 2.5, 2.5), (1, 0, 0)) == (3, 2, 2)
    assert g.pick((0.5, 2.5, 2.5), (-1, 0, 0)) is None
    # grazing: exactly on the plane y = 2 between cells iy=1 and iy=2
    assert g.pick((-1, 2.0, 2.5), (1, 0, 0)) == (3, 2, 2)


def test_pick_of_a_ray_pointing_away_from_the_grid_is_none():
    """A full grid wholly behind the ray's origin (the ray starts at x = 2 and points to +x,
    the box is 0..1): the ray's t >= 0 part meets no cell, so no pick (the slab test took an
    interval lying entirely at t < 0 for a hit and gave the cell (3, 2, 2))."""
    g = VoxelGrid.empty((4, 4, 4), (0, 0, 0), (1, 1, 1))
    g.occupied[:] = True
    assert g.pick((2.0, 0.5, 0.5), (1, 0, 0)) is None
    assert g.pick((2.0, 0.5, 0.5), (-1, 0, 0)) == (3, 2, 2)        # turned round: the near cell


def test_pick_of_an_axis_parallel_ray_passing_outside_the_grid_is_none():
    """A ray along +x at y = 1.5 passes above the box 0..1 (and one at y = -0.5 below it):
    parallel to the y slabs and outside them, it meets no cell (the test for an origin
    beyond the slab's upper side was missing: the ray above picked (0, 3, 2))."""
    g = VoxelGrid.empty((4, 4, 4), (0, 0, 0), (1, 1, 1))
    g.occupied[:] = True
    assert g.pick((-1.0, 1.5, 0.5), (1, 0, 0)) is None
    assert g.pick((-1.0, -0.5, 0.5), (1, 0, 0)) is None
    assert g.pick((-1.0, 0.9, 0.5), (1, 0, 0)) == (0, 3, 2)        # inside the slab: a hit


def test_pick_finds_thin_wall_that_64_fixed_steps_skip():
    """GO-Draaw marched 64 equal steps; a one-cell wall in a 256-cell grid is skipped."""
    g = VoxelGrid.empty((256, 1, 1), (0, 0, 0), (256, 1, 1))
    g.occupied[101] = True
    o, d = np.array([-0.3, 0.5, 0.5]), np.array([1.0, 0.0, 0.0])
    # GO-Draaw's march: entry..exit in 64 equal steps
    ts = np.linspace(0.3, 256.3, 64, endpoint=False)
    go = [g.index_of(o + t * d) for t in ts]
    assert not any(i is not None and g.occupied[i] for i in go)
    assert g.pick(o, d) == (101, 0, 0)


def test_pick_pixel_uses_the_sensor_ray():
    g = VoxelGrid.empty((5, 5, 5), (-1, -1, -1), (1, 1, 1))
    g.occupied[2, 2, 4] = True                          # the cell facing a camera on +z
    sensor = mi.load_dict({"type": "perspective", "fov": 30,
                           "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 9, "height": 9}})
    assert g.pick_pixel(sensor, 4, 4) == (2, 2, 4)
    assert g.pick_pixel(sensor, 0, 0) is None
    with pytest.raises(ParameterError, match="outside"):
        g.pick_pixel(sensor, 9, 0)


def test_pick_pixel_takes_a_draaw_scene_as_its_first_sensor():
    """The docstring takes a DraawScene: it had raised AttributeError (no 'film')."""
    g = VoxelGrid.empty((5, 5, 5), (-1, -1, -1), (1, 1, 1))
    g.occupied[2, 2, 4] = True
    scene = draaw_mi.load_scene({"render": {"resolution": [9, 9], "spp": 1},
                                 "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 30},
                                 "lights": [{"type": "constant", "intensity": 0.5}],
                                 "shapes": [{"type": "sphere", "center": [5, 5, -5], "radius": 0.1}]})
    sensor = scene.mi_scene.sensors()[0]
    for x, y in ((4, 4), (0, 0), (3, 5)):
        assert g.pick_pixel(scene, x, y) == g.pick_pixel(scene.mi_scene, x, y) == g.pick_pixel(sensor, x, y)
    assert g.pick_pixel(scene, 4, 4) == (2, 2, 4)


def test_pick_refuses_a_nan_or_malformed_origin():
    """A NaN origin had returned None with numpy's 'invalid value' warning."""
    g = VoxelGrid.empty(4)
    for origin in ((np.nan, 0, 0), (0, 0), (0, np.inf, 0)):
        with pytest.raises(ParameterError, match=r"VoxelGrid.pick: origin .*; expected a finite 3-vector"):
            g.pick(origin, (1, 0, 0))


def test_copy_keeps_both_generators_where_they_were():
    """copy() drew a seed from the original's generator, so the original's later random edits
    were not those it would have made uncopied; now the copy repeats them."""
    def edits(g):
        g.paint((0.5, 0.5, 0.5), randomness=0.5)
        return g.color.copy()
    grid = VoxelGrid.from_arrays(occupied=np.ones((3, 3, 3)), seed=5)
    uncopied = edits(VoxelGrid.from_arrays(occupied=np.ones((3, 3, 3)), seed=5))
    twin = grid.copy()
    assert np.array_equal(edits(grid), uncopied)
    assert np.array_equal(edits(twin), uncopied)


def test_complex_arrays_are_refused():
    """numpy had dropped the imaginary part with only a ComplexWarning."""
    for kw in (dict(density=np.ones((2, 2, 2)) * (1 + 1j)), dict(occupied=np.ones((2, 2, 2)),
                                                                 color=np.full((2, 2, 2, 3), 0.5 + 0j))):
        name = "density" if "density" in kw else "color"
        with pytest.raises(ParameterError, match=rf"VoxelGrid.from_arrays: {name} is complex; expected real"):
            VoxelGrid.from_arrays(**kw)


# --------------------------------------------------------------------------- editing
def test_draw_erase_via_ray_and_index():
    g = VoxelGrid.empty((4, 4, 4), (0, 0, 0), (1, 1, 1))
    g.occupied[1, 1, 1] = g.occupied[2, 1, 1] = True
    ray = ((-1, 0.3, 0.3), (1, 0, 0))
    assert g.draw(ray, (1, 0, 0)) == (1, 1, 1)
    assert np.allclose(g.color[1, 1, 1], (1, 0, 0))
    assert g.erase(ray) == (1, 1, 1)
    assert not g.occupied[1, 1, 1]
    assert g.pick(*ray) == (2, 1, 1)                    # the one behind is now visible
    assert g.erase(((-1, 0.9, 0.9), (1, 0, 0))) is None
    with pytest.raises(ParameterError, match="outside the grid"):
        g.draw((4, 0, 0), (1, 1, 1))


def test_add_is_a_clipped_3x3x3_block_without_wrapping():
    g = VoxelGrid.empty((5, 5, 5))
    assert g.add((0, 2, 2), (0, 1, 0)) == (0, 2, 2)
    assert int(g.occupied.sum()) == 2 * 3 * 3
    # GO-Draaw's linear-index offsets would have filled the previous row's end (x = 4)
    assert not g.occupied[4].any()
    g2 = VoxelGrid.empty((5, 5, 5))
    g2.add((2, 2, 2), (0, 1, 0))
    assert int(g2.occupied.sum()) == 27 and g2.occupied[1:4, 1:4, 1:4].all()


def test_paint_randomness_is_symmetric_seeded_and_reaches_dark_voxels():
    g = VoxelGrid.empty((20, 20, 20), seed=5)
    g.occupied[:] = True
    g.color[:] = 0.0                                   # dark voxels: GO-Draaw skipped them
    g.paint((0.5, 0.5, 0.5), randomness=0.4)
    c = g.color[g.occupied]
    # uniform noise of width 0.4: mean 0.5, std 0.4/sqrt(12); standard error of the mean
    se = 0.4 / np.sqrt(12) / np.sqrt(c.shape[0])
    assert np.all(np.abs(c.mean(0) - 0.5) < 5 * se)
    assert c.min() >= 0.3 - 1e-6 and c.max() <= 0.7 + 1e-6 and c.std() > 0.1
    g2 = VoxelGrid.empty((20, 20, 20), seed=5)
    g2.occupied[:] = True
    g2.paint((0.5, 0.5, 0.5), randomness=0.4)
    assert np.array_equal(g2.color, g.color)


def test_overwrite_fills_the_box_and_smoke_colour_noise_depends_on_randomness():
    g = VoxelGrid.empty((3, 4, 5))
    assert g.overwrite((0.2, 0.3, 0.4)) == 60 and g.occupied.all()
    g.density[:] = 0.0
    g.set_smoke_color((0.5, 0.5, 0.5), randomness=0.2)   # density 0: GO-Draaw added no noise
    assert g.smoke_color.std() > 0.01
    g.set_smoke_color((0.5, 0.5, 0.5))
    assert np.all(g.smoke_color == 0.5)


def test_to_smoke_moves_colour_and_per_cell_density():
    g = VoxelGrid.empty((4, 4, 4))
    g.draw((1, 2, 3), (0.9, 0.1, 0.2))
    g.draw((0, 0, 0), (0.1, 0.9, 0.2))
    assert g.to_smoke(density=7.0) == 2
    assert not g.occupied.any()
    assert g.density[1, 2, 3] == 7.0 and g.density[0, 0, 0] == 7.0 and g.density.sum() == 14.0
    assert np.allclose(g.smoke_color[1, 2, 3], (0.9, 0.1, 0.2))


@pytest.mark.parametrize("density", [1e39, float("nan"), -1.0, "1", True])
def test_to_smoke_refuses_a_density_float32_cannot_hold(density):
    """The grid stores float32: 1e39 was stored as Inf (NaN pixels at render), "1" raised a
    bare TypeError; the grid is left as it was."""
    g = VoxelGrid.empty((2, 2, 2))
    g.draw((0, 0, 0), (0.5, 0.5, 0.5))
    with pytest.raises(ParameterError, match="VoxelGrid.to_smoke: density="):
        g.to_smoke(density)
    assert g.occupied[0, 0, 0] and not g.density.any()


# --------------------------------------------------------------------------- voxelisation
def test_npz_round_trip_and_atomic_save(tmp_path, monkeypatch):
    g = random_grid(seed=2)
    g.density[:] = np.random.default_rng(0).random(g.shape)
    p = tmp_path / "g.npz"
    g.save(p)
    h = VoxelGrid.load(p)
    for k in ("occupied", "color", "density", "smoke_color", "bbox_min", "bbox_max"):
        assert np.array_equal(getattr(g, k), getattr(h, k)), k
    before = p.read_bytes()

    def boom(*a, **k):
        raise RuntimeError("disk full")
    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(RuntimeError):
        VoxelGrid.empty(2).save(p)
    assert p.read_bytes() == before
    assert [f.name for f in tmp_path.iterdir()] == ["g.npz"]


def test_a_grid_is_saved_to_npz_names_only(tmp_path):
    with pytest.raises(ParameterError, match=r"expected a \.npz file name"):
        VoxelGrid.empty(2).save(tmp_path / "g.txt")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("color", [(2.0, 0.0, 0.0), (-0.1, 0.5, 0.5), (0.5, float("nan"), 0.5)])
def test_colours_outside_0_1_are_refused_not_clipped(color):
    g = VoxelGrid.empty(2)
    with pytest.raises(ParameterError, match=r"expected 3 values in \[0, 1\]"):
        g.draw((0, 0, 0), color)
    assert not g.occupied.any()


def test_per_voxel_colours_and_indices_are_held_to_the_same_rules():
    """Per-voxel arrays follow draw()'s rules: a solid colour of 2 amplified light (image max
    1.245), a smoke albedo of 2 was clipped unsaid; a NaN index raised a bare ValueError."""
    occ = np.ones((2, 2, 2), bool)
    for name in ("color", "smoke_color"):
        arr = np.full((2, 2, 2, 3), 0.5)
        arr[1, 0, 1, 2] = 2.0
        with pytest.raises(ParameterError, match=f"from_arrays: {name} has values outside"):
            VoxelGrid.from_arrays(occupied=occ, **{name: arr})
        arr[1, 0, 1, 2] = 1.0
        VoxelGrid.from_arrays(occupied=occ, **{name: arr})           # 1 itself is a colour
    g = VoxelGrid.empty(2)
    for at in ((float("nan"), 0, 0), ((0, 0, 5), (0, float("inf"), -1)), "abc"):
        with pytest.raises(ParameterError, match=r"VoxelGrid.draw: "):
            g.draw(at, (0.5, 0.5, 0.5))
    assert not g.occupied.any()


def test_load_errors(tmp_path):
    with pytest.raises(IOFailure, match="missing.npz"):
        VoxelGrid.load(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, occupied=np.zeros((2, 2, 2)), density=-np.ones((2, 2, 2)))
    with pytest.raises(ParameterError, match="bad.npz.*density"):
        VoxelGrid.load(bad)


def test_vol_round_trip_against_mitsubas_reader(tmp_path):
    rng = np.random.default_rng(1)
    g = VoxelGrid.from_arrays(density=rng.random((5, 4, 3)).astype(np.float32) * 3,
                              bbox_min=(-1, 0, 2), bbox_max=(1.5, 1, 2.6))
    p = str(tmp_path / "d.vol")
    g.save_vol(p)
    # Mitsuba 3 ignores the box stored in the file: place the unit cube with to_world
    to_world = mi.ScalarTransform4f().translate(g.bbox_min.tolist()).scale((g.bbox_max - g.bbox_min).tolist())
    vol = mi.load_dict({"type": "gridvolume", "filename": p, "filter_type": "nearest",
                        "to_world": to_world})
    c = g.centers().reshape(-1, 3)
    it = dr_interaction(c)
    vals = np.array(vol.eval_1(it))
    assert np.allclose(vals, g.density.reshape(-1), atol=1e-6)
    h = VoxelGrid.from_vol(p)
    assert np.array_equal(h.density, g.density)
    assert np.allclose(h.bbox_min, g.bbox_min) and np.allclose(h.bbox_max, g.bbox_max)


def dr_interaction(points: np.ndarray):
    it = mi.Interaction3f()
    it.p = mi.Point3f(*[mi.Float(points[:, i].astype(np.float32)) for i in range(3)])
    return it


def test_truncated_or_bad_vol_is_one_clear_error(tmp_path):
    p = tmp_path / "t.vol"
    write_vol(p, np.ones((4, 4, 4, 1), np.float32), (0, 0, 0), (1, 1, 1))
    raw = p.read_bytes()
    p.write_bytes(raw[:-10])
    with pytest.raises(ParameterError, match="truncated"):
        read_vol(p)
    p.write_bytes(raw[:20])
    with pytest.raises(ParameterError, match="header"):
        read_vol(p)
    p.write_bytes(b"XYZ" + raw[3:])
    with pytest.raises(ParameterError, match="magic"):
        read_vol(p)


def _vol_header(p, version=3, encoding=1, size=(2, 2, 2, 1)):
    """A ``.vol`` with Mitsuba's 48-byte header (``'VOL'``, version byte, int32 encoding,
    int32 x, y, z, channels, six float32 bounds) and 8 float32 ones after it."""
    import struct
    p.write_bytes(struct.pack("<3sBiiiii6f", b"VOL", version, encoding, *size, 0, 0, 0, 1, 1, 1)
                  + np.ones(8, "<f4").tobytes())
    return p


@pytest.mark.parametrize("header, message", [
    (dict(version=2), r"format version 2; expected 3"),
    (dict(encoding=0), r"encoding 0; only 1 \(float32\) is supported"),
    (dict(size=(0, 2, 2, 1)), r"size 0x2x2x1; expected positive sizes"),
])
def test_a_vol_of_another_version_or_encoding_or_with_an_empty_side_is_refused(tmp_path, header, message):
    """Mitsuba 3 reads version 3 with encoding 1 (float32) only, and a grid needs a cell: a
    version-2 header, encoding 0 or a side of 0 was read as float32 data (a (2, 2, 0, 1)
    grid for the side of 0) instead of one ParameterError naming what is wrong."""
    p = _vol_header(tmp_path / "g.vol", **header)
    with pytest.raises(ParameterError, match=r"read_vol\(.*g\.vol'\): " + message):
        read_vol(p)
    assert read_vol(_vol_header(tmp_path / "ok.vol"))[0].shape == (2, 2, 2, 1)   # the same, valid


def test_a_vol_is_read_as_the_kind_it_holds(tmp_path):
    """A 3-channel .vol (save_vol(what='smoke_color')) was read as a density (the mean of the
    albedo channels) and a 2-channel one taken: each kind is read only when asked for, and
    bytes after the data are refused."""
    rng = np.random.default_rng(2)
    g = VoxelGrid.from_arrays(density=rng.random((3, 4, 2)), smoke_color=rng.random((3, 4, 2, 3)))
    c, d = str(tmp_path / "c.vol"), str(tmp_path / "d.vol")
    g.save_vol(c, what="smoke_color")
    g.save_vol(d)
    with pytest.raises(ParameterError, match=r"VoxelGrid.from_vol\('.*c\.vol'\): the file has 3 channels \(a "
                                             r"colour grid, as save_vol\(what='smoke_color'\) writes\); "
                                             r"what='density' reads 1; read it with what='smoke_color'"):
        VoxelGrid.from_vol(c)
    h = VoxelGrid.from_vol(c, what="smoke_color")
    assert np.array_equal(h.smoke_color, g.smoke_color) and not h.density.any()
    with pytest.raises(ParameterError, match=r"d\.vol'\): the file has 1 channels \(a density grid\); "
                                             r"what='smoke_color' reads 3; read it with what='density'"):
        VoxelGrid.from_vol(d, what="smoke_color")
    assert np.array_equal(VoxelGrid.from_vol(d).density, g.density)
    two = tmp_path / "two.vol"
    write_vol(two, rng.random((2, 2, 2, 2)), (0, 0, 0), (1, 1, 1))
    with pytest.raises(ParameterError, match=r"the file has 2 channels \(neither a density nor a colour grid\)"):
        VoxelGrid.from_vol(two)
    extra = tmp_path / "extra.vol"
    extra.write_bytes(open(d, "rb").read() + b"junk")
    with pytest.raises(ParameterError, match=r"read_vol\(.*extra\.vol'\): 100 data bytes for a 3x4x2x1 grid; "
                                             r"expected 96 \(4 bytes after the data\)"):
        VoxelGrid.from_vol(extra)


def test_a_vol_with_an_empty_header_box_is_placed_by_the_box_given(tmp_path):
    """Mitsuba ignores a .vol's header box, and a file may leave it empty: with bbox_min /
    bbox_max given the file is read (it had been refused for the box it was not to use);
    without them the error says the empty box is the file header's and to give bounds (it
    said only "VoxelGrid: bounds ... are empty")."""
    import struct
    p = tmp_path / "flat.vol"
    vals = np.arange(8, dtype="<f4")
    p.write_bytes(struct.pack("<3sBiiiii6f", b"VOL", 3, 1, 2, 2, 2, 1, 0, 0, 0, 0, 0, 0) + vals.tobytes())
    with pytest.raises(ParameterError, match=r"from_vol\(.*flat\.vol'\): the file's header box \[0\.0, 0\.0, "
                                             r"0\.0\]\.\.\[0\.0, 0\.0, 0\.0\] is empty.*give the grid's bounds "
                                             r"\(bbox_min=, bbox_max="):
        VoxelGrid.from_vol(p)
    g = VoxelGrid.from_vol(p, bbox_min=(-1, 0, 0), bbox_max=(1, 2, 3))
    assert g.bbox_min.tolist() == [-1, 0, 0] and g.bbox_max.tolist() == [1, 2, 3]
    assert np.array_equal(g.density, vals.reshape(2, 2, 2).transpose(2, 1, 0))


@pytest.mark.parametrize("data, lo, hi, message", [
    (np.ones((2, 2, 2)), (0, 0), (1, 1, 1), r"box \(0, 0\)\.\.\(1, 1, 1\); expected two finite 3-vectors"),
    (np.ones((2, 2, 2)), (1, 1, 1), (0, 0, 0), r"box \(1, 1, 1\)\.\.\(0, 0, 0\); .* with bbox_min < bbox_max"),
    (np.full((2, 2, 2), np.nan), (0, 0, 0), (1, 1, 1), r"data\[0, 0, 0, 0\] = nan; expected finite values >= 0"),
    (-np.ones((2, 2, 2)), (0, 0, 0), (1, 1, 1), r"data\[0, 0, 0, 0\] = -1\.0; expected finite values >= 0"),
    (np.ones((2, 2, 2)) * (1 + 1j), (0, 0, 0), (1, 1, 1), r"complex data; expected real values"),
])
def test_write_vol_refuses_what_from_vol_would_refuse(tmp_path, data, lo, hi, message):
    """A box of 2 values was a bare struct.error; an inverted box, NaN or negative data were
    written, to be refused when read back."""
    p = tmp_path / "w.vol"
    with pytest.raises(ParameterError, match=r"write_vol\('.*w\.vol'\): " + message):
        write_vol(p, data, lo, hi)
    assert not p.exists()


def test_file_names_and_kinds_mixed_up_are_named(tmp_path):
    """save_vol under a .npz name wrote a .vol there; load of a .vol said 'pickled object
    data ... allow_pickle'."""
    g = VoxelGrid.from_arrays(density=np.ones((2, 2, 2)))
    with pytest.raises(ParameterError, match=r"VoxelGrid.save_vol\('.*y\.npz'\): expected a \.vol file name"):
        g.save_vol(str(tmp_path / "y.npz"))
    assert not (tmp_path / "y.npz").exists()
    g.save_vol(str(tmp_path / "x.vol"))
    with pytest.raises(IOFailure, match=r"VoxelGrid.load\('.*x\.vol'\): a Mitsuba \.vol grid, not a \.npz; "
                                        r"read it with VoxelGrid.from_vol"):
        VoxelGrid.load(str(tmp_path / "x.vol"))
    (tmp_path / "t.npz").write_text("hello")
    with pytest.raises(IOFailure, match=r"t\.npz'\): not a \.npz file"):
        VoxelGrid.load(str(tmp_path / "t.npz"))


def test_a_smoke_colour_is_where_its_voxel_is():
    """A red voxel at the x-max, y-min, z-min corner of a 4x4x4 grid: the medium's albedo
    volume (Mitsuba's own gridvolume, evaluated at the voxel's centre with nearest lookup)
    is red there and grey at the mirrored corner (the grid's (z, y, x) layout for Mitsuba
    was applied to the density only: coloured smoke came out mirrored)."""
    import mitsuba as mi
    from draaw_mi.media.mitsuba_dicts import smoke_medium
    col = np.full((4, 4, 4, 3), 0.5, np.float32)
    col[3, 0, 0] = (1.0, 0.0, 0.0)
    g = VoxelGrid.from_arrays(density=np.ones((4, 4, 4)), smoke_color=col, bbox_min=(0, 0, 0), bbox_max=(4, 4, 4))
    vol = mi.load_dict(smoke_medium(g, filter_type="nearest")["albedo"])
    it = mi.Interaction3f()
    for centre, want in (((3.5, 0.5, 0.5), (1.0, 0.0, 0.0)), ((0.5, 0.5, 3.5), (0.5, 0.5, 0.5))):
        it.p = mi.Point3f(*centre)
        np.testing.assert_allclose(np.array(vol.eval(it)).ravel(), want, atol=1e-6)
    assert g.index_of((4.0, 4.0, 4.0)) == (3, 3, 3)          # the max face belongs to the last cell
    assert g.index_of((4.0, 2.5, 0.0)) == (3, 2, 0)


def test_an_inline_density_past_float32_is_named_as_given(recwarn):
    """A density of 1e39 was cast to float32 first: reported as ``inf`` after numpy's overflow
    warning. It is checked in float64 before the cast: named with its value and the float32
    limit, and no warning."""
    d = np.zeros((2, 2, 2))
    d[1, 0, 1] = 1e39
    with pytest.raises(ParameterError, match=r"VoxelGrid.from_arrays: density\[1, 0, 1\] = 1e\+39; expected "
                                             r"finite values >= 0 up to the float32 limit 3\.40282"):
        VoxelGrid.from_arrays(density=d)
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in recwarn]
