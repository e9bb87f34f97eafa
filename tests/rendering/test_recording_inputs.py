"""What a frozen small render's replay follows (draaw_mi.rendering.frozen): plain-number parameters,
the film size and crop window, textures of another resolution or transform, a Python plugin's
host values and moved geometry; the number of recordings kept. Each replay equals a traced
render of the same state."""
from __future__ import annotations


import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import draaw_mi
from draaw_mi.bench import reference_scenes as rs

from draaw_mi.rendering import frozen as F, session as S
from draaw_mi.rendering.session import session_of


@pytest.fixture(scope="module")
def scene():
    return draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))


@pytest.mark.filterwarnings("error::RuntimeWarning")     # a fallback to tracing fails it
@pytest.mark.parametrize("name, key, values", [
    ("many_lights", "emitter.sampling_weight", (50.0, 0.02, 7.0)),   # path's light choice
    ("glass", "glass.eta", (2.65, 1.2)),                               # a dielectric's IOR
])
def test_replay_follows_plain_number_parameters(monkeypatch, name, key, values):
    """Kernels bake plain-float parameters in as constants (a light's sampling weight, read
    through a virtual-call getter; a dielectric's eta): a plain ``dr.freeze`` of ``mi.render``
    replays the old values (up to 26 and 4.8 off here). render.scene_scalars makes them part
    of the recording's key, so a frozen render equals the traced one after every change."""
    from draaw_mi.bench import suite as ss
    scene = draaw_mi.load_scene(ss.build(name, 16, spp=4))

    def render(freeze, version):
        monkeypatch.setattr(S, "FREEZE", freeze)
        return np.array(draaw_mi.render(scene, version=version, spp=4, seed=3, post=[], max_depth=3))

    first = {v: [render(True, v) for _ in range(3)][-1] for v in ("path", "v4")}
    key = next(k for k in scene.params.keys() if k.endswith(key))
    for value in values:
        scene.params[key] = value
        scene.params.update()
        for version in ("path", "v4") if name == "glass" else ("path",):
            frozen, traced = render(True, version), render(False, version)
            assert np.abs(traced - first[version]).max() > 1e-3           # the change shows ...
            assert np.allclose(frozen, traced, rtol=1e-5, atol=1e-6), (version, value)   # ... replayed too


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("version", ["path", "v4"])
def test_replay_follows_the_film_size_and_crop_window(monkeypatch, version):
    """The film's size and crop window are host-side vectors that the recorded kernels bake
    in: a replay after ``sensor.film.size`` changed returned an image of the old size. Each
    change must give the traced render's image, pixel for pixel."""
    scene = draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))
    params = scene.params

    def render(freeze):
        monkeypatch.setattr(S, "FREEZE", freeze)
        return np.array(draaw_mi.render(scene, version=version, spp=4, seed=3, post=[]))

    for _ in range(3):
        render(True)                                 # recorded and replayed at 16x16
    changes = [({"sensor.film.size": mi.ScalarVector2u(24, 20)}, (20, 24)),
               ({"sensor.film.crop_size": mi.ScalarVector2u(12, 10),
                 "sensor.film.crop_offset": mi.ScalarPoint2u(6, 4)}, (10, 12))]
    for change, shape in changes:
        for key, value in change.items():
            params[key] = value
        params.update()
        traced = render(False)
        assert traced.shape[:2] == shape
        frozen = [render(True) for _ in range(2)]
        for image in frozen:
            assert image.shape == traced.shape
            assert np.allclose(image, traced, rtol=1e-5, atol=1e-6)


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("version", ["path", "v4"])
def test_replay_follows_a_texture_of_another_resolution(monkeypatch, version):
    """An environment map's data swapped for an image of another size: Dr.Jit's key sees the
    tensor's type, not its shape, and the kernels bake the resolution in. The first frozen
    render after the swap records anew (the map's inner layout changed), the second replayed
    the old recording (up to 45 off). Every frozen render must equal the traced one."""
    from draaw_mi.bench import suite as ss
    scene = draaw_mi.load_scene(ss.build("envmap", 16, spp=4))

    def render(freeze):
        monkeypatch.setattr(S, "FREEZE", freeze)
        return np.array(draaw_mi.render(scene, version=version, spp=4, seed=1, post=[]))

    for _ in range(3):
        render(True)
    sky = np.full((16, 32, 3), 0.3, np.float32)
    sky[2:4, 10:12] = 200.0                          # a sun elsewhere, at another resolution
    scene.params["sky.data"] = mi.TensorXf(sky)
    scene.params.update()
    traced = render(False)
    for _ in range(3):
        assert np.allclose(render(True), traced, rtol=1e-5, atol=1e-6)


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("version", ["path", "v4"])
def test_replay_follows_a_texture_transform(monkeypatch, version):
    """A bitmap's ``to_uv`` is a host-side ``ScalarAffineTransform3f`` (neither a number nor a
    Dr.Jit array) that the kernels bake in: a replay after it changed kept the old tiling
    (0.22 off the traced render)."""
    from draaw_mi.bench import reference_scenes as rs
    scene = draaw_mi.load_scene(rs.feature_scene(res=16, spp=4, texture=True))
    key = next(k for k in scene.params.keys() if k.endswith("base_color.to_uv"))

    def render(freeze):
        monkeypatch.setattr(S, "FREEZE", freeze)
        return np.array(draaw_mi.render(scene, version=version, spp=4, seed=1, post=[]))

    for _ in range(3):
        before = render(True)
    scene.params[key] = mi.ScalarAffineTransform3f().scale(mi.ScalarPoint2f(7.0, 7.0))
    scene.params.update()
    traced = render(False)
    assert np.abs(traced - before).max() > 0.05        # the tiling shows at this size
    for _ in range(3):
        assert np.allclose(render(True), traced, rtol=1e-5, atol=1e-6)


class _UvGain(mi.BSDF):
    """A Python BSDF whose albedo comes from a host-side transform it exposes with
    ``cb.put`` (no value type: params.update changes the object in place)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.to_uv = mi.ScalarAffineTransform3f()
        self.m_components = [mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide]
        self.m_flags = self.m_components[0]

    def _albedo(self):
        return 0.2 * self.to_uv.matrix[0, 0]                 # a Python float: baked in

    def sample(self, ctx, si, s1, s2, active=True):
        bs = mi.BSDFSample3f()
        bs.wo = mi.warp.square_to_cosine_hemisphere(s2)
        bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
        bs.eta, bs.sampled_type = 1.0, mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        bs.sampled_component = mi.UInt32(0)
        ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(bs.wo) > 0)
        return bs, dr.select(ok, mi.Spectrum(self._albedo()), 0.0)

    def eval(self, ctx, si, wo, active=True):
        ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
        return dr.select(ok, mi.Spectrum(self._albedo() * dr.inv_pi) * mi.Frame3f.cos_theta(wo), 0.0)

    def pdf(self, ctx, si, wo, active=True):
        ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
        return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def traverse(self, cb):
        cb.put("to_uv", self.to_uv, mi.ParamFlags.NonDifferentiable)


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_replay_follows_a_python_plugins_host_transform(monkeypatch):
    """A host-side value that a Python plugin exposes (``cb.put`` gives it no value type) is
    keyed too: a replay kept the old albedo after the transform changed."""
    mi.register_bsdf("uv_gain_test", lambda props: _UvGain(props))
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=16, height=16)
    d["small-box"]["bsdf"] = {"type": "uv_gain_test"}
    scene = draaw_mi.load_scene(mi.load_dict(d))
    key = next(k for k in scene.params.keys() if k.endswith("to_uv"))

    def render(freeze):
        monkeypatch.setattr(S, "FREEZE", freeze)
        return np.array(draaw_mi.render(scene, version="path", spp=4, seed=1, post=[]))

    for _ in range(3):
        before = render(True)
    scene.params[key] = mi.ScalarAffineTransform3f().scale(mi.ScalarPoint2f(3.0, 3.0))
    scene.params.update()
    traced = render(False)
    assert np.abs(traced - before).max() > 0.05
    for _ in range(2):
        assert np.allclose(render(True), traced, rtol=1e-5, atol=1e-6)


def test_recordings_kept_are_bounded(monkeypatch, capfd):
    """Each value of a plain-number parameter records anew; the oldest recordings are dropped
    beyond ``RECORDINGS_KEPT`` (25 light weights kept 25 recordings, and Dr.Jit warned on
    every render from the tenth on), and a dropped one records again correctly."""
    from draaw_mi.bench import reference_scenes as rs
    monkeypatch.setattr(S, "FREEZE", True)
    scene = draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))
    session = session_of(scene)
    integ = session.integrator("path", scene.settings["max_depth"])
    call = session.recording(integ, 4)
    n = F.RECORDINGS_KEPT + 4
    capfd.readouterr()
    n0 = call.frozen.n_recordings           # the integrator and its recording may be shared
    for i in range(n):
        scene.params["light.emitter.sampling_weight"] = 1.37 + 0.01 * i   # values no other test uses
        scene.params.update()
        call(scene.mi_scene, dr.opaque(mi.UInt32, 1), scene, session)
    assert "has been recorded" not in capfd.readouterr().err      # Dr.Jit's log, on stderr
    assert call.frozen.n_recordings - n0 == n
    assert call.frozen.n_cached_recordings == F.RECORDINGS_KEPT
    scene.params["light.emitter.sampling_weight"] = 1.37       # its recording was dropped
    scene.params.update()
    again = call(scene.mi_scene, dr.opaque(mi.UInt32, 1), scene, session)
    monkeypatch.setattr(S, "FREEZE", False)
    traced = mi.render(scene.mi_scene, integrator=integ, spp=4, seed=1)
    assert np.allclose(np.array(again), np.array(traced), rtol=1e-5, atol=1e-6)


def test_scene_scalars_reads_values_set_through_another_parameter_table(scene):
    """The cached reader follows the objects, not the scene's own parameter table: a value
    changed through a fresh ``mi.traverse`` shows too (and equals the uncached read)."""
    ms = scene.mi_scene
    before = F.scene_scalars(ms, scene, session_of(scene))
    other = mi.traverse(ms)
    key = next(k for k in other.keys() if k.endswith("sensor.far_clip"))
    old = other[key]
    other[key] = 77.0
    other.update()
    try:
        now = F.scene_scalars(ms, scene, session_of(scene))
        assert now != before and 77.0 in now and now == F.scene_scalars(ms)
    finally:
        other[key] = old
        other.update()


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_replay_follows_moved_geometry(scene, monkeypatch):
    """Moving a mesh's vertices rebuilds the acceleration structure: a replay must trace the
    moved mesh, as a traced render does."""
    key = next(k for k in scene.params.keys() if k.endswith("vertex_positions"))
    p = scene.params
    v0 = mi.Float(p[key])
    monkeypatch.setattr(S, "FREEZE", True)
    before = [np.array(draaw_mi.render(scene, version="v1", spp=4, seed=2, post=[])) for _ in range(3)][-1]
    v = dr.unravel(mi.Point3f, v0)
    p[key] = dr.ravel(mi.Point3f(v.x + 0.3, v.y, v.z))
    p.update()
    try:
        frozen = np.array(draaw_mi.render(scene, version="v1", spp=4, seed=2, post=[]))
        monkeypatch.setattr(S, "FREEZE", False)
        traced = np.array(draaw_mi.render(scene, version="v1", spp=4, seed=2, post=[]))
    finally:
        p[key] = v0
        p.update()
    assert np.abs(traced - before).max() > 1e-3
    assert np.allclose(frozen, traced, rtol=1e-5, atol=1e-6)
    # and back: a replay after the mesh returned is the first image again (no stale replay)
    monkeypatch.setattr(S, "FREEZE", True)
    again = np.array(draaw_mi.render(scene, version="v1", spp=4, seed=2, post=[]))
    assert np.allclose(again, before, rtol=1e-5, atol=1e-6)


@pytest.mark.filterwarnings("error::RuntimeWarning")     # a fallback to tracing fails it
def test_volpath_records_after_a_smoke_scene_rendered_with_v4(monkeypatch):
    """V4's majorant tables keep a smoke scene's medium alive after the scene is gone; a
    volpath render of a scene without media then traces medium calls over it, and its
    recording failed ("no such object instance was found in the function's inputs") and fell
    back to tracing with a RuntimeWarning, until the held media became the recording's
    inputs (``volume.held_media``). The replay equals a traced render."""
    import gc
    from draaw_mi.integrators import volume
    monkeypatch.setattr(S, "FREEZE", True)
    volume.release_tables()                         # (earlier tests' smokes: not this test's)
    T = mi.ScalarTransform4f
    smoke = mi.load_dict({
        "type": "scene", "integrator": {"type": "draaw_v4", "max_depth": 4},
        "sensor": {"type": "perspective", "to_world": T().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8}},
        "sky": {"type": "constant"},
        "box": {"type": "cube", "bsdf": {"type": "null"},
                "interior": {"type": "homogeneous", "sigma_t": 2.0, "albedo": 0.9}}})
    mi.render(smoke, spp=4)
    # and a draaw smoke volume (a grid medium with its own hg phase) rendered by V4: held as
    # an input, its medium still broke the recording ("no such object instance ... in the
    # function's inputs"); the failed recording lets the held media go and records again
    from conftest import tiny_description
    d = tiny_description(resolution=[8, 6], spp=1)
    d["volumes"] = [{"name": "v", "mode": "smoke", "density": [[[1.0, 2.0]], [[0.5, 0.0]]], "g": 0.3,
                     "bounds": [[-1, -1, -4], [1, 1, -3]]}]
    draaw_mi.render(draaw_mi.load_scene(d), version="v4", spp=1, post=[])
    del smoke
    gc.collect()
    assert len(volume.held_media()) == 2           # the tables hold the smokes' media
    d = rs.cornell_draaw(res=16, spp=4)
    d["integrator"] = {"type": "volpath", "max_depth": 4}
    plain = draaw_mi.load_scene(d)
    calls = []
    real = F.freeze_render
    monkeypatch.setattr(S, "freeze_render", lambda *a, **k: (calls.append(1), real(*a, **k))[1])
    frozen = [np.array(draaw_mi.render(plain, spp=4, seed=s, post=[])) for s in (1, 1)]
    traced = np.array(mi.render(plain.mi_scene, integrator=mi.load_dict({"type": "volpath", "max_depth": 4}),
                                spp=4, seed=1))
    assert calls and np.allclose(frozen[0], traced, atol=1e-6) and np.array_equal(frozen[0], frozen[1])
