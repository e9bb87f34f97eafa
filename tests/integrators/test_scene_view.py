"""What V4 reads of a scene before each frozen render, found once per scene
(``integrators/scene_view.py``): the view must name the scene it was made for, key the same
light table as a traced render, and leave every changeable input (camera, film, the lights'
bounds) read anew, so the edge map a recording gets is the one a fresh lookup makes."""
from __future__ import annotations


import numpy as np
import pytest

from integrators_helpers import integrator, mi, rs

import draaw_mi
from draaw_mi.integrators import emission_split, scene_view as sv
from draaw_mi.integrators.v4 import DraawV4Integrator

from draaw_mi.rendering import session as S


@pytest.fixture()
def box():
    return mi.load_dict(rs.cornell_draaw(res=32, spp=4))


def fresh_edges(scene) -> np.ndarray:
    """The edge map of the scene's first sensor, made from nothing cached."""
    sensor = scene.sensors()[0]
    rect = emission_split.emitter_rect(scene, sensor)
    return np.array(emission_split.edge_map(scene, sensor, rect, mi.RayFlags.ShadingFrame))


def test_view_keys_the_table_a_traced_render_keys(box):
    """Frozen renders look the light table up by the view's key, traced ones by
    ``selection_key``: the same scene must give the same key (else two tables, one stale)."""
    assert sv.scene_view(box, {}).key == DraawV4Integrator.selection_key(box)
    assert sv.scene_view(box).key == DraawV4Integrator.selection_key(box)


def test_a_view_of_another_scene_under_the_same_id_is_not_used(box):
    """A memo entry whose scene is not the one asked for (a dead scene's id reused) is made
    anew, with this scene's sensor and emitters."""
    other = mi.load_dict(rs.cornell_draaw(res=16, spp=4))
    memo = {id(box): sv.scene_view(other)}
    view = sv.scene_view(box, memo)
    assert view.scene is box and tuple(view.sensor.film().size()) == (32, 32)
    assert memo[id(box)] is view and view.key == DraawV4Integrator.selection_key(box)


def test_frozen_edge_map_follows_camera_film_and_light(box):
    """Through a kept view, each change that moves the emitter's image -- the camera, the
    film's size, the light's own geometry -- gives the map a fresh lookup makes (the view
    keeps the sensor and the shapes, never their state)."""
    integ = integrator("draaw_v4", max_depth=3)
    memo = {}
    params = mi.traverse(box)

    def state_edges():
        edges = integ.freeze_state(box, memo)[1]
        return None if edges is None else np.array(edges)

    first = state_edges()
    assert first is not None and first.any() and (first == fresh_edges(box)).all()
    old_cam = mi.Transform4f(params["sensor.to_world"])
    changes = [("sensor.to_world", mi.Transform4f().translate([0.2, 0.0, 0.0]) @ old_cam),
               ("sensor.film.size", mi.ScalarVector2u(40, 40)),
               ("light.to_world", mi.Transform4f().translate([0.3, 0.0, 0.0]) @ params["light.to_world"])]
    previous = first
    for key, value in changes:
        params[key] = value
        params.update()
        got = state_edges()
        assert got is not None and got.shape == fresh_edges(box).shape, key
        assert (got == fresh_edges(box)).all(), key
        assert got.shape != previous.shape or (got != previous).any(), key   # the change shows
        previous = got
    assert len(memo) == 1                          # one view for the scene throughout


def test_kept_edge_map_follows_a_light_that_grows_from_a_fixed_corner():
    """A rectangle light scaled from 0.3 to 0.6 about its lower-left corner: its box's min
    stays (bit for bit) and only its max moves. The map kept between renders must be the one
    a fresh lookup makes (52 edge pixels); a cache keyed on the bounds' min alone kept the
    small light's 28."""
    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "draaw_v4", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40, "to_world": T().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "wall": {"type": "rectangle", "to_world": T().translate([0, 0, -1]).scale(3), "bsdf": {"type": "diffuse"}},
        "light": {"type": "rectangle", "to_world": T().scale([0.3, 0.3, 1]),
                  "emitter": {"type": "area", "radiance": 5.0}}})
    integ, memo = scene.integrator(), {}
    shape = scene.emitters()[0].get_shape()
    before = shape.bbox()
    first = np.array(integ.freeze_state(scene, memo)[1])
    params = mi.traverse(scene)
    params["light.to_world"] = mi.Transform4f().translate([0.3, 0.3, 0]) @ mi.Transform4f().scale([0.6, 0.6, 1])
    params.update()
    after = shape.bbox()
    assert tuple(after.min) == tuple(before.min) and tuple(after.max) != tuple(before.max)
    kept = np.array(integ.freeze_state(scene, memo)[1])
    fresh = fresh_edges(scene)
    assert fresh.sum() > first.sum()                       # the bigger light shows
    np.testing.assert_array_equal(kept, fresh)


def test_a_thin_lens_camera_gets_no_frozen_edge_map(box):
    """A thin-lens camera samples its aperture: a pixel's rays leave from points across the
    lens, the pinhole probe of the edge map does not say which pixels see a light's edge, and
    splitting is ruled out: frozen_edge_map builds nothing (None; with the aperture test gone
    it built a 12-pixel map) and the view says so; the same scene through a pinhole gets its
    map."""
    d = rs.cornell_draaw(res=32, spp=4)
    d["sensor"].update(type="thinlens", aperture_radius=0.05, focus_distance=3.9)
    lens = mi.load_dict(d)
    integ = integrator("draaw_v4", max_depth=3)
    view = sv.scene_view(lens, {})
    assert integ.frozen_edge_map(lens, view) is None
    assert not view.no_aperture
    assert integ.frozen_edge_map(box, sv.scene_view(box, {})) is not None


def test_render_keeps_one_view_per_scene(monkeypatch):
    """draaw_mi.render hands V4 the scene's memo: repeated frozen renders make the view once."""
    made = []
    real = sv.SceneView.__init__

    def counting(self, scene):
        made.append(id(scene))
        real(self, scene)

    monkeypatch.setattr(sv.SceneView, "__init__", counting)
    monkeypatch.setattr(S, "FREEZE", True)
    scene = draaw_mi.load_scene(rs.cornell_draaw(res=16, spp=4))
    for seed in range(4):
        draaw_mi.render(scene, version="v4", spp=4, seed=seed, post=[])
    assert made.count(id(scene.mi_scene)) == 1, made


def test_doctests():
    import doctest
    res = doctest.testmod(sv)
    assert res.attempted >= 4 and res.failed == 0
