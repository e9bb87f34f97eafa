"""Shared fixtures: tiny scenes (<= 64x64, box filter, fixed seeds) and paths."""
from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import draaw_mi  # noqa: F401  (sets the variant, registers plugins)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")
# The helper modules of the test folders (integrators_helpers, sdf_helpers, media_scenes, ...)
# import by name from any test, whichever folder it is in
for _folder in ("batch", "integrators", "materials", "media", "post", "sdf", "stability"):
    _path = os.path.join(ROOT, "tests", _folder)
    if _path not in sys.path:
        sys.path.append(_path)
GO_DRAAW = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "go-draaw"))


@pytest.fixture(autouse=True, scope="session")
def _temporary_files_stay_in_this_runs_folder(tmp_path_factory):
    """What the code under test puts in the system's temporary folder (``tempfile.mkdtemp`` in
    doctests, notebook kernels, CLI and worker subprocesses) goes under this run's pytest folder,
    which pytest prunes (it keeps the last three runs), not into ``/tmp`` run after run."""
    import tempfile
    folder = str(tmp_path_factory.mktemp("tempfile"))
    before = tempfile.tempdir, os.environ.get("TMPDIR")
    tempfile.tempdir = os.environ["TMPDIR"] = folder
    yield folder
    tempfile.tempdir = before[0]
    if before[1] is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = before[1]


@pytest.fixture(autouse=True)
def _batch_tests_run_in_their_folder(request, monkeypatch):
    """A batch writes under its output folder, by default the current one: the batch tests run
    in their own temporary folder (their manifests' relative patterns land there)."""
    if os.sep + os.path.join("tests", "batch") + os.sep in str(request.node.fspath):
        monkeypatch.chdir(request.getfixturevalue("tmp_path"))


@pytest.fixture
def no_collections():
    """Earlier tests' garbage freed first and no automatic collection during the test: a scene
    freed by the collector is a change of the registry too (a test that counts recordings would see it)."""
    import gc
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


def tiny_description(**render):
    """A sphere on a floor under a point light and a dim sky, 32x24 by default."""
    r = {"resolution": [32, 24], "spp": 4, "max_depth": 4, "filter": "box"}
    r.update(render)
    return {
        "render": r,
        "camera": {"origin": [0.0, 1.0, 5.0], "target": [0.0, 0.5, 0.0], "fov": 40},
        "materials": {
            "ball": {"base_color": [0.8, 0.3, 0.2], "roughness": 0.4, "metallic": 0.2},
            "ground": {"base_color": [0.5, 0.5, 0.5], "roughness": 0.9, "specular": 0.2},
        },
        "shapes": [
            {"type": "sphere", "name": "ball_shape", "material": "ball", "center": [0, 0.8, 0], "radius": 0.8},
            {"type": "rectangle", "name": "floor", "material": "ground", "scale": 4.0,
             "rotate": {"axis": [1, 0, 0], "angle": -90}},
        ],
        "lights": [
            {"type": "point", "position": [2.0, 4.0, 3.0], "intensity": 40.0},
            {"type": "constant", "intensity": 0.2},
        ],
    }


def go_draaw_patch_uv(position, theta, phi, fov_deg, point):
    """``(u, v)``, 0..1 from the left and the top, where GO-Draaw's image patch sees ``point``,
    written from go-draaw-spec.md §2.8 and independent of draaw-mi: the primary ray of patch
    point (u, v) is ``TL + u (TR - TL) + v (BL - TL)`` with ``S(θ, φ) = (sin φ cos θ,
    sin φ sin θ, cos φ)``, ``TL = S(θ, φ)``, ``TR = S(θ + F, φ)``, ``BL = S(θ, φ + F)``."""
    def s(th, ph):
        return np.array([np.sin(ph) * np.cos(th), np.sin(ph) * np.sin(th), np.cos(ph)])
    f = np.radians(fov_deg)
    tl = s(theta, phi)
    dx, dy = s(theta + f, phi) - tl, s(theta, phi + f) - tl
    # a (point - position) = TL + u dx + v dy
    _, u, v = np.linalg.solve(np.stack([np.subtract(point, position), -dx, -dy], axis=1), tl)
    return float(u), float(v)


def go_draaw_patch_point(position, theta, phi, fov_deg, u, v, distance):
    """The point ``distance`` from ``position`` along GO-Draaw's ray of patch point (u, v)
    (see :func:`go_draaw_patch_uv`)."""
    def s(th, ph):
        return np.array([np.sin(ph) * np.cos(th), np.sin(ph) * np.sin(th), np.cos(ph)])
    f = np.radians(fov_deg)
    tl = s(theta, phi)
    d = tl + u * (s(theta + f, phi) - tl) + v * (s(theta, phi + f) - tl)
    return np.asarray(position, float) + distance * d / np.linalg.norm(d)


def glowing_ball(camera: dict, centre, radius: float = 0.15, resolution=(32, 32)) -> dict:
    """A scene of one emitting ball on black, seen by ``camera`` (a ``[camera]`` table)."""
    return {"render": {"resolution": list(resolution), "spp": 4, "max_depth": 2, "filter": "box"},
            "camera": camera,
            "materials": {"ball": {"base_color": [0.0, 0.0, 0.0]}},
            "shapes": [{"type": "sphere", "name": "ball_shape", "material": "ball",
                        "center": [float(c) for c in centre], "radius": radius, "emission": [5.0, 5.0, 5.0]}]}


def bright_column(image) -> float:
    """The brightness-weighted mean column of ``image`` (H, W, C), in pixel units from the left
    edge (the patch's ``u`` times the width)."""
    w = np.asarray(image, float)[..., :3].sum(axis=(0, 2))
    return float((w * (np.arange(len(w)) + 0.5)).sum() / w.sum())


@pytest.fixture
def tiny_desc():
    return tiny_description()


@pytest.fixture
def tiny_scene():
    return draaw_mi.load_scene(tiny_description())


@pytest.fixture
def go_draaw_dir():
    if not os.path.isdir(GO_DRAAW):
        pytest.skip(f"GO-Draaw data folder {GO_DRAAW} is absent (it lives in ../shared beside the project)")
    return GO_DRAAW


NOTEBOOKS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "notebooks")


def notebook_generator(script: str):
    """The module of ``notebooks/<script>`` (a ``make_*.py`` generator; they import
    notebooks/_nbgen.py, so that folder goes on sys.path)."""
    import importlib.util
    import sys
    if NOTEBOOKS not in sys.path:
        sys.path.insert(0, NOTEBOOKS)
    spec = importlib.util.spec_from_file_location(script[:-3], os.path.join(NOTEBOOKS, script))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
