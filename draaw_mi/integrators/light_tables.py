"""``draaw_v4``'s light-selection tables, cached per scene: the learned one of
:mod:`~.light_pilot`, or the power table, or none (uniform).

:class:`LightTables` is a link in ``draaw_v4``'s class chain (Mitsuba's integrators are
nanobind types, which take one base class, so it cannot be a mixin): ``DraawV4Integrator``
derives from it, it from :class:`~.emission_split.EmissionSplitting`.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .emission_split import EmissionSplitting
from .light_pilot import learn_selection, pilot_paths
from .sampling import PowerSelection
from .scene_view import emitters_key


#: the emitter plugins whose powers ``auto`` compares: lights of one of these kinds alone
POWER_KINDS = ({"AreaLight"}, {"PointLight"})


def one_kind_of_light(scene) -> bool:
    """Whether ``scene``'s emitters are all area lights or all point lights (their powers then
    rank what they give the scene; a spot's cone or a sun's direction would not).

    >>> import mitsuba as mi
    >>> pts = {f"p{i}": {"type": "point", "position": [i, 1, 0]} for i in range(2)}
    >>> one_kind_of_light(mi.load_dict({"type": "scene", **pts}))
    True
    >>> one_kind_of_light(mi.load_dict({"type": "scene", **pts, "s": {"type": "spot"}}))
    False
    """
    return {e.class_name() for e in scene.emitters()} in POWER_KINDS


def describe_selection(scene, light_selection: str = "auto") -> str:
    """How ``draaw_v4`` with ``light_selection`` picks the light its next-event estimation
    samples in ``scene``, in words (``draaw-mi info``).

    >>> import mitsuba as mi
    >>> pts = {f"p{i}": {"type": "point", "position": [i, 1, 0], "intensity": 1.0 + 9 * i} for i in range(2)}
    >>> describe_selection(mi.load_dict({"type": "scene", **pts}))
    'by power (2 point lights of different powers)'
    >>> describe_selection(mi.load_dict({"type": "scene", **pts, "s": {"type": "spot"}}))
    'by a table a pilot of 2^16 camera paths learns before the first render (3 lights of different kinds)'
    """
    emitters = scene.emitters()
    n = len(emitters)
    if n < 2:
        return "one light: nothing to choose"
    if light_selection == "uniform":
        return "uniformly (light_selection=uniform)"
    power = PowerSelection.of(scene)
    one_kind = one_kind_of_light(scene)
    kind = emitters[0].class_name() if one_kind else None
    lights = f"{n} {'area lights' if kind == 'AreaLight' else 'point lights' if kind == 'PointLight' else 'lights'}"
    if any(mi.has_flag(e.flags(), mi.EmitterFlags.Infinite) for e in emitters):
        why = ", an environment among them"
    elif not one_kind:
        why = " of different kinds"
    else:
        why = " of different powers" if power is not None else " of similar powers"
    if light_selection == "power" or (light_selection == "auto" and _keeps_power(one_kind, power)):
        return f"by power ({lights}{why})" if power is not None else f"uniformly ({lights}{why})"
    return (f"by a table a pilot of 2^{pilot_paths(scene).bit_length() - 1} camera paths learns "
            f"before the first render ({lights}{why})")


def _keeps_power(one_kind: bool, power) -> bool:
    """``auto``'s rule: the power table where it exists (the powers differ, no environment)
    and the lights are of one kind (:func:`one_kind_of_light`)."""
    return one_kind and power is not None


class LightTables(EmissionSplitting):
    """The tables, by :meth:`selection_key`: ``light_selection`` says which (``auto``,
    ``learned``, ``power``, ``uniform``), ``_tables`` maps the key to ``(emitter array, table |
    None, learned)``, ``_frozen_selection`` holds a pilot's or a recording's table while it
    runs. The subclass sets those three (and ``_light_sums``, which the pilot fills) in its
    constructor, traces the pilot's paths with its own ``sample``
    (:func:`~.light_pilot.learn_selection`), and has ``features(scene)`` and ``guides`` (its
    :class:`~.guide_cache.GuideCache`)."""

    def emitter_selection(self, scene):
        """:class:`~.sampling.PowerSelection` of ``scene`` (cached), or ``None`` for uniform:
        the table :meth:`prepare_selection` learned, else the power table. Never runs the
        pilot (it is called while the render is being traced)."""
        return self._table(scene, learn=False)

    def prepare_selection(self, scene):
        """With ``auto`` / ``learned`` selection, run the light pilot for ``scene`` unless its
        table is learned already (outside any recording: the pilot reads its result back), and
        return the table. Called before primal renders and by ``draaw_v4``'s
        :meth:`~draaw_mi.integrators.v4.DraawV4Integrator.freeze_state`; adjoint passes reuse
        the table of their primal."""
        return self._table(scene, learn=True)

    def _table(self, scene, learn: bool, key: tuple | None = None):
        if self._frozen_selection is not None:
            return self._frozen_selection[0]           # the pilot's or a recording's table
        if self.light_selection == "uniform":
            return None
        if dr.flag(dr.JitFlag.FreezingScope):
            # a recording made without ``freeze_state`` (emitter values cannot be read
            # while recording): uniform selection, unbiased too
            return None
        key = self.selection_key(scene) if key is None else key
        entry = self._tables.get(key)
        learns = learn and self.light_selection in ("auto", "learned")
        if entry is not None and (entry[2] or not learns):
            return entry[1]                            # learned, or not asked to learn
        power = PowerSelection.of(scene) if entry is None else entry[1]
        # ``auto`` keeps a power table only among lights of one kind that emit alike (all area
        # lights, or all point lights): a spot's power, or a point's beside an area light's,
        # says little about what each gives the surfaces in view (a spot aimed at the objects
        # in view, an area light over a wide floor: power selection 2.4x uniform selection's
        # variance, learned 1x; see light_pilot)
        if not learns or (self.light_selection == "auto" and _keeps_power(one_kind_of_light(scene), power)):
            if entry is not None:
                return entry[1]                        # (the power table stored before)
            return self._store(key, scene, power, learned=False)
        sel = None if self.features(scene)["media"] else learn_selection(self, scene)
        return self._store(key, scene, sel if sel is not None else power, learned=True)

    def _store(self, key, scene, sel, learned: bool):
        # Cached per scene without holding it (a held scene keeps its Python BSDFs alive, and
        # every live instance enlarges BSDF calls and must enter dr.freeze recordings). The
        # entry holds the scene's emitter array instead: while it is held, its JIT index (part
        # of the key) cannot be given to another scene's array, so a dead scene's table is
        # never found for a new one.
        if len(self._tables) >= 4:
            self._tables.pop(next(iter(self._tables)))
        self._tables[key] = (scene.emitters_dr(), sel, learned)
        return sel

    def forget_scene(self, scene, learned: bool = False) -> None:
        """Drop ``scene``'s cached power table (its lights changed): the next render computes
        it anew. :meth:`Session.scene_changed <draaw_mi.rendering.session.Session.scene_changed>` calls this. A learned table stays
        (see :mod:`~.light_pilot`) unless ``learned``."""
        for key in [k for k, e in self._tables.items() if k[0] == id(scene) and (learned or not e[2])]:
            del self._tables[key]
        if learned:
            self.guides.forget(id(scene))

    def selection_state(self, scene):
        """``scene``'s light-selection entry as it is now (opaque; None before its first
        render), for :meth:`restore_selection`: a fit whose captures switch lights keeps one
        learned table per capture instead of a pilot per render."""
        return self._tables.get(self.selection_key(scene))

    def restore_selection(self, scene, state) -> None:
        """Use ``state`` (from :meth:`selection_state` of this scene) for ``scene`` again."""
        key = self.selection_key(scene)
        if state is None:
            self._tables.pop(key, None)
        else:
            self._tables[key] = state

    @staticmethod
    def selection_key(scene) -> tuple:
        """Key of ``scene``'s table in the cache: ``(id(scene), JIT index of its emitter array,
        emitter addresses)``, all read on the host. (Registry ids read from the device cost a
        synchronisation with the last render's kernels: about 0.1 ms per frozen render.)"""
        return emitters_key(scene)
