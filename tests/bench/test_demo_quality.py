"""Issue 43: `make demo`'s image (scenes/cornell.toml with --denoise) must not fall back to the
speckled one. At 64x64 (the demo's 256x256 costs minutes in a reference): the demo's settings
(the scene's settings: the independent sampler, 64 spp, OIDN with the emitters seen directly kept out of
it) against the raw 64-spp render of the old settings (independent sampler, no denoising),
both against a V4 reference at 2048 spp. benchmarks/results/demo_quality.md has the
full-size figures (RMSE 0.0201 -> 0.0043)."""
from __future__ import annotations

import os

import numpy as np
import pytest

import draaw_mi

from conftest import SCENES

pytest.importorskip("pyoidn")


def test_the_demo_settings_halve_the_error_of_the_raw_render():
    """Measured at 64x64, seeds 0 and 1 (with the multijitter sampler: raw 0.0207 and 0.0201,
    demo 0.0075 and 0.0074, ratio 0.37; the scene keeps the independent sampler, which V4's
    adaptive sampling and the expectation tests use); the reference's own noise (V4 at 2048 spp, about 0.003 here) is in both.
    The bound, half the raw error, is the issue's acceptance; the errors' spread over seeds
    (3 %) is far inside its 27 % margin. Also: the raw render kept beside the denoised one
    has about the raw error (it is the full render's expectation, not a smoothed one)."""
    scene = draaw_mi.load_scene(os.path.join(SCENES, "cornell.toml"), resolution=(64, 64))
    assert scene.settings["spp"] == 64
    old = scene
    ref = np.array(draaw_mi.render(old, spp=2048, seed=12345, post=[]))[..., :3]     # unbiased

    def rmse(x):
        return float(np.sqrt(np.mean((np.asarray(x)[..., :3] - ref) ** 2)))
    for seed in (0, 1):
        raw = rmse(draaw_mi.render(old, seed=seed, post=[]))
        demo, info = draaw_mi.render(scene, seed=seed, post=[], denoise=True, return_info=True)
        assert rmse(demo) < 0.5 * raw, (seed, rmse(demo), raw)
        assert rmse(info["raw"]) > 0.7 * raw           # the undenoised image: raw noise
