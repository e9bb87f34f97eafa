"""Parameter specifications, validation and the callable :class:`Filter` base of ``draaw_mi.post``.

Every filter is described once by a :class:`FilterSpec`: its canonical name, its GO-Draaw type
name(s), its parameters (:class:`Param`: default, range, GO-Draaw names) and its *effect*, a
function ``effect(rgb, p) -> rgb`` on an (H, W, 3) ``mi.TensorXf``. The plain functions
(``post.bloom``), the callable classes (``post.Bloom``) and the chain (``post.apply``) all go
through the same :meth:`FilterSpec.validate` and :meth:`FilterSpec.run_rgb`, so they agree exactly
and raise the same :class:`~draaw_mi.errors.ParameterError` messages.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Callable, Mapping, Sequence

import drjit as dr
import mitsuba as mi
import numpy as np

from ..errors import ParameterError, suggest
from ._util import as_image, finite_rgb, join_alpha, split_alpha

MIN_ALPHA = 2.0 ** -63       # alpha at or below this counts as 0 (c / a and a^2 stay finite)

#: Boundary modes of the neighbourhood filters, named as in ``scipy.ndimage`` / ``dr.convolve``.
BOUNDARIES = ("reflect", "nearest", "mirror", "wrap", "zero")

Effect = Callable[[mi.TensorXf, SimpleNamespace], mi.TensorXf]


def norm_name(name: str) -> str:
    """Canonical form used to match names: lower case, without ``_``, ``-`` and spaces."""
    return "".join(ch for ch in str(name).lower() if ch not in "_- ")


def valid_list(names: Sequence[str]) -> str:
    return ", ".join(names)


def unknown_name_message(what: str, name: str, valid: Sequence[str]) -> str:
    """``unknown <what> 'x'; did you mean 'y'? (valid: a, b, c)``: valid names always listed."""
    hint = suggest(str(name), valid)
    if hint.startswith("; did you mean"):
        return f"unknown {what} {name!r}{hint} (valid: {valid_list(valid)})"
    return f"unknown {what} {name!r} (valid: {valid_list(valid)})"


def _fmt_bound(v: float) -> str:
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return str(int(v)) if float(v).is_integer() else f"{v:g}"     # (2147483647, not 2.14748e+09)


@dataclass(frozen=True)
class Param:
    """One filter parameter.

    ``kind`` is ``'float'``, ``'int'``, ``'bool'``, ``'choice'``, ``'color'`` (three floats; a
    number, a 3-sequence, ``'#rrggbb'`` or ``{'r','g','b'}`` are accepted) or ``'levels'`` (one or
    three integers). ``lo``/``hi`` bound every component (``lo_open`` excludes ``lo``).
    ``aliases`` are other accepted names (GO-Draaw's JSON names); ``components`` name the three
    components separately (GO-Draaw's ``ColorR``/``ColorG``/``ColorB``).
    """
    name: str
    default: Any
    kind: str = "float"
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    choices: tuple[str, ...] = ()
    aliases: tuple[str, ...] = ()
    components: tuple[str, ...] = ()

    def range_text(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        if self.kind == "bool":
            return "true or false"
        if self.kind == "color":
            return (f"a colour: 3 numbers in [{_fmt_bound(self.lo)}, {_fmt_bound(self.hi)}"
                    f"{']' if not math.isinf(self.hi) else ')'}, one number, '#rrggbb' or "
                    "{'r': .., 'g': .., 'b': ..}")
        left = "(" if self.lo_open else "["
        right = ")" if math.isinf(self.hi) else "]"
        kind = "an integer" if self.kind in ("int", "levels") else "a number"
        each = " (each component)" if self.kind in ("color", "levels") else ""
        return f"{kind} in {left}{_fmt_bound(self.lo)}, {_fmt_bound(self.hi)}{right}{each}"

    # -- validation -------------------------------------------------------------------------
    def _bad(self, where: str, value: Any) -> ParameterError:
        return ParameterError(f"{where}: parameter {self.name!r} must be {self.range_text()}, "
                              f"got {value!r}")

    def _number(self, where: str, v: Any, full: Any, integer: bool) -> float | int:
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise self._bad(where, full)
        v = float(v)
        if not math.isfinite(v) or v < self.lo or v > self.hi or (self.lo_open and v == self.lo):
            raise self._bad(where, full)
        if integer:
            if v != math.floor(v):
                raise self._bad(where, full)
            return int(v)
        return v

    def check(self, where: str, value: Any) -> Any:
        """Return the normalised value or raise :class:`ParameterError` naming ``where``."""
        k = self.kind
        if k == "float":
            return self._number(where, value, value, False)
        if k == "int":
            return self._number(where, value, value, True)
        if k == "bool":
            if isinstance(value, (bool, np.bool_)):          # (numpy's from a widget or array)
                return bool(value)
            if isinstance(value, numbers.Integral) and value in (0, 1):
                return bool(value)
            if isinstance(value, str) and value.lower() in ("true", "false", "yes", "no"):
                return value.lower() in ("true", "yes")
            raise self._bad(where, value)
        if k == "choice":
            if isinstance(value, str) and value.lower() in self.choices:
                return value.lower()
            hint = suggest(value, self.choices) if isinstance(value, str) else ""
            raise ParameterError(f"{where}: parameter {self.name!r} must be {self.range_text()}, "
                                 f"got {value!r}" + (hint if hint.startswith("; did you mean") else ""))
        if k in ("color", "levels"):
            integer = k == "levels"
            comps: Any = value
            if k == "color" and isinstance(value, str):
                s = value.strip().lstrip("#")
                if len(s) != 6 or any(ch not in "0123456789abcdefABCDEF" for ch in s):
                    raise self._bad(where, value)
                comps = [int(s[i:i + 2], 16) / 255.0 for i in (0, 2, 4)]
            elif isinstance(value, Mapping):
                low = {norm_name(key): val for key, val in value.items()}
                if set(low) != {"r", "g", "b"}:
                    raise self._bad(where, value)
                comps = [low["r"], low["g"], low["b"]]
            elif isinstance(value, numbers.Real) and not isinstance(value, bool):
                comps = [value] * 3
            try:
                comps = list(comps)
            except TypeError:
                raise self._bad(where, value) from None
            if len(comps) != 3:
                raise self._bad(where, value)
            return tuple(self._number(where, c, value, integer) for c in comps)
        raise AssertionError(f"unknown parameter kind {k!r}")  # pragma: no cover


AMOUNT = Param("amount", 1.0, lo=0.0, hi=1.0)


def multipass_param(default: int) -> Param:
    return Param("multipass", default, "int", lo=1, hi=100)


@dataclass
class FilterSpec:
    """Name, parameters and effect of one filter; see the module docstring."""
    name: str
    params: tuple[Param, ...]
    effect: Effect
    aliases: tuple[str, ...] = ()
    multipass: int = 1
    #: a per-pixel curve, applied to the colour itself where the image has alpha (:meth:`run`)
    straight: bool = False

    def __post_init__(self) -> None:
        self.params = tuple(self.params) + (AMOUNT, multipass_param(self.multipass))
        self.by_name = {p.name: p for p in self.params}
        # every accepted spelling -> (param, component index or None)
        self.lookup: dict[str, tuple[Param, int | None]] = {}
        for p in self.params:
            for n in (p.name, *p.aliases):
                self.lookup[norm_name(n)] = (p, None)
            for i, n in enumerate(p.components):
                self.lookup[norm_name(n)] = (p, i)

    @property
    def valid_names(self) -> list[str]:
        names: list[str] = []
        for p in self.params:
            names += [p.name, *p.aliases, *p.components]
        return names

    def defaults(self) -> dict[str, Any]:
        return {p.name: p.default for p in self.params}

    def validate(self, where: str, values: Mapping[str, Any]) -> dict[str, Any]:
        """Check canonical ``values`` (missing ones take their default); return all, normalised."""
        out: dict[str, Any] = {}
        for key, value in values.items():
            if key not in self.by_name:
                raise ParameterError(f"{where}: " + unknown_name_message(
                    "parameter", key, [p.name for p in self.params]))
            out[key] = self.by_name[key].check(where, value)
        for p in self.params:
            if p.name not in out:
                out[p.name] = p.check(where, p.default)
        return out

    def from_entry(self, where: str, entry: Mapping[str, Any]) -> dict[str, Any]:
        """Validate a chain entry's parameters, accepting GO-Draaw names and components."""
        whole: dict[str, Any] = {}
        parts: dict[str, dict[int, Any]] = {}
        seen: dict[str, str] = {}
        for key, value in entry.items():
            hit = self.lookup.get(norm_name(key))
            if hit is None:
                raise ParameterError(f"{where}: " + unknown_name_message(
                    "parameter", key, self.valid_names))
            p, comp = hit
            slot = p.name if comp is None else f"{p.name}[{comp}]"
            if slot in seen:
                raise ParameterError(f"{where}: parameter {p.name!r} is given twice "
                                     f"(as {seen[slot]!r} and {key!r})")
            seen[slot] = key
            if comp is None:
                whole[p.name] = value
            else:
                parts.setdefault(p.name, {})[comp] = value
        for name, comps in parts.items():
            p = self.by_name[name]
            base = list(p.check(where, whole.get(name, p.default)))
            for i, v in comps.items():
                base[i] = v
            whole[name] = base
        return self.validate(where, whole)

    # -- running ----------------------------------------------------------------------------
    def run_rgb(self, rgb: mi.TensorXf, params: Mapping[str, Any]) -> mi.TensorXf:
        """Apply ``multipass`` passes of the effect blended by ``amount`` to an RGB tensor."""
        amount = params["amount"]
        if amount == 0.0:
            return rgb
        p = SimpleNamespace(**params)
        for _ in range(params["multipass"]):
            fx = self.effect(rgb, p)
            rgb = fx if amount == 1.0 else rgb + (fx - rgb) * amount
        return rgb

    def apply(self, image: Any, values: Mapping[str, Any], where: str | None = None
              ) -> mi.TensorXf:
        """Validate ``values``, then filter ``image`` ((H, W, 3|4) tensor or array)."""
        where = where or f"{self.name}()"
        params = self.validate(where, values)
        return self.apply_validated(image, params, where)

    def run(self, rgb: mi.TensorXf, alpha: mi.TensorXf | None, params: Mapping[str, Any]
            ) -> mi.TensorXf:
        """:meth:`run_rgb` of an image whose colour is premultiplied by ``alpha`` (a film's
        RGBA, as EXR stores it): a ``straight`` effect (a display curve: sRGB, GO-Draaw's grades)
        acts on the colour itself, ``c / a``, and the result is multiplied
        by ``a`` again; an encoding of ``c a`` had stored ``srgb(0.125 c)`` for a pixel an
        eighth covered (dark fringes). Pixels of alpha at most :data:`MIN_ALPHA` (2^-63) keep
        their colour as it is."""
        if alpha is None or not self.straight or params["amount"] == 0.0:
            return self.run_rgb(rgb, params)
        # (alpha as write_png reads it: in [0, 1]; an infinite one had made 0 * inf = NaN.
        # Below MIN_ALPHA the pixel counts as uncovered: a subnormal alpha, flushed to 0 by the
        # vector kernel, made c / a infinite and the colour NaN, and a**2 in the gradient 0)
        a = dr.select((alpha.array > MIN_ALPHA) & dr.isfinite(alpha.array), dr.minimum(alpha.array, 1.0), 1.0)
        a3 = mi.TensorXf(dr.repeat(a, 3), rgb.shape)       # (one alpha per colour value)
        return self.run_rgb(rgb / a3, params) * a3

    def apply_validated(self, image: Any, params: Mapping[str, Any], where: str
                        ) -> mi.TensorXf:
        t = as_image(image, where)
        rgb, alpha = split_alpha(t)
        return join_alpha(self.run(finite_rgb(rgb), alpha, params), alpha)


class Filter:
    """Base of the callable filter classes (kornia style): validated parameters + ``__call__``.

    Subclasses set ``spec`` and give ``__init__`` an explicit signature. ``Filter(...)(image)``
    equals the plain function called with the same parameters.
    """
    spec: FilterSpec

    def __init__(self, **params: Any) -> None:
        self.params = self.spec.validate(f"{type(self).__name__}()", params)

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> "Filter":
        """An instance holding already validated, complete ``params`` (used by the chain)."""
        obj = cls.__new__(cls)
        obj.params = dict(params)
        return obj

    def __call__(self, image: Any) -> mi.TensorXf:
        return self.spec.apply_validated(image, self.params, f"{type(self).__name__}()")

    def to_dict(self) -> dict[str, Any]:
        """The chain-entry form: ``{"type": name, **params}`` (JSON-serialisable)."""
        out: dict[str, Any] = {"type": self.spec.name}
        for k, v in self.params.items():
            out[k] = list(v) if isinstance(v, tuple) else v
        return out

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self) and other.params == self.params  # type: ignore

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"{type(self).__name__}({args})"

