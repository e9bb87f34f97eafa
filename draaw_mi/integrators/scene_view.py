"""What V4 reads of a scene on the host before each render, found once per scene.

Why: a frozen replay (:meth:`Session.recording <draaw_mi.rendering.session.Session.recording>`) is preceded by V4's
``freeze_state``: the light-selection table's key and the edge map's key (camera, film,
emitting surfaces). Right after a render's kernels every call into Mitsuba runs 5-20 times
slower than warm (cold caches: ``scene.sensors()`` 16-26 us, ``scene.emitters()`` 18 us, against 1.4 us
warm), so
the number of calls, not their warm cost, sets the price. The parts of a scene that cannot
change while it lives -- its first sensor and film, its emitters, the film's filter, whether
the sensor samples an aperture -- are looked up here once; what parameters can change (the
camera's transform, the film's size and crop window, the shutter, the emitting shapes'
bounds) is still read on every render.

Where a view is kept: in a ``memo`` dict that lives exactly as long as the scene -- the
renderer's state for a :class:`~draaw_mi.scene.DraawScene` (:func:`draaw_mi.rendering.frozen.freeze_render`
passes it). The view holds the scene itself, so its ``id`` names it for as long as the memo
holds the view; an integrator's own caches never hold a view (a held scene keeps its Python
BSDFs alive). Without a memo (a bare ``mi.Scene``) a view is made for each call: as many
calls as without one, no saving.
"""
from __future__ import annotations

import mitsuba as mi


def emitters_key(scene: mi.Scene, emitter_array=None, emitters=None) -> tuple:
    """``(id(scene), JIT index of its emitter array, emitter addresses)``: the key of V4's
    light-selection tables (``emitter_array`` / ``emitters``: the scene's, if already at hand).
    A rebuilt emitter array or another set of emitters gives another key."""
    emitter_array = scene.emitters_dr() if emitter_array is None else emitter_array
    emitters = scene.emitters() if emitters is None else emitters
    return id(scene), emitter_array.index, tuple(e.ptr for e in emitters)


class SceneView:
    """The fixed host-side parts of one scene (see the module docstring).

    ``key``: the light-selection table's key (:func:`emitters_key`, as
    :meth:`DraawV4Integrator.selection_key
    <draaw_mi.integrators.light_tables.LightTables.selection_key>`); ``emitter_array``: the
    array (a cache entry that holds it keeps its index from going to another scene);
    ``sensor`` / ``film``: the first sensor and its film (``None`` without sensors);
    ``no_aperture``: whether that sensor samples no aperture (emission splitting needs it);
    ``emitting_shapes``: the emitters' shapes (area lights).
    """
    __slots__ = ("scene", "key", "emitter_array", "sensor", "film", "no_aperture",
                 "emitting_shapes")

    def __init__(self, scene: mi.Scene):
        emitters = list(scene.emitters())
        self.scene = scene
        self.emitter_array = scene.emitters_dr()
        self.key = emitters_key(scene, self.emitter_array, emitters)
        sensors = scene.sensors()
        self.sensor = sensors[0] if sensors else None
        self.film = None if self.sensor is None else self.sensor.film()
        self.no_aperture = self.sensor is not None and not self.sensor.needs_aperture_sample()
        self.emitting_shapes = tuple(sh for sh in (e.get_shape() for e in emitters) if sh is not None)

    def emitter_bounds(self) -> tuple:
        """The emitting shapes' bounding boxes now (params can move them), as
        ``(min..., max...)`` tuples."""
        boxes = (shape.bbox() for shape in self.emitting_shapes)
        return tuple(tuple(b.min) + tuple(b.max) for b in boxes)


def scene_view(scene: mi.Scene, memo: dict | None = None) -> SceneView:
    """The :class:`SceneView` of ``scene``: from ``memo`` (a dict that lives as long as the
    scene; see the module docstring), made and stored there if absent; made anew without one.

    >>> import mitsuba as mi
    >>> scene = mi.load_dict(mi.cornell_box())
    >>> memo = {}
    >>> view = scene_view(scene, memo)
    >>> scene_view(scene, memo) is view, scene_view(scene) is view
    (True, False)
    >>> len(view.emitting_shapes), view.no_aperture, view.key == scene_view(scene).key
    (1, True, True)
    """
    if memo is None:
        return SceneView(scene)
    view = memo.get(id(scene))
    if view is None or view.scene is not scene:
        view = memo[id(scene)] = SceneView(scene)
    return view
