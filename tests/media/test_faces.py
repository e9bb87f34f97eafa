"""Solid voxels as exterior-face meshes: face counts, orientation, no interior faces, renders."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi  # noqa: F401
import drjit as dr
import mitsuba as mi

from draaw_mi import ParameterError
from draaw_mi.media import VoxelGrid
from draaw_mi.media.faces import exterior_faces, solid_meshes


def adjacent_pairs(occ):
    return sum(int((np.take(occ, range(1, occ.shape[a]), a) & np.take(occ, range(occ.shape[a] - 1), a)).sum())
               for a in range(3))


def test_face_count_is_six_per_voxel_minus_shared():
    rng = np.random.default_rng(0)
    for p in (0.1, 0.5, 0.9):
        occ = rng.random((9, 7, 8)) < p
        v, f, cells = exterior_faces(occ, (0, 0, 0), (9, 7, 8))
        n = int(occ.sum())
        assert cells.shape[0] == 6 * n - 2 * adjacent_pairs(occ)
        assert f.shape[0] == 2 * cells.shape[0] and v.shape[0] == 4 * cells.shape[0]


def test_faces_are_outward_and_exterior():
    import trimesh
    rng = np.random.default_rng(1)
    occ = rng.random((6, 5, 7)) < 0.4
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([2.0, 1.0, 3.4])
    v, f, cells = exterior_faces(occ, lo, hi)
    mesh = trimesh.Trimesh(v, f, process=True)             # merges shared vertices
    cell_vol = np.prod((hi - lo) / occ.shape)
    assert np.isclose(mesh.volume, occ.sum() * cell_vol, rtol=1e-5)   # only with outward winding
    # every face has an occupied cell behind it and an empty one (or outside) in front
    tri = v[f]
    centre = tri.mean(1)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    size = (hi - lo) / occ.shape
    for c, n in zip(centre, normal):
        inner = np.floor((c - 0.25 * n * size - lo) / size).astype(int)
        outer = np.floor((c + 0.25 * n * size - lo) / size).astype(int)
        assert occ[tuple(inner)]
        inside = np.all((outer >= 0) & (outer < occ.shape))
        assert not (inside and occ[tuple(outer)])


def _scene(shapes: dict, spp_res=24):
    d = {"type": "scene", "integrator": {"type": "draaw_v4", "max_depth": 3},
         "sensor": {"type": "perspective", "fov": 35,
                    "to_world": mi.ScalarTransform4f().look_at([2.2, 1.8, 3.0], [0, 0, 0], [0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": spp_res, "height": spp_res, "rfilter": {"type": "box"}}},
         "light": {"type": "point", "position": [2.0, 3.0, 1.5], "intensity": 12.0},
         "env": {"type": "constant", "radiance": 0.3}}
    d.update(shapes)
    return mi.load_dict(d)


def test_voxel_block_renders_like_the_same_cube():
    g = VoxelGrid.empty((4, 3, 5), (-0.5, -0.4, -0.6), (0.5, 0.4, 0.6))
    g.occupied[:] = True
    g.color[:] = (0.7, 0.3, 0.2)
    mat = {"roughness": 0.6, "specular": 0.5}
    vox = _scene(solid_meshes(g, mat))
    cube = _scene({"cube": {"type": "cube", "to_world": mi.ScalarTransform4f().scale([0.5, 0.4, 0.6]),
                            "bsdf": {"type": "draaw", "base_color": [0.7, 0.3, 0.2], **mat}}})
    a = np.stack([np.array(mi.render(vox, spp=32, seed=s)) for s in range(4)])
    b = np.stack([np.array(mi.render(cube, spp=32, seed=100 + s)) for s in range(4)])
    diff = a.mean(0) - b.mean(0)
    se = np.sqrt(a.var(0, ddof=1) / 4 + b.var(0, ddof=1) / 4) + 1e-4
    z = diff / se
    assert np.mean(np.abs(z) > 4) < 0.02, np.abs(z).max()
    assert a.mean() > 0.05


def test_face_colours_equal_colour_groups_and_are_differentiable():
    g = VoxelGrid.empty((2, 1, 1), (-0.5, -0.25, -0.25), (0.5, 0.25, 0.25))
    g.occupied[:] = True
    g.color[0] = (0.9, 0.1, 0.1)
    g.color[1] = (0.1, 0.1, 0.9)
    one = solid_meshes(g, {"roughness": 0.7})
    groups = solid_meshes(g, {"roughness": 0.7}, group_by="color")
    assert len(one) == 1 and len(groups) == 2
    assert sum(m.face_count() for m in groups.values()) == one["voxels"].face_count() == 20
    s1, s2 = _scene(one, 16), _scene(groups, 16)
    a = np.array(mi.render(s1, spp=64, seed=0))
    b = np.array(mi.render(s2, spp=64, seed=0))
    assert a[..., 0].sum() > 0.2 * a.sum()          # the red voxel is visible
    # the same triangles, colours and samples: the same pixels (measured: bit-identical); the
    # two voxels' colours have equal channel sums, so only pixels see a face given the other's
    np.testing.assert_allclose(a, b, atol=1e-5)
    # the derivative of the mean image along each voxel's face colours (scaled about their
    # values): AD and central differences, each over 6 seeds, agree within 4 standard errors
    # of their difference (both are estimates with their own noise)
    params = mi.traverse(s1)
    key = "voxels.face_color"
    c0 = np.array(params[key])
    red = np.zeros_like(c0).reshape(-1, 3)
    red[:10] = c0.reshape(-1, 3)[:10]          # (per triangle) the first voxel's 5 exterior faces
    red = red.ravel()
    seeds = range(6)
    grads = []
    for seed in seeds:
        dr.enable_grad(params[key])
        params.update()
        dr.backward(dr.mean(mi.render(s1, params, spp=16, seed=10 + seed, seed_grad=500 + seed), axis=None))
        grads.append(np.array(dr.grad(params[key])))
        params[key] = mi.Float(c0)
        params.update()
    grads = np.array(grads)
    assert np.all(np.isfinite(grads))

    def mean_at(c, seed):
        params[key] = mi.Float(c)
        params.update()
        return float(np.mean(np.array(mi.render(s1, spp=16, seed=seed))))

    h = 0.02
    for direction in (red, c0 - red):
        fd = np.array([(mean_at(c0 + h * direction, 900 + s) - mean_at(c0 - h * direction, 900 + s)) / (2 * h)
                       for s in seeds])
        ad = grads @ direction
        se = np.sqrt(ad.var(ddof=1) / len(ad) + fd.var(ddof=1) / len(fd))
        assert fd.mean() > 1e-3
        assert abs(ad.mean() - fd.mean()) < 4 * se, (ad, fd)
    params[key] = mi.Float(c0)
    params.update()


def test_group_by_takes_none_or_color_only():
    """``group_by`` groups by colour or not at all: another value ("material") is refused
    with the valid ones, not taken for "color"."""
    g = VoxelGrid.empty((2, 2, 2))
    g.occupied[0, 0, 0] = True
    with pytest.raises(ParameterError, match=r"solid_meshes: group_by='material'; expected None or 'color'"):
        solid_meshes(g, group_by="material")
    assert len(solid_meshes(g, group_by="color")) == 1
