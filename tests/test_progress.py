"""Progress reports: a bar on a terminal, whole lines at a bounded rate in a log, refused modes."""
from __future__ import annotations

import io

import pytest

from draaw_mi.errors import ParameterError
from draaw_mi.progress import LineProgress, progress_bar, progress_mode


class Clock:
    """A clock the test moves by hand."""

    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_lines_are_written_at_most_every_interval_and_at_the_end():
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(100, "batch", "frames", file=out, every=10.0, clock=clock)
    for _ in range(100):          # one step every 0.5 s: 50 s in all
        clock.now += 0.5
        bar.update(1)
    bar.close()
    lines = out.getvalue().splitlines()
    # one line when 10 s have passed (steps 20, 40, 60, 80), one at the last step, none at close
    assert [line.split(",")[0] for line in lines] == [f"batch: {n}/100 frames ({n} %)"
                                                      for n in (20, 40, 60, 80, 100)]
    assert "\r" not in out.getvalue()


def test_a_line_tells_elapsed_time_eta_and_the_postfix():
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(8, "fit", "it", file=out, every=5.0, clock=clock)
    clock.now += 6.0
    bar.set_postfix(done=2, failed=1)
    bar.update(2)
    # 2 of 8 in 6 s: 18 s to go at that rate
    assert out.getvalue() == "fit: 2/8 it (25 %), 6.0 s, ETA 18 s, done=2 failed=1\n"


def test_close_writes_the_last_state_once():
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(10, "render", "spp", file=out, every=60.0, clock=clock)
    bar.update(3)                 # stopped early (a time budget): no line yet
    bar.close()
    bar.close()
    # (it said "ETA 0 s": no time was left to estimate)
    assert out.getvalue().splitlines() == ["render: 3/10 spp (30 %), 0.0 s, stopped"]


def test_close_before_any_step_still_writes_one_line():
    """A report stopped before its first step (a time budget spent on the warm-up) wrote
    nothing: "nothing new since the last line" was taken for step 0. Closing it writes its
    one line, once."""
    out, clock = io.StringIO(), Clock()
    bar = LineProgress(10, "render", "spp", file=out, every=60.0, clock=clock)
    bar.close()
    bar.close()
    assert out.getvalue().splitlines() == ["render: 0/10 spp (0 %), 0.0 s, stopped"]


class Stream(io.StringIO):
    def __init__(self, tty):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


def test_command_line_mode_follows_the_stream():
    assert progress_mode(False, Stream(True)) == "bar"
    assert progress_mode(False, Stream(False)) == "lines"
    assert progress_mode(True, Stream(True)) is False


def test_modes_are_checked_by_name():
    assert progress_bar(3, "x", "it", False) is None
    assert isinstance(progress_bar(3, "x", "it", "lines", file=io.StringIO()), LineProgress)
    with pytest.raises(ParameterError, match=r"fit: progress='yes'; expected False, True, 'bar' or 'lines'"):
        progress_bar(3, "x", "it", "yes", where="fit")


@pytest.mark.parametrize("mode", [1, 0, 1.0, 0.0])
def test_numbers_equal_to_true_or_false_are_not_modes(mode):
    """``progress=1`` (or 0, 1.0) passed as True / False (1 == True in Python); a mode is
    one of False, None, True, 'bar' or 'lines' by identity, a string by value."""
    with pytest.raises(ParameterError, match=rf"fit: progress={mode!r}; expected False, True"):
        progress_bar(3, "x", "it", mode, where="fit")


def test_render_refuses_a_bad_mode_before_it_loads_anything():
    import draaw_mi
    with pytest.raises(ParameterError, match="render: progress=2"):
        draaw_mi.render("no-such-scene.toml", progress=2)



def test_true_is_a_bar_where_someone_watches_and_lines_in_a_log(monkeypatch):
    """``fit(...)``'s default ``progress=True`` wrote tqdm's carriage-return bars into a
    script's log; there it writes lines, and a bar on a terminal or in a notebook."""
    import tqdm.auto
    from draaw_mi import progress as P
    log = io.StringIO()
    assert isinstance(progress_bar(3, "fit", "it", True, file=log), LineProgress)
    bars = []
    monkeypatch.setattr(tqdm.auto, "tqdm", lambda **k: bars.append(k) or "bar")
    assert progress_bar(3, "fit", "it", True, file=Stream(True)) == "bar"          # a terminal
    OutStream = type("OutStream", (io.StringIO,), {"__module__": "ipykernel.iostream"})
    assert P.watched(OutStream()) and progress_bar(3, "fit", "it", True, file=OutStream()) == "bar"
    assert progress_bar(3, "fit", "it", "bar", file=log) == "bar" and len(bars) == 3   # asked for


@pytest.mark.parametrize("mode", ["lines", "bar"])
def test_an_interrupted_render_closes_its_bar(mode, monkeypatch, capsys):
    """A render stopped by Ctrl-C (or a pass's error) left its bar open: in a terminal the next
    bar was drawn a line lower, and a log never got the last line. Its bar is closed (the
    log's last line says ``stopped``), as is a tqdm bar."""
    import sys
    import draaw_mi
    from draaw_mi.rendering.session import Session
    sys.path.insert(0, "tests")
    from conftest import tiny_description
    import tqdm.auto
    made = []
    real_tqdm = tqdm.auto.tqdm
    monkeypatch.setattr(tqdm.auto, "tqdm", lambda **k: made.append(real_tqdm(**k)) or made[-1])
    scene = draaw_mi.load_scene(tiny_description(resolution=[8, 6]))
    real = Session.render_pass
    passes = []

    def third_is_interrupted(self, *a, **k):
        passes.append(1)
        if len(passes) == 3:
            raise KeyboardInterrupt
        return real(self, *a, **k)
    monkeypatch.setattr(Session, "render_pass", third_is_interrupted)
    with pytest.raises(KeyboardInterrupt):
        draaw_mi.render(scene, spp=8, pass_spp=1, progress=mode, post=[])
    assert len(passes) == 3
    if mode == "lines":
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert last.startswith("render v4: 2/8 spp (25 %)") and "stopped" in last, last
    else:
        assert len(made) == 1 and made[0].disable               # (tqdm's close disables it)
