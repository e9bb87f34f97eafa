"""The keyword arguments of :func:`draaw_mi.fit`, checked before anything renders
(:func:`validate`): a bad value is a :class:`~draaw_mi.errors.ParameterError` that names it."""
from __future__ import annotations

import numbers

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .views import LOSSES


@dataclass(kw_only=True)
class FitSettings:
    """:func:`fit`'s keyword arguments, checked (see its docstring for each; the defaults are
    :func:`fit`'s)."""
    version: str | None
    spp: int
    iterations: int
    lr: float
    loss: str
    post: object
    progress: bool | str
    seed: int
    exposure: str
    init: dict | None
    max_depth: int | None
    average_last: float
    tol: float
    resolution: object
    lr_final: float
    spp_grad: int | None
    beta_2: float
    smooth: bool | None
    integrator_options: dict | None = None
    maps: object = None                # MapOptions
    batch: int | None = None
    polish: int = 0
    polish_spp: int | None = None


def check_counts(who: str, optional: tuple = (), **counts) -> None:
    """ParameterError naming ``who`` for the first ``name=(value, lowest)`` whose value is not
    an integer >= lowest (None passes for the names in ``optional``: their default).

    >>> check_counts("fit", ("polish_spp",), spp=(16, 1), polish_spp=(None, 1))
    >>> check_counts("fit", polish=(-1, 0))
    Traceback (most recent call last):
    ...
    draaw_mi.errors.ParameterError: fit: polish=-1; expected an integer >= 0
    """
    for name, (value, lo) in counts.items():
        if value is None and name in optional:
            continue
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
            raise ParameterError(f"{who}: {name}={value!r}; expected an integer >= {lo}")


def validate(s: FitSettings) -> FitSettings:
    """``s`` with every value checked: a bad one is a :class:`ParameterError` naming it."""
    if s.loss not in LOSSES:
        raise ParameterError(f"fit: loss={s.loss!r}; expected one of {', '.join(LOSSES)}")
    if s.exposure not in ("fixed", "fit"):
        raise ParameterError(f"fit: exposure={s.exposure!r}; expected 'fixed' or 'fit'")
    if s.integrator_options is not None and not isinstance(s.integrator_options, dict):
        raise ParameterError(f"fit: integrator_options={s.integrator_options!r}; expected a dict of "
                             "integrator properties")
    check_counts("fit", ("spp_grad", "polish_spp"), spp=(s.spp, 1), iterations=(s.iterations, 1),
                 spp_grad=(s.spp_grad, 1), polish=(s.polish, 0), polish_spp=(s.polish_spp, 1))
    if isinstance(s.lr, bool) or not (isinstance(s.lr, numbers.Real) and 0 < s.lr < float("inf")):
        raise ParameterError(f"fit: lr={s.lr!r}; expected a positive finite number")
    if isinstance(s.seed, bool) or not isinstance(s.seed, numbers.Integral) or not 0 <= s.seed <= 0xFFFFFFFF:
        raise ParameterError(f"fit: seed={s.seed!r}; expected an integer in [0, {0xFFFFFFFF}]")
    if not (isinstance(s.average_last, numbers.Real) and 0 < s.average_last <= 1):
        raise ParameterError(f"fit: average_last={s.average_last!r}; expected a fraction in (0, 1]")
    # lr_final in [0, 1] (below 0 the averaged iterations climb the loss), beta_2 in [0, 1)
    for name, value, hi_open in (("lr_final", s.lr_final, False), ("beta_2", s.beta_2, True)):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (
                0 <= value < 1 if hi_open else 0 <= value <= 1):
            raise ParameterError(f"fit: {name}={value!r}; expected a number in [0, 1{')' if hi_open else ']'}")
    if isinstance(s.tol, bool) or not isinstance(s.tol, numbers.Real) or not s.tol >= 0:
        raise ParameterError(f"fit: tol={s.tol!r}; expected a number >= 0")
    if s.batch is not None and (isinstance(s.batch, bool) or not isinstance(s.batch, numbers.Integral) or s.batch < 1):
        raise ParameterError(f"fit: batch={s.batch!r}; expected an integer >= 1 (views per iteration) or None")
    if s.max_depth is not None and (isinstance(s.max_depth, bool) or not isinstance(s.max_depth, numbers.Integral)
                                    or s.max_depth < -1):
        raise ParameterError(f"fit: max_depth={s.max_depth!r}; expected an integer >= -1 (-1: unbounded) "
                             "or None (the scene's)")
    if s.smooth is not None and not isinstance(s.smooth, (bool, np.bool_)):
        raise ParameterError(f"fit: smooth={s.smooth!r}; expected True, False or None")
    return s
