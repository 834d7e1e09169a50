"""Terminal output for the CLI: verbosity, one-line errors, rich progress bars.

rich is imported on the first message, not with the CLI: ``--help`` and usage errors never print
through it (docs/conventions.md, Command start-up).
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from roboisf.progress import Advance, noop_advance

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["RichProgress", "state"]


class _State:
    """Process-wide CLI verbosity (set by the root callback; -q → 0, default 1, -v → 2), and
    whether the process is the command's own (``own_process``: set by the console script,
    :func:`roboisf.cli.main.entry`; False when :func:`~roboisf.cli.main.main` is called inside
    another program, whose process settings a command must then leave alone)."""

    def __init__(self) -> None:
        self.verbosity = 1
        self.own_process = False
        self._out: Console | None = None
        self._err: Console | None = None

    def imports_done(self) -> None:
        """A command's libraries are loaded: in the command's own process, move every object
        alive now (modules, classes, functions: ~250 k with numba and pandas) to the garbage
        collector's permanent generation, so its full collections during the run no longer
        walk them (0.1 s of `roboisf analyze`'s GIL time). Nothing inside another program."""
        if self.own_process:
            import gc

            gc.freeze()

    @property
    def out(self) -> Console:
        """The stdout console (created on first use)."""
        if self._out is None:
            self._out = _console(stderr=False)
        return self._out

    @property
    def err(self) -> Console:
        """The stderr console (created on first use)."""
        if self._err is None:
            self._err = _console(stderr=True)
        return self._err

    def info(self, msg: str) -> None:
        if self.verbosity >= 1:
            self.out.print(msg, markup=False, soft_wrap=True)

    def notice(self, msg: str) -> None:
        """A line on stderr (not -q): what is happening that takes long, e.g. a first compile."""
        if self.verbosity >= 1:
            self.err.print(msg, markup=False, soft_wrap=True)

    def debug(self, msg: str) -> None:
        if self.verbosity >= 2:
            from rich.markup import escape

            self.err.print(f"[dim]{escape(msg)}[/dim]")

    def warn(self, msg: str) -> None:
        if self.verbosity >= 1:
            from rich.markup import escape

            self.err.print(f"[yellow]warning:[/yellow] {escape(msg)}", soft_wrap=True)

    def progress(self) -> RichProgress | None:
        """The progress display on stderr (None with -q); with -v it also writes each step's
        time as the step ends."""
        if self.verbosity < 1:
            return None
        return RichProgress(self.err, timings=self.verbosity >= 2)


def _console(stderr: bool) -> Console:
    from rich.console import Console

    # messages carry user values (paths, names): never read them as emoji codes or markup
    return Console(stderr=stderr, highlight=False, emoji=False)


state = _State()


class RichProgress:
    """:class:`roboisf.progress.Progress` on a rich progress bar (stderr, transient).

    One live display for all open tasks: nested tasks and tasks opened from worker threads (the
    analysis compares the scans while it reads the logs) are lines of the same display, added
    and removed under a lock; the display stops when the last task ends. A nested task is
    labelled with the task it runs in, in its own thread ("scan robot › outlier removal"): the
    two scans' steps, run in two threads, are told apart — also in the one line per stage
    written when stderr is not a terminal (a CI log). ``timings`` (``-v``): every step, when
    it ends, leaves a line with its label and wall time (``scan cnc › outlier removal: 0.41 s``)
    — where a run's time went, on a terminal and in a log alike."""

    def __init__(self, console: Console, *, timings: bool = False) -> None:
        self.console = console
        self.timings = timings
        self._lock = threading.Lock()
        self._bar: Any = None
        self._open = 0
        self._local = threading.local()  # each thread's open tasks, outermost first

    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Advance]:
        stack: list[str] = self._local.__dict__.setdefault("stack", [])
        label = f"{stack[-1]} › {description}" if stack else description
        stack.append(description)
        t0 = time.perf_counter()
        try:
            with self._show(label, total) as advance:
                yield advance
        finally:
            stack.pop()
            if self.timings:
                from rich.markup import escape

                dt = time.perf_counter() - t0
                self.console.print(
                    f"[dim]{escape(label)}: {dt:.2f} s[/dim]", soft_wrap=True, highlight=False
                )

    @contextlib.contextmanager
    def _show(self, label: str, total: float | None) -> Iterator[Advance]:
        if not self.console.is_terminal and not sys.stderr.isatty():
            # keep logs readable when piped: one line per stage
            self.console.print(f"{label} …", markup=False)
            yield noop_advance
            return
        from rich.markup import escape

        with self._lock:
            if self._bar is None:
                self._bar = self._new_bar()
                self._bar.start()
            bar = self._bar
            self._open += 1
            tid = bar.add_task(escape(label), total=total)

        def advance(amount: float = 1.0) -> None:
            bar.advance(tid, amount)

        try:
            yield advance
        finally:
            with self._lock:
                bar.remove_task(tid)
                self._open -= 1
                if self._open == 0:
                    bar.stop()
                    self._bar = None

    def _new_bar(self) -> Any:
        from rich.progress import (
            BarColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        cols = [
            TextColumn("{task.description}"),
            BarColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
        ]
        return Progress(*cols, console=self.console, transient=True)
