"""What the ``draaw-mi`` subcommands share: the one-line error, its exit status, the progress
mode and small readers of option values (:mod:`draaw_mi.cli`, :mod:`draaw_mi.cli.bench`)."""
from __future__ import annotations

import json

from ..progress import progress_mode as mode

EXIT_BAD_INPUT = 2
PROGRESS_HELP = ("no progress report (by default a bar on a terminal, else a line every "
                 "10 s on standard error)")


class CliError(Exception):
    """Bad command-line input: printed as one line, exit status 2."""


def progress_mode(no_progress: bool):
    """A bar on a terminal, lines now and then in a log or pipe, none with ``--no-progress``
    (:func:`draaw_mi.progress.progress_mode`; imported late, as draaw_mi checks the set-up)."""
    return mode(no_progress)


def read_json(path: str, option: str):
    """The JSON document in ``path`` (named ``option`` in the one-line error)."""
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except OSError as e:
        raise CliError(f"{option} {path!r}: cannot read it ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise CliError(f"{option} {path!r}: not a text (UTF-8 JSON) file") from None
    except json.JSONDecodeError as e:
        raise CliError(f"{option} {path!r}: malformed JSON at line {e.lineno} column {e.colno}: "
                       f"{e.msg}") from None


def int_list(text, name):
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise CliError(f"{name} {text!r}: expected comma-separated integers") from None
    if not values:
        raise CliError(f"{name} is empty")
    return values
