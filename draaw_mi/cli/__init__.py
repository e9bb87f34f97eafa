"""The ``draaw-mi`` command line: :func:`main` and its subcommands.

* :mod:`~draaw_mi.cli.commands` -- the parser and the ``render``, ``info``, ``post``, ``fit``
  and ``batch`` subcommands;
* :mod:`~draaw_mi.cli.bench` -- ``bench`` (the accuracy/time study, the SDF study, the speed
  suite, denoised points);
* :mod:`~draaw_mi.cli.common` -- the one-line error and its exit status, shared options.
"""
from __future__ import annotations

from .commands import main

__all__ = ["main"]
