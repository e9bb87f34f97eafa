"""Voxelising meshes (draaw_mi.media.voxelize, VoxelGrid.from_mesh, VoxelGrid.go_draaw):
surface cells against a brute-force reference and GO-Draaw's own rule, solid fills against
the closed form of convex meshes; open meshes, unwelded copies and T-junctions."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi  # noqa: F401

from draaw_mi import ParameterError
from draaw_mi.media import VoxelGrid
from draaw_mi.media.voxelize import voxelize

GO_DRAAW = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared",
                                         "data", "go-draaw"))


def test_surface_voxelisation_of_a_sphere_is_a_closed_shell():
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.8)
    g = VoxelGrid.from_mesh(sphere, resolution=32, bbox_min=(-1, -1, -1), bbox_max=(1, 1, 1))
    r = np.linalg.norm(g.centers(), axis=-1)
    cell = 2 / 32
    edge = np.max(sphere.edges_unique_length)
    facet = 0.8 * (1 - np.cos(edge / 0.8)) + 1e-4     # how far the facets sag inside the sphere
    assert g.occupied[np.abs(r - 0.8) < 0.5 * cell - facet].all()
    assert not g.occupied[np.abs(r - 0.8) > 0.5 * np.sqrt(3) * cell + facet].any()
    # closed: the interior is not 6-connected to the outside
    from scipy import ndimage
    lab, n = ndimage.label(~g.occupied)
    assert n == 2


def test_solid_voxelisation_matches_inside_test():
    import trimesh
    box = trimesh.creation.box(extents=(1.2, 0.8, 0.5))
    g = VoxelGrid.from_mesh(box, resolution=(24, 16, 10), fill="solid", bbox_min=(-1, -0.5, -0.5),
                            bbox_max=(1, 0.5, 0.5))
    c = g.centers()
    inside = np.all(np.abs(c) < np.array([0.6, 0.4, 0.25]), axis=-1)
    assert np.array_equal(g.occupied[inside], np.ones(inside.sum(), bool))
    far = np.any(np.abs(c) > np.array([0.6, 0.4, 0.25]) + g.cell_size, axis=-1)
    assert not g.occupied[far].any()


def _convex_inside(mesh, points):
    """Closed form for a convex mesh: inside when behind every face's plane."""
    n = np.asarray(mesh.face_normals)
    v0 = np.asarray(mesh.triangles)[:, 0]
    off = np.einsum("fk,fk->f", n, v0)
    return np.all(points @ n.T - off <= 0, axis=-1)


def _surface_band(g, mesh_tris, points):
    """Points within half a cell diagonal of a triangle (where surface cells may be filled)."""
    from draaw_mi.media.voxelize import _closest_sq_dist
    half = 0.5 * float(np.linalg.norm(g.cell_size))
    near = np.zeros(len(points), bool)
    for a, b, c in mesh_tris:
        near |= _closest_sq_dist(points, a, b, c) <= half * half
    return near


def test_solid_fill_of_a_closed_mesh_is_its_inside_without_a_warning():
    """A closed (convex) mesh: the cells whose centres are inside it by the closed form are
    filled, and none outside it beyond the surface band; no warning."""
    import warnings
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = VoxelGrid.from_mesh(sphere, 20, fill="solid", bbox_min=(-1.2,) * 3, bbox_max=(1.2,) * 3)
    c = g.centers().reshape(-1, 3)
    occ = g.occupied.reshape(-1)
    inside = _convex_inside(sphere, c)
    assert inside.sum() > 1000 and occ[inside].all()
    band = _surface_band(g, np.asarray(sphere.triangles), c)
    assert not occ[~inside & ~band].any()


def test_solid_fill_of_an_open_mesh_warns_and_fills_only_its_closed_parts():
    """A closed sphere beside an open sheet (a quad at x = 1.5, crossed by lines along x):
    the sheet has no inside, so it is a surface only; the sphere is filled as alone, and
    nothing else. (A parity count along x through the sheet had filled every line crossing it
    out to the box's +x face; GO-Draaw's monkey.obj filled 88 % of its box.)"""
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    sheet = trimesh.Trimesh(vertices=[[1.5, -1.1, -1.1], [1.5, 1.1, -1.1], [1.5, 1.1, 1.1], [1.5, -1.1, 1.1]],
                            faces=[[0, 1, 2], [0, 2, 3]], process=False)
    both = trimesh.util.concatenate([sphere, sheet])
    box = dict(bbox_min=(-1.2, -1.2, -1.2), bbox_max=(2.4, 1.2, 1.2))
    with pytest.warns(RuntimeWarning, match=r"VoxelGrid.from_mesh: mesh the Trimesh is not closed: 4 edges "
                                            r".* 2 of its 322 triangles.*fill_holes.*fill='surface'"):
        g = VoxelGrid.from_mesh(both, (30, 20, 20), fill="solid", **box)
    c = g.centers().reshape(-1, 3)
    occ = g.occupied.reshape(-1)
    inside = _convex_inside(sphere, c)
    assert occ[inside].all()
    band = _surface_band(g, np.asarray(both.triangles), c)
    assert not occ[~inside & ~band].any(), f"{int(occ[~inside & ~band].sum())} cells filled outside"
    alone = VoxelGrid.from_mesh(sphere, (30, 20, 20), fill="solid", **box)
    surface = VoxelGrid.from_mesh(sheet, (30, 20, 20), fill="surface", **box)
    assert np.array_equal(g.occupied, alone.occupied | surface.occupied)


def _cube_triangles() -> np.ndarray:
    import trimesh
    return np.asarray(trimesh.creation.box(extents=(2.0, 2.0, 2.0)).triangles, float)


def _t_junction_cube() -> np.ndarray:
    """The cube with its top face (y = 1) split at the middle M of its edge A B (z = -1): the
    top's edges A M and M B and the side face's edge A B each bound one triangle, and
    together cover that line twice (a T-junction, as mesh editors leave them)."""
    tris = _cube_triangles()
    top = np.all(np.isclose(tris[:, :, 1], 1.0), axis=1)
    A, B, C, D = [np.array(v, float) for v in ([-1, 1, -1], [1, 1, -1], [1, 1, 1], [-1, 1, 1])]
    M = 0.5 * (A + B)
    return np.concatenate([tris[~top], np.array([[A, M, D], [M, B, C], [M, C, D]])])


@pytest.mark.parametrize("make", ["t_junction", "unwelded", "both"])
def test_closed_meshes_with_t_junctions_or_unwelded_copies_fill_as_closed(make):
    """A cube with a T-junction, one whose corner copies differ by 1e-9 (an exporter's
    unwelded vertices), and both: closed, so filled as the plain cube is, without a warning
    (an exact-position edge count called them open and filled their surfaces only: 33 % of
    the box for 100 %)."""
    import warnings
    tris = _t_junction_cube() if make in ("t_junction", "both") else _cube_triangles()
    if make in ("unwelded", "both"):
        tris = tris.copy()
        tris[0, 0] += 1e-9
    box = dict(shape=(8, 8, 8), bbox_min=(-1.0,) * 3, bbox_max=(1.0,) * 3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        occ = voxelize(tris, box["shape"], box["bbox_min"], box["bbox_max"], "solid")
    assert occ.all()


def test_an_open_box_is_still_open_and_nothing_is_a_solid_of_nothing():
    """The cube without its top: its rim's edges each bound one triangle on lines nothing
    else covers (a hole, not a T-junction), so it warns; no triangles give an empty grid."""
    tris = _cube_triangles()
    open_box = tris[~np.all(np.isclose(tris[:, :, 1], 1.0), axis=1)]
    with pytest.warns(RuntimeWarning, match="is not closed: 4 edges"):
        occ = voxelize(open_box, (8, 8, 8), (-1.0,) * 3, (1.0,) * 3, "solid")
    assert np.array_equal(occ, voxelize(open_box, (8, 8, 8), (-1.0,) * 3, (1.0,) * 3, "surface"))
    assert not voxelize(np.zeros((0, 3, 3)), (4, 4, 4), (0.0,) * 3, (1.0,) * 3, "solid").any()


def go_draaw_reference_voxelize(tris, shape, lo, hi):
    """GO-Draaw's rule verbatim: plane distance <= 0.5 max(step), barycentric inside."""
    shape = np.asarray(shape)
    step = (hi - lo) / shape
    occ = np.zeros(tuple(shape), bool)
    c = lo + (np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1) + 0.5) * step
    for a, b, cc in tris:
        i0 = np.clip(np.floor((np.minimum(np.minimum(a, b), cc) - lo) / step).astype(int), 0, shape - 1)
        i1 = np.clip(np.floor((np.maximum(np.maximum(a, b), cc) - lo) / step).astype(int), 0, shape - 1)
        sub = c[i0[0]:i1[0] + 1, i0[1]:i1[1] + 1, i0[2]:i1[2] + 1]
        n = np.cross(b - a, cc - a)
        nn = np.linalg.norm(n)
        if nn == 0:
            continue
        n = n / nn
        dist = (sub - a) @ n
        p = sub - dist[..., None] * n
        v0, v1, v2 = b - a, cc - a, p - a
        d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
        d20, d21 = v2 @ v0, v2 @ v1
        den = d00 * d11 - d01 * d01
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        ok = (np.abs(dist) <= 0.5 * step.max()) & (v >= 0) & (w >= 0) & (v + w <= 1)
        occ[i0[0]:i1[0] + 1, i0[1]:i1[1] + 1, i0[2]:i1[2] + 1] |= ok
    return occ


def test_surface_rule_contains_go_draaws_and_fills_its_holes():
    import trimesh
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.9)
    tris = np.asarray(mesh.triangles)
    lo, hi = np.full(3, -1.0), np.full(3, 1.0)
    ours = voxelize(tris, (24, 24, 24), lo, hi)
    ref = go_draaw_reference_voxelize(tris, (24, 24, 24), lo, hi)
    assert ref.sum() > 500
    assert not (ref & ~ours).any()                     # superset (cubic cells)
    from scipy import ndimage
    assert ndimage.label(~ref)[1] < ndimage.label(~ours)[1] or (ours & ~ref).sum() > 0


def test_surface_fill_takes_the_cells_at_exactly_half_a_cell_on_both_sides():
    """A plane on the boundary between two cell layers is half a cell from both layers'
    centres, so the rule (centre within half a cell of the triangle) takes both; the lower
    one was left out of the candidate cells (a plane filled layers [0, 0, 16, 0])."""
    quad = np.array([[[-0.1, -0.1, 0.5], [1.1, -0.1, 0.5], [1.1, 1.1, 0.5]],
                     [[-0.1, -0.1, 0.5], [1.1, 1.1, 0.5], [-0.1, 1.1, 0.5]]])
    occ = voxelize(quad, (4, 4, 4), (0, 0, 0), (1, 1, 1))
    assert occ.sum(axis=(0, 1)).tolist() == [0, 16, 16, 0]


def test_surface_fill_of_a_centred_box_is_mirror_symmetric():
    """A box centred in a grid centred on it: the occupancy is the same mirrored along each
    axis (its x profile was [0, 0, 0, 8, 7, 4, 0, 0] at 8 cells)."""
    import trimesh
    tris = np.asarray(trimesh.creation.box(extents=(0.5, 0.5, 0.5)).triangles)
    occ = voxelize(tris, (8, 8, 8), (-1, -1, -1), (1, 1, 1))
    assert occ.sum() > 0
    for axis in range(3):
        assert np.array_equal(occ, np.flip(occ, axis=axis)), (axis, occ.sum(axis=(1, 2)).tolist())


@pytest.mark.skipif(not os.path.isdir(GO_DRAAW), reason=f"GO-Draaw data not found at {GO_DRAAW}")
def test_go_draaw_start_up_grid_on_monkey():
    g = VoxelGrid.go_draaw(os.path.join(GO_DRAAW, "monkey.obj"), seed=1)
    assert g.shape == (96, 96, 96)
    # go-draaw-spec.md §4.1 figures for the x75 monkey
    assert np.allclose(g.bbox_min, (-285.7, -22.9, -204.5), atol=0.1)
    assert np.allclose(g.bbox_max, (203.9, 374.6, 203.9), atol=0.1)
    assert 10000 < g.occupied.sum() < 100000
    assert np.all(g.density == np.float32(0.001)) and np.all(g.smoke_color == 0)
    c = g.color[g.occupied]
    assert 0.45 < c.mean() < 0.55 and c.std() > 0.2        # random colours U()
    g2 = VoxelGrid.go_draaw(os.path.join(GO_DRAAW, "monkey.obj"), seed=1)
    assert np.array_equal(g.color, g2.color)


@pytest.mark.skipif(not os.path.isfile(os.path.join(GO_DRAAW, "cubes.obj")), reason="GO-Draaw's cubes.obj not found")
def test_go_draaw_grid_box_holds_the_origin():
    """GO-Draaw's object box starts as the zero box (go-draaw-spec.md §2.1): the cubes, at
    y 4.28..13.44, get a grid from y = 0 (its cells 7.87 high, not 5.36)."""
    g = VoxelGrid.go_draaw(os.path.join(GO_DRAAW, "cubes.obj"), resolution=16, seed=1)
    s = 75.0 * 0.75
    assert np.allclose(g.bbox_min, (-5.01 * s, 0.0, -3.68 * s), atol=1.0)
    assert np.allclose(g.bbox_max, (2.47 * s, 13.44 * s, 3.66 * s), atol=1.0)


# --------------------------------------------------------------------------- files
def test_an_empty_mesh_has_no_triangles_to_voxelise():
    """trimesh.Trimesh() has no faces: one ParameterError, not a (0, 3, 3) array that
    voxelises to an empty grid."""
    import trimesh
    from draaw_mi.media.voxelize import load_triangles
    with pytest.raises(ParameterError, match="voxelize: the mesh has no triangles"):
        load_triangles(trimesh.Trimesh())
    assert load_triangles(trimesh.creation.box()).shape == (12, 3, 3)
