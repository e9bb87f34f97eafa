"""The exception hierarchy of draaw-mi: everything it raises on bad input is a DraawError."""
from __future__ import annotations

import difflib
import os
import re
import sys
from typing import Any, Iterable

import numpy as np

_PACKAGE = os.path.dirname(os.path.abspath(__file__)) + os.sep


def user_stacklevel() -> int:
    """The ``stacklevel`` that points a ``warnings.warn`` made by this function's caller at the
    first frame outside draaw-mi (the user's line, however deep the loader's calls)."""
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    return level


class DraawError(Exception):
    """Base class of every error draaw-mi raises for bad input or a bad environment.

    The message is one line that names the file or function, the field, the bad value and
    what was expected, so the CLI can print it as is.
    """


class SceneError(DraawError, ValueError):
    """A scene description (TOML, JSON, dict, XML or mesh) is malformed or inconsistent."""


class ParameterError(DraawError, ValueError):
    """A parameter value is out of its range or of the wrong type."""


class RenderError(DraawError, RuntimeError):
    """A render request cannot be carried out (bad version, spp, resolution, ...)."""


class IOFailure(DraawError, OSError):
    """An image or scene file cannot be read or written."""


class BusyError(DraawError, RuntimeError):
    """A resource is held by another draaw-mi process (a batch output folder)."""


class NonFiniteWarning(RuntimeWarning):
    """A render holds NaN or inf values (:func:`draaw_mi.render` says which parameter made them
    where it can); callers that report them their own way filter this category."""


def suggest(name: str, valid: Iterable[str]) -> str:
    """A ``"; did you mean 'x'?"`` suffix for an unknown ``name``, or a list of valid names.

    >>> suggest('roughnes', ['roughness', 'metallic'])
    "; did you mean 'roughness'?"
    >>> suggest('x', [])
    ' (there are none)'
    """
    valid = sorted(set(valid))
    if not valid:              # (not "; valid: " with nothing after it: a scene with no materials)
        return " (there are none)"
    close = difflib.get_close_matches(name, valid, n=1, cutoff=0.6)
    if close:
        return f"; did you mean {close[0]!r}?"
    return "; valid: " + ", ".join(valid)


def shown(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, for error messages (a texture given
    inline as nested lists would print thousands of numbers).

    >>> shown([[0.5, 0.5, 0.5]] * 64)
    '[[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0. ... (a list of 64)'
    >>> shown(0.25)
    '0.25'
    >>> import numpy as np; shown(np.full((8, 8, 3), np.nan))
    'an array of shape (8, 8, 3), all NaN or inf'
    >>> shown(np.full((8, 8, 3), 1.5))
    'an array of shape (8, 8, 3) in [1.5, 1.5]'
    """
    shape = getattr(value, "shape", None)
    if isinstance(shape, tuple) and len(shape) >= 2 and hasattr(value, "dtype"):
        a = np.asarray(value, dtype=np.float64)      # (an array: its shape and range, not its repr)
        bad = int(np.sum(~np.isfinite(a)))
        finite = a[np.isfinite(a)]
        if not finite.size:
            return f"an array of shape {shape}, all NaN or inf"
        rng = f"[{finite.min():.4g}, {finite.max():.4g}]"
        return f"an array of shape {shape}" + (f": {bad} NaN or inf, the rest in {rng}" if bad else f" in {rng}")
    text = repr(value)
    if len(text) <= limit:
        return text
    size = f" (a {type(value).__name__} of {len(value)})" if hasattr(value, "__len__") else ""
    return text[:limit] + " ..." + size


def exception_chain(error: BaseException, suppressed: bool = False) -> list[BaseException]:
    """``error`` and the exceptions it was raised from (``raise ... from``) or while handling,
    outermost first; a cycle ends it. ``suppressed``: stop where ``raise ... from None``
    suppressed the context.

    >>> try:
    ...     raise RuntimeError("drjit.custom(): error (see above)") from ValueError("the BSDF failed")
    ... except RuntimeError as e:
    ...     [type(x).__name__ for x in exception_chain(e)]
    ['RuntimeError', 'ValueError']
    """
    chain, seen, e = [], set(), error
    while e is not None and id(e) not in seen:
        chain.append(e)
        seen.add(id(e))
        e = e.__cause__ if e.__cause__ is not None or (suppressed and e.__suppress_context__) \
            else e.__context__
    return chain


def caused_by_interrupt(error: BaseException) -> bool:
    """Whether ``error`` was raised because of a ``KeyboardInterrupt``: Dr.Jit's custom
    operations (``mi.render`` is one) and frozen functions raise Ctrl-C in their kernels again
    as a ``RuntimeError`` caused by it.

    >>> try:
    ...     raise RuntimeError("drjit.custom(): error (see above)") from KeyboardInterrupt()
    ... except RuntimeError as e:
    ...     caused_by_interrupt(e), caused_by_interrupt(RuntimeError("other"))
    (True, False)
    """
    return any(isinstance(e, KeyboardInterrupt) for e in exception_chain(error))


# the last line of a Python traceback that Mitsuba's error text carries when a Python plugin's
# constructor was interrupted ("KeyboardInterrupt: ", "draaw_mi.cli.commands.Terminated: ")
_INTERRUPT_LINE = re.compile(r"^\s*(?:[\w.]+\.)?(?:KeyboardInterrupt|Terminated):", re.M)


def raise_if_interrupted(error: BaseException) -> None:
    """Raise the ``KeyboardInterrupt`` behind ``error`` (Ctrl-C, or the CLI's SIGTERM) as it
    is, where a caller would otherwise wrap ``error`` in a :class:`DraawError`: one in its
    chain (:func:`caused_by_interrupt`), or one that Mitsuba's ``RuntimeError`` names only in
    its text (a Python plugin's constructor interrupted while ``mi.load_dict`` made it). Else
    return. An ``except DraawError`` loop would go on past Ctrl-C, and the CLI would exit 2
    instead of 130.

    >>> try:
    ...     raise_if_interrupted(RuntimeError('failed to instantiate "draaw_v4": Traceback ...\\nKeyboardInterrupt: '))
    ... except KeyboardInterrupt:
    ...     print("interrupted")
    interrupted
    >>> raise_if_interrupted(RuntimeError("unreferenced property"))
    """
    for cause in exception_chain(error):
        if isinstance(cause, KeyboardInterrupt):
            raise cause
    if isinstance(error, RuntimeError) and _INTERRUPT_LINE.search(str(error)):
        raise KeyboardInterrupt from None
