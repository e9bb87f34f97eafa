"""Vertex normals of ``smooth = true`` meshes (draaw_mi.scene.smooth_normals), against
Mitsuba's own angle-weighted normals of the same mesh with its vertices shared."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

import draaw_mi
from draaw_mi.scene.smooth_normals import _gather_within_crease, smooth_normals


def _bumpy_sphere():
    """An icosphere with radially jittered vertices: irregular triangles, on which angle,
    area and uniform weights give normals up to 0.018 apart; faces at a vertex differ by at
    most 37°, within the default crease."""
    rng = np.random.default_rng(1)
    m = trimesh.creation.icosphere(subdivisions=2)
    return m.vertices * (1 + 0.05 * rng.random((len(m.vertices), 1))), np.asarray(m.faces)


def _mitsuba_normals(v, f) -> np.ndarray:
    """Mitsuba's ``recompute_vertex_normals`` of the mesh (shared vertices)."""
    import mitsuba as mi
    mesh = mi.Mesh("ref", len(v), len(f), has_vertex_normals=True)
    p = mi.traverse(mesh)
    p["vertex_positions"] = mi.Float(np.asarray(v, np.float32).ravel())
    p["faces"] = mi.UInt32(np.asarray(f, np.uint32).ravel())
    p.update()
    mesh.recompute_vertex_normals()
    return np.asarray(mi.traverse(mesh)["vertex_normals"]).reshape(-1, 3)


def _by_position(v, n) -> dict:
    return {tuple(np.float32(p)): x for p, x in zip(v, n)}


def _split(v, f):
    """Every face with its own three vertices (as a mesh file whose corners all differ in
    texture coordinates), with a random uv per corner."""
    rng = np.random.default_rng(2)
    sv = np.asarray(v)[f.ravel()]
    return sv, np.arange(len(sv)).reshape(-1, 3), rng.random((len(sv), 2)).astype(np.float32)


def test_normals_are_mitsubas_angle_weighted_ones_where_vertices_are_shared():
    v, f = _bumpy_sphere()
    ref = _by_position(v, _mitsuba_normals(v, f))
    out_v, out_f, _, n = smooth_normals(v, f, crease_deg=180)
    got = np.array([ref[tuple(p)] for p in out_v])
    assert np.abs(n - got).max() < 1e-5
    assert np.array_equal(out_v[out_f], np.asarray(v, np.float32)[f])      # same triangles


def test_split_vertices_get_the_normals_of_the_shared_mesh():
    """The defect: Mitsuba's normals of a split mesh are its face normals (the monkey stayed
    faceted under smooth = true); here they are those of the mesh with shared vertices."""
    v, f = _bumpy_sphere()
    ref = _by_position(v, _mitsuba_normals(v, f))
    sv, sf, uv = _split(v, f)
    out_v, out_f, out_uv, n = smooth_normals(sv, sf, uv)      # (crease 60°: the sphere is smooth)
    assert np.abs(n - np.array([ref[tuple(p)] for p in out_v])).max() < 1e-5
    # Mitsuba alone, on the split mesh, is as flat as the faces: what this replaces
    flat = _mitsuba_normals(sv, sf)
    assert np.abs(flat - np.array([ref[tuple(np.float32(p))] for p in sv])).max() > 0.05
    assert np.array_equal(out_v[out_f], sv[sf].astype(np.float32))         # same triangles
    assert np.array_equal(out_uv[out_f], uv[sf])                            # and texture coordinates


def test_faces_meeting_beyond_the_crease_keep_their_own_normals():
    box = trimesh.creation.box()
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    out_v, out_f, _, n = smooth_normals(v, f)
    face_n = np.asarray(box.face_normals)
    assert np.abs(n[out_f] - face_n[:, None, :]).max() < 1e-6
    # smoothed across every edge, a box corner's normal is a diagonal
    _, out_f, _, n = smooth_normals(v, f, crease_deg=180)
    assert np.abs(np.abs(n[out_f]) - 1 / np.sqrt(3)).max() < 1e-6


def test_a_vertex_shared_by_thousands_of_faces_is_gathered_in_chunks():
    n = 3000                                       # one position with n corners, 2n alone
    rng = np.random.default_rng(3)
    group = np.zeros(3 * n, dtype=np.int64)
    group[n:] = np.arange(1, 2 * n + 1)
    normals = rng.normal(size=(3 * n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    weights = rng.random((3 * n, 3))
    whole = _gather_within_crease(group, normals, weights, 0.5, chunk=1 << 40)
    chunked = _gather_within_crease(group, normals, weights, 0.5, chunk=1000)
    assert np.allclose(whole, chunked, rtol=1e-12, atol=1e-12)
    near = normals[:n] @ normals[:n].T >= 0.5                  # numpy reference, one group
    assert np.allclose(whole[:n], near.astype(float) @ weights[:n])
    assert np.array_equal(whole[n:], weights[n:])             # a corner alone keeps its own


def test_a_crease_angle_outside_0_to_180_degrees_is_refused():
    v, f = _bumpy_sphere()
    with pytest.raises(ValueError, match="crease_deg=200"):
        smooth_normals(v, f, crease_deg=200)


def test_a_smooth_obj_is_shaded_with_the_normals_of_its_shared_vertices(tmp_path):
    """Through the scene loader: an OBJ whose corners all have their own texture coordinates
    (trimesh splits its vertices), loaded with smooth = true."""
    v, f = _bumpy_sphere()
    sv, sf, uv = _split(v, f)
    lines = [f"v {x} {y} {z}" for x, y, z in sv] + [f"vt {a} {b}" for a, b in uv]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in sf]
    path = tmp_path / "ball.obj"
    path.write_text("\n".join(lines) + "\n")
    ref = _by_position(v, _mitsuba_normals(v, f))
    for smooth in (True, False):
        scene = draaw_mi.load_scene({"shapes": [{"type": "mesh", "file": str(path), "smooth": smooth}],
                                     "render": {"resolution": [8, 8]}})
        shape = scene.mi_scene.shapes()[0]
        pos = np.asarray(scene.params[f"{shape.id()}.vertex_positions"]).reshape(-1, 3)
        if smooth:
            n = np.asarray(scene.params[f"{shape.id()}.vertex_normals"]).reshape(-1, 3)
            assert np.abs(n - np.array([ref[tuple(p)] for p in pos])).max() < 1e-5
        else:
            assert not shape.has_vertex_normals()                          # flat, as GO-Draaw


def test_texture_coordinates_follow_their_vertices_when_the_mesh_is_reindexed():
    v, f = _bumpy_sphere()
    uv = np.random.default_rng(4).random((len(v), 2)).astype(np.float32)   # one per shared vertex
    out_v, out_f, out_uv, _ = smooth_normals(v, f, uv)
    assert np.array_equal(out_uv[out_f], uv[f])
    assert np.array_equal(out_v[out_f], np.asarray(v, np.float32)[f])


def test_a_degenerate_face_takes_its_neighbours_normal_and_leaves_theirs_alone():
    v, f = _bumpy_sphere()
    a, b = f[0, 0], f[0, 1]
    bad = np.vstack([f, [[a, a, b]]])                          # zero area, at two real vertices
    _, of, _, n = smooth_normals(v, f)
    _, bf, _, bn = smooth_normals(v, bad)
    assert np.isfinite(bn).all()
    assert np.abs(bn[bf[:-1]] - n[of]).max() < 1e-6           # the real faces' normals unchanged
    ref = _by_position(v, _mitsuba_normals(v, f))
    assert np.abs(bn[bf[-1]] - np.array([ref[tuple(np.float32(v[i]))] for i in (a, a, b)])).max() < 1e-5


def test_normals_are_smooth_across_the_border_of_two_materials(tmp_path):
    """An OBJ whose two halves use two materials: two parts, two Mitsuba shapes, and on their
    border the same normals on both sides (each part smoothed alone left the seam faceted)."""
    v, f = _bumpy_sphere()
    half = v[f].mean(axis=1)[:, 2] > 0
    lines = ["mtllib ball.mtl"] + [f"v {x} {y} {z}" for x, y, z in v]
    for name, mask in (("top", half), ("bottom", ~half)):
        lines.append(f"usemtl {name}")
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f[mask]]
    (tmp_path / "ball.obj").write_text("\n".join(lines) + "\n")
    (tmp_path / "ball.mtl").write_text("newmtl top\nKd 0.8 0.2 0.2\nnewmtl bottom\nKd 0.2 0.2 0.8\n")
    scene = draaw_mi.load_scene({"shapes": [{"type": "mesh", "file": str(tmp_path / "ball.obj"),
                                             "smooth": True}], "render": {"resolution": [8, 8]}})
    ref = _by_position(v, _mitsuba_normals(v, f))
    shapes = [s for s in scene.mi_scene.shapes() if "_part" in s.id()]
    assert len(shapes) == 2
    for shape in shapes:
        pos = np.asarray(scene.params[f"{shape.id()}.vertex_positions"]).reshape(-1, 3)
        n = np.asarray(scene.params[f"{shape.id()}.vertex_normals"]).reshape(-1, 3)
        assert np.abs(n - np.array([ref[tuple(p)] for p in pos])).max() < 1e-5


def test_a_degenerate_face_alone_at_its_positions_gets_plus_z_not_nan():
    v = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1], [5, 5, 5], [6, 6, 6]], float)
    f = np.array([[0, 1, 2], [3, 4, 4]])                        # the second has no area
    _, of, _, n = smooth_normals(v, f)
    assert np.array_equal(n[of[1]], np.tile(np.float32([0, 0, 1]), (3, 1)))
    assert np.array_equal(n[of[0]], np.tile(np.float32([1, 0, 0]), (3, 1)))   # the real one: +x
