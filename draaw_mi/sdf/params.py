"""``draaw_mi.sdf.parameters(scene)``: the scene's ``mi.traverse`` parameters plus its SDF
shape parameters (``"sdf.NODE.PARAM"``), for differentiable renders.

>>> # params = draaw_mi.sdf.parameters(scene)
>>> # dr.enable_grad(params["sdf.ball.radius"]); params.update()
>>> # img = draaw_mi.render(scene, params=params, spp=64); dr.backward(loss(img))
>>> # dr.grad(params["sdf.ball.radius"])

The SDF values are the nodes' own Dr.Jit arrays, so ``dr.enable_grad`` on them reaches the
tracer; assigning ``params["sdf.ball.radius"] = 0.7`` (then ``params.update()``) sets the
node's parameter with the constructor's range checks. The object is a
``mi.SceneParameters`` (``mi.render`` requires one) that delegates every other key to
``mi.traverse(scene)``; optimisers such as ``mi.ad.Adam`` work on it as on Mitsuba's.
"""
from __future__ import annotations

import mitsuba as mi

from ..errors import ParameterError

PREFIX = "sdf."


class SDFParameters(mi.SceneParameters):
    """``base`` (``mi.traverse`` of the scene, made if not given) plus ``"sdf.NODE.PARAM"``."""
    def __init__(self, scene, base=None):
        super().__init__({}, {})
        self._base = mi.traverse(scene.mi_scene) if base is None else base
        self._sdf = scene.sdf
        self._pending: dict = {}        # SDF values set, applied together by update()

    @property
    def base(self) -> mi.SceneParameters:
        """The ``mi.traverse`` parameters under the SDF objects' keys."""
        return self._base

    def _sdf_keys(self):
        return [PREFIX + k for k in self._sdf.params()] if self._sdf is not None else []

    def sdf_name(self, key: str) -> str | None:
        """``"NODE.PARAM"`` when ``key`` is an SDF object's ``"sdf.NODE.PARAM"``, else ``None``."""
        if self._sdf is None or not key.startswith(PREFIX) or key in self._base:
            return None
        name = key[len(PREFIX):]
        return name if name in self._sdf.params() else None

    def _refuse_unknown(self, key: str) -> None:
        """Raise a :class:`ParameterError` naming the unknown node or parameter (and the
        closest known one) when ``key`` is an ``"sdf."`` key of neither the SDF objects nor
        ``mi.traverse``; a bare ``KeyError`` said nothing of what exists."""
        if self._sdf is not None and isinstance(key, str) and key.startswith(PREFIX) and key not in self._base:
            try:
                node, param = self._sdf._node(key[len(PREFIX):])  # (an unknown node raises here)
                node._checked_value(param, 0.0)                   # (an unknown parameter here)
            except ParameterError as e:
                raise ParameterError(f"parameters[{key!r}]: {e}") from None

    def get(self, key, default=None):
        """``self[key]``, or ``default`` for a key it does not hold (an unknown ``"sdf."`` key
        too: ``Mapping.get`` catches only ``KeyError``)."""
        return self[key] if key in self else default

    def keys(self):
        return list(self._base.keys()) + self._sdf_keys()

    def __iter__(self):
        return iter([(k, self[k]) for k in self.keys()])

    def items(self):
        return self.__iter__()

    def __len__(self):
        return len(self.keys())

    def __contains__(self, key):
        return key in self._base or self.sdf_name(key) is not None

    def __getitem__(self, key):
        name = self.sdf_name(key)
        if name is None:
            self._refuse_unknown(key)
            return self._base[key]
        return self._pending[name] if name in self._pending else self._sdf.params()[name]

    def __setitem__(self, key, value):
        """An SDF value takes effect at once when its node accepts it as the node stands;
        one that only fails the node's cross-check (a round box's new size with the radius
        it still has) waits for :meth:`update`, which sets the waiting values together, so
        that a frame's size and radius are checked with each other, in either order."""
        name = self.sdf_name(key)
        if name is not None:
            self._pending.pop(name, None)
            try:
                self._sdf.set(name, value)
            except ParameterError:
                node, param = self._sdf._node(name)
                node._checked_value(param, value)        # out of range on its own: the error
                self._pending[name] = value
        else:
            self._refuse_unknown(key)
            self._base[key] = value

    def update(self, values=None):
        if values is not None:
            for k, v in values.items():
                if k in self:
                    self[k] = v
        if self._pending:
            pending, self._pending = self._pending, {}
            self._sdf.set_many(pending)         # all or nothing
        return self._base.update()

    def __repr__(self):
        return f"SDFParameters[{len(self)} keys, {len(self._sdf_keys())} SDF]"


def parameters(scene) -> SDFParameters:
    """``mi.traverse`` of a loaded draaw scene plus its ``"sdf.NODE.PARAM"`` keys (a fresh
    traversal; :attr:`DraawScene.all_params <draaw_mi.scene.DraawScene.all_params>` is the
    scene's own, shared with ``scene.params``). ``scene``: what ``draaw_mi.load_scene`` returns."""
    if not (hasattr(scene, "mi_scene") and hasattr(scene, "sdf")):
        raise ParameterError(f"sdf.parameters: scene={scene!r}; expected a scene loaded with "
                             "draaw_mi.load_scene (load a file first)")
    return SDFParameters(scene)
