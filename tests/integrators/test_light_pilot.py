"""V4's learned emitter selection (draaw_mi.integrators.light_pilot): the pilot's second
moments, the table it gives, when ``auto`` learns, determinism, refresh after light changes,
and frozen renders taking the learned table."""
from __future__ import annotations


import numpy as np
import pytest

import draaw_mi
from integrators_helpers import integrator, mi

from draaw_mi.integrators import light_pilot as lp
from draaw_mi.bench import reference_scenes as rs
from draaw_mi.integrators.sampling import PowerSelection

from draaw_mi.rendering import session as S
from draaw_mi.rendering.session import session_of


def two_point_lights(i_left: float, i_right: float, res: int = 16) -> dict:
    """A diffuse floor seen from straight above, two point lights placed mirror-symmetrically:
    each light's contribution is the other's mirrored and scaled by the intensity ratio, so
    the second moments are in the ratio of the intensities squared."""
    film, sampler = rs._film(res, 4)
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 60.0,
                       "to_world": T().look_at(origin=[0, 4, 0], target=[0, 0, 0], up=[0, 0, 1]),
                       "film": film, "sampler": sampler},
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(4.0),
                      "bsdf": {"type": "diffuse"}},
            "left": {"type": "point", "position": [-1.0, 1.0, 0.0],
                     "intensity": {"type": "rgb", "value": [i_left] * 3}},
            "right": {"type": "point", "position": [1.0, 1.0, 0.0],
                      "intensity": {"type": "rgb", "value": [i_right] * 3}}}


def test_moments_follow_the_intensities_squared_and_the_table_their_roots():
    scene = mi.load_dict(two_point_lights(3.0, 1.0))
    integ = integrator("draaw_v4", max_depth=2, light_selection="learned")
    m = lp.light_moments(integ, scene)
    names = [e.id() for e in scene.emitters()]
    ratio = m[names.index("left")] / m[names.index("right")]
    assert ratio == pytest.approx(9.0, rel=0.05)        # symmetric scene: exactly 9 in expectation
    sel = lp.selection_from_moments(scene, m)
    p = dict(zip(names, sel.pmf_np))
    # sqrt(M): 3 : 1, then 80 % of it plus a uniform 10 % each
    assert p["left"] == pytest.approx(0.8 * 0.75 + 0.1, abs=0.01)
    assert p["right"] == pytest.approx(0.8 * 0.25 + 0.1, abs=0.01)


def test_moment_of_one_point_light_is_the_mean_squared_direct_light():
    """One point light of intensity 3 at height 1 over a diffuse floor (albedo 0.5), seen
    from height 4 with a 60 degree field of view, direct light only: the pilot's M is the
    mean over the film of L^2 (pmf 1), L = 0.5 / pi * 3 / d^3 at the floor point seen
    (cos / d^2 with cos = 1 / d), the film mapping uniformly onto the floor square
    |x|, |z| <= 4 tan 30. The pilot's own error is the standard deviation of L^2 over the
    square divided by sqrt(PILOT_PATHS) (0.43 %; measured 0.9 of it): within 4 of them
    (dividing the sums by twice the paths gave half the moment)."""
    d = two_point_lights(3.0, 1.0)
    del d["right"]
    scene = mi.load_dict(d)
    m = lp.light_moments(integrator("draaw_v4", max_depth=2, light_selection="learned"), scene)
    h, n = 4 * np.tan(np.radians(30)), 1000
    x = (np.arange(n) + 0.5) / n * 2 * h - h                  # midpoint rule on the square
    X, Z = np.meshgrid(x, x)
    L2 = (0.5 / np.pi * 3.0 / ((X + 1.0) ** 2 + Z ** 2 + 1.0) ** 1.5) ** 2
    want, se = float(L2.mean()), float(L2.std() / np.sqrt(lp.PILOT_PATHS))
    assert m.shape == (1,)
    assert abs(float(m[0]) - want) < 4 * se, (float(m[0]), want, se)


def test_nothing_seen_means_uniform():
    scene = mi.load_dict(two_point_lights(1.0, 1.0))
    assert lp.selection_from_moments(scene, np.zeros(2)) is None
    assert lp.selection_from_moments(scene, np.array([np.nan, 1.0])) is None


def test_auto_learns_where_power_does_not_apply_and_keeps_power_where_it_does():
    sky_and_area = mi.load_dict(rs.feature_scene(res=16, spp=4, constant=True))
    assert PowerSelection.of(sky_and_area) is None               # an environment: no power table
    auto = integrator("draaw_v4", max_depth=3)
    assert auto.light_selection == "auto"
    auto.prepare_selection(sky_and_area)
    sel = auto.emitter_selection(sky_and_area)
    assert sel is not None and np.ptp(sel.pmf_np) > 0.2           # learned: far from uniform
    from draaw_mi.bench import suite as ss
    many = ss.load("many_lights", 16)
    power = PowerSelection.of(many)
    auto.prepare_selection(many)
    np.testing.assert_array_equal(auto.emitter_selection(many).pmf_np, power.pmf_np)
    off = integrator("draaw_v4", max_depth=3, light_selection="power")
    off.prepare_selection(sky_and_area)
    assert off.emitter_selection(sky_and_area) is None           # 'power' never learns


def test_auto_learns_among_lights_of_different_kinds():
    """A spot aimed at the objects in view beside a wide area light: their powers differ
    (a power table exists), but a spot's power says little about what the surfaces in view
    get next to an area light's, so ``auto`` learns the table (the speed suite's
    ``spot_and_area``: 0.53x ``path``'s time to its error with the power table, 0.23x with the
    learned one; benchmarks/results/speed_suite.md, session 67). Among area lights alone it
    keeps the power table (the test above)."""
    T = mi.ScalarTransform4f
    d = two_point_lights(1.0, 1.0)
    del d["left"], d["right"]
    d["spot"] = {"type": "spot", "intensity": 30.0, "cutoff_angle": 25.0,
                 "to_world": T().look_at(origin=[1, 2, 0], target=[0, 0, 0], up=[0, 0, 1])}
    d["panel"] = {"type": "rectangle", "emitter": {"type": "area", "radiance": 10.0},
                  "to_world": T().translate([0, 3, 3]).rotate([1, 0, 0], 90).scale(0.7)}
    scene = mi.load_dict(d)
    power = PowerSelection.of(scene)
    assert power is not None                                     # the powers differ
    auto = integrator("draaw_v4", max_depth=3)
    auto.prepare_selection(scene)
    state = auto.selection_state(scene)
    assert state[2], "auto kept the power table"                 # learned
    assert not np.allclose(state[1].pmf_np, power.pmf_np, atol=0.02)


def test_learned_table_is_deterministic_and_relearns_only_when_asked():
    scene = draaw_mi.load_scene(two_point_lights(1.0, 1.0))
    tables = []
    for _ in range(2):
        integ = integrator("draaw_v4", max_depth=2, light_selection="learned")
        integ.prepare_selection(scene.mi_scene)
        tables.append(integ.emitter_selection(scene.mi_scene).pmf_np)
    np.testing.assert_array_equal(tables[0], tables[1])          # fixed seed, float64 sums
    assert tables[0] == pytest.approx([0.5, 0.5], abs=0.02)
    key = next(k for k in scene.params.keys() if k.startswith("left") and "intensity" in k)
    scene.params[key] = mi.Color3f(16.0)
    scene.params.update()
    integ.forget_scene(scene.mi_scene)            # what Session.scene_changed does: the learned
    integ.prepare_selection(scene.mi_scene)       # table stays (no pilot per slider step) ...
    np.testing.assert_array_equal(integ.emitter_selection(scene.mi_scene).pmf_np, tables[0])
    integ.forget_scene(scene.mi_scene, learned=True)   # ... unless asked
    integ.prepare_selection(scene.mi_scene)
    p = dict(zip([e.id() for e in scene.mi_scene.emitters()], integ.emitter_selection(scene.mi_scene).pmf_np))
    assert p["left"] == pytest.approx(0.8 * 16 / 17 + 0.1, abs=0.02)


def test_the_pilot_gives_the_same_bits_every_time():
    """Its sums are atomic additions in an order that varies from run to run: in float32 the
    moments differed in the last bits between runs (and with them a batch frame's pixels
    between processes); float64 sums rounded to 6 digits do not."""
    scene = mi.load_dict(rs.feature_scene(res=16, spp=4, constant=True, point=True))
    integ = integrator("draaw_v4", max_depth=3, light_selection="learned")
    moments = [lp.light_moments(integ, scene) for _ in range(6)]
    assert moments[0].size == 3 and moments[0].min() > 0
    for m in moments[1:]:
        np.testing.assert_array_equal(m, moments[0])


def test_frozen_and_traced_renders_use_the_learned_table(monkeypatch):
    """The table is learned before the recording (freeze_state), enters it as an input, and
    frozen and traced renders choose lights alike."""
    scene = draaw_mi.load_scene(rs.feature_scene(res=16, spp=4, constant=True))
    integ = session_of(scene).integrator("v4", 3)
    monkeypatch.setattr(S, "FREEZE", True)
    frozen = [np.array(draaw_mi.render(scene, version="v4", spp=8, seed=s, post=[], max_depth=3))
              for s in (1, 2)]
    assert integ.emitter_selection(scene.mi_scene) is not None  # learned, not uniform
    monkeypatch.setattr(S, "FREEZE", False)
    traced = [np.array(draaw_mi.render(scene, version="v4", spp=8, seed=s, post=[], max_depth=3))
              for s in (1, 2)]
    for f, t in zip(frozen, traced):
        assert np.isfinite(f).all() and f.mean() > 0
        assert np.allclose(f, t, rtol=1e-5, atol=1e-6), np.abs(f - t).max()


def test_doctests():
    import doctest
    assert doctest.testmod(lp).failed == 0


def test_auto_keeps_power_among_point_lights_alone():
    """Point lights alone emit alike (their power ranks them, as area lights'): ``auto`` keeps
    the power table there and runs no pilot (on three point lights of intensities 5 : 40 : 12,
    power 0.12 against learned 0.14 of ``path``'s time to its error, 128^2, 7 cycles)."""
    scene = mi.load_dict(two_point_lights(1.0, 10.0))
    auto = integrator("draaw_v4", max_depth=3)
    auto.prepare_selection(scene)
    state = auto.selection_state(scene)
    assert not state[2]
    np.testing.assert_array_equal(state[1].pmf_np, PowerSelection.of(scene).pmf_np)


def test_the_pilot_is_large_only_where_glints_need_it(monkeypatch):
    """2^18 paths where delta lights meet near-mirrors (the thesis scene's glints, which 2^16
    paths missed with some seeds), 2^16 elsewhere (the same table in a quarter of the time)."""
    seen = []
    real = lp.light_moments
    monkeypatch.setattr(lp, "light_moments", lambda *a, **k: (seen.append(k.get("paths")), real(*a, **k))[1])
    plain = mi.load_dict(two_point_lights(1.0, 2.0))
    glinting = two_point_lights(1.0, 2.0)
    glinting["floor"]["bsdf"] = {"type": "roughconductor", "alpha": 0.02}
    for d in (plain, mi.load_dict(glinting)):
        lp.learn_selection(integrator("draaw_v4", max_depth=3), d)
    assert seen == [lp.PILOT_PATHS_PLAIN, lp.PILOT_PATHS] == [1 << 16, 1 << 18]


@pytest.mark.parametrize("scene_name, said", [
    ("many_lights", "by power (24 area lights of different powers)"),
    ("spot_and_area", "by a table a pilot of 2^16 camera paths learns before the first render (2 lights of different kinds)"),
    ("glass", "by a table a pilot of 2^18 camera paths learns before the first render (3 lights, an environment among them)"),
    ("metal_018", "one light: nothing to choose"),
])
def test_info_says_how_v4_picks_its_lights(scene_name, said):
    """``draaw-mi info``'s ``v4 lights`` line names what ``auto`` does with the scene's lights:
    the power table, a pilot's table (2^18 paths where glints need them), or nothing to choose;
    it follows the integrator's own decision."""
    from draaw_mi.bench import suite as ss
    from draaw_mi.integrators.light_tables import describe_selection
    scene = ss.load(scene_name, 8)
    assert describe_selection(scene) == said
    auto = integrator("draaw_v4", max_depth=3)
    auto.prepare_selection(scene)
    _, table, learned = auto.selection_state(scene)
    if "pilot" in said:
        assert learned and table is not None
    elif said.startswith("by power"):
        assert not learned and table is not None
    else:
        assert table is None                                   # uniform: nothing to choose
