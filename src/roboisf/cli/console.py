"""Terminal output for the CLI: verbosity, one-line errors, rich progress bars."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from roboisf.progress import Advance, noop_advance

__all__ = ["RichProgress", "state"]


class _State:
    """Process-wide CLI verbosity (set by the root callback; -q → 0, default 1, -v → 2)."""

    def __init__(self) -> None:
        self.verbosity = 1
        # messages carry user values (paths, names): never read them as emoji codes or markup
        self.out = Console(highlight=False, emoji=False)
        self.err = Console(stderr=True, highlight=False, emoji=False)

    def info(self, msg: str) -> None:
        if self.verbosity >= 1:
            self.out.print(msg, markup=False, soft_wrap=True)

    def debug(self, msg: str) -> None:
        if self.verbosity >= 2:
            self.err.print(f"[dim]{escape(msg)}[/dim]")

    def warn(self, msg: str) -> None:
        if self.verbosity >= 1:
            self.err.print(f"[yellow]warning:[/yellow] {escape(msg)}", soft_wrap=True)

    def progress(self) -> RichProgress | None:
        return RichProgress(self.err) if self.verbosity >= 1 else None


state = _State()


class RichProgress:
    """:class:`roboisf.progress.Progress` on a rich progress bar (stderr, transient)."""

    def __init__(self, console: Console) -> None:
        self.console = console

    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Advance]:
        if not self.console.is_terminal and not sys.stderr.isatty():
            # keep logs readable when piped: one line per stage
            self.console.print(f"{description} …", markup=False)
            yield noop_advance
            return
        cols = [
            TextColumn("{task.description}"),
            BarColumn(),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
        ]
        with Progress(*cols, console=self.console, transient=True) as bar:
            tid = bar.add_task(escape(description), total=total)

            def advance(amount: float = 1.0) -> None:
                bar.advance(tid, amount)

            yield advance
