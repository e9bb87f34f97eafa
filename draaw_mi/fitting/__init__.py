"""Inverse fitting: material (and light, SDF) parameters from reference images.

* :mod:`~draaw_mi.fitting.fitter` -- :func:`fit`, in phases (validate, set up, iterate, report);
* :mod:`~draaw_mi.fitting.params` -- each parameter's range and the space Adam moves it in;
* :mod:`~draaw_mi.fitting.reference` -- references from EXR/PNG files or arrays;
* :mod:`~draaw_mi.fitting.views` -- the views' sensors and each view's loss;
* :mod:`~draaw_mi.fitting.result` -- :class:`FitResult` and when a run counts as converged.
"""
from __future__ import annotations

from .fitter import fit
from .reference import load_reference
from .result import FitResult

__all__ = ["FitResult", "fit", "load_reference"]
