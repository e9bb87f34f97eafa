"""Validation helpers for scene descriptions: typed fields, ranges, unknown-key suggestions.

Every error is a :class:`SceneError` whose message starts with the location
(``file: section.key``), then the bad value and what was expected.
"""
from __future__ import annotations

import json
import math
import numbers
from typing import Any, Iterable

import tomllib

import numpy as np

from ..errors import SceneError, shown, suggest  # noqa: F401 (shown: re-exported)
from ..limits import FLOAT32_MAX


class Where:
    """A location in a scene description, used to prefix error messages."""
    def __init__(self, source: str, path: str = ""):
        self.source, self.path = source, path

    def __truediv__(self, key) -> "Where":
        key = f"[{key}]" if isinstance(key, int) else str(key)
        sep = "" if (not self.path or key.startswith("[")) else "."
        return Where(self.source, f"{self.path}{sep}{key}")

    def __str__(self) -> str:
        return f"{self.source}: {self.path}" if self.path else self.source

    def error(self, msg: str) -> SceneError:
        return SceneError(f"{self}: {msg}")


def check_keys(table: dict, allowed: Iterable[str], where: Where, required: Iterable[str] = ()) -> None:
    """Reject keys not in ``allowed`` (suggesting the closest) and missing ``required`` keys."""
    if not isinstance(table, dict):
        raise where.error(f"expected a table, got {type(table).__name__} {shown(table)}")
    allowed = list(allowed)
    for key in table:
        if key not in allowed:
            raise (where / key).error(f"unknown key {key!r}{suggest(str(key), allowed)}")
    for key in required:
        if key not in table:
            raise where.error(f"missing required key {key!r}")


def number(value: Any, where: Where, lo: float | None = None, hi: float | None = None,
           integer: bool = False, lo_open: bool = False) -> float:
    """A finite number (or int) within [lo, hi] (or (lo, hi] with ``lo_open``); numpy
    numbers too (np.int64(8) is one)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):      # (numpy's bool is neither)
        raise where.error(f"{shown(value)} is not a number")
    value = int(value) if isinstance(value, numbers.Integral) else float(value)
    if not math.isfinite(value):
        raise where.error(f"{shown(value)} is not finite")
    if abs(value) > FLOAT32_MAX:        # (Mitsuba stores it as float32: inf, then NaN pixels)
        raise where.error(f"{shown(value)} is beyond float32 (|x| <= 3.4e38)")
    if integer and int(value) != value:
        raise where.error(f"{shown(value)} is not an integer")
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise where.error(f"{shown(value)} is out of range; expected {_range_text(lo, hi, lo_open)}")
    if hi is not None and value > hi:
        raise where.error(f"{shown(value)} is out of range; expected {_range_text(lo, hi, lo_open)}")
    return int(value) if integer else float(value)


def _range_text(lo, hi, lo_open=False):
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo}"
    if lo is None:
        return f"<= {hi}"
    return f"a value in {'(' if lo_open else '['}{lo}, {hi}]"


def vector(value: Any, where: Where, n: int = 3, lo: float | None = None) -> list[float]:
    """A list of ``n`` finite numbers (a single number is broadcast for colours)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value] * n
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise where.error(f"{shown(value)} is not a list of {n} numbers")
    return [number(v, where / i, lo=lo) for i, v in enumerate(value)]


def control_character(text: str) -> str | None:
    """The first control character of ``text`` (a NUL, a tab, a newline, DEL), or None: names
    and file names hold none (a NUL makes every path function raise).

    >>> control_character("frame_001.exr"), control_character("f\\x01.exr")
    (None, '\\x01')
    """
    return next((c for c in text if ord(c) < 32 or ord(c) == 127), None)


def string(value: Any, where: Where, choices: Iterable[str] | None = None) -> str:
    """A string value of a scene or manifest table: no control characters (a NUL or a tab in
    a name or a path is a typo, and a NUL makes every path function raise).

    >>> string("a\\x00b", Where("m.toml") / "jobs" / 0 / "name")
    Traceback (most recent call last):
    ...
    draaw_mi.errors.SceneError: m.toml: jobs[0].name: 'a\\x00b' holds a control character (\\x00); expected printable text
    """
    if not isinstance(value, str):
        raise where.error(f"{shown(value)} is not a string")
    bad = control_character(value)
    if bad is not None:
        raise where.error(f"{value!r} holds a control character ({repr(bad)[1:-1]}); expected "
                          "printable text")
    if choices is not None:
        choices = list(choices)
        if value not in choices:
            hint = suggest(value, choices)           # (its list of valid names would repeat ours)
            hint = hint if hint.startswith("; did you mean") else ""
            raise where.error(f"{shown(value)} is not one of {', '.join(choices)}{hint}")
    return value


def kind_of(table: dict, where: Where, choices: Iterable[str], default: str | None = None) -> str:
    """A table's ``type``: one of ``choices``; a table without one gets ``default`` or one
    clear error ("missing key 'type'", not "'' is not one of ...").

    >>> kind_of({"type": "sphere"}, Where("s.toml") / "shapes" / 0, ("sphere", "cube"))
    'sphere'
    >>> kind_of({"radius": 1}, Where("s.toml") / "shapes" / 0, ("sphere", "cube"))
    Traceback (most recent call last):
    ...
    draaw_mi.errors.SceneError: s.toml: shapes[0]: missing key 'type'; expected one of sphere, cube
    """
    if "type" not in table:
        if default is not None:
            return default
        raise where.error(f"missing key 'type'; expected one of {', '.join(choices)}")
    return string(table["type"], where / "type", choices)


def boolean(value: Any, where: Where) -> bool:
    if not isinstance(value, bool):
        raise where.error(f"{shown(value)} is not true or false")
    return value


def resolution(value: Any, where: Where) -> tuple[int, int]:
    """``[W, H]``, ``"WxH"`` or a single int (square), each side in 1..16384."""
    if isinstance(value, str):
        parts = value.lower().split("x")
        try:
            value = [int(p) for p in parts]
        except ValueError:
            raise where.error(f"{shown(value)} is not a resolution; expected 'WxH' such as '256x256'") from None
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        value = [value, value]
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()             # np.array([640, 480])
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise where.error(f"{shown(value)} is not a resolution; expected [width, height] or 'WxH'")
    w = number(value[0], where / "width", lo=1, hi=16384, integer=True)
    h = number(value[1], where / "height", lo=1, hi=16384, integer=True)
    return int(w), int(h)


def rotations(table: dict, where: Where) -> list:
    """``[(axis, angle in degrees), ...]`` of ``table["rotate"]`` (one table or a list of
    them), validated; empty without ``rotate``. Shared by meshes and SDF objects: a list is
    applied in order, its first rotation first."""
    if "rotate" not in table:
        return []
    rot = table["rotate"]
    out = []
    for i, r in enumerate(rot if isinstance(rot, list) else [rot]):
        wr = where / "rotate" / i if isinstance(rot, list) else where / "rotate"
        check_keys(r, ("axis", "angle"), wr, required=("axis", "angle"))
        axis = vector(r["axis"], wr / "axis")
        if not any(axis):
            raise (wr / "axis").error("is the zero vector")
        out.append((axis, number(r["angle"], wr / "angle")))
    return out


def read_document(path: str, what: str = "scene file") -> dict:
    """A TOML (``.toml``) or JSON (any other name) file as a dict; every error is a
    :class:`SceneError` naming the file (and the line, for malformed JSON)."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except OSError as e:
        raise SceneError(f"{path}: cannot read {what} ({e.strerror})") from None
    try:
        # (utf-8-sig: a byte-order mark, which editors on Windows write, is not part of the text)
        text = raw.decode("utf-8-sig")
        if path.lower().endswith(".toml"):
            return tomllib.loads(text)
        return json.loads(text)
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not a UTF-8 text file") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: malformed TOML: {e}") from None
    except json.JSONDecodeError as e:
        raise SceneError(f"{path}: malformed JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
