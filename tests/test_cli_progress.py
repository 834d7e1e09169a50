"""The CLI's rich progress: one live display for nested tasks and tasks of worker threads."""

from __future__ import annotations

import io
import threading

import pytest
from rich.console import Console

from roboisf.cli.console import RichProgress


def _terminal() -> tuple[Console, io.StringIO]:
    buf = io.StringIO()
    return Console(file=buf, force_terminal=True, width=100), buf


def test_tasks_from_two_threads_share_one_display_and_it_stops_after_the_last():
    console, buf = _terminal()
    p = RichProgress(console)
    started, release = threading.Event(), threading.Event()
    seen: list[int] = []

    def worker() -> None:
        with p.task("scan robot") as advance:
            with p.task("outlier removal", total=2):
                advance(1.0)
                started.set()
                release.wait(5)

    t = threading.Thread(target=worker)
    t.start()
    assert started.wait(5)
    with p.task("alignment of the logs"):
        bar = p._bar
        assert bar is not None
        seen.append(len(bar.tasks))  # three tasks open at once, one display
        release.set()
        t.join(5)
        assert p._bar is bar  # still open: this task has not ended
    assert seen == [3]
    assert p._bar is None and p._open == 0
    assert not bar.live.is_started
    assert "outlier removal" in buf.getvalue() or "alignment" in buf.getvalue()


def test_an_error_inside_a_task_closes_the_display():
    console, _ = _terminal()
    p = RichProgress(console)
    with pytest.raises(ValueError, match="bad log"), p.task("alignment"):
        raise ValueError("bad log")
    assert p._bar is None and p._open == 0


def test_a_nested_step_names_the_step_it_runs_in_in_its_own_thread(monkeypatch):
    # piped (a CI log): one line per stage; the two scans' steps, one scan in a worker thread
    # and one in the calling thread, are told apart by the step each runs in
    buf = io.StringIO()
    monkeypatch.setattr("sys.stderr", io.StringIO())  # not a terminal
    p = RichProgress(Console(file=buf, force_terminal=False, width=200))

    def worker() -> None:
        with p.task("scan cnc"), p.task("outlier removal"):
            pass

    with p.task("analyze"):  # open in this thread while the worker's steps run
        t = threading.Thread(target=worker)
        t.start()
        t.join(5)
        with p.task("scan robot"), p.task("register (fixture)"):
            pass
        with p.task("report", total=3) as advance:
            advance(1.0)
    lines = buf.getvalue().splitlines()
    assert lines == [
        "analyze …",
        "scan cnc …",  # the worker's own outermost step
        "scan cnc › outlier removal …",
        "analyze › scan robot …",
        "scan robot › register (fixture) …",
        "analyze › report …",
    ]


@pytest.mark.parametrize("terminal", [True, False])
def test_verbose_writes_each_step_s_time_when_it_ends(terminal, monkeypatch):
    """``-v``: every step leaves its label (nested ones with their parent) and wall time, on a
    terminal and in a piped log; without it, no timing line."""
    import re

    if not terminal:
        monkeypatch.setattr("sys.stderr", io.StringIO())
    for timings in (True, False):
        buf = io.StringIO()
        console = Console(file=buf, force_terminal=terminal, width=100)
        p = RichProgress(console, timings=timings)
        with p.task("scan cnc"), p.task("outlier removal"):
            pass
        lines = re.findall(r"(scan cnc(?: › outlier removal)?): (\d+\.\d\d) s", buf.getvalue())
        if timings:
            assert [name for name, _ in lines] == ["scan cnc › outlier removal", "scan cnc"]
        else:
            assert lines == []


def test_the_cli_state_gives_timings_with_v_only():
    from roboisf.cli.console import _State

    s = _State()
    s.verbosity = 1
    assert s.progress() is not None and not s.progress().timings
    s.verbosity = 2
    assert s.progress().timings
    s.verbosity = 0
    assert s.progress() is None
