"""Progress reports for long work: a tqdm bar on a terminal, plain lines in a log.

A batch run under ``nohup`` or a scheduler writes its standard error to a file, where a tqdm
bar is either hidden (the command line turns it off away from a terminal) or a stream of
carriage returns. There :class:`LineProgress` writes a whole line now and then instead::

    batch: 6/24 frames (25 %), 12.4 s, ETA 37 s, done=6 failed=0

Every long-running function of draaw-mi takes ``progress``, read by :func:`progress_bar`:
``False``/``None`` for none, ``"bar"`` for a tqdm bar, ``"lines"`` for these lines, ``True``
for a bar where someone watches it (a terminal, a notebook) and lines elsewhere (a log file).

>>> import io
>>> out = io.StringIO()
>>> bar = progress_bar(4, "fit", "it", "lines", file=out, every=0.0)
>>> bar.update(2); bar.set_postfix(loss=0.5); bar.update(2); bar.close()
>>> print(out.getvalue().splitlines()[-1].split(", ")[0])
fit: 4/4 it (100 %)
"""
from __future__ import annotations

import contextlib
import sys
import time

from .errors import ParameterError

MODES = (False, None, True, "bar", "lines")

#: seconds between two lines of a :class:`LineProgress` (the last line is always written)
LINE_INTERVAL = 10.0


def progress_mode(no_progress: bool, stream=None) -> bool | str:
    """What a command-line tool passes as ``progress``: nothing with ``--no-progress``, a bar
    on a terminal, lines elsewhere (a log file, a pipe)."""
    if no_progress:
        return False
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    return "bar" if isatty is not None and isatty() else "lines"


def check_mode(progress, where: str):
    """``progress`` if it is one of :data:`MODES`, else a :class:`ParameterError` naming
    ``where``."""
    if not any(progress is m or (isinstance(m, str) and progress == m) for m in MODES):
        raise ParameterError(f"{where}: progress={progress!r}; expected False, True, 'bar' or 'lines'")
    return progress


def progress_bar(total: int, desc: str, unit: str, mode, *, leave: bool = True, file=None,
                 every: float = LINE_INTERVAL, where: str = "progress_bar"):
    """A progress report over ``total`` steps, or ``None`` when ``mode`` asks for none.

    ``mode``: ``"bar"`` a tqdm bar (``leave``: whether it stays when closed); ``"lines"`` a
    :class:`LineProgress` on ``file`` (standard error by default) at most every ``every``
    seconds; ``True`` the bar on a terminal or in a notebook, the lines elsewhere (a script's
    log got tqdm's carriage returns). Both have ``update``, ``set_postfix``,
    ``set_postfix_str``, ``close``. A bad ``mode`` raises :class:`ParameterError` naming
    ``where`` (the caller)."""
    check_mode(mode, where)
    if not mode:
        return None
    if mode is True:
        mode = "bar" if watched(sys.stderr if file is None else file) else "lines"
    if mode == "lines":
        return LineProgress(total, desc, unit, file=file, every=every)
    from tqdm.auto import tqdm  # (27 ms, and it probes for ipywidgets: paid by bars only)
    return tqdm(total=total, desc=desc, unit=unit, leave=leave, dynamic_ncols=True, file=file)


@contextlib.contextmanager
def closed_after(bar):
    """``bar`` (a :func:`progress_bar`, or ``None``) closed however the block ends: a render
    stopped by Ctrl-C or an error had left its bar open (the next bar drawn a line lower, a
    log's last line never written); :class:`LineProgress` ends with ``stopped``.

    >>> import io
    >>> out = io.StringIO()
    >>> try:
    ...     with closed_after(progress_bar(4, "render", "spp", "lines", file=out, every=60.0)) as bar:
    ...         bar.update(1)
    ...         raise KeyboardInterrupt
    ... except KeyboardInterrupt:
    ...     pass
    >>> out.getvalue().split(", ")[0], out.getvalue().split(", ")[2].strip()
    ('render: 1/4 spp (25 %)', 'stopped')
    """
    try:
        yield bar
    finally:
        if bar is not None:
            bar.close()


def watched(stream) -> bool:
    """Whether someone watches ``stream`` as it is written: a terminal, or a notebook's
    output (an IPython kernel's stream, where tqdm draws a widget).

    >>> import io
    >>> watched(io.StringIO())
    False
    """
    isatty = getattr(stream, "isatty", None)
    if isatty is not None and isatty():
        return True
    return type(stream).__module__.split(".")[0] == "ipykernel"


class LineProgress:
    """Progress as whole lines (``desc: n/total unit (p %), elapsed, ETA, postfix``), written
    when at least ``every`` seconds passed since the last one and when the work ends, so a
    log gets a bounded number of lines however many steps there are."""

    def __init__(self, total: int, desc: str, unit: str, file=None, every: float = LINE_INTERVAL,
                 clock=time.monotonic):
        self.total, self.desc, self.unit = int(total), desc, unit
        self.file, self.every, self.clock = file, float(every), clock
        self.n = 0
        self.postfix = ""
        self.start = self.last = clock()
        self.written_at = -1                     # self.n when the last line was written
        self.closed = False

    def update(self, n: int = 1):
        self.n += n
        now = self.clock()
        if now - self.last >= self.every or (self.total and self.n >= self.total):
            self._write(now)

    def set_postfix(self, refresh: bool = True, **values):
        """The ``key=value`` text of the next line (``refresh``: tqdm's argument, unused:
        lines are written by :meth:`update`)."""
        self.postfix = " ".join(f"{k}={v}" for k, v in values.items())

    def set_postfix_str(self, text: str):
        self.postfix = str(text)

    def close(self):
        self.closed = True
        if self.written_at != self.n:
            self._write(self.clock())

    def line(self, now: float) -> str:
        """The line for the present state, at time ``now`` of the clock."""
        elapsed = now - self.start
        parts = [f"{self.desc}: {self.n}/{self.total} {self.unit}"
                 + (f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""),
                 f"{elapsed:.1f} s"]
        if self.closed and self.n < self.total:
            parts.append("stopped")        # (a time budget: no time is left to estimate)
        elif 0 < self.n < self.total:
            parts.append(f"ETA {elapsed * (self.total - self.n) / self.n:.0f} s")
        if self.postfix:
            parts.append(self.postfix)
        return ", ".join(parts)

    def _write(self, now: float):
        stream = sys.stderr if self.file is None else self.file
        print(self.line(now), file=stream, flush=True)
        self.last, self.written_at = now, self.n
