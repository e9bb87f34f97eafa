"""``draaw-mi render --set NAME=VALUE``: a parameter's value for one render, the one command
that makes a fit reference from the fitting scene (issue 43: "a truth scene and the one
command that makes a fit reference")."""
from __future__ import annotations

import json
import os

import mitsuba as mi
import numpy as np
import OpenEXR
import pytest

import draaw_mi
from draaw_mi.cli import main

from conftest import SCENES

SCENE = os.path.join(SCENES, "fit_sphere.toml")
SMALL = ["--resolution", "16x16", "--spp", "4", "--seed", "3", "--no-progress"]


def _reference_by_hand(rough, metal):
    """The same render with the values written through ``mi.traverse`` directly."""
    scene = draaw_mi.load_scene(SCENE, resolution=(16, 16), spp=4, seed=3)
    p = mi.traverse(scene.mi_scene)
    p["target.roughness.value"] = rough
    p["target.metallic.value"] = metal
    p.update()
    return np.array(draaw_mi.render(scene))


def test_set_renders_the_scene_with_those_values_and_says_so_in_the_header(tmp_path, capsys):
    """The image equals the render with the values set by hand (fails if --set is ignored or
    sets another parameter) and differs from the scene as written; the EXR records them."""
    out = tmp_path / "ref.exr"
    assert main(["render", SCENE, "-o", str(out), *SMALL,
                 "--set", "target.roughness=0.3", "--set", "target.metallic=0.8"]) == 0
    img = draaw_mi.read_exr(str(out))[..., :3]
    np.testing.assert_array_equal(img, _reference_by_hand(0.3, 0.8))
    plain = tmp_path / "plain.exr"
    assert main(["render", SCENE, "-o", str(plain), *SMALL]) == 0
    assert np.abs(draaw_mi.read_exr(str(plain))[..., :3] - img).max() > 1e-3
    header = OpenEXR.File(str(out)).header()
    assert json.loads(header["draaw:set"]) == {"target.roughness": 0.3, "target.metallic": 0.8}
    assert "draaw:set" not in OpenEXR.File(str(plain)).header()


@pytest.mark.parametrize("given, says", [
    ("nosuch.roughness=0.3", "no parameter 'nosuch.roughness'"),
    ("target.roughness=rough", "'rough' is not a finite number or a JSON list"),
    ("target.roughness=NaN", "is not a finite number"),
    ("target.roughness=1e999", "is not a finite number"),
    ("target.roughness=true", "is not a finite number"),
    ("target.base_color=[]", "is not a finite number"),
    ("target.roughness", "expected NAME=VALUE"),
    ("target.base_color=[0.1,0.2]", "target.base_color=[0.1, 0.2]; expected 3 numbers"),
    # the ranges a scene file keeps to (a TOML roughness of -3 is refused): they rendered
    ("target.roughness=-3", "target.roughness=-3; expected a number in [0.0, 1.0]"),
    ("target.metallic=1.5", "target.metallic=1.5; expected a number in [0.0, 1.0]"),
    ("target.base_color=[0.5,-2,0.5]", "target.base_color=[0.5, -2, 0.5]; expected values >= 0"),
])
def test_a_bad_set_is_one_line_and_status_2(tmp_path, capsys, given, says):
    out = tmp_path / "x.exr"
    assert main(["render", SCENE, "-o", str(out), *SMALL, "--set", given]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("draaw-mi: error: --set") and says in err[0], err
    assert not out.exists()


def test_set_fills_a_textured_parameter_with_a_number_or_a_colour(tmp_path, capsys):
    """``--set m.roughness=0.2`` on a textured roughness said "texels of shape (); this texture
    takes (H, W, 1)", and the help's ``--set target.base_color=[0.9,0.2,0.1]`` failed on a
    textured base colour. Both fill the texture: the render equals the scene with those
    values as arrays of the texture's shape; an array of arrays is refused in one line."""
    text = open(SCENE).read()

    def scene_with(base, rough, name):
        t = text.replace("base_color = [0.06, 0.22, 0.75]", f"base_color = {np.full((2, 2, 3), base).tolist()}")
        t = t.replace("roughness = 0.5", f"roughness = {np.full((2, 2), rough).tolist()}")
        (tmp_path / name).write_text(t)
        return str(tmp_path / name)

    start = scene_with([0.5, 0.5, 0.5], 0.6, "start.toml")
    want = scene_with([0.9, 0.2, 0.1], 0.2, "want.toml")
    out, ref = tmp_path / "set.exr", tmp_path / "want.exr"
    assert main(["render", start, "-o", str(out), *SMALL, "--set", "target.roughness=0.2",
                 "--set", "target.base_color=[0.9,0.2,0.1]"]) == 0
    assert main(["render", want, "-o", str(ref), *SMALL]) == 0
    np.testing.assert_allclose(draaw_mi.read_exr(str(out))[..., :3], draaw_mi.read_exr(str(ref))[..., :3],
                               rtol=0, atol=1e-3)
    capsys.readouterr()
    assert main(["render", start, "-o", str(tmp_path / "x.exr"), *SMALL, "--set", "target.roughness=[[0.2]]"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is an array of arrays; --set takes a number or a JSON list of numbers" in err[0], err
