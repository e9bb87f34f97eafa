"""Batch overrides of SDF objects' parameters (``sdf.NODE.PARAM``): animated frames equal the
scene set to their values, with no recompiles, and a frame's values are checked together."""
from __future__ import annotations

import os

import numpy as np
import tomli_w
from conftest import tiny_description

import draaw_mi
from draaw_mi.batch import runner as batch
from draaw_mi.batch.planner import frame_seed, param_value


def _sdf_scene_file(folder) -> str:
    d = tiny_description()
    d["sdf"] = [{"type": "sphere", "name": "blob", "material": "ball", "center": [0.9, 0.35, 0.6],
                 "radius": 0.3},
                {"type": "box", "name": "brick", "material": "ground", "center": [-0.9, 0.3, 0.6],
                 "size": [0.5, 0.6, 0.5]},
                {"type": "smooth_union", "name": "pair", "children": ["blob", "brick"], "k": 0.1}]
    path = os.path.join(str(folder), "sdf.toml")
    with open(path, "wb") as fh:
        tomli_w.dump(d, fh)
    return path


def test_sdf_objects_are_animated_by_overrides(tmp_path):
    """``sdf.NODE.PARAM`` overrides (a growing radius, a smooth-union k, a moving centre):
    each frame equals the scene loaded once and set to that frame's values, with no kernel
    compiled after the first frame (the values enter the kernels opaque), and a job without
    overrides after them renders the scene as loaded."""
    scene_file = _sdf_scene_file(tmp_path)
    out = os.path.join("out", "{job}", "{frame:04d}.exr")        # under tmp_path (the cwd)
    doc = {"output": out, "jobs": [
        {"name": "grow", "scene": scene_file, "frames": 3, "spp": 4, "seed": 5,
         "params": {"sdf.blob.radius": {"from": 0.2, "to": 0.5},
                    "sdf.pair.k": {"values": [0.0, 0.3, 0.6]},
                    "sdf.brick.center": {"from": [-0.9, 0.3, 0.6], "to": [-0.5, 0.6, 0.6]}}},
        {"name": "still", "scene": scene_file, "frames": 1, "spp": 4, "seed": 5}]}
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 4 and not res.failed
    assert [r.get("new_kernels") for r in res.results][:3] == [None, 0, 0]
    m, specs, _ = batch.load(doc)
    frames = [draaw_mi.read_exr(s["output"]) for s in specs]
    ref_scene = draaw_mi.load_scene(scene_file)
    draaw_mi.render(ref_scene, seed=99, spp=1)             # V4 learns with the scene as loaded
    still = np.array(draaw_mi.render(ref_scene, seed=frame_seed(5, 0), spp=4))
    assert np.array_equal(frames[3], still)
    for f in range(3):
        ref_scene.sdf.set("blob.radius", param_value("linear", (0.2, 0.5), f, 3))
        ref_scene.sdf.set("pair.k", [0.0, 0.3, 0.6][f])
        ref_scene.sdf.set("brick.center", param_value("linear", ([-0.9, 0.3, 0.6], [-0.5, 0.6, 0.6]), f, 3))
        ref = np.array(draaw_mi.render(ref_scene, seed=frame_seed(5, f), spp=4))
        assert np.array_equal(frames[f], ref), f
    assert np.abs(frames[0] - frames[2]).max() > 0.1       # the objects moved


def test_an_sdf_size_and_radius_animated_together_plan_and_render(tmp_path):
    """Each frame's values are checked with each other, on the scene as loaded: a round box
    that shrinks with its radius (valid at every frame) was refused at frame 1 because its
    new size was checked against the loaded radius."""
    d = tiny_description()
    d["sdf"] = [{"type": "round_box", "name": "block", "material": "ball", "center": [0.9, 0.3, 0.6],
                 "size": [0.6, 0.6, 0.6], "radius": 0.25}]
    scene_file = str(tmp_path / "rb.toml")
    with open(scene_file, "wb") as fh:
        tomli_w.dump(d, fh)
    doc = {"output": "out/{job}/{frame:04d}.exr", "jobs": [
        {"name": "shrink", "scene": scene_file, "frames": 2, "spp": 2, "seed": 7,
         "params": {"sdf.block.size": {"values": [[0.6, 0.6, 0.6], [0.3, 0.3, 0.3]]},
                    "sdf.block.radius": {"values": [0.25, 0.1]}}}]}
    res = batch.run(doc, progress=False)
    assert res.complete and res.rendered == 2 and not res.failed
    # frame 1 is the scene loaded once and shrunk as a whole
    m, specs, _ = batch.load(doc)
    frames = [draaw_mi.read_exr(s["output"]) for s in specs]
    ref = draaw_mi.load_scene(scene_file)
    draaw_mi.render(ref, seed=99, spp=1)                   # V4 learns with the scene as loaded
    ref.sdf.set_many({"block.size": [0.3, 0.3, 0.3], "block.radius": 0.1})
    assert np.array_equal(frames[1], np.array(draaw_mi.render(ref, seed=frame_seed(7, 1), spp=2)))
    assert np.abs(frames[0] - frames[1]).max() > 0.05
