"""Fitted light values written back into a scene file (``draaw_mi.scene.light_values``):
the saved scene renders as the scene did with those values set in its parameters."""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi


def _desc(sky):
    return {"render": {"resolution": [16, 12], "filter": "box", "max_depth": 3},
            "materials": {"m": {"roughness": 0.5}},
            "shapes": [{"type": "sphere", "material": "m", "radius": 0.6},
                       {"type": "sphere", "name": "glow", "center": [1.2, 0.8, 0], "radius": 0.2,
                        "emission": [2.0, 2.0, 2.0], "emission_color": [1.0, 0.5, 0.5]}],
            "lights": [{"type": "point", "position": [2, 2, 3], "intensity": 6.0, "color": [1, 0.9, 0.8]},
                       {"type": "area", "name": "key", "position": [-2, 2, 2], "target": [0, 0, 0], "intensity": 3.0},
                       sky],
            "camera": {"origin": [0, 0, 4], "target": [0, 0, 0]}}


FITTED = {"point_light0.intensity": [3.0, 1.5, 0.75], "key.emitter.radiance": [1.0, 2.0, 4.0],
          "glow.emitter.radiance": [0.5, 3.0, 1.0]}


@pytest.mark.parametrize("sky_kind", ["constant", "envmap"])
def test_fitted_light_values_written_back_render_as_set(tmp_path, sky_kind):
    from PIL import Image
    if sky_kind == "constant":                       # (an intensity of 0 has no colour to carry)
        sky, fitted = {"type": "constant", "intensity": 0.0}, {"constant_light2.radiance": [0.05, 0.1, 0.2]}
    else:
        env = str(tmp_path / "env.png")
        Image.fromarray(np.random.default_rng(1).integers(0, 255, (8, 16, 3), dtype=np.uint8)).save(env)
        sky, fitted = {"type": "envmap", "file": env, "intensity": 0.3}, {"envmap_light2.scale": 0.7}
    values = {**FITTED, **fitted}
    scene = draaw_mi.load_scene(_desc(sky))
    p = scene.params
    for name, value in values.items():
        p[scene.key(name)] = value
    p.update()
    doc = scene.updated_description(values)
    saved = draaw_mi.load_scene(doc)
    for name, value in values.items():
        np.testing.assert_allclose(np.array(saved.params[saved.key(name)]).ravel(), np.ravel(value), rtol=1e-6)
    a, b = (np.array(draaw_mi.render(s, spp=4, seed=3, version="path", post=[])) for s in (scene, saved))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    assert doc["lights"][0]["intensity"] == 6.0          # the intensity stays; the colour takes the fit
    assert doc["lights"][2]["intensity"] == (1.0 if sky_kind == "constant" else 0.7)


def test_a_parameter_of_neither_a_material_nor_a_light_names_what_can_be_written():
    scene = draaw_mi.load_scene({"shapes": [{"type": "sphere", "name": "ball"}],
                                 "lights": [{"type": "point", "position": [0, 0, 5]}]})
    with pytest.raises(draaw_mi.DraawError, match=r"cannot write 'ball.to_world' back: no material or "
                                                  r"light 'ball' in the file \(parameters of \[materials\]"):
        scene.updated_description({"ball.to_world": 0.0})
    with pytest.raises(draaw_mi.DraawError, match=r"cannot write 'point_light0.position' back: of a light, only "
                                                  r"emitter.radiance, radiance, intensity, irradiance, scale"):
        scene.updated_description({"point_light0.position": [0.0, 0.0, 1.0]})
