"""Filter chains: :class:`Chain`, :func:`apply` and :func:`load_chain`.

A chain is an ordered list of filters, each a dict such as
``{"type": "bloom", "amount": 0.5, "multipass": 3, "threshold": 0.1}`` or a filter object
(``post.Bloom(threshold=0.1)``). GO-Draaw's ``/submitShader`` form is accepted as well:
``{"type": "bloomV2", "params": {"amount": 0.5, "BloomThreshold": 0.1}}``. Type and parameter
names match case-insensitively and ignoring ``_``/``-`` (``bloomV2`` = ``bloom_v2``,
``BloomThreshold`` = ``threshold``).
"""
from __future__ import annotations

import json
import os
import warnings
from typing import Any, Iterable, Iterator, Mapping

import mitsuba as mi

from ..errors import IOFailure, ParameterError, user_stacklevel
from ..io import write_text
from ._spec import Filter, norm_name, unknown_name_message
from ._util import as_image, finite_rgb, join_alpha, split_alpha
from .aberration import ChromaticAberration
from .blur import Bloom, BloomV2, Sharpen
from .color import ColorMapping, Contrast, Lighten, Tint
from .crt_look import CRT
from .edges import EdgeDetection
from .tone import SRGB, Linear, Log

#: Canonical filter name → callable class, in GO-Draaw's order, then the tone curves.
FILTERS: dict[str, type[Filter]] = {cls.spec.name: cls for cls in (
    Contrast, Tint, Bloom, BloomV2, Sharpen, ColorMapping, ChromaticAberration, EdgeDetection,
    Lighten, CRT, Linear, Log, SRGB)}

_BY_NAME: dict[str, type[Filter]] = {}
for _cls in FILTERS.values():
    for _n in (_cls.spec.name, *_cls.spec.aliases):
        _BY_NAME[norm_name(_n)] = _cls


def filter_class(name: str, where: str = "post") -> type[Filter]:
    """The filter class for a canonical, GO-Draaw or alias ``name``; ParameterError if unknown."""
    cls = _BY_NAME.get(norm_name(name)) if isinstance(name, str) else None
    if cls is None:
        valid = [n for c in FILTERS.values() for n in (c.spec.name, *c.spec.aliases)]
        raise ParameterError(f"{where}: " + unknown_name_message("filter type", name, valid))
    return cls


def make_filter(entry: Mapping[str, Any] | Filter, where: str = "post") -> Filter:
    """Build one validated filter from a chain entry (dict or :class:`Filter`)."""
    if isinstance(entry, Filter):
        return entry
    if not isinstance(entry, Mapping):
        raise ParameterError(f"{where}: a chain entry must be a dict with a 'type' or a filter "
                             f"object, got {type(entry).__name__}")
    if "type" not in entry:
        raise ParameterError(f"{where}: chain entry has no 'type' (keys: "
                             f"{', '.join(map(str, entry)) or 'none'})")
    cls = filter_class(entry["type"], where)
    where = f"{where} ({cls.spec.name})"
    params = {k: v for k, v in entry.items() if k not in ("type", "params")}
    nested = entry.get("params", {})
    if not isinstance(nested, Mapping):
        raise ParameterError(f"{where}: 'params' must be a dict, got {type(nested).__name__}")
    for k, v in nested.items():
        if k in params:
            raise ParameterError(f"{where}: parameter {k!r} is given both at the top level "
                                 "and in 'params'")
        params[k] = v
    return cls.from_params(cls.spec.from_entry(where, params))


class Chain:
    """An ordered, validated list of filters; calling it filters an image.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> chain = post.Chain([{"type": "contrast", "contrast": 1.2},
        ...                     {"type": "bloomV2", "params": {"amount": 0.5}}])
        >>> len(chain), chain(np.zeros((8, 8, 3), np.float32)).shape
        (2, (8, 8, 3))
    """
    def __init__(self, filters: Iterable[Mapping[str, Any] | Filter] = (), *,
                 source: str | None = None) -> None:
        if isinstance(filters, (str, bytes, Mapping)) or not isinstance(filters, Iterable):
            raise ParameterError(f"{source or 'post chain'}: a chain must be a list of filters, "
                                 f"got {type(filters).__name__}")
        self.source = source
        self.filters: list[Filter] = [
            make_filter(e, f"{source + ': ' if source else 'post '}chain[{i}]")
            for i, e in enumerate(filters)]

    def __call__(self, image: Any) -> mi.TensorXf:
        rgb, alpha = split_alpha(as_image(image, "apply()"))
        rgb = finite_rgb(rgb)               # (NaN/inf read as 0: a blur would spread them)
        for f in self.filters:
            rgb = f.spec.run(rgb, alpha, f.params)
        return join_alpha(rgb, alpha)

    def __len__(self) -> int:
        return len(self.filters)

    def __iter__(self) -> Iterator[Filter]:
        return iter(self.filters)

    def __getitem__(self, i: int) -> Filter:
        return self.filters[i]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Chain) and other.filters == self.filters

    def to_list(self) -> list[dict[str, Any]]:
        """Canonical, JSON-serialisable form (every parameter spelled out)."""
        return [f.to_dict() for f in self.filters]

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write :meth:`to_list` as JSON (readable by :func:`load_chain`), atomically (a
        crash mid-write leaves the previous chain, not a truncated file)."""
        write_text(os.fspath(path), json.dumps(self.to_list(), indent=2) + "\n")

    def __repr__(self) -> str:
        return "Chain([" + ", ".join(map(repr, self.filters)) + "])"


def display_encoded(chain: Iterable[Any] | Chain | None) -> bool:
    """Whether ``chain``'s output is display-encoded: its last display curve decides, an
    ``srgb`` filter (an ``inverse=True`` one decodes) or one of GO-Draaw's grades ``linear``
    and ``log``, whose values GO-Draaw stores as its 8-bit pixels (white through ``log``: 128);
    no such filter leaves the image linear. A filter at ``amount`` 0 does nothing and is not
    counted; one between 0 and 1 leaves values neither linear nor encoded (a
    ``RuntimeWarning`` says so; they are taken as encoded). What writes 8-bit images (PNG
    files, the Jupyter preview) then stores the values as they are instead of encoding them a
    second time, which would wash them out.

    >>> display_encoded([{"type": "bloom"}, {"type": "srgb"}]), display_encoded([])
    (True, False)
    >>> display_encoded([{"type": "srgb"}, {"type": "srgb", "inverse": True}])
    False
    >>> display_encoded([{"type": "log"}]), display_encoded([{"type": "srgb", "amount": 0}])
    (True, False)
    """
    encoded, partial = False, None
    for f in load_chain(chain or []):
        if f.spec.straight and f.params["amount"] > 0.0:        # (the display curves)
            encoded = not (isinstance(f, SRGB) and f.params["inverse"])
            partial = f if f.params["amount"] < 1.0 else None
    if partial is not None:
        warnings.warn(f"display_encoded: {partial.spec.name} at amount={partial.params['amount']:g} leaves "
                      "values between linear and display-encoded; they are taken as "
                      f"{'encoded' if encoded else 'linear'}", RuntimeWarning, stacklevel=user_stacklevel())
    return encoded


def load_chain(source: str | os.PathLike[str] | Iterable[Any] | Chain) -> Chain:
    """Read and validate a chain from a JSON file, or validate an in-memory list.

    The file holds a list of entries (see the module docstring), GO-Draaw's ``/submitShader``
    body (a list of ``{type, params: {...}}``), or an object ``{"chain": [...]}``.

    Raises:
        IOFailure: the file cannot be read.
        ParameterError: malformed JSON (with line and column) or an invalid entry; the message
            starts with the file name and the entry index.
    """
    if isinstance(source, Chain):
        return source
    if isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        try:
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
        except OSError as exc:
            raise IOFailure(f"{path}: cannot read post chain file ({exc.strerror or exc})"
                            ) from None
        except UnicodeDecodeError:
            raise ParameterError(f"{path}: not a post chain file (UTF-8 JSON text)") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ParameterError(f"{path}: malformed JSON at line {exc.lineno} column "
                                 f"{exc.colno}: {exc.msg}") from None
        if isinstance(data, Mapping):
            keys = list(data)
            if keys != ["chain"]:
                raise ParameterError(f"{path}: expected a list of filters or {{\"chain\": [...]}},"
                                     f" got an object with keys {keys}")
            data = data["chain"]
        if not isinstance(data, list):
            raise ParameterError(f"{path}: expected a list of filters, got "
                                 f"{type(data).__name__}")
        return Chain(data, source=path)
    return Chain(source)


def apply(image: Any, chain: Iterable[Any] | Chain | str | os.PathLike[str]) -> mi.TensorXf:
    """Run a filter chain on an image.

    Args:
        image: (H, W, 3) or (H, W, 4) ``mi.TensorXf`` or float numpy array (linear, HDR allowed).
        chain: a :class:`Chain`, a list of dicts / filter objects, or a JSON file path (see
            :func:`load_chain`). The whole chain is validated before anything runs.

    Returns:
        ``mi.TensorXf`` of the input's shape; alpha passes through. Differentiable. Non-finite
        colour values (NaN, ±inf) are read as 0, so none spreads through a blur.

    Shape:
        (H, W, C) → (H, W, C), C ∈ {3, 4}.

    Example:
        >>> import numpy as np, draaw_mi.post as post
        >>> img = np.full((4, 4, 3), 0.5, np.float32)
        >>> out = post.apply(img, [{"type": "lighten", "strength": 1.0},
        ...                        {"type": "colorMapping", "ColorR": 4, "amount": 1.0}])
        >>> [float(v) for v in out[0, 0].array]
        [1.0, 1.0, 1.0]
    """
    return load_chain(chain)(image)


__all__ = ["FILTERS", "Chain", "apply", "filter_class", "load_chain", "make_filter"]
