"""``draaw_mi.integrators.reconnection``: second vertices whose BSDF depends on where they are
seen from, shared among 2x2 pixel tiles: ``path``'s expectation per pixel, no fireflies off
near-mirrors, and guided renders that share."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from integrators_helpers import check_same_expectation, integrator, seed_stack

from draaw_mi.integrators import reconnection

T = mi.ScalarTransform4f


def _panel_room(panel: dict, res: int = 12, floor: dict | None = None) -> mi.Scene:
    """A floor lit only by a lamp's light off the panel overhead (the lamp faces up: the
    floor is behind it)."""
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": T().look_at(origin=[0, 2.0, 3.0], target=[-0.6, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "gaussian"}}},
        "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(2),
                  "bsdf": floor or {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.7}}},
        "panel": {"type": "rectangle", "to_world": T().translate([0, 1.5, 0]).rotate([1, 0, 0], 90),
                  "bsdf": panel},
        "lamp": {"type": "rectangle", "to_world": T().translate([1.0, 0.3, 0]).rotate([1, 0, 0], -90).scale(0.2),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 100.0}}}})


NORMALS = np.stack(np.broadcast_arrays(0.4 * np.sin(np.linspace(0, 12, 16))[None, :],
                                       np.zeros((16, 1)), np.ones((16, 16))), -1)


@pytest.mark.parametrize("panel, v4_options", [
    ({"type": "roughconductor", "alpha": 0.1}, {}),
    # (roulette after the panel's bounce stops most paths: what they find weighs 1 / survival)
    ({"type": "roughconductor", "alpha": 0.1}, {"rr_threshold": 1.0}),
    ({"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": {"type": "rgb", "value": 0.3}}, {}),
    ({"type": "normalmap", "bsdf": {"type": "diffuse"},
      "normalmap": {"type": "bitmap", "raw": True,
                    "bitmap": mi.Bitmap((0.5 + 0.5 * NORMALS / np.linalg.norm(NORMALS, axis=-1, keepdims=True))
                                        .astype(np.float32))}}, {}),
], ids=["metal", "metal, roulette", "plastic", "normal-mapped diffuse"])
def test_glossy_second_vertices_keep_paths_expectation(panel, v4_options):
    """Each neighbour sees the panel's light from its own direction: the panel's BSDF is
    evaluated again towards it (under a gaussian filter)."""
    scene = _panel_room(panel)
    K, spp = 24, 512
    ref = seed_stack(scene, integrator("path", max_depth=4), spp, range(K))
    v4 = integrator("draaw_v4", max_depth=4, pixel_reuse="on", **v4_options)
    assert v4.reuse_table(scene, scene.sensors()[0], spp).reevaluates
    st = seed_stack(scene, v4, spp, range(300, 300 + K))
    assert np.isfinite(st).all()
    check_same_expectation(ref, st, max_frac3=0.03, max_mean=0.35)


def test_the_reflection_off_a_glossy_panel_is_shared_with_less_variance():
    """The floor's light arrives off the metal panel: the tile's four samples of it take its
    variance well down (0.49x measured, 16 renders; 0.7 allowed)."""
    scene = _panel_room({"type": "roughconductor", "alpha": 0.1}, res=24)
    on = seed_stack(scene, integrator("draaw_v4", max_depth=4, pixel_reuse="on"), 16, range(16))
    off = seed_stack(scene, integrator("draaw_v4", max_depth=4, pixel_reuse="off"), 16, range(16))
    ratio = on.var(0, ddof=1).mean() / off.var(0, ddof=1).mean()
    assert ratio < 0.7, ratio


def test_near_mirrors_add_no_fireflies():
    """Off a near-mirror a neighbour's sample is one its own BSDF would almost never draw:
    with the members' BSDF densities in the balance heuristic it weighs almost nothing
    (without them, re-weighting by the BSDF ratio alone took the variance to 100x)."""
    scene = _panel_room({"type": "roughconductor", "alpha": 0.005}, res=24)
    on = seed_stack(scene, integrator("draaw_v4", max_depth=4, pixel_reuse="on"), 16, range(16))
    off = seed_stack(scene, integrator("draaw_v4", max_depth=4, pixel_reuse="off"), 16, range(16))
    assert np.isfinite(on).all()
    ratio = on.var(0, ddof=1).mean() / off.var(0, ddof=1).mean()
    assert ratio < 1.25, ratio


def test_a_guided_render_shares_with_the_guides_densities(monkeypatch):
    """A guided render shares too: its tiles' densities are the guided mixture's."""
    seen, real = [], reconnection.ReconnectedLight.prepare

    def spy(self, scene, layout, ray, pi, active, flags, guide):
        seen.append(guide)
        return real(self, scene, layout, ray, pi, active, flags, guide)

    monkeypatch.setattr(reconnection.ReconnectedLight, "prepare", spy)
    scene = _panel_room({"type": "roughconductor", "alpha": 0.1}, res=16)
    img = np.array(mi.render(scene, integrator=integrator("draaw_v4", max_depth=4, pixel_reuse="on",
                                                          guiding="on"), spp=64, seed=1))
    assert np.isfinite(img).all() and img.mean() > 0
    assert seen and all(g is not None for g in seen)
