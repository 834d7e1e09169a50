"""Progress reporting without a UI dependency in the core.

Library functions that take long accept ``progress: Progress | None``; they call
``with progress.task("assemble", total=n) as advance: advance(k)``. The CLI passes a rich-backed
implementation (``roboisf.cli.console``); library users get silence by default.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator
from typing import Protocol

__all__ = [
    "NULL_PROGRESS",
    "Cancelled",
    "Progress",
    "cancellable",
    "noop_advance",
    "notice_once",
    "set_notice",
    "task",
]

Advance = Callable[[float], None]


class Progress(Protocol):
    def task(
        self, description: str, total: float | None = None
    ) -> contextlib.AbstractContextManager[Advance]:
        """Context manager yielding ``advance(amount)``."""
        ...


def noop_advance(amount: float = 1.0) -> None:
    """An ``advance`` that does nothing."""


class _Null:
    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Advance]:
        yield noop_advance


NULL_PROGRESS: Progress = _Null()


def task(
    progress: Progress | None, description: str, total: float | None = None
) -> contextlib.AbstractContextManager[Advance]:
    """``progress.task(...)`` or a no-op when ``progress`` is None."""
    return (progress or NULL_PROGRESS).task(description, total)


class Cancelled(Exception):
    """Raised at a task boundary of work whose result is no longer wanted (:func:`cancellable`)."""


class _Cancellable:
    def __init__(self, progress: Progress | None, cancel: threading.Event) -> None:
        self._progress = progress or NULL_PROGRESS
        self._cancel = cancel

    @contextlib.contextmanager
    def task(self, description: str, total: float | None = None) -> Iterator[Advance]:
        if self._cancel.is_set():
            raise Cancelled(description)
        with self._progress.task(description, total) as advance:
            yield advance
        if self._cancel.is_set():
            raise Cancelled(description)


def cancellable(progress: Progress | None, cancel: threading.Event) -> Progress:
    """``progress`` for work in a worker thread that stops at its next task boundary once
    ``cancel`` is set (:class:`Cancelled` is raised there): the way the analysis stops the
    scan comparison it started beside the log reading when the logs turn out bad."""
    return _Cancellable(progress, cancel)


_notice: Callable[[str], None] | None = None
_announced = False


def set_notice(fn: Callable[[str], None] | None) -> None:
    """Where :func:`notice_once` says its line (the CLI: stderr); None: nowhere (default)."""
    global _notice, _announced
    _notice, _announced = fn, False


def notice_once(text: str) -> bool:
    """Say ``text`` through :func:`set_notice`'s hook if nothing was said yet in this run (the
    compiled kernels' build notices, :mod:`roboisf.jit`); True when it was said."""
    global _announced
    if _notice is None or _announced:
        return False
    _announced = True
    _notice(text)
    return True
