"""Shared set-up for the batch tests: a tiny scene file and small manifests (32x24, box filter)."""
from __future__ import annotations

import os
import sys

import numpy as np
import tomli_w

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from conftest import tiny_description  # noqa: E402

from draaw_mi.io import read_exr  # noqa: E402


def write_scene(folder, name="tiny.toml", **render) -> str:
    path = os.path.join(str(folder), name)
    with open(path, "wb") as fh:
        tomli_w.dump(tiny_description(**render), fh)
    return path


def manifest(folder, frames=4, **job) -> dict:
    """A one-job manifest dict: an orbit around the tiny scene with a roughness ramp, its
    frames in ``out/`` of the output folder (the batch tests run in their ``tmp_path``, so
    without ``--out`` that is ``folder/out``)."""
    scene = write_scene(folder)
    j = {"name": "orbit", "scene": scene, "frames": frames, "spp": 4,
         "camera": {"orbit": {"target": [0.0, 0.5, 0.0], "radius": 5.0, "height": 0.8}},
         "params": {"ball.roughness": {"from": 0.1, "to": 0.9}}}
    j.update(job)
    return {"output": os.path.join("out", "{job}", "{frame:04d}.exr"), "jobs": [j]}


def write_manifest(folder, doc, name="batch.toml") -> str:
    path = os.path.join(str(folder), name)
    with open(path, "wb") as fh:
        tomli_w.dump(doc, fh)
    return path


def frames_of(folder) -> dict:
    """{relative path: pixel array} of every final .exr under ``folder`` (temp files excluded)."""
    out = {}
    for root, _, files in os.walk(str(folder)):
        for f in files:
            if f.endswith(".exr") and not f.startswith("."):
                p = os.path.join(root, f)
                out[os.path.relpath(p, str(folder))] = read_exr(p)
    return out


def assert_bit_identical(a: dict, b: dict):
    assert sorted(a) == sorted(b), (sorted(a), sorted(b))
    for k in a:
        assert a[k].shape == b[k].shape, k
        assert np.array_equal(a[k].view(np.uint32), b[k].view(np.uint32)),\
            f"{k}: max |diff| {np.abs(a[k] - b[k]).max()}"
