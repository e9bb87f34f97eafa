"""Jupyter widgets: :class:`MaterialTuner` (the tuner and its panels) and the orbit canvas.

:mod:`~draaw_mi.widgets.tuning` holds the tuner's helpers that need no widgets (plain numpy)
and imports without ipywidgets; :class:`MaterialTuner` (:mod:`~draaw_mi.widgets.tuner`, with
the panels :mod:`~draaw_mi.widgets.camera_panel`, :mod:`~draaw_mi.widgets.lights_panel`,
:mod:`~draaw_mi.widgets.post_panel`, :mod:`~draaw_mi.widgets.save_panel`; its scene rebuilds in
:mod:`~draaw_mi.widgets.rebuild`) and
:class:`OrbitCanvas` (:mod:`~draaw_mi.widgets.orbit_canvas`) need the ``notebooks`` extra and
are imported when first named::

    from draaw_mi.widgets import MaterialTuner      # pip install 'draaw-mi[notebooks]'
"""
from __future__ import annotations

import importlib

from . import tuning

# name -> module that defines it; these modules import ipywidgets / jupyter_rfb (optional)
_NEEDS_NOTEBOOK_EXTRA = {"MaterialTuner": "tuner", "scaled_resolution": "tuner", "OrbitCanvas": "orbit_canvas"}


def __getattr__(name: str):
    if name in _NEEDS_NOTEBOOK_EXTRA:
        return getattr(importlib.import_module(f"{__name__}.{_NEEDS_NOTEBOOK_EXTRA[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["MaterialTuner", "OrbitCanvas", "scaled_resolution", "tuning"]
