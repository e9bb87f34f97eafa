"""The hash of the render code in the names of cached references (draaw_mi.bench.code_digest)."""
from __future__ import annotations

import os
import shutil

import numpy as np

import draaw_mi
from draaw_mi.bench import speed as speed_bench, study as bench
from draaw_mi.bench.code_digest import RENDER_CODE, code_digest

PACKAGE = os.path.dirname(os.path.abspath(draaw_mi.__file__))


def _copy(tmp_path):
    root = tmp_path / "pkg"
    for sub in RENDER_CODE:
        shutil.copytree(os.path.join(PACKAGE, sub), root / sub,
                        ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(os.path.join(PACKAGE, "cli", "commands.py"), root / "cli.py")
    return root


def test_the_digest_follows_the_render_code_and_nothing_else(tmp_path):
    root = _copy(tmp_path)
    first = code_digest(str(root))
    assert first == code_digest(PACKAGE)                   # the same sources, elsewhere
    assert code_digest() == first                          # the default: this package's
    with open(root / "cli.py", "a") as f:                  # outside the render code
        f.write("\n# a comment\n")
    (root / "materials" / "notes.txt").write_text("not code")
    assert code_digest(str(root)) == first
    bsdf = root / "materials" / "draaw_bsdf.py"            # the BSDF path's references call
    bsdf.write_text(bsdf.read_text().replace("return", "return ", 1))
    second = code_digest(str(root))
    assert second != first
    (root / "sdf" / "extra.py").write_text("X = 1\n")      # a new module counts too
    third = code_digest(str(root))
    assert third not in (first, second)
    # a reference of many passes is their mean, made in rendering/ (a change there had kept
    # every cached reference: a copy that doubled multi-pass images hashed the same)
    renderer = root / "rendering" / "renderer.py"
    renderer.write_text(renderer.read_text().replace("return", "return ", 1))
    assert code_digest(str(root)) not in (first, second, third)


def test_a_cached_ground_truth_is_rendered_anew_when_the_render_code_changes(tmp_path, monkeypatch):
    """bench.ground_truth's cache kept a reference rendered with the old BSDF after a fix in
    it: every error of the study was then measured against the old result."""
    from conftest import tiny_description
    scene = draaw_mi.load_scene(tiny_description())
    import importlib
    render_module = importlib.import_module("draaw_mi.bench.study")      # the module that calls render()
    calls = []
    real = render_module.render

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(render_module, "render", counting)
    cache = str(tmp_path / "cache")
    first = bench.ground_truth(scene, spp=4, cache_dir=cache)
    again = bench.ground_truth(scene, spp=4, cache_dir=cache)
    assert len(calls) == 1 and np.array_equal(first, again)      # read back from the cache
    monkeypatch.setattr(bench, "code_digest", lambda: "0123456789ab")
    bench.ground_truth(scene, spp=4, cache_dir=cache)
    assert len(calls) == 2
    assert len(os.listdir(cache)) == 2


def test_a_speed_reference_is_cached_under_the_code_digest(tmp_path, monkeypatch):
    from draaw_mi.bench import suite as ss
    scene = ss.load("metal_018", 8)
    ref = 2 * speed_bench.REF_PASS_SPP                  # the fewest a reference takes
    cache = str(tmp_path)
    monkeypatch.setattr(speed_bench, "code_digest", lambda: "aaaaaaaaaaaa")
    _, _, t = speed_bench.reference("metal_018", 8, scene, 3, ref, cache, "d")
    assert t > 0 and os.listdir(cache) == [f"metal_018_8_d3_{ref}_d_caaaaaaaaaaaa.exr"]
    _, _, t = speed_bench.reference("metal_018", 8, scene, 3, ref, cache, "d")
    assert t == 0.0                                               # read back
    monkeypatch.setattr(speed_bench, "code_digest", lambda: "bbbbbbbbbbbb")
    _, _, t = speed_bench.reference("metal_018", 8, scene, 3, ref, cache, "d")
    assert t > 0 and len(os.listdir(cache)) == 2
