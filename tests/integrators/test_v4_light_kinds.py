"""draaw_v4's per-scene sampling choices must not drop a kind of light.

Regression: ``only_constant_environment`` took a directional sun (an *infinite*, not spatially
varying emitter, like ``constant``) for a constant sky, so V4 switched to BSDF sampling alone
and a delta light that BSDF sampling can never hit went dark (half the image energy of
``scenes/sdf_csg.toml``). Reference: Mitsuba's own ``path`` on the same scene, mean over
independent seeds, tolerance from the seeds' standard error.
"""
from __future__ import annotations

import numpy as np
import pytest

import draaw_mi

LIGHTS = {
    "directional": [{"type": "directional", "direction": [-0.3, -1, -0.2], "intensity": 2.0}],
    "directional+constant": [{"type": "directional", "direction": [-0.3, -1, -0.2], "intensity": 2.0},
                             {"type": "constant", "intensity": 0.3}],
    "constant": [{"type": "constant", "intensity": 0.8}],
}


def _scene(lights):
    return draaw_mi.load_scene({
        "camera": {"origin": [0, 1, 4], "target": [0, 0, 0]},
        "render": {"resolution": [16, 12], "filter": "box"},
        "materials": {"m": {"base_color": [0.7, 0.6, 0.5], "roughness": 0.4}},
        "shapes": [{"type": "sphere", "radius": 1, "material": "m"},
                   {"type": "rectangle", "scale": 5, "material": "m",
                    "rotate": {"axis": [1, 0, 0], "angle": -90}, "translate": [0, -1, 0]}],
        "lights": lights})


@pytest.mark.parametrize("kind", list(LIGHTS))
def test_v4_image_mean_matches_path(kind):
    scene = _scene(LIGHTS[kind])
    means = {v: np.array([float(np.array(draaw_mi.render(scene, version=v, spp=32, seed=s)).mean())
                          for s in range(6)]) for v in ("v4", "path")}
    diff = means["v4"].mean() - means["path"].mean()
    se = np.sqrt(means["v4"].var(ddof=1) / 6 + means["path"].var(ddof=1) / 6)
    assert means["path"].mean() > 0.02                      # the light reaches the image
    assert abs(diff) < 4 * se + 1e-4, (kind, means)
