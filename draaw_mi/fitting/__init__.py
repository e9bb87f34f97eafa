"""Inverse fitting: material (and light, SDF) parameters and texture maps from reference images.

* :mod:`~draaw_mi.fitting.fitter` -- :func:`fit`, in phases (validate, set up, iterate, report);
* :mod:`~draaw_mi.fitting.settings` -- its keyword arguments, checked;
* :mod:`~draaw_mi.fitting.polish` -- ``fit(polish=N)``: its last steps at more samples per pixel;
* :mod:`~draaw_mi.fitting.params` -- each parameter's range and the space Adam moves it in;
* :mod:`~draaw_mi.fitting.maps` -- texture maps as multi-scale latents kept in range;
* :mod:`~draaw_mi.fitting.two_starts` -- :func:`fit_two_starts`: maps from two starts of their metallic maps, merged;
* :mod:`~draaw_mi.fitting.captures` -- each reference's camera and lights (:func:`render_capture`);
* :mod:`~draaw_mi.fitting.reference` -- references from EXR/PNG files or arrays;
* :mod:`~draaw_mi.fitting.views` -- the views' sensors and each view's loss;
* :mod:`~draaw_mi.fitting.result` -- :class:`FitResult` and when a run counts as converged;
* :mod:`~draaw_mi.fitting.map_outputs` -- fitted maps as files, their errors, a figure.
"""
from __future__ import annotations

from .captures import render_capture
from .fitter import fit
from .maps import MapOptions
from .reference import load_reference
from .result import FitResult
from .two_starts import fit_two_starts

__all__ = ["FitResult", "MapOptions", "fit", "fit_two_starts", "load_reference", "render_capture"]
