"""Stamps: what tells that a Dr.Jit value changed between two looks at it, for the caches and
checks keyed by a scene's parameter values (a medium's majorant table,
:meth:`draaw_mi.scene.DraawScene.out_of_range`).

A variable's index alone does not tell it: Dr.Jit gives a freed variable's index to the next
new one (a density grid set twice between two renders came back under the index of the one a
table was built for, 10 of 30 times), and plugins update some single values in place under
their index (an ``hg``'s g, the draaw BSDF's values). So a number is its own stamp, a single
value or colour is stamped by its numbers, and an array by its variables' indices with the
array held (:class:`Held`): while the stamp lives, no new array can take those indices.

>>> import mitsuba as mi
>>> stamp(mi.Float(0.5)), stamp(2)
(('values', 0.5), ('number', 2))
>>> t = mi.TensorXf([1.0, 2.0])
>>> stamp(t) == stamp(t) != stamp(mi.TensorXf([1.0, 2.0]))
True
"""
from __future__ import annotations

import drjit as dr
import numpy as np


class Held:
    """A value a stamp holds alive, equal to any other :class:`Held`."""
    __slots__ = ("value",)

    def __init__(self, value):
        self.value = value

    def __eq__(self, other) -> bool:
        return isinstance(other, Held)

    __hash__ = None


def stamp(value) -> tuple:
    """The stamp of ``value`` (see the module docstring): equal for two looks at an unchanged
    value, different once it changed. An array's stamp holds a new Python array on its
    variables (a getter may return a plugin's member itself, which a later set would move)."""
    if isinstance(value, (bool, int, float)):
        return ("number", value)
    if not dr.is_array_v(value):
        return ("other", repr(value))
    if not dr.is_tensor_v(value) and dr.width(value) == 1:
        if dr.depth_v(value) > 2:              # (a matrix: rare)
            return ("values", *np.array(value, dtype=np.float64).ravel().tolist())
        first = dr.slice(value, 0)             # (a tenth of a numpy read's time)
        return ("values", *(first if dr.depth_v(value) == 2 else (first,)))
    return ("ids", *dr.detail.collect_indices(value), Held(type(value)(value)))
