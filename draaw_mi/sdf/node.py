"""The SDF node base class: distance, material weights, bounding box, parameters.

Every node of an SDF tree (primitive, transform or operator) evaluates

* ``node.distance(p: mi.Point3f) -> mi.Float`` -- a signed distance (negative inside) that is
  *exact* or a documented *bound* (``|f(p)| <= distance to the surface``, i.e. 1-Lipschitz),
  so that sphere tracing never steps through a surface;
* ``node.eval(p, n_slots) -> (mi.Float, list[mi.Float])`` -- the distance and the blend
  weights of the ``n_slots`` material slots at ``p`` (they sum to 1; smooth operators blend
  the weights of their operands with the same weight that blends the distances);
* ``node.bbox() -> mi.ScalarBoundingBox3f`` -- a world box that contains the surface
  (infinite for a plane);
* ``node.params()`` -- ``{"NAME.PARAM": Dr.Jit array}`` of the differentiable parameters of
  the subtree (radius, centre, size, smooth ``k``, translation, scale), to be used with
  ``dr.enable_grad`` and :meth:`SDFNode.set_param` (``node.set_param("radius", value)``; in a
  scene, ``SDFScene.set("NODE.PARAM", value)``).

Parameters are stored as *opaque* Dr.Jit arrays (``dr.opaque``), so a new value does not
recompile the render kernel.
"""
from __future__ import annotations

import copy
import math
import numbers
import re

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, suggest
from ..limits import FLOAT32_MAX

#: what a node's name may be (it is part of the keys ``sdf.NAME.PARAM``)
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")

INF = float("inf")
# how far inside an open lower bound (radius > 0) an optimiser's projection stays
OPEN_MARGIN = 1e-4
#: the smallest normal float32: a positive parameter (radius > 0, scale > 0) is at least this,
#: since a smaller one is subnormal (1 / scale is inf, its distances NaN)
FLOAT32_TINY = float(np.finfo(np.float32).tiny)


def _vec3(value, where: str, name: str) -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)):         # ("123" would be (1, 2, 3); "abc" a bare ValueError)
        raise ParameterError(f"{where}: {name}={value!r}; expected 3 numbers")
    try:
        if dr.is_array_v(value):     # a Dr.Jit array (mi.Vector3f: float() refuses its entries)
            v = tuple(float(x) for x in np.array(dr.detach(value), dtype=np.float64).reshape(-1))
        else:
            v = tuple(float(x) for x in value)
    except TypeError:
        raise ParameterError(f"{where}: {name}={value!r}; expected 3 numbers") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise ParameterError(f"{where}: {name}={value!r}; expected 3 finite numbers")
    if any(abs(x) > FLOAT32_MAX for x in v):     # (stored as float32: inf, the object gone)
        raise ParameterError(f"{where}: {name}={value!r}; expected 3 numbers within float32 "
                             "(|x| <= 3.4e38)")
    return v


def _as_point3(value):
    """A JIT 3-vector of another type (``mi.Vector3f``, ``mi.Normal3f``, ``mi.Color3f``) as
    the ``mi.Point3f`` a node stores (width 1), its AD edges kept, so that it is not refused as
    "expected 3 numbers"; anything else unchanged."""
    if (dr.is_array_v(value) and dr.is_jit_v(value) and not isinstance(value, mi.Point3f)
            and dr.depth_v(value) == 2 and dr.size_v(value) == 3 and dr.type_v(value) == dr.VarType.Float32
            and dr.backend_v(value) == dr.backend_v(mi.Float) and dr.width(value) == 1):
        return mi.Point3f(value)
    return value


def _scalar(value, where: str, name: str, lo: float | None = None, lo_open: bool = False) -> float:
    if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
        value = float(value)               # numpy scalars too (np.float32(0.5))
    elif isinstance(value, np.ndarray):
        # one number of any shape (np.array(0.5), np.array([[0.5]])); not a bool
        if value.size == 1 and value.dtype.kind in "iuf":
            value = float(value.reshape(-1)[0])
    elif not isinstance(value, (str, bytes, bool, np.bool_)):
        try:
            value = float(value[0]) if len(value) == 1 else value   # 1-element Dr.Jit array
        except (TypeError, ValueError):
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f"{where}: {name}={value!r}; expected a finite number")
    if abs(value) > FLOAT32_MAX:           # (stored as float32: inf, then -inf or NaN distances)
        raise ParameterError(f"{where}: {name}={value!r}; expected a number within float32 (|x| <= 3.4e38)")
    if lo is not None and (value < lo or (lo_open and value == lo)):
        op = ">" if lo_open else ">="
        raise ParameterError(f"{where}: {name}={value!r}; expected a number {op} {lo}")
    if lo == 0 and lo_open and value < FLOAT32_TINY:
        raise ParameterError(f"{where}: {name}={value!r}; expected a number >= {FLOAT32_TINY:.9g} "
                             "(the smallest normal float32; a subnormal one gives NaN distances)")
    return float(value)


def safe_norm(v) -> mi.Float:
    """``|v|`` with a finite derivative at 0 (``sqrt(max(|v|^2, 1e-30))``)."""
    return dr.sqrt(dr.maximum(dr.squared_norm(v), 1e-30))


def scalar_of(x) -> float:
    """The Python value of a 1-element Dr.Jit Float (detached)."""
    return float(dr.detach(x)[0]) if dr.is_array_v(x) else float(x)


def vec_of(x) -> tuple[float, float, float]:
    return tuple(scalar_of(c) for c in (x.x, x.y, x.z))


def box(lo, hi) -> mi.ScalarBoundingBox3f:
    return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(*lo), mi.ScalarPoint3f(*hi))


def infinite_box() -> mi.ScalarBoundingBox3f:
    return box((-INF,) * 3, (INF,) * 3)


def is_infinite(bb: mi.ScalarBoundingBox3f) -> bool:
    return not all(math.isfinite(float(c)) for c in list(bb.min) + list(bb.max))


def pad(bb: mi.ScalarBoundingBox3f, amount: float) -> mi.ScalarBoundingBox3f:
    if is_infinite(bb):
        return bb
    return box([float(c) - amount for c in bb.min], [float(c) + amount for c in bb.max])


class SDFNode:
    """Base class of SDF tree nodes (see the module docstring).

    ``name`` names the node in parameter keys and errors; ``material`` (a material name of
    the scene, or ``None`` to inherit) is resolved to a slot by :mod:`draaw_mi.sdf.scene`.
    """
    kind = "node"

    def __init__(self, name: str | None = None, material: str | None = None):
        if name is not None and not (isinstance(name, str) and NAME_PATTERN.fullmatch(name)):
            raise ParameterError(f"sdf.{self.kind}: name={name!r}; expected letters, digits, '_' or '-', "
                                 "starting with a letter or '_' (a name is part of the keys sdf.NAME.PARAM)")
        if material is not None and not isinstance(material, str):
            raise ParameterError(f"sdf.{self.kind}: material={material!r}; expected a material's name "
                                 "(a string) or None to inherit")
        self.name = name or self.kind
        self.material = material
        self.slot = 0                      # material slot; set when a scene resolves materials
        self._params: dict[str, object] = {}

    # ------------------------------------------------------------------ parameters
    def _scalar_param(self, key: str, value, lo: float | None = None, lo_open: bool = False):
        v = _scalar(value, f"sdf.{self.kind} {self.name!r}", key, lo, lo_open)
        arr = dr.opaque(mi.Float, v)
        self._params[key] = arr
        return arr

    def _vec_param(self, key: str, value):
        v = _vec3(value, f"sdf.{self.kind} {self.name!r}", key)
        arr = dr.opaque(mi.Point3f, v)
        self._params[key] = arr
        return arr

    def set_param(self, key: str, value) -> None:
        """Set parameter ``key`` (e.g. ``"radius"``) of this node to a number, a 3-vector or
        a Dr.Jit array (which may carry gradients); checks the same ranges as the constructor.
        A value that fails a check leaves the node as it was.

        >>> from draaw_mi.sdf import Sphere
        >>> s = Sphere(radius=1.0); s.set_param("radius", 2.0); s.bbox().max.x
        2.0
        """
        # (checked on a copy: a round box's radius above half its size is not kept)
        self._assign(key, self.with_values({key: value})._params[key])

    def check_param(self, key: str, value) -> None:
        """Raise :class:`~draaw_mi.errors.ParameterError` if :meth:`set_param` would refuse
        ``value``; the node is not changed.

        >>> from draaw_mi.sdf import RoundBox
        >>> b = RoundBox(size=(1, 1, 1), radius=0.1)
        >>> b.check_param("radius", 0.8)
        Traceback (most recent call last):
        ...
        draaw_mi.errors.ParameterError: sdf.round_box 'round_box': radius=0.8; expected a value in [0, min(size)/2 = 0.5]
        >>> round(float(b.radius[0]), 6)
        0.1
        """
        self.with_values({key: value})

    def with_values(self, values: dict) -> "SDFNode":
        """A copy of this node with ``{param: value}`` set, every value range-checked and the
        node's cross-checks run on them together; raises
        :class:`~draaw_mi.errors.ParameterError` otherwise. The node itself is not touched
        (it may be in a render on another thread, a preview's)."""
        probe = copy.copy(self)
        probe._params = dict(self._params)
        for key, value in values.items():
            probe._assign(key, probe._checked_value(key, value))
        probe._check()
        return probe

    def param_range(self, key: str) -> tuple:
        """``(low, high)`` that an optimiser may project parameter ``key`` onto (``None``: no
        bound): an open lower bound (radius > 0) becomes ``bound + OPEN_MARGIN``.

        >>> from draaw_mi.sdf import Sphere
        >>> Sphere(radius=1.0).param_range("radius")
        (0.0001, None)
        """
        self._checked_value(key, self._params.get(key))       # (an unknown key: the error)
        lo = getattr(self, "_lower_bounds", {}).get(key)
        return (None if lo is None else lo + OPEN_MARGIN, None)

    def project(self, values: dict) -> dict:
        """``values`` (parameter -> new value, numbers or sequences) moved into the ranges an
        optimiser may take them to, the new values counted together where they bound each
        other (:class:`~draaw_mi.sdf.primitives.RoundBox`: its radius and size); here each is
        clipped to :meth:`param_range`.

        >>> from draaw_mi.sdf import Sphere
        >>> Sphere(radius=1.0).project({"radius": -0.5})["radius"].tolist()
        0.0001
        """
        out = {}
        for key, value in values.items():
            lo, hi = self.param_range(key)
            out[key] = np.clip(np.asarray(value, dtype=np.float64), -np.inf if lo is None else lo,
                               np.inf if hi is None else hi)
        return out

    def _assign(self, key: str, new) -> None:
        self._params[key] = new
        setattr(self, key, new)

    def _checked_value(self, key: str, value):
        """``value`` as this node stores parameter ``key`` (range-checked, not cross-checked)."""
        if key not in self._params:
            raise ParameterError(f"sdf.{self.kind} {self.name!r}: no parameter {key!r}"
                                 f"{suggest(key, self._params)}")
        old = self._params[key]
        lo = getattr(self, "_lower_bounds", {}).get(key)
        value = _as_point3(value) if isinstance(old, mi.Point3f) else value
        if dr.is_array_v(value) and type(value) is type(old):
            vals = np.array(dr.detach(value), dtype=np.float64)
            # (a wide array would give one object per lane of the kernel's rays; NaN, no object)
            if dr.width(value) != 1:
                raise ParameterError(f"sdf.{self.kind} {self.name!r}: {key} is an array of width "
                                     f"{dr.width(value)}; expected one value (width 1)")
            if lo is not None:
                # an optimiser's step can leave the range (a negative radius makes the object
                # vanish with a zero gradient; a zero cone height gives NaN distances)
                low = float(np.min(vals))
                if not low > lo:
                    raise ParameterError(
                        f"sdf.{self.kind} {self.name!r}: {key}={low!r}; expected a number > {lo} "
                        f"(clamp an optimiser's value before the update, e.g. "
                        f"opt[k] = dr.maximum(opt[k], 1e-3))")
                if lo == 0 and low < FLOAT32_TINY:
                    raise ParameterError(
                        f"sdf.{self.kind} {self.name!r}: {key}={low!r}; expected a number >= "
                        f"{FLOAT32_TINY:.9g} (the smallest normal float32; a subnormal one gives NaN distances)")
            if not np.all(np.isfinite(vals)):
                raise ParameterError(f"sdf.{self.kind} {self.name!r}: {key}={vals.ravel().tolist()!r}; "
                                     "expected finite values")
            # made opaque in place (the caller's array, AD edges kept): a literal such as
            # mi.Float(0.6) would be baked into the kernel, compiled anew for every value
            dr.make_opaque(value)
            return value
        if isinstance(old, mi.Point3f):
            return dr.opaque(mi.Point3f, _vec3(value, f"sdf.{self.kind} {self.name!r}", key))
        return dr.opaque(mi.Float, _scalar(value, f"sdf.{self.kind} {self.name!r}", key,
                                           lo, lo_open=lo is not None))

    def _check(self) -> None:
        """Cross-parameter checks (overridden where needed)."""
    def own_params(self) -> dict:
        return dict(self._params)

    def params(self) -> dict:
        """``{"NAME.PARAM": array}`` for this node and its subtree; two nodes of one name
        (``union(Sphere(), Sphere())``: both ``sphere``) are refused, as one would hide the
        other's values (a scene made of the tree, :func:`~draaw_mi.sdf.export.to_entries`,
        names them ``sphere``, ``sphere_1``)."""
        owners: dict[str, SDFNode] = {}
        for node in self.nodes():
            if not node._params:               # (a sharp operator: no keys to hide or lose)
                continue
            other = owners.setdefault(node.name, node)
            if other is not node:
                raise ParameterError(f"sdf.{self.kind} {self.name!r}: two nodes are named {node.name!r} "
                                     f"({other.describe()}; {node.describe()}); give them distinct names "
                                     "(name=...) to tell their parameters apart")
        return {f"{n.name}.{k}": v for n in owners.values() for k, v in n._params.items()}

    # ------------------------------------------------------------------ tree
    def children(self) -> tuple["SDFNode", ...]:
        return ()

    def nodes(self):
        """This node and its subtree, depth first."""
        yield self
        for c in self.children():
            yield from c.nodes()

    # ------------------------------------------------------------------ evaluation
    def distance(self, p: mi.Point3f) -> mi.Float:
        raise NotImplementedError

    def eval(self, p: mi.Point3f, n_slots: int):
        """``(distance, weights)``; a leaf puts all weight on its material slot."""
        d = self.distance(p)
        w = [mi.Float(1.0 if i == self.slot else 0.0) for i in range(n_slots)]
        return d, w

    def bbox(self) -> mi.ScalarBoundingBox3f:
        raise NotImplementedError

    def fixed_values(self) -> dict:
        """Shape values that are Python constants, not parameters (shown by :meth:`describe`)."""
        return {}

    def describe(self) -> str:
        """One line for ``draaw-mi info``: the parameters, then the fixed values."""
        vals = []
        for k, v in self._params.items():
            if isinstance(v, mi.Point3f):
                vals.append(f"{k}=({', '.join(f'{c:g}' for c in vec_of(v))})")
            else:
                vals.append(f"{k}={scalar_of(v):g}")
        vals += [f"{k}={v}" for k, v in self.fixed_values().items()]
        mat = f" material={self.material}" if self.material else ""
        return f"{self.name}: {self.kind}({', '.join(vals)}){mat}"

    def __repr__(self) -> str:
        return f"SDF[{self.describe()}]"
