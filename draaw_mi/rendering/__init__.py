"""Rendering: the public :func:`render`, one :class:`Session` per scene, previews, denoising.

* :mod:`~draaw_mi.rendering.session` -- the one place a pass is rendered (traced or replayed
  from a ``dr.freeze`` recording), with the scene's lock, integrators, recordings and worker
  threads;
* :mod:`~draaw_mi.rendering.renderer` -- :func:`render`: settings, passes, progress, budget,
  denoising and the post chain around the session's passes;
* :mod:`~draaw_mi.rendering.passes`, :mod:`~draaw_mi.rendering.frozen`,
  :mod:`~draaw_mi.rendering.film_colour`, :mod:`~draaw_mi.rendering.subsample` (adaptive
  subsampling), :mod:`~draaw_mi.rendering.denoiser` (Intel OIDN);
* :mod:`~draaw_mi.rendering.preview` and its worker thread
  (:mod:`~draaw_mi.rendering.preview_worker`): progressive running-mean previews.
"""
from __future__ import annotations

from .denoiser import denoise
from .preview import Preview, PreviewFrame, PreviewSuperseded
from .renderer import render
from .session import Session, close_all, session_of

__all__ = ["Preview", "PreviewFrame", "PreviewSuperseded", "Session", "close_all", "denoise", "render", "session_of"]
