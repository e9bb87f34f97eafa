"""render.sampler: Mitsuba's samplers on request, passes a sampler takes exactly, clear errors."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.errors import DraawError
from conftest import tiny_description

from draaw_mi.rendering import session as S
from draaw_mi.rendering.passes import pass_seeds, sample_passes
from draaw_mi.rendering.session import session_of


def _sampler_name(scene) -> str:
    return str(scene.mi_scene.sensors()[0].sampler()).split("[")[0].strip()


def test_default_is_independent_and_the_setting_reaches_the_sensor():
    assert _sampler_name(draaw_mi.load_scene(tiny_description())) == "IndependentSampler"
    s = draaw_mi.load_scene(tiny_description(sampler="multijitter"))
    assert _sampler_name(s) == "MultijitterSampler" and s.settings["sampler"] == "multijitter"
    o = draaw_mi.load_scene(tiny_description(), sampler="ldsampler")      # keyword override
    assert _sampler_name(o) == "LowDiscrepancySampler"
    assert _sampler_name(o.with_resolution(16, 12)) == "LowDiscrepancySampler"


@pytest.mark.parametrize("sampler, spp, kept", [("ldsampler", 5, 16), ("orthogonal", 5, 9),
                                                ("multijitter", 5, 6), ("ldsampler", 16, 16)])
def test_a_scene_with_a_rounding_sampler_loads_without_mitsubas_log_line(sampler, spp, kept):
    """`--sampler ldsampler --spp 5` printed Mitsuba's raw "WARN [LowDiscrepancySampler] ...
    rounding to 16" at load (the render then takes 8 samples in passes the sampler keeps, and
    says so): the sensor is built with the count the sampler keeps."""
    said = []

    class Recorder(mi.Appender):
        def append(self, level, text):
            said.append(text)

        def log_progress(self, *args):
            pass

    recorder = Recorder()
    mi.logger().add_appender(recorder)
    try:
        scene = draaw_mi.load_scene(tiny_description(sampler=sampler, spp=spp))
    finally:
        mi.logger().remove_appender(recorder)
    assert [t for t in said if "ampler" in t] == []
    assert scene.mi_scene.sensors()[0].sampler().sample_count() == kept
    mi.logger().add_appender(recorder)
    try:
        mi.load_dict({"type": sampler, "sample_count": spp})     # (the recorder hears Mitsuba's line)
    finally:
        mi.logger().remove_appender(recorder)
    assert len(said) == (0 if kept == spp else 1)


def test_bad_sampler_names_fail_with_the_choices():
    with pytest.raises(DraawError, match=r"render.sampler.*'sobol'.*multijitter"):
        draaw_mi.load_scene(tiny_description(sampler="sobol"))
    with pytest.raises(DraawError, match="sampler"):
        draaw_mi.load_scene(tiny_description(), sampler="sobol")
    mitsuba_scene = draaw_mi.load_scene(tiny_description()).mi_scene
    with pytest.raises(DraawError, match="cannot override the sampler of a Mitsuba scene"):
        draaw_mi.load_scene(mitsuba_scene, sampler="multijitter")


@pytest.mark.parametrize("sampler", ["multijitter", "ldsampler", "stratified", "independent"])
def test_passes_are_counts_the_sampler_takes(sampler):
    scene = draaw_mi.load_scene(tiny_description(sampler=sampler)).mi_scene
    base = scene.sensors()[0].sampler()
    for spp in (1, 5, 7, 32, 100, 128, 300):
        for pass_spp in (16, 256):
            passes = sample_passes(scene, spp, pass_spp)
            for k in passes:
                f = base.fork()
                f.set_sample_count(k)
                assert int(f.sample_count()) == k, (sampler, spp, passes)     # rendered as said
                assert k <= max(pass_spp, 4)
            if sampler == "ldsampler":                    # takes nothing below 4: rounds up
                assert 0 <= sum(passes) - spp < 4
            else:
                assert sum(passes) == spp, (sampler, spp, passes)
    if sampler == "independent":
        assert sample_passes(scene, 40, 16) == [16, 16, 8]


def test_a_rounded_count_renders_as_a_mean_of_exact_passes():
    """multijitter would render 35 samples for 32: render() draws 30 + 2 in two passes, and the
    image is their spp-weighted mean with the pass seeds (what info reports)."""
    scene = draaw_mi.load_scene(tiny_description(sampler="multijitter"))
    img, info = draaw_mi.render(scene, version="path", spp=32, seed=3, post=[], return_info=True)
    assert info["spp"] == 32 and info["passes"] == 2
    integ = mi.load_dict({"type": "path", "max_depth": 4})
    s0, s1 = pass_seeds(3, 2)
    manual = (30 * np.array(mi.render(scene.mi_scene, integrator=integ, spp=30, seed=s0))
              + 2 * np.array(mi.render(scene.mi_scene, integrator=integ, spp=2, seed=s1))) / 32
    np.testing.assert_allclose(np.array(img), manual, rtol=1e-5, atol=1e-6)


def test_multijitter_lowers_the_variance():
    """Per-pixel variance over independent renders: multijitter well below the independent
    sampler at 16 spp (measured 0.1-0.5x on the speed suite); the means agree (both unbiased).
    V4 samples an independent-sampler scene with the orthogonal pattern (``stratify``, on by
    default; 16 spp as 9 + 4 stratified and 3 independent samples): its variance there is also
    well below the independent sampler's, which it has with ``stratify`` off."""
    def stack(sampler, **options):
        scene = draaw_mi.load_scene(tiny_description(sampler=sampler, resolution=[16, 12]))
        return np.stack([np.array(draaw_mi.render(scene, version="v4", spp=16, seed=s, post=[],
                                                  integrator_options=options or None))
                         for s in range(12)])
    mj, ind, own = stack("multijitter"), stack("independent", stratify=False), stack("independent")
    v_mj, v_ind, v_own = (a.var(0, ddof=1).mean() for a in (mj, ind, own))
    assert v_mj < 0.7 * v_ind and v_own < 0.7 * v_ind, (v_mj, v_own, v_ind)
    for a in (mj, own):
        se = np.sqrt((a.var(0, ddof=1) + ind.var(0, ddof=1)).mean() / 12 / a[0].size)
        assert abs(a.mean() - ind.mean()) < 4 * se


def test_pass_plans_remembered_per_scene_equal_fresh_ones(monkeypatch):
    """The session remembers a scene's pass plan per (spp, pass_spp) for Mitsuba's samplers: each
    plan must be the one sample_passes makes for that pair, and render() must follow it."""
    scene = draaw_mi.load_scene(tiny_description(sampler="multijitter"))
    pairs = [(32, 256), (32, 16), (40, 16), (7, 256)]
    for _ in range(2):                                    # made, then remembered
        for spp, pass_spp in pairs:
            got = session_of(scene).sample_passes(spp, pass_spp)
            assert got == sample_passes(scene.mi_scene, spp, pass_spp), (spp, pass_spp)
    asked = []
    real = S.sample_passes                   # what the session asks when it has no plan
    monkeypatch.setattr(S, "sample_passes", lambda *a: asked.append(a[1:]) or real(*a))
    _, info = draaw_mi.render(scene, version="path", spp=32, pass_spp=16, seed=1, post=[],
                              return_info=True)
    assert not asked and info["passes"] == 2 and info["spp"] == 32     # from the memo: [16, 16]


def test_the_progress_lines_count_the_samples_taken(capsys):
    """ldsampler takes 8 samples for 5: the progress read "8/5 spp (160 %)" (its total was the
    request, not the samples the passes take)."""
    scene = draaw_mi.load_scene(tiny_description(sampler="ldsampler"))
    _, info = draaw_mi.render(scene, version="path", spp=5, progress="lines", return_info=True)
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert info["spp"] == 8 and last.startswith("render path: 8/8 spp (100 %)"), last
