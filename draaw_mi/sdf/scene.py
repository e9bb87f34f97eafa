"""The SDF part of a scene (:class:`SDFScene`) and how the integrators find it (:func:`find`).

Materials are placed in *slots*; each slot gets a hidden proxy shape (one degenerate triangle,
never hit by a ray) that carries the slot's BSDF, so SDF hits are shaded through the ordinary
``si.bsdf()`` path, the BSDF parameters appear in ``mi.traverse`` as for meshes, and the
integrators find the SDF tree from the proxies' ids (``__sdf_<token>_<slot>``) in
:data:`REGISTRY`. :func:`find` returns the :class:`SDFScene` of an ``mi.Scene`` or ``None``.
:data:`REGISTRY` holds its scenes weakly: an :class:`SDFScene` lives as long as its owner (the
``info["sdf"]`` of the loaded :class:`~draaw_mi.scene.DraawScene`), and its entry goes with it
(an ``mi.Scene`` takes neither weak references nor attributes, so it cannot hold them);
:data:`NAMES` keeps the object names of recent tokens, for the error that an ``mi_scene``
whose owner is gone gets.
The ``[[sdf]]`` tables of scene files are read by :mod:`draaw_mi.scene.sdf_dicts`.
"""
from __future__ import annotations

import itertools
import weakref

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, SceneError, suggest
from .node import SDFNode, box, infinite_box, is_infinite

PROXY_PREFIX = "__sdf_"
#: ``{token: SDFScene}`` of the live SDF scenes (weak values: an entry goes with its scene)
REGISTRY: "weakref.WeakValueDictionary[str, SDFScene]" = weakref.WeakValueDictionary()
_TOKENS = itertools.count()
#: ``{token: names of the SDF scene's objects}`` (strings only, held strongly) of the last
#: :data:`NAMES_KEPT` SDF scenes: :func:`find` names the objects of one that is gone
NAMES: dict = {}
NAMES_KEPT = 1024


class SDFScene:
    """The SDF part of a scene: root nodes (implicitly unioned) and material slots.

    ``slots``: material ids (one per slot; the proxy shape ``proxy_ids[i]`` carries slot
    ``i``'s BSDF). ``distance(p)`` / ``eval(p)`` evaluate the union of the roots.
    """
    def __init__(self, roots: list[SDFNode], slots: list[str], nodes: dict | None = None):
        self.roots = list(roots)
        self.slots = list(slots)
        self.nodes = dict(nodes or {n.name: n for r in roots for n in r.nodes()})
        self.token = f"{next(_TOKENS)}x{id(self) & 0xFFFF:x}"
        self.proxy_ids = [f"{PROXY_PREFIX}{self.token}_{i}" for i in range(len(self.slots))]
        REGISTRY[self.token] = self
        NAMES[self.token] = tuple(r.name for r in self.roots)
        while len(NAMES) > NAMES_KEPT:
            NAMES.pop(next(iter(NAMES)))

    def distance(self, p: mi.Point3f) -> mi.Float:
        d = self.roots[0].distance(p)
        for r in self.roots[1:]:
            d = dr.minimum(d, r.distance(p))
        return d

    def eval(self, p: mi.Point3f):
        n = len(self.slots)
        d, w = self.roots[0].eval(p, n)
        for r in self.roots[1:]:
            d2, w2 = r.eval(p, n)
            closer = d2 < d
            d = dr.select(closer, d2, d)
            w = [dr.select(closer, b, a) for a, b in zip(w, w2)]
        return d, w

    def bboxes(self) -> list[mi.ScalarBoundingBox3f]:
        return [r.bbox() for r in self.roots]

    def bbox(self) -> mi.ScalarBoundingBox3f:
        """The box around every root (infinite when one of them is: a plane)."""
        boxes = self.bboxes()
        if any(is_infinite(b) for b in boxes):
            return infinite_box()
        lo = np.min([list(b.min) for b in boxes], axis=0)
        hi = np.max([list(b.max) for b in boxes], axis=0)
        return box(lo, hi)

    def params(self) -> dict:
        """``{"NODE.PARAM": Dr.Jit array}`` of every node (see :meth:`SDFNode.params`)."""
        out: dict = {}
        for r in self.roots:
            out.update(r.params())
        return out

    def set(self, key: str, value) -> None:
        """Set ``"NODE.PARAM"`` (e.g. ``"ball.radius"``) to a number, vector or Dr.Jit array."""
        self.set_many({key: value})

    def set_many(self, values: dict) -> None:
        """Set several ``"NODE.PARAM"`` at once, each node's values checked with each other
        (a round box shrunk to size 0.3 with radius 0.1 is accepted with the size first,
        though the old radius 0.25 does not fit it). On an error nothing has changed."""
        for node, probe, params in self._probes(values):
            for param in params:
                node._assign(param, probe._params[param])

    def check(self, key: str, value) -> None:
        """Raise :class:`~draaw_mi.errors.ParameterError` if :meth:`set` would refuse
        ``value``; nothing changes."""
        self.check_many({key: value})

    def check_many(self, values: dict) -> None:
        """Raise :class:`~draaw_mi.errors.ParameterError` if :meth:`set_many` would refuse
        ``values``; nothing changes."""
        self._probes(values)

    def _probes(self, values: dict) -> list:
        """``[(node, checked copy with the new values, their names)]`` for the nodes that
        ``values`` touch (:meth:`SDFNode.with_values <draaw_mi.sdf.node.SDFNode.with_values>`)."""
        by_node: dict = {}
        for key, value in values.items():
            node, param = self._node(key)
            by_node.setdefault(id(node), (node, {}))[1][param] = value
        return [(node, node.with_values(vals), list(vals)) for node, vals in by_node.values()]

    def param_range(self, key: str) -> tuple:
        """``(low, high)`` of ``"NODE.PARAM"`` for an optimiser's projection
        (:meth:`SDFNode.param_range <draaw_mi.sdf.node.SDFNode.param_range>`)."""
        node, param = self._node(key)
        return node.param_range(param)

    def _node(self, key: str):
        node, _, param = key.partition(".")
        if node not in self.nodes:
            raise ParameterError(f"sdf: no node {node!r}{suggest(node, self.nodes)}")
        return self.nodes[node], param

    def describe(self) -> list[str]:
        """One line per node (roots first, children indented), for ``draaw-mi info``."""
        lines: list[str] = []

        def walk(n, depth):
            lines.append("  " * depth + n.describe())
            for c in n.children():
                walk(c, depth + 1)
        for r in self.roots:
            walk(r, 0)
        return lines


def find(scene: mi.Scene, who: str = "mi.render of an mi_scene with a draaw integrator") -> SDFScene | None:
    """The :class:`SDFScene` placed in ``scene`` (via its proxy shapes), or ``None`` when it has
    no proxy. A :class:`~draaw_mi.errors.SceneError` starting with ``who`` (the call that
    rendered or loaded ``scene``) when it has proxies but their SDF scene is gone (its owner,
    the loaded scene, was let go while its ``mi_scene`` is still rendered): the image would
    silently lose every SDF object."""
    for sh in scene.shapes():
        sid = sh.id()
        if sid.startswith(PROXY_PREFIX):
            token = sid[len(PROXY_PREFIX):].rsplit("_", 1)[0]
            sdf = REGISTRY.get(token)
            if sdf is None:
                names = NAMES.get(token)
                many = names is None or len(names) > 1
                what = "SDF object" + "s" * many + (f" {', '.join(map(repr, names))}" if names else "")
                raise SceneError(f"{who}: the {what} of this mi.Scene {'were' if many else 'was'} freed with the DraawScene "
                                 "that loaded it (only its mi_scene was kept, and an mi.Scene cannot "
                                 "hold them); keep scene = draaw_mi.load_scene(...) and render it (or "
                                 "its mi_scene while scene lives)")
            return sdf
    return None


__all__ = ["NAMES", "PROXY_PREFIX", "REGISTRY", "SDFScene", "find"]
