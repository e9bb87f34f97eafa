"""When V4 stratifies (``draaw_mi/integrators/stratify.py``): where the scene's sampler is
``independent``, V4's renders and gradient passes draw from its own stratified sampler
(``strata_sampler.py``, tested in ``test_strata_sampler.py``); guided renders, glints and
other samplers keep theirs. The expectation is ``path``'s (also
``test_v4_filters.py``'s per-filter tests and every V4 expectation test, which render
stratified)."""
from __future__ import annotations

import numpy as np
import pytest

from integrators_helpers import check_same_expectation, integrator, mi, rs, seed_stack

from draaw_mi.integrators import adaptive_sampling as ads
from draaw_mi.integrators import guiding, spp_map, v4_passes
from draaw_mi.integrators.features import sampler_plugin
from draaw_mi.integrators.strata_sampler import StrataSampler


def _sampler_kinds(monkeypatch, integ) -> list:
    """The samplers V4's ``prepare`` hands out (``"strata"`` for its own, else Mitsuba's
    plugin name), appended as they are made."""
    kinds = []
    real = type(integ).prepare

    def spy(self, *a, **k):
        r = real(self, *a, **k)
        kinds.append("strata" if isinstance(r[0], StrataSampler) else sampler_plugin(r[0]))
        return r
    monkeypatch.setattr(type(integ), "prepare", spy)
    return kinds


@pytest.mark.parametrize("sampler, options, expected", [
    ("independent", {}, ["strata"]),
    ("independent", {"stratify": False}, ["independent"]),
    ("ldsampler", {}, ["ldsampler"]),
])
def test_v4_stratifies_what_the_independent_sampler_would_sample(monkeypatch, sampler, options, expected):
    """A 32-spp render of an independent-sampler scene: V4's stratified sampler;
    ``stratify=False`` or a scene with a sampler of its own: that sampler."""
    d = rs.cornell_draaw(res=8, spp=4)
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 4}
    scene = mi.load_dict(d)
    integ = integrator("draaw_v4", max_depth=2, **options)
    kinds = _sampler_kinds(monkeypatch, integ)
    mi.render(scene, integrator=integ, spp=32, seed=1)
    assert kinds == expected


def test_a_gradient_pass_is_stratified_and_replays_its_samples(monkeypatch):
    """A differentiated render: its primal pass and its adjoint pass (Mitsuba's path replay,
    whose primal replay draws from a clone of the sampler: ``test_strata_sampler.py`` checks
    the clone) both stratified, and the gradient equals the one with ``stratify=False``
    within their noise; the FD gradient tests run stratified too."""
    import drjit as dr
    scene = mi.load_dict(rs.cornell_draaw(res=8, spp=4))
    params = mi.traverse(scene)
    key = "white.base_color.value"

    def grads(options, seeds):
        out = []
        for seed in seeds:
            dr.enable_grad(params[key])
            params.update()
            img = mi.render(scene, params, integrator=integ if not options else
                            integrator("draaw_v4", max_depth=2, **options), spp=16, seed=seed)
            dr.backward(dr.mean(img, axis=None))
            out.append(np.array(dr.grad(params[key])))
            dr.disable_grad(params[key])
        return np.array(out)
    integ = integrator("draaw_v4", max_depth=2)
    kinds = _sampler_kinds(monkeypatch, integ)
    strat = grads({}, range(8))
    assert kinds == ["strata", "strata"] * 8, kinds
    indep = grads({"stratify": False}, range(100, 108))
    assert np.isfinite(strat).all() and (strat > 0).all(), strat
    se = np.sqrt(strat.var(0, ddof=1) / 8 + indep.var(0, ddof=1) / 8)
    assert (np.abs(strat.mean(0) - indep.mean(0)) < 4 * se).all(), (strat.mean(0), indep.mean(0), se)


def test_a_stratified_render_has_paths_expectation_and_less_variance():
    """32 spp stratified against ``path`` per pixel (box filter), and its per-pixel variance
    against V4 with ``stratify=False`` (independent, uniform below 64 spp): measured 0.04-0.06x
    on this 12x12 Cornell box, whose error is mostly each pixel's area and light (0.33x at 4
    spp, 0.92x at 1, where there is nothing to stratify); a sampler that did not stratify a
    pixel reads about 1."""
    scene = mi.load_dict(rs.cornell_draaw(res=12, spp=4))
    K = 16
    strat = seed_stack(scene, integrator("draaw_v4", max_depth=3), 32, range(K))
    indep = seed_stack(scene, integrator("draaw_v4", max_depth=3, stratify=False), 32, range(100, 100 + K))
    ref = seed_stack(scene, integrator("path", max_depth=3), 32, range(200, 200 + K))
    assert all((strat[k] != strat[0]).mean() > 0.5 for k in range(1, K))   # the seed reaches the sampler
    check_same_expectation(ref, strat)
    ratio = strat.var(0, ddof=1).sum() / indep.var(0, ddof=1).sum()
    assert ratio < 0.3, ratio


def test_a_scenes_first_render_decides_on_guiding_by_the_adaptive_pilot(monkeypatch):
    """At 128x128 and 64 spp (2^20 samples) a scene's first render with guiding ``auto``
    is adaptive: its pilot decides on guiding at no extra pass; the scene's later renders
    are stratified (uniform). With guiding ``off`` none is adaptive."""
    calls = []
    real = ads.render_adaptive
    monkeypatch.setattr(ads, "render_adaptive", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    scene = mi.load_dict(rs.cornell_draaw(res=128, spp=4))
    auto = integrator("draaw_v4", max_depth=2)
    for _ in range(2):
        mi.render(scene, integrator=auto, spp=64, seed=3)
    assert len(calls) == 1 and auto.guides.share(auto.selection_key(scene)) is not None
    off = integrator("draaw_v4", max_depth=2, guiding="off")
    mi.render(scene, integrator=off, spp=64, seed=3)
    assert len(calls) == 1


def test_a_first_render_left_unguided_renders_the_rest_stratified(monkeypatch):
    """The first render's adaptive pilot only decides on guiding: its 4 samples are the first
    of each pixel's stratified pattern of 64, and where it leaves the scene unguided the
    other 60 of that pattern render uniformly (same seed), not adaptively with independent
    samples: a first CLI render of Mitsuba's Cornell box read 0.16x ``path``'s MSE at 128^2
    that way, 0.05x now, as later renders (``benchmarks/first_render.py``). Passing no
    stratified rest, independent pilot samples, or the rest with a seed of its own (a
    pattern of its own) fails."""
    monkeypatch.setattr(guiding, "PILOTED_MIN_SAMPLES", 1)
    allocations = []
    allocate = ads.allocate
    monkeypatch.setattr(ads, "allocate", lambda *a, **k: allocations.append(1) or allocate(*a, **k))
    scene = mi.load_dict(rs.cornell_draaw(res=16, spp=4))
    integ = integrator("draaw_v4", max_depth=3)
    kinds = _sampler_kinds(monkeypatch, integ)
    counts, pilots = [], []
    real = ads.render_adaptive
    monkeypatch.setattr(ads, "render_adaptive", lambda *a, **k: (counts.append(a[4]), real(*a, **k))[1])
    rests = []
    made = spp_map.strata_sampler
    monkeypatch.setattr(spp_map, "strata_sampler", lambda spp, seed, w, part: pilots.append((spp, int(seed), part))
                        or made(spp, seed, w, part))
    monkeypatch.setattr(v4_passes, "strata_sampler", lambda spp, seed, w, part: rests.append((spp, int(seed), part))
                        or made(spp, seed, w, part))
    img = np.array(mi.render(scene, integrator=integ, spp=64, seed=1))
    assert counts == [64] and allocations == [] and np.isfinite(img).all()
    # one pattern of 64 per pixel, one seed: the pilot's first 4 samples, the rest's 60
    assert kinds == ["strata"] and pilots == [(4, 1, (64, 0))] and rests == [(60, 1, (64, 4))]
    assert integ._strata_part is None
    assert integ.guides.share(integ.selection_key(scene)) < guiding.SHARE_MIN


@pytest.mark.parametrize("rfilter", ["box", "tent"])
def test_a_first_render_of_pilot_and_stratified_rest_keeps_paths_expectation(monkeypatch, rfilter):
    """Each seed a fresh integrator, so each render is the scene's first: a 4-spp pilot
    (independent samples) that leaves the Cornell box unguided, and 60 stratified samples,
    weighted 1/16 and 15/16, per pixel against ``path`` (under a tent filter each part the
    filter's ratio estimate). Weighting the pilot by 1 / spp instead of a / spp darkens every
    pixel by 3/64: mean z 1.7 / 2.4 (box / tent) over the 100 pixels, against 0.35."""
    monkeypatch.setattr(guiding, "PILOTED_MIN_SAMPLES", 1)
    d = rs.cornell_draaw(res=10, spp=4)
    d["sensor"]["film"]["rfilter"] = {"type": rfilter}
    scene = mi.load_dict(d)
    K = 24
    v4 = np.stack([np.array(mi.render(scene, integrator=integrator("draaw_v4", max_depth=3), spp=64,
                                      seed=s), np.float64) for s in range(K)])
    ref = seed_stack(scene, integrator("path", max_depth=3), 64, range(100, 100 + K))
    check_same_expectation(ref, v4, max_mean=0.35)


@pytest.mark.parametrize("spp, sampler, said", [
    (64, "independent", "stratified (its own correlated multi-jittered samples"),
    (64, "ldsampler", "the scene's ldsampler sampler"),
    (1, "independent", "independent (one sample per pixel)"),        # (its reason alone, not every one)
])
def test_info_says_how_v4_samples(tmp_path, capsys, spp, sampler, said):
    """``draaw-mi info`` names V4's sampling of the scene's render: stratified in place of
    the independent sampler, independent where V4 keeps it (one sample per pixel: its answer
    is V4's own ``stratified``), or the scene's own."""
    import json
    from conftest import tiny_description
    from draaw_mi.cli import main
    d = tiny_description(sampler=sampler)
    d["render"]["spp"] = spp
    path = tmp_path / "s.json"
    path.write_text(json.dumps(d))
    assert main(["info", str(path)]) == 0
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("v4 samples:")]
    assert len(line) == 1 and said in line[0], line


@pytest.mark.parametrize("bsdf, expected", [
    ({"type": "draaw", "roughness": 0.05, "metallic": 1.0}, ["independent"]),
    ({"type": "draaw", "roughness": 0.3}, ["strata"]),
])
def test_glints_of_delta_lights_keep_the_independent_sampler(monkeypatch, bsdf, expected):
    """A point light over a near-mirror floor (the thesis scene's glints: Mitsuba's
    multijitter measured 2-3x the independent sampler's MSE there) renders with the independent sampler; the
    same floor at roughness 0.3, stratified."""
    d = {"type": "scene", "light": {"type": "point", "position": [0, 2, 2]},
         "floor": {"type": "rectangle", "bsdf": bsdf},
         "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
             origin=[0, 1, 3], target=[0, 0, 0], up=[0, 1, 0]),
             "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}}
    scene = mi.load_dict(d)
    integ = integrator("draaw_v4", max_depth=3)
    kinds = _sampler_kinds(monkeypatch, integ)
    mi.render(scene, integrator=integ, spp=16, seed=1)
    assert kinds == expected


def test_a_guided_render_keeps_the_independent_sampler(monkeypatch):
    """With a guide (``guiding="on"``) V4 renders with the independent sampler: stratified,
    the floor lit through a glossy panel took 1.31 / 1.22x ``path``'s time per render
    against 1.12 / 1.09x for 0.93 / 0.94x its MSE. Without one, the same scene stratified."""
    scene = mi.load_dict(rs.cornell_draaw(res=8, spp=4))
    for mode, expected in (("on", ["independent"]), ("off", ["strata"])):
        integ = integrator("draaw_v4", max_depth=3, guiding=mode)
        kinds = _sampler_kinds(monkeypatch, integ)
        mi.render(scene, integrator=integ, spp=16, seed=1)
        assert kinds == expected, (mode, kinds)
        monkeypatch.undo()


def test_glints_are_read_once_a_render_and_anew_the_next(monkeypatch):
    """``glints.has_glints`` reads every BSDF's roughness back (0.8 ms for a 1024^2 map);
    a 64-spp render asks whether to render adaptively, stratified, and in ``prepare``, and
    reads it once. The answer does not outlive the pass: the floor made a near-mirror
    between two renders gives the independent sampler in the second. Catches a memo that
    is never kept (three reads) or kept past its pass (the second render stratified)."""
    from draaw_mi.integrators import glints
    d = {"type": "scene", "light": {"type": "point", "position": [0, 2, 2]},
         "floor": {"type": "rectangle", "bsdf": {"type": "draaw", "roughness": 0.3}},
         "sensor": {"type": "perspective", "to_world": mi.ScalarTransform4f().look_at(
             origin=[0, 1, 3], target=[0, 0, 0], up=[0, 1, 0]),
             "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}}}}
    scene = mi.load_dict(d)
    integ = integrator("draaw_v4", max_depth=3)
    reads = []
    real = glints.has_glints
    monkeypatch.setattr(glints, "has_glints", lambda s: (reads.append(1), real(s))[1])
    kinds = _sampler_kinds(monkeypatch, integ)
    mi.render(scene, integrator=integ, spp=64, seed=1)
    assert len(reads) == 1 and kinds == ["strata"], (reads, kinds)
    params = mi.traverse(scene)
    key = [k for k in params.keys() if k.endswith("roughness.value")][0]
    params[key] = 0.05
    params.update()
    mi.render(scene, integrator=integ, spp=64, seed=2)
    assert len(reads) == 2 and kinds == ["strata", "independent"], (reads, kinds)
