"""Figures for files, drawn without pyplot: no backend switch, no global figure list.

``matplotlib.use("Agg")`` inside a library call would switch a notebook's inline backend for the
rest of the session (its next ``plt.show()`` would draw nothing). A :class:`matplotlib.figure.Figure`
made directly renders with its own Agg canvas and is garbage-collected like any object; a
notebook still displays one returned as a cell's value.

>>> import os, tempfile
>>> fig, ax = subplots(figsize=(2, 2))
>>> _ = ax.plot([0, 1], [1, 0])
>>> path = os.path.join(tempfile.mkdtemp(), "p.png")
>>> save(fig, path); os.path.getsize(path) > 0
True
"""
from __future__ import annotations

from .io import atomic_path


def subplots(nrows: int = 1, ncols: int = 1, figsize=(6.4, 4.8), **kwargs):
    """``(figure, axes)`` as :func:`matplotlib.pyplot.subplots` returns them, without pyplot."""
    from matplotlib.figure import Figure  # (0.25 s to import: paid by plots only)
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save(fig, path: str, dpi: int = 100) -> None:
    """Write ``fig`` to ``path`` as PNG, atomically (:func:`draaw_mi.io.atomic_path`)."""
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
