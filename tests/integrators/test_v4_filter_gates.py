"""Issue 45's first step: what V4 leaves off under a pixel filter other than box (adaptive
sampling, emission splitting) is said once, as a RuntimeWarning, and by ``draaw-mi info``."""
from __future__ import annotations

import warnings

import pytest

import draaw_mi
from draaw_mi.cli import main

from conftest import tiny_description


def _render_warnings(filter_name: str, **options) -> list[str]:
    scene = draaw_mi.load_scene(tiny_description(filter=filter_name, resolution=[12, 8]))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        for _ in range(2):                  # two renders by one integrator: said once
            draaw_mi.render(scene, version="v4", spp=2, integrator_options=options or None)
    return [str(w.message) for w in seen if issubclass(w.category, RuntimeWarning)
            and "pixel filter" in str(w.message)]


@pytest.mark.parametrize("name", ["gaussian", "tent", "lanczos", "mitchell"])
def test_a_filter_that_gates_v4s_speedups_is_said_once(name):
    said = _render_warnings(name)
    assert len(said) == 1 and f"the film's pixel filter is {name!r}" in said[0], said
    assert "adaptive sampling and emission splitting are off" in said[0]


def test_nothing_is_said_with_a_box_filter_or_with_the_speedups_asked_off():
    assert _render_warnings("box") == []
    assert _render_warnings("gaussian", adaptive=False, emission_split=1) == []


def test_info_says_what_the_filter_gates(tmp_path, capsys):
    import json
    path = tmp_path / "g.json"
    path.write_text(json.dumps(tiny_description(filter="gaussian")))
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "v4 note: adaptive sampling and emission splitting are off: the film's pixel filter is 'gaussian'" in out
    path.write_text(json.dumps(tiny_description(filter="box")))
    assert main(["info", str(path)]) == 0
    assert "v4 note" not in capsys.readouterr().out
