"""Local majorant grids (media/majorant.py): bounds checked against Mitsuba's own
``gridvolume`` lookups (conservative at random points for both filters, tight at voxel
centres), the level chosen per medium, and a dense voxel rendered by draaw_v3/draaw_v4
against a closed-form transmittance reference."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import draaw_mi  # noqa: F401
import drjit as dr
import mitsuba as mi

from draaw_mi.media import VoxelGrid
from draaw_mi.media import majorant as mj
from draaw_mi.media.mitsuba_dicts import smoke_medium, smoke_shape

sys.path.insert(0, os.path.dirname(__file__))
import media_scenes as ms  # noqa: E402

import draaw_mi.integrators.volume as volume  # noqa: E402


def sigma_at(medium, pts: np.ndarray) -> np.ndarray:
    """Mitsuba's own sigma_t of ``medium`` at world points ``pts`` (N, 3)."""
    m = dr.zeros(mi.MediumInteraction3f, len(pts))
    m.p = mi.Point3f(*[mi.Float(pts[:, a].astype(np.float32)) for a in range(3)])
    m.medium = mi.MediumPtr(medium)
    _, _, s = medium.get_scattering_coefficients(m)
    return np.array(s)[0].astype(np.float64)


def cell_of(maj, pts: np.ndarray) -> np.ndarray:
    shape = np.asarray(maj.values.shape)
    size = (maj.bbox_max - maj.bbox_min) / shape
    return np.clip(np.floor((pts - maj.bbox_min) / size).astype(int), 0, shape - 1)


def sparse_grid(n, lo, hi, seed=3) -> VoxelGrid:
    """Empty space with a few light blobs and three isolated dense voxels."""
    rng = np.random.default_rng(seed)
    g = VoxelGrid.empty(n, lo, hi)
    c = g.centers()
    for p in rng.uniform(np.asarray(lo) * 0.6, np.asarray(hi) * 0.6, (3, 3)):
        g.density[np.linalg.norm(c - p, axis=-1) < 0.2] = rng.uniform(2.0, 8.0)
    for _ in range(3):
        g.density[tuple(rng.integers(0, n))] = 400.0
    return g


CASES = {  # grid size, box; the 32^3 one pools several voxels per cell
    "small": ((6, 5, 7), (-1.0, -0.5, 0.0), (1.0, 1.0, 0.7)),
    "pooled": ((32, 32, 32), (-1.0, -1.0, -1.0), (1.0, 1.0, 1.0)),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("filter_type", ["trilinear", "nearest"])
def test_bound_holds_at_every_point(case, filter_type):
    """sigma_t <= the bound of the cell holding the point, at random points of the box, on
    voxel centres and on voxel faces (where a misplaced cell face shows first)."""
    n, lo, hi = CASES[case]
    g = sparse_grid(n, lo, hi)
    medium = mi.load_dict(smoke_medium(g, filter_type=filter_type, scale=1.5))
    maj = mj.build_majorant(medium, inside=0.5 * (np.array(lo) + np.array(hi)))
    assert maj.kind == "grid" and maj.values.size > 1, maj
    if case == "pooled":
        assert maj.values.shape[0] < n[0], maj.note        # several voxels per cell
    rng = np.random.default_rng(1)
    h = (np.array(hi) - np.array(lo)) / np.array(n)
    idx = rng.integers(0, n, (6000, 3))
    pts = np.concatenate([
        rng.uniform(lo, hi, (20000, 3)),
        np.array(lo) + (idx[:2000] + 0.5) * h,                               # centres
        np.array(lo) + (idx[2000:4000] + rng.uniform(0, 1, (2000, 3)) * [1, 1, 0]) * h,   # z faces
        np.array(lo) + (idx[4000:] + rng.uniform(0, 1, (2000, 3)) * [0, 1, 1]) * h,       # x faces
    ])
    pts = np.clip(pts, lo, np.array(hi) - 1e-6)
    s = sigma_at(medium, pts)
    assert s.max() > 100.0                                   # the dense voxels were sampled
    c = cell_of(maj, pts)
    bound = maj.values[c[:, 0], c[:, 1], c[:, 2]]
    # Mitsuba's float32 trilinear weights leak up to ~2e-6 of a voxel's value across the
    # centre plane that bounds a cell (measured 1.9e-6), only within float rounding of it
    over = s > bound * (1 + 1e-5) + 1e-5 * s.max()
    assert not over.any(), (pts[over][:3], s[over][:3], bound[over][:3])


@pytest.mark.parametrize("case", list(CASES))
def test_bound_is_tight_for_trilinear_lookups(case):
    """A trilinear lookup's maximum over a cell is at a voxel centre, so each cell's bound is
    the largest sigma_t Mitsuba returns at the voxel centres lying in that (closed) cell; a
    one-voxel dilation of the pooling fails this."""
    n, lo, hi = CASES[case]
    g = sparse_grid(n, lo, hi)
    medium = mi.load_dict(smoke_medium(g, filter_type="trilinear"))
    maj = mj.build_majorant(medium, inside=0.5 * (np.array(lo) + np.array(hi)))
    h = (np.array(hi) - np.array(lo)) / np.array(n)
    ijk = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
    centres = np.array(lo) + (ijk + 0.5) * h
    s = sigma_at(medium, centres)
    shape = np.asarray(maj.values.shape)
    size = (maj.bbox_max - maj.bbox_min) / shape
    u = (centres - maj.bbox_min) / size                        # in cells
    want = np.zeros(maj.values.shape)
    for a_lo in (0, 1):                        # a centre on a cell face belongs to both cells
        for b_lo in (0, 1):
            for c_lo in (0, 1):
                off = np.array([a_lo, b_lo, c_lo])
                on_face = np.abs(u - np.round(u)) < 1e-4
                cell = np.where(on_face, np.round(u) - off, np.floor(u)).astype(int)
                cell = np.clip(cell, 0, shape - 1)
                np.maximum.at(want, (cell[:, 0], cell[:, 1], cell[:, 2]), s)
    # (centres next to a dense voxel read its float32 leak, up to ~2e-6 of it: see above)
    np.testing.assert_allclose(maj.values, want, rtol=1e-5, atol=1e-5 * s.max())


def test_level_follows_the_density():
    """One voxel of density 1e4 in an empty 64^3 grid: cells refined until the densest is at
    most MAX_CELL_DEPTH optical depths across (the 16-per-axis level is 2165). Light sparse
    blobs: the coarse 16-per-axis level, the cheapest by the work estimate."""
    def majorant_of(g):
        return mj.build_majorant(mi.load_dict(smoke_medium(g, filter_type="nearest")))

    g = VoxelGrid.empty((64, 64, 64), (-1, -1, -1), (1, 1, 1))
    g.density[40, 30, 20] = 1e4
    dense = majorant_of(g)
    k = (dense.bbox_max - dense.bbox_min) / np.asarray(dense.values.shape) / (2 / 64)
    depth = dense.values.max() * np.linalg.norm(k * 2 / 64)
    assert 2 * depth > mj.MAX_CELL_DEPTH >= depth, (dense.note, depth)
    g.density[:] = 0.0
    c = g.centers()
    for p in ((-0.4, -0.2, 0.1), (0.3, 0.3, -0.2), (0.1, -0.5, 0.4)):
        g.density[np.linalg.norm(c - np.array(p), axis=-1) < 0.15] = 3.0
    assert majorant_of(g).values.shape == (17, 17, 17), majorant_of(g).note
    # no level within the cap (one voxel of 1e6: 54 000 depths even at one voxel per cell):
    # the finest level, where null steps are fewest
    g.density[:] = 0.0
    g.density[10, 10, 10] = 1e6
    assert majorant_of(g).values.shape == (65, 65, 65), majorant_of(g).note


def test_a_differentiated_render_chooses_its_level_for_its_scaled_bounds():
    """Differentiated renders track against ``DIFF_MAJORANT_FACTOR`` x the bounds: the cap on a
    cell's optical depth holds for the scaled values (one voxel of 1e4 in 64^3: 2 voxels per
    cell are 1082 depths across, 2165 doubled; one voxel per cell, 1082 doubled)."""
    g = VoxelGrid.empty((64, 64, 64), (-1, -1, -1), (1, 1, 1))
    g.density[40, 30, 20] = 1e4
    medium = mi.load_dict(smoke_medium(g, filter_type="nearest"))
    assert mj.build_majorant(medium).values.shape == (33, 33, 33)
    assert mj.build_majorant(medium, factor=volume.DIFF_MAJORANT_FACTOR).values.shape == (65, 65, 65)


def optical_depth_reference(scene, medium, centre, half, px: int, per_axis: int = 12,
                            steps: int = 400) -> np.ndarray:
    """Mean over each pixel's footprint of exp(-tau) along the camera ray, with tau by the
    midpoint rule over the ray's chord through the box ``centre +- half`` (sigma_t is 0
    outside it), sigma_t from Mitsuba's medium; stratified footprint positions."""
    sensor = scene.sensors()[0]
    s = (np.arange(per_axis) + 0.5) / per_axis
    fx, fy = np.meshgrid(s, s, indexing="xy")
    iy, ix = np.meshgrid(np.arange(px), np.arange(px), indexing="ij")
    pos_x = (ix[..., None, None] + fx) / px
    pos_y = (iy[..., None, None] + fy) / px
    pos = mi.Point2f(mi.Float(pos_x.ravel().astype(np.float32)), mi.Float(pos_y.ravel().astype(np.float32)))
    ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    o = np.array(ray.o).T.astype(np.float64)
    d = np.array(ray.d).T.astype(np.float64)
    lo, hi = np.asarray(centre) - half, np.asarray(centre) + half
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.nanmax(np.minimum((lo - o) / d, (hi - o) / d), axis=1)
        t1 = np.nanmin(np.maximum((lo - o) / d, (hi - o) / d), axis=1)
    hit = t1 > np.maximum(t0, 0)
    tau = np.zeros(len(o))
    if hit.any():
        a, b = np.maximum(t0[hit], 0), t1[hit]
        w = (b - a) / steps
        t = a[:, None] + (np.arange(steps) + 0.5) * w[:, None]
        p = o[hit][:, None, :] + t[..., None] * d[hit][:, None, :]
        tau[hit] = sigma_at(medium, p.reshape(-1, 3)).reshape(-1, steps).sum(1) * w
    return np.exp(-tau).reshape(px, px, -1).mean(-1)


@pytest.mark.parametrize("differentiated", [False, True])
@pytest.mark.parametrize("integrator", ["draaw_v3", "draaw_v4"])
def test_dense_voxel_in_a_small_grid_transmits_as_the_closed_form(integrator, differentiated):
    """A 4^3 grid, empty but for one black voxel of density 1e4, before a constant sky of
    0.4 (nothing else). With cells on voxel faces dilated by a voxel its bound covered 27 of
    64 cells: flights through empty space ran past MAX_TRACKING_STEPS and counted as absorbed
    (image mean 0.14 against volpath's 0.27). Pixels that miss the voxel's support are
    exactly 0.4; the rest match 0.4 x the footprint mean of exp(-tau), tau from Mitsuba's
    sigma_t by quadrature, within the Bernoulli noise of the escape count. Differentiated
    (the density has gradients on), the bounds are doubled (DIFF_MAJORANT_FACTOR): cells of
    2e4 over half a unit took flights past the former cap of 4096 steps (absorbed)."""
    px, spp = 16, 64
    g = VoxelGrid.empty((4, 4, 4), (-1, -1, -1), (1, 1, 1))
    g.density[2, 2, 1] = 1e4
    g.smoke_color[:] = 0.0
    d = ms.base({"type": integrator, "max_depth": 4}, res=px)
    del d["floor"], d["light"]
    d["smoke"] = smoke_shape(g)
    volume._TABLES.clear()
    scene = mi.load_dict(d)
    params = mi.traverse(scene)
    if differentiated:
        key = [k for k in params.keys() if k.endswith("sigma_t.data")][0]
        dr.enable_grad(params[key])
        params.update()
    img = np.array(mi.render(scene, params, spp=spp, seed=0), dtype=np.float64)[..., 0]
    if differentiated:
        assert volume._TABLES and all(t[-1].values.numpy().max() == 2e4 for t in volume._TABLES.values()),\
            "the differentiated table was not used"
    medium = [s for s in scene.shapes() if s.interior_medium() is not None][0].interior_medium()
    centre = np.array(g.centers()[2, 2, 1])
    ref = 0.4 * optical_depth_reference(scene, medium, centre, 0.5, px)
    clear = ref == 0.4                         # every footprint ray misses the support
    assert clear.sum() > 0.3 * px * px and (~clear).sum() > 20
    assert np.allclose(img[clear], 0.4, rtol=1e-5, atol=0), np.sort(img[clear])[:5]
    p = ref[~clear] / 0.4
    se = 0.4 * np.sqrt(np.sum(p * (1 - p) / spp))
    z = (img[~clear].sum() - ref[~clear].sum()) / se
    assert abs(z) < 4.0, (z, img[~clear].sum(), ref[~clear].sum())


def test_a_grid_far_from_the_origin_keeps_its_local_bounds():
    """A 64^3 unit box at x = 150: its voxel centres carry float32 position error (~1e-3 of
    a voxel); the placement check allows for it (it fell back to one bound, calling the grid
    rotated or mirrored)."""
    g = sparse_grid((64, 64, 64), (149.5, -0.5, -0.5), (150.5, 0.5, 0.5))
    maj = mj.build_majorant(mi.load_dict(smoke_medium(g)), inside=(150.0, 0.0, 0.0))
    assert maj.kind == "grid" and maj.values.size > 1, maj.note


def test_a_large_noisy_grid_keeps_its_local_bounds():
    """160^3 voxels, 1 % of them dense at random: the placement check's tolerance follows
    Mitsuba's float32 error at voxel centres, which grows with the grid's size (2.9e-5 of the
    largest value here; with a fixed 1e-5 such grids fell back to one global bound)."""
    n = 160
    rng = np.random.default_rng(0)
    g = VoxelGrid.empty((n, n, n), (-1, -1, -1), (1, 1, 1))
    g.density[:] = np.where(rng.random((n, n, n)) < 0.01, rng.uniform(0, 50, (n, n, n)), 0.0)
    maj = mj.build_majorant(mi.load_dict(smoke_medium(g)))
    assert maj.kind == "grid" and maj.values.size > 1, maj.note


@pytest.mark.parametrize("to_world", ["rotated", "mirrored", "repeat"])
def test_a_grid_not_placed_on_its_box_falls_back_to_one_bound(to_world):
    """A ``gridvolume`` turned 90 degrees about z, or mirrored in x, still fills an axis-aligned
    box, but its voxels are not where the pooled cells would put them; one with
    ``wrap_mode = 'repeat'`` blends the opposite face's voxels into the half voxel by each
    face, which no cell bounds (only the far face dense here: that sigma_t was 4.2 where the
    bound was 0). The placement check sees each, and the medium gets one global bound,
    ``scale * max``, with the reason."""
    rng = np.random.default_rng(2)
    data = np.where(rng.random((6, 6, 6)) < 0.2, rng.uniform(1, 40, (6, 6, 6)), 0.0)
    xf = mi.ScalarTransform4f().translate([0.5, 0.5, 0.5])
    if to_world == "rotated":
        xf = xf @ mi.ScalarTransform4f().rotate([0, 0, 1], 90)
    elif to_world == "mirrored":
        xf = xf @ mi.ScalarTransform4f().scale([-1, 1, 1])
    else:
        data[:] = 0.0
        data[:, :, 5] = 10.0                       # [z][y][x]: the face x = max only
    xf = xf @ mi.ScalarTransform4f().translate([-0.5, -0.5, -0.5])
    medium = mi.load_dict({"type": "heterogeneous", "scale": 2.0,
                           "sigma_t": {"type": "gridvolume", "data": mi.TensorXf(data[..., None].astype(np.float32)),
                                       "to_world": xf, "wrap_mode": "repeat" if to_world == "repeat" else "clamp"}})
    maj = mj.build_majorant(medium, inside=(0.5, 0.5, 0.5))
    assert maj.kind == "global" and "rotated or mirrored" in maj.note, maj
    assert maj.values.max() == pytest.approx(2.0 * data.max(), rel=1e-6)


def test_coarser_levels_derived_from_finer_ones_equal_pooling_the_voxels():
    """Levels are pooled from the voxels once, at the finest, and coarsened pairwise: each must
    equal pooling the voxels at its own size (odd sizes, per-axis sizes that stop halving)."""
    rng = np.random.default_rng(5)
    data = rng.random((37, 20, 3)) ** 8
    n = np.asarray(data.shape)
    ks = [np.array([16, 8, 1]), np.array([8, 4, 1]), np.array([4, 2, 1]), np.array([2, 1, 1]), np.array([1, 1, 1])]
    values = mj.pool_between_centres(data, ks[-1])
    for fine, coarse in zip(ks[::-1], ks[::-1][1:]):
        values = mj.coarsen(values, n, fine, coarse)
        np.testing.assert_array_equal(values, mj.pool_between_centres(data, coarse), err_msg=str(coarse))


@pytest.mark.parametrize("factor", [1.0, 2.0])
def test_flights_beside_a_dense_voxel_finish_their_cells(factor):
    """Rays along x at 0.98 voxel from the centre of one voxel of density 2300 in a 4^3 grid
    cross two cells bounded by 2300 (x 2 in a differentiated render) over half a unit each:
    ~4600 null steps doubled, past the former cap of 4096 (both trackers returned 0 there).
    Ratio tracking's mean transmittance and delta tracking's escape fraction over 2000 rays
    match exp(-tau), tau from Mitsuba's sigma_t by quadrature, within 4 binomial standard
    errors (a bound for ratio tracking's spread too: its weights lie in [0, 1])."""
    import draaw_mi.integrators.volume_tracking as vt
    g = VoxelGrid.empty((4, 4, 4), (-1, -1, -1), (1, 1, 1))
    g.density[1, 1, 1] = 2300.0                               # centre (-0.25, -0.25, -0.25)
    scene = mi.load_dict({"type": "scene", "smoke": smoke_shape(g)})
    medium = scene.shapes()[0].interior_medium()
    table = volume.MediaTable(scene, factor)
    n, y = 2000, -0.25 + 0.98 * 0.5
    ray = dr.gather(mi.Ray3f, mi.Ray3f(mi.Point3f(-3.0, y, y), mi.Vector3f(1, 0, 0)), dr.zeros(mi.UInt32, n))
    idx, tmax, on = dr.zeros(mi.UInt32, n), dr.full(mi.Float, dr.inf, n), dr.full(mi.Bool, True, n)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(0, n)
    T = np.array(vt.ratio_track(table, mi.MediumPtr(medium), idx, ray, tmax, sampler, on))
    sampler.seed(1, n)
    flight = vt.free_flight(table, mi.MediumPtr(medium), idx, ray, tmax, sampler, on)
    escaped = np.array(dr.select(flight.collided, 0.0, 1.0))
    x = np.linspace(-1, 1, 20001)
    tau = np.trapezoid(sigma_at(medium, np.stack([x, np.full_like(x, y), np.full_like(x, y)], 1)), x)
    want = np.exp(-tau)
    assert 0.3 < want < 0.9
    se = np.sqrt(want * (1 - want) / n)
    assert abs(T.mean() - want) < 4 * se and abs(escaped.mean() - want) < 4 * se, (T.mean(), escaped.mean(), want)


def test_a_medium_only_the_camera_is_in_is_stamped_and_seen_differentiated():
    """The sensor's medium goes into the table's stamp (an edited density kept the old
    majorant: 0.1247 where a fresh scene gave 0.0001) and its gradients double the bounds
    (else a uniform grid has no null collisions, and the density gradient had the wrong
    sign: +0.067 against finite differences' -0.076)."""
    import drjit as dr
    import media_scenes as ms
    from draaw_mi.integrators.volume import DIFF_MAJORANT_FACTOR, media_table
    from draaw_mi.media.mitsuba_dicts import smoke_medium
    g = ms.grid("uniform", 4)
    d = ms.base({"type": "draaw_v4"}, 8, sensor_medium=smoke_medium(g), origin=(0.1, 0.2, 0.6))
    scene = mi.load_dict(d)
    p = mi.traverse(scene)
    key = next(k for k in p.keys() if k.endswith("sigma_t.data"))
    first = media_table(scene)
    top = float(np.max(np.array(first.values)))
    p[key] = p[key] * 10.0
    p.update()
    edited = media_table(scene)
    assert edited is not first and float(np.max(np.array(edited.values))) == pytest.approx(10 * top, rel=1e-5)
    dr.enable_grad(p[key])
    try:
        diff = media_table(scene)
        assert float(np.max(np.array(diff.values))) == pytest.approx(DIFF_MAJORANT_FACTOR * 10 * top, rel=1e-5)
    finally:
        dr.disable_grad(p[key])


def test_a_grid_set_again_and_again_gets_its_own_majorant():
    """A density grid set 0-2 times with one density and then with a larger one before the next
    render could come back under the variable index the table had been built for (Dr.Jit gives
    a freed index to the next new array): the old majorant stayed, below the new densities, in
    10 of 30 such renders (delta tracking is then biased). The stamp holds the grid it saw."""
    import media_scenes as ms
    from draaw_mi.integrators.volume import media_table
    scene = ms.scene("uniform", res=8)
    p = mi.traverse(scene)
    key = next(k for k in p.keys() if k.endswith("sigma_t.data"))
    grid = np.array(p[key])
    top = float(np.max(np.array(media_table(scene).values)))
    for i in range(12):
        for _ in range(i % 3):
            p[key] = mi.TensorXf(grid)
            p.update()
        p[key] = mi.TensorXf(grid * (2.0 + i))
        p.update()
        assert float(np.max(np.array(media_table(scene).values))) == pytest.approx((2.0 + i) * top, rel=1e-5), i


@pytest.mark.parametrize("mirrored", [True, False])
def test_a_mirrored_grid_with_a_large_dynamic_range_is_caught(mirrored):
    """Two voxels of 1e6 that are mirror images of each other and a block of density 5 on one
    side, mirrored in x by the to_world: the placement check's tolerance was 1e-5 x max(data)
    = 10 for every probe, so the block (5 where the mirrored lookup reads 0) passed, and its
    bounds were placed unmirrored (density-5 smoke under cells bounded by 0). Each probe's
    tolerance now scales with the voxels around it: the mirrored grid falls back to one bound,
    the same grid unmirrored keeps its local bounds."""
    d = np.zeros((16, 16, 16))                                   # [ix, iy, iz]
    d[2, 8, 8] = d[13, 8, 8] = 1e6
    d[0:4, 2:6, 2:6] = 5.0
    d[0:4, 10:14, 2:14] = 3.0
    xf = (mi.ScalarTransform4f().translate([0.5, -0.5, -0.5]).scale([-1, 1, 1]) if mirrored
          else mi.ScalarTransform4f().translate([-0.5, -0.5, -0.5]))
    medium = mi.load_dict({"type": "heterogeneous", "sigma_t": {
        "type": "gridvolume", "to_world": xf,
        "data": mi.TensorXf(np.ascontiguousarray(d.transpose(2, 1, 0)[..., None], np.float32))}})
    maj = mj.build_majorant(medium, inside=(0.0, 0.0, 0.0))
    assert maj.kind == ("global" if mirrored else "grid"), maj.note
    if not mirrored:                      # the local bounds hold at random points
        pts = np.random.default_rng(0).uniform(-0.49, 0.49, (20000, 3))
        c = cell_of(maj, pts)
        assert np.all(sigma_at(medium, pts) <= maj.values[c[:, 0], c[:, 1], c[:, 2]] * (1 + 1e-5) + 1e-6)
