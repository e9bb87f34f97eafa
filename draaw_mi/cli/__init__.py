"""The ``draaw-mi`` command line: :func:`main` and its subcommands.

* :mod:`~draaw_mi.cli.commands` -- :func:`main` and the ``render``, ``post``, ``fit`` and
  ``batch`` subcommands;
* :mod:`~draaw_mi.cli.parser` -- every subcommand's arguments;
* :mod:`~draaw_mi.cli.scenes` -- what the commands that read a scene share (``-D NAME=VALUE``
  for a Mitsuba XML file, a manifest told from a scene, the note on an XML scene's own
  integrator) and the ``info`` subcommand;
* :mod:`~draaw_mi.cli.bench` -- ``bench`` (the accuracy/time study, the SDF study, the speed
  suite, denoised points);
* :mod:`~draaw_mi.cli.common` -- the one-line error and its exit status, shared options.
"""
from __future__ import annotations

from .._lazy import old_names
from .commands import main

__all__ = ["main"]

# names draaw_mi/cli.py had, served from their new modules with a DeprecationWarning
__getattr__ = old_names(__name__, dict.fromkeys(
    ("CliError", "EXIT_BAD_INPUT", "PROGRESS_HELP", "progress_mode", "read_json"), f"{__name__}.common"))
