"""V4's stratified samples (``draaw_mi/integrators/stratify.py``): where the scene's sampler is
``independent``, V4 samples with the ``multijitter`` pattern, in passes of counts it takes
that the film sums; the expectation is ``path``'s (also ``test_v4_filters.py``'s per-filter
tests and every V4 expectation test, which now render stratified)."""
from __future__ import annotations

import numpy as np
import pytest

from integrators_helpers import check_same_expectation, integrator, mi, rs, seed_stack

from draaw_mi.integrators import adaptive_sampling as ads
from draaw_mi.integrators import stratify


def test_passes_are_counts_the_pattern_takes():
    """Every count from 1 to 300 that splits at all: equal passes summing to it, each one a
    multijitter sampler renders as asked (probed afresh, not through ``taken``'s cache)."""
    probe = mi.load_dict({"type": "multijitter"})
    logger = mi.logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)
    try:
        for n in range(1, 301):
            counts = stratify.passes(n)
            if counts is None:
                continue
            assert sum(counts) == n and len(set(counts)) == 1 and len(counts) <= stratify.MAX_PASSES, n
            probe.set_sample_count(counts[0])
            assert probe.sample_count() == counts[0], (n, counts)
    finally:
        logger.set_log_level(level)
    assert [stratify.passes(n) for n in (64, 128, 32, 256)] == [[64], [64, 64], [16, 16], [256]]


def _sampler_kinds(monkeypatch, integ) -> list:
    """The samplers V4's ``prepare`` hands out, by plugin name, appended as they are made."""
    from draaw_mi.integrators.features import sampler_plugin
    kinds = []
    real = type(integ).prepare
    monkeypatch.setattr(type(integ), "prepare", lambda self, *a, **k: (
        lambda r: (kinds.append(sampler_plugin(r[0])), r)[1])(real(self, *a, **k)))
    return kinds


@pytest.mark.parametrize("sampler, options, expected", [
    ("independent", {}, ["multijitter"] * 2),
    ("independent", {"stratify": False}, ["independent"]),
    ("ldsampler", {}, ["ldsampler"]),
])
def test_v4_stratifies_what_the_independent_sampler_would_sample(monkeypatch, sampler, options, expected):
    """A 32-spp render (two passes of 16) of an independent-sampler scene: two multijitter
    passes; ``stratify=False`` or a scene with a sampler of its own: that sampler, one pass."""
    d = rs.cornell_draaw(res=8, spp=4)
    d["sensor"]["sampler"] = {"type": sampler, "sample_count": 4}
    scene = mi.load_dict(d)
    integ = integrator("draaw_v4", max_depth=2, **options)
    kinds = _sampler_kinds(monkeypatch, integ)
    mi.render(scene, integrator=integ, spp=32, seed=1)
    assert kinds == expected


def test_a_gradient_pass_keeps_the_independent_sampler_at_a_count_the_pattern_rounds(monkeypatch):
    """Mitsuba runs a gradient pass as one: at 32 spp (multijitter would render 35) V4's
    adjoint pass keeps the scene's independent sampler; at 16 it is stratified."""
    import drjit as dr
    scene = mi.load_dict(rs.cornell_draaw(res=8, spp=4))
    params = mi.traverse(scene)
    key = "white.base_color.value"
    integ = integrator("draaw_v4", max_depth=2)
    kinds = _sampler_kinds(monkeypatch, integ)
    for spp in (32, 16):
        dr.enable_grad(params[key])
        params.update()
        img = mi.render(scene, params, integrator=integ, spp=spp, seed=2)
        dr.backward(dr.mean(img, axis=None))
        dr.disable_grad(params[key])
    assert kinds == ["multijitter", "multijitter", "independent", "multijitter", "multijitter"], kinds


def test_two_passes_sum_in_the_film_with_paths_expectation():
    """32 spp in two stratified passes against ``path`` per pixel (box filter: Mitsuba's own
    render per pass), and half the variance of one 16-spp pass: a later pass that cleared
    the film (the image would be the last pass alone) or reused the first pass's seed (the
    same samples twice) leaves the 16-spp variance. The film holds the render's image."""
    scene = mi.load_dict(rs.cornell_draaw(res=12, spp=4))
    v4 = integrator("draaw_v4", max_depth=3)
    K = 16
    two = seed_stack(scene, v4, 32, range(K))
    one = seed_stack(scene, v4, 16, range(100, 100 + K))
    ref = seed_stack(scene, integrator("path", max_depth=3), 32, range(200, 200 + K))
    check_same_expectation(ref, two)
    ratio = two.var(0, ddof=1).sum() / one.var(0, ddof=1).sum()
    # measured 0.49; cleared film or one seed: about 1
    assert ratio < 0.7, ratio
    img = np.array(mi.render(scene, integrator=v4, spp=32, seed=5))
    held = np.array(scene.sensors()[0].film().bitmap(), dtype=np.float64)
    np.testing.assert_allclose(held[..., :3], img[..., :3], rtol=1e-5, atol=1e-6)


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


@pytest.mark.parametrize("spp, sampler, said", [
    (64, "independent", "the multijitter pattern in place of the independent sampler, one pass"),
    (32, "independent", "2 passes of 16"),
    (1000, "independent", "independent (the multijitter pattern takes 1000 spp in no 4 equal passes)"),
    (64, "ldsampler", "the scene's ldsampler sampler"),
])
def test_info_says_how_v4_samples(tmp_path, capsys, spp, sampler, said):
    """``draaw-mi info`` names V4's sampling of the scene's render: the pattern and its
    passes, the independent sampler where no passes take the count, or the scene's own."""
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
    ({"type": "draaw", "roughness": 0.3}, ["multijitter"]),
])
def test_glints_of_delta_lights_keep_the_independent_sampler(monkeypatch, bsdf, expected):
    """A point light over a near-mirror floor (the thesis scene's glints: the pattern measured
    2-3x the independent sampler's MSE there) renders with the independent sampler; the
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
    for mode, expected in (("on", ["independent"]), ("off", ["multijitter"])):
        integ = integrator("draaw_v4", max_depth=3, guiding=mode)
        kinds = _sampler_kinds(monkeypatch, integ)
        mi.render(scene, integrator=integ, spp=16, seed=1)
        assert kinds == expected, (mode, kinds)
        monkeypatch.undo()
