"""Guided paths in draaw_v4 (``integrators/guiding.py``): a grid of directional histograms
learned from a training pass, sampled in a one-sample mixture with the BSDF. Whatever the
guide learned, the image keeps ``path``'s expectation; "auto" guides only where the light
arrives indirectly; gradient passes sample the BSDF alone and still match finite differences."""
from __future__ import annotations

import numpy as np
import pytest
from integrators_helpers import (
    ad_gradient,
    check_same_expectation,
    fd_gradient,
    integrator,
    mi,
    render_np,
    rs,
    seed_stack,
)

from draaw_mi.bench import suite as ss
from draaw_mi.integrators import adaptive_sampling, guiding, spp_map


@pytest.fixture(scope="module")
def panel():
    """The speed suite's floor lit only through a glossy metal panel, at 16x16."""
    return ss.load("glossy_diffuse", 16)


def test_guided_renders_keep_paths_expectation(panel):
    """Per pixel over 12 seeds at 256 spp ("on": every render guided, every pixel alike).
    Leaving the guide's density out of the MIS weights against next-event estimation (or
    weighting a guided sample by the BSDF's pdf alone) moves the image by many errors."""
    integ = integrator("draaw_v4", max_depth=5, guiding="on")
    K = 12
    v4 = seed_stack(panel, integ, 256, range(K))
    assert integ.guides.share(integ.selection_key(panel)) == 1.0      # "on": learned
    ref = seed_stack(panel, integrator("path", max_depth=5), 256, range(100, 100 + K))
    assert np.isfinite(v4).all()
    check_same_expectation(ref, v4, max_frac3=0.03)


def test_guided_cornell_box_keeps_paths_expectation():
    """The Cornell box forced to guide: its light is found by next-event estimation and by
    guided or BSDF-sampled hits alike, so MIS weights that leave the guide's density out of
    the light samples' weights count its light wrongly."""
    scene = mi.load_dict(rs.cornell_draaw(res=16, spp=4))
    K = 12
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=4, guiding="on", hide_emitters=True), 256, range(K))
    ref = seed_stack(scene, integrator("path", max_depth=4, hide_emitters=True), 256, range(100, 100 + K))
    check_same_expectation(ref, v4)


def test_guiding_with_area_lights_and_glass_keeps_the_expectation():
    """The feature scene (glass, a rough conductor, textures, area and point lights, an
    environment map) forced to guide: delta lobes are never guided, MIS against every light."""
    scene = mi.load_dict(rs.feature_scene(res=10, spp=16, point=True, envmap=True, texture=True,
                                          glass=True, conductor=True))
    K = 12
    v4 = seed_stack(scene, integrator("draaw_v4", max_depth=4, guiding="on"), 128, range(K))
    ref = seed_stack(scene, integrator("path", max_depth=4), 128, range(100, 100 + K))
    check_same_expectation(ref, v4, max_frac3=0.03)


def test_guiding_lowers_the_error_behind_the_panel():
    """At 32x32 and 64 spp the guided render's squared error against a 2048-spp ``path``
    reference is well under the unguided V4's (measured 0.45x at 64x64)."""
    scene = ss.load("glossy_diffuse", 32)
    ref = np.mean([np.array(mi.render(scene, integrator=integrator("path", max_depth=5), spp=512,
                                      seed=900 + s)) for s in range(4)], 0)
    err = {}
    for mode in ("on", "off"):
        integ = integrator("draaw_v4", max_depth=5, guiding=mode)
        err[mode] = np.mean([np.mean((np.array(mi.render(scene, integrator=integ, spp=64, seed=s)) - ref) ** 2)
                             for s in range(6)])
    assert err["on"] < 0.75 * err["off"], err


@pytest.mark.parametrize("name, guided", [("glossy_diffuse", True), ("cornell", False)])
def test_adaptive_samplings_pilot_decides_on_guiding(name, guided, monkeypatch):
    """An adaptive "auto" render reads the indirect share from its pilot's extra per-pixel sum
    (no pilot of its own runs): within 0.05 of :func:`guiding.indirect_share`'s 2^15 paths
    (measured 0.000 / 0.008 apart: 1.000 / 0.225); the guided main pass samples every pixel
    alike; only that first pilot carries the extra loop variable. Taking the light after the
    second vertex for the first's (``depth == 1``) puts the panel at 0.15; a pilot that never
    calls ``decide`` leaves no share; asking every pass (the flag shadowed by a helper of the
    same name in ``_pass_sums``) fails the list of passes. The scene's second render (V4 now
    renders it stratified, not adaptively) is guided where the first decided so: a decided
    scene looked up only from the separate pilot's 2^21 samples rendered the panel unguided."""
    scene = ss.load(name, 32)
    monkeypatch.setattr(guiding, "PILOTED_MIN_SAMPLES", 1)         # at 32x32, 64 spp
    separate = guiding.indirect_share
    monkeypatch.setattr(guiding, "indirect_share", lambda *a, **k: pytest.fail("a separate pilot ran"))
    allocations = []
    allocate = adaptive_sampling.allocate
    monkeypatch.setattr(adaptive_sampling, "allocate", lambda *a, **k: allocations.append(1) or allocate(*a, **k))
    integ = integrator("draaw_v4", max_depth=5)
    asked = []                    # whether each traced pass gathered the first vertex's light
    with_guide = []               # ... and whether it had a guide
    sample = integ.sample
    monkeypatch.setattr(integ, "sample", lambda *a, **k: asked.append(integ.want_first)
                        or with_guide.append(integ._guide is not None) or sample(*a, **k))
    img = render_np(scene, integ, 64, 0)
    assert asked[0] and True not in asked[1:]    # the pilot only (then training, main pass)
    n = len(asked)
    render_np(scene, integ, 64, 1)
    assert len(asked) > n and True not in asked[n:]   # decided: no pass asks again
    assert set(with_guide[n:]) == {guided}, with_guide[n:]
    key = integ.selection_key(scene)
    share = integ.guides.share(key)
    assert share is not None and np.isfinite(img).all()
    assert abs(share - separate(integ, scene, 1 << 15)) < 0.05, share
    assert (share >= guiding.SHARE_MIN) == guided
    assert (integ.guides.guide(integ, scene, key) is not None) == guided
    if guided:
        assert allocations == []                 # the guided main pass: uniform


def test_the_pilot_records_every_strideth_path_with_its_own_radiance():
    """A 2-spp pilot of the Cornell box recording every second lane (its pixels' even samples): each record's
    final radiance is its pixel's even sample (the pilot's sums less its odd ones), exactly,
    and no vertex of a path holds more light than the path ends with. Recording lane ``i``
    as path ``i`` (not ``i // 2``), or keeping the odd lanes' radiance, fails both."""
    scene = ss.load("cornell", 16)
    integ = integrator("draaw_v4", max_depth=5)
    sensor = scene.sensors()[0]
    h, w = sensor.film().crop_size()[::-1]
    rec = guiding.Records(h * w, 5, stride=2)
    sums, _ = spp_map.pass_sums(integ, scene, sensor, 2, 5, False, False, pilot=True,
                                           record=rec)
    rgb, odd = sum(np.array(c, np.float64) for c in sums[:3]), np.array(sums[-3], np.float64)
    L_end = np.array(rec.L_end, np.float64)
    assert np.count_nonzero(L_end) > 0.5 * h * w
    assert np.allclose(3.0 * L_end, rgb - odd, rtol=1e-4, atol=1e-6)
    L = np.array(rec.L, np.float64).reshape(h * w, 5)
    valid = np.array(rec.valid()).reshape(h * w, 5)
    assert valid[:, 0].mean() > 0.5                      # (the box's walls: 0.89)
    assert np.all(L[valid] <= np.repeat(L_end[:, None], 5, 1)[valid] * (1 + 1e-5) + 1e-6)


def test_the_pilots_paths_train_the_guide_without_a_pass_of_their_own(monkeypatch):
    """Where the pilot has as many paths as the training takes (32x32 at 64 spp: 4,096 pilot
    paths, the training 2,048 once its floor is lowered), the guide learns from every second
    of them alone: no separate camera pass. Their records reach each depth as often as a
    camera pass's (2^14 paths): the share of paths with a record at depth k agrees within
    0.04 (sd 0.01 at 2,048 paths; measured 0.000-0.020 apart over four seeds). Not recording
    the pilot runs the camera pass; recording only its paths' first vertices leaves the
    deeper depths empty. (Each record's own radiance: the test above.)"""
    scene = ss.load("glossy_diffuse", 32)
    monkeypatch.setattr(guiding, "PILOTED_MIN_SAMPLES", 1)
    monkeypatch.setattr(guiding, "MIN_TRAIN_PATHS", 1)
    traced = []
    trace = guiding._trace
    monkeypatch.setattr(guiding, "_trace", lambda *a, **k: traced.append(a[2]) or trace(*a, **k))
    taught = []
    learn = guiding.learn_guide
    monkeypatch.setattr(guiding, "learn_guide", lambda *a, **k: taught.append(a[3]) or learn(*a, **k))
    integ = integrator("draaw_v4", max_depth=5)
    img = render_np(scene, integ, 64, 0)
    assert np.isfinite(img).all()
    assert traced == [] and len(taught) == 1 and taught[0].n == 2048 and taught[0].stride == 2
    assert integ.guides.guide(integ, scene, integ.selection_key(scene)) is not None

    def reached(rec):            # per depth: the share of paths with a record there
        return np.array(rec.valid()).reshape(rec.n, rec.depth).mean(0)
    pilot, camera = reached(taught[0]), reached(trace(integ, scene, 1 << 14, 3))
    assert camera[1] > 0.2 and np.abs(pilot - camera).max() < 0.04, (pilot, camera)


def test_the_pilot_records_only_a_whole_training():
    """The pilot's paths are recorded only where they are the whole training (one batch of
    at most 2^16 paths, no more than the pilot has), every stride-th lane: at 128^2 and
    64 spp the training's 32,768 of the pilot's 65,536 lanes; at 256^2 (131,072, two
    batches) and at 1024^2 none, where their 12 MiB raised a 256-spp render's peak to 1.27x
    ``path``'s for a training pass 1/6 shorter. Recording a first batch at any size fails."""
    from draaw_mi.integrators.guide_cache import PilotDecision
    scene = ss.load("glossy_diffuse", 16)
    integ = integrator("draaw_v4", max_depth=5)

    def records(res, spp):
        d = PilotDecision(integ.guides, integ, scene, integ.selection_key(scene), spp * res * res)
        return d.records(max(2, spp // 16) * res * res)
    rec = records(128, 64)
    assert rec.n == 32768 and rec.stride == 2 and rec.depth == 5
    assert records(256, 64) is None and records(1024, 256) is None
    assert records(64, 64) is None              # the training's floor: more paths than the pilot has
    assert records(181, 64).n == 65522          # all the training's paths, one lane in two
    assert records(128, 100).n == 49152         # 6 spp of 98,304 lanes for 51,200: one batch at most


def test_a_first_render_decided_by_the_pilot_keeps_paths_expectation(panel, monkeypatch):
    """Each seed a fresh integrator, so each render is the scene's first: an unguided pilot of
    spp/16 decides (its share 1.0) and teaches the guide, then a guided uniform render of the
    other samples, which shares among 2x2 tiles, is the image (the pilot's unguided image left
    out). Popping the pilot's first sum for the decision instead of its last (``sums.pop(0)``:
    the red channel) puts 32 % of pixels beyond 3 sigma."""
    monkeypatch.setattr(guiding, "PILOTED_MIN_SAMPLES", 1)
    K = 12
    integs = [integrator("draaw_v4", max_depth=5) for _ in range(K)]
    v4 = np.stack([render_np(panel, integ, 256, s) for s, integ in enumerate(integs)])
    for integ in integs:          # each decided by its pilot, and guided
        key = integ.selection_key(panel)
        assert integ.guides.share(key) >= guiding.SHARE_MIN
        assert integ.guides.guide(integ, panel, key) is not None
    # (path at 4x the samples: its per-pixel means are skewed (a firefly lifts both the mean
    # and its error), which against V4's guided, shared renders, with a fifth of its
    # variance, put 5 % of pixels beyond 3 sigma at 256 spp; the image means agree to 1 %)
    ref = seed_stack(panel, integrator("path", max_depth=5), 1024, range(100, 100 + K))
    assert np.isfinite(v4).all()
    check_same_expectation(ref, v4, max_frac3=0.03)


@pytest.mark.parametrize("name, guided", [("glossy_diffuse", True), ("cornell", False)])
def test_auto_guides_where_light_arrives_indirectly(name, guided):
    scene = ss.load(name, 16)
    integ = integrator("draaw_v4", max_depth=5)
    key = integ.selection_key(scene)
    found = integ.guides.guide(integ, scene, key)
    share = integ.guides.share(key)
    assert (share >= guiding.SHARE_MIN) == guided, share
    assert (found is not None) == guided


def test_auto_looks_for_a_guide_only_in_renders_worth_its_pilot():
    """From 64 spp and 2^21 samples (the decision pilot's 2^13 paths, 20-40 ms, at most ~2 %
    of the render), or 2^20 where adaptive sampling's pilot decides at no extra pass: a
    preview, a fit's iteration or a small test render pays no pilot; "on" always guides."""
    small, large = ss.load("glossy_diffuse", 16), ss.load("glossy_diffuse", 96)
    auto = integrator("draaw_v4", max_depth=5)
    wanted = auto.guides.wanted
    assert wanted(large.sensors()[0], 256) and not wanted(large.sensors()[0], 32)   # 2.4M samples
    assert not wanted(large.sensors()[0], 128)                                       # 1.2M
    assert wanted(large.sensors()[0], 128, piloted=True)
    assert not wanted(large.sensors()[0], 64, piloted=True)                          # 0.6M
    assert not wanted(small.sensors()[0], 1024)                   # 262144 samples
    mi.render(small, integrator=auto, spp=64, seed=0)
    assert auto.guides.share(auto.selection_key(small)) is None    # no pilot ran
    on = integrator("draaw_v4", max_depth=5, guiding="on")
    assert on.guides.wanted(small.sensors()[0], 1)
    off = integrator("draaw_v4", max_depth=5, guiding="off")
    assert not off.guides.wanted(large.sensors()[0], 4096)
    mi.render(large, integrator=off, spp=64, seed=0)
    assert off.guides.share(off.selection_key(large)) is None


def test_the_guide_is_bounded(panel):
    integ = integrator("draaw_v4", max_depth=5, guiding="on")
    g = guiding.learn_guide(integ, panel)
    cells = g.res ** 3
    assert 2 <= g.res <= guiding.MAX_GRID
    assert len(g.prob) == len(g.cdf) == cells * guiding.BINS
    assert 8 * guiding.MAX_GRID ** 3 * guiding.BINS <= 64 * 2 ** 20
    p = np.array(g.prob).reshape(cells, guiding.BINS)
    assert np.allclose(p.sum(1), 1.0, atol=1e-5) and (p > 0).all()     # every bin can be drawn


def test_a_sampled_direction_has_the_density_the_guide_reports(panel):
    """Guide.sample's pdf against Guide.pdf of the sampled direction, and the pdf integrating
    to one over the sphere (a histogram of samples against the density)."""
    integ = integrator("draaw_v4", max_depth=5, guiding="on")
    g = guiding.learn_guide(integ, panel)
    n = 1 << 16
    rng = np.random.default_rng(3)
    p = mi.Point3f(*[mi.Float(np.full(n, v, np.float32)) for v in (1.5, 0.1, 0.0)])
    u = mi.Point2f(mi.Float(rng.random(n).astype(np.float32)), mi.Float(rng.random(n).astype(np.float32)))
    d, pdf = g.sample(p, u, mi.Bool(True))
    assert np.allclose(np.array(pdf), np.array(g.pdf(p, d, mi.Bool(True))), rtol=1e-4)
    assert np.allclose(np.linalg.norm(np.array(d), axis=0), 1.0, atol=1e-5)
    # E[1 / pdf] over the guide's samples = the sphere's area
    assert abs(np.mean(1.0 / np.array(pdf)) / (4 * np.pi) - 1.0) < 0.03


def test_light_gradient_with_guiding_on_matches_finite_differences(panel):
    """Reverse mode replays BSDF sampling alone; the finite differences render guided: both
    estimate d(mean image)/d(lamp radiance)."""
    key = "lamp.emitter.radiance.value"
    integ = integrator("draaw_v4", max_depth=4, guiding="on")
    # the full training (TRAIN_PATHS), not the 1/32 of a 16x16 render's samples: a weak guide
    # gives these heavy-tailed renders a skewed spread that six seeds do not average out
    assert integ.guides.guide(integ, panel, integ.selection_key(panel)) is not None
    n = 6
    # (256 spp: light reaches this floor only off the panel, and at 64 spp six seeds' mean
    # of the adjoint swings by 15 % -- seeds 0-5 read 0.000226, 0-11 0.000200 +- 0.000015)
    ad = np.array([ad_gradient(panel, integ, key, 256, s) for s in range(n)])
    fd = np.array([fd_gradient(panel, integ, key, 5.0, 256, 10 + s) for s in range(n)])
    se = np.sqrt(ad.var(ddof=1) / n + fd.var(ddof=1) / n)
    assert np.isfinite(ad).all() and abs(ad.mean() - fd.mean()) <= 4 * se + 1e-8, (ad, fd, se)


def test_training_traces_in_bounded_batches(panel, monkeypatch):
    """The records of a training pass take 32 bytes a vertex: 2^18 paths at once held 48 MiB
    (106 MiB of resident memory while learning, against issue 45's 64); batches of at most
    2^16 camera paths, and of light paths (``benchmarks/guide_memory.py``: a peak of 36 MiB
    over the resident at 256x256, 38 MiB at 1024x1024)."""
    sizes = []
    real = guiding._trace
    monkeypatch.setattr(guiding, "_trace", lambda i, s, n, *a: (sizes.append(n), real(i, s, n, *a))[1])
    integ = integrator("draaw_v4", max_depth=5, guiding="on")
    assert guiding.learn_guide(integ, panel, guiding.TRAIN_PATHS) is not None
    assert max(sizes) <= guiding.CHUNK_PATHS and sum(sizes) == guiding.TRAIN_PATHS
    light = []
    real_light = guiding._light_trace
    monkeypatch.setattr(guiding, "_light_trace", lambda s, n, *a: (light.append(n), real_light(s, n, *a))[1])
    assert guiding.learn_guide(integ, panel, guiding.TRAIN_PATHS) is not None
    assert max(light) <= guiding.CHUNK_PATHS and sum(light) == int(guiding.TRAIN_PATHS * guiding.LIGHT_PER_CAMERA)
    assert guiding._chunks(100_000) == [50_000, 50_000] and sum(guiding._chunks(65_537)) == 65_537


def test_light_paths_record_where_indirect_light_arrives_from(panel):
    """The training's light paths (``_light_trace``) record the floor behind the wall lit from
    the panel: 2^16 paths, their hits there carry power from directions within 26 degrees of
    the panel's centre (measured: 88 % of it; a direction recorded as the ray's, not the
    way back, points into the floor), and hits after the first only (the panel's own
    records, light reflected back onto it, carry 7 % of the floor's power; its first hits,
    straight from the lamp, would carry several times the floor's)."""
    p, d, power, valid = (np.array(a) for a in guiding._light_trace(panel, 1 << 16, 5))
    p, d = p.reshape(3, -1).T, d.reshape(3, -1).T
    assert np.isfinite(power).all() and (power >= 0).all()
    floor = valid & (np.abs(p[:, 1]) < 1e-3) & (p[:, 0] > 0.1)
    to_panel = np.array([2.2, 3.8, 0.0]) - p[floor]
    to_panel /= np.linalg.norm(to_panel, axis=1, keepdims=True)
    near = np.sum(d[floor] * to_panel, axis=1) > 0.9
    assert floor.sum() > 500 and power[floor][near].sum() > 0.7 * power[floor].sum()
    n = np.array([-0.5, -0.87, 0.0]) / np.hypot(0.5, 0.87)
    on_panel = valid & (np.abs((p - np.array([2.2, 3.8, 0.0])) @ n) < 1e-3)
    assert power[on_panel].sum() < 0.25 * power[floor].sum()


def test_the_guide_averages_the_camera_and_light_histograms():
    """Per cell: each histogram normalised, then averaged where both saw light; a cell only
    one of them saw keeps that one's (a cell the light paths missed keeps the camera's)."""
    cam = np.zeros((2, 1, 1, 4))
    light = np.zeros((2, 1, 1, 4))
    cam[0, 0, 0] = [2.0, 2.0, 0.0, 0.0]
    light[0, 0, 0] = [0.0, 0.0, 0.0, 5.0]
    light[1, 0, 0] = [1.0, 0.0, 0.0, 3.0]
    out = guiding._combined(cam, light)
    assert np.allclose(out[0, 0, 0], [0.25, 0.25, 0.0, 0.5])
    assert np.allclose(out[1, 0, 0], [0.25, 0.0, 0.0, 0.75])
    assert not guiding._combined(np.zeros_like(cam), np.zeros_like(light)).any()


def test_the_learned_guide_takes_the_light_paths(panel, monkeypatch):
    """``learn_guide`` merges a light histogram that saw the panel's light into its guide."""
    seen = {}
    real = guiding._combined
    monkeypatch.setattr(guiding, "_combined", lambda c, l: (seen.update(light=l), real(c, l))[1])
    integ = integrator("draaw_v4", max_depth=5, guiding="on")
    assert guiding.learn_guide(integ, panel, 1 << 14) is not None
    assert seen["light"].sum() > 0


def test_a_bad_guiding_value_is_refused_in_one_line():
    from draaw_mi.errors import ParameterError
    # (Mitsuba's plugin loader wraps the error in a RuntimeError that quotes it)
    with pytest.raises((ParameterError, RuntimeError), match=r"draaw_v4: guiding='maybe'; expected 'auto', 'on' or 'off'"):
        integrator("draaw_v4", guiding="maybe")


def test_a_new_guide_renders_with_the_kernels_already_compiled(panel):
    """Two guides over different grids (the second learned from other paths) render through
    the same kernels: the grid's corner, scale and size are opaque values, not literals. As
    literals each new guide compiled its guided render anew, which took a first guided render
    of the glossy panel at 128^2 from 1.1x to 2.1x ``path``'s time."""
    import drjit as dr
    integ = integrator("draaw_v4", max_depth=5, guiding="on")
    key = integ.selection_key(panel)
    render_np(panel, integ, 64, 0)                       # learns a guide, compiles
    first = integ.guides.guide(integ, panel, key)
    integ.guides = type(integ.guides)("on")
    old = guiding.GUIDE_SEED
    try:
        guiding.GUIDE_SEED = old + 12345                 # other training paths: another grid
        second = integ.guides.guide(integ, panel, key)
    finally:
        guiding.GUIDE_SEED = old
    assert not np.allclose(np.ravel(np.array(first.lo, float)), np.ravel(np.array(second.lo, float)))
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()                              # (cleared)
        render_np(panel, integ, 64, 1)
        compiled = [k for k in dr.kernel_history() if k.get("type") == dr.KernelType.JIT and not k.get("cache_hit")]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert compiled == [], [k.get("operation_count") for k in compiled]
