"""Progress reporting without a UI dependency in the core.

Library functions that take long accept ``progress: Progress | None``; they call
``with progress.task("assemble", total=n) as advance: advance(k)``. The CLI passes a rich-backed
implementation (``roboisf.cli.console``); library users get silence by default.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Protocol

__all__ = [
    "COMPILE_WAIT",
    "NULL_PROGRESS",
    "Cancelled",
    "Progress",
    "background_build_notice",
    "cancellable",
    "compile_notice",
    "kernel_cached",
    "noop_advance",
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


#: What the first build of the compiled kernels costs, as the compile notice says it (measured:
#: docs/report.md, "The terminal"; `robot show` compiles the robot kernels, `analyze` those and
#: the scan, force-log and sync kernels).
COMPILE_WAIT = "about 30 s to 2 minutes, once (longer on a busy machine)"

_notice: Callable[[str], None] | None = None
_announced = False


def set_notice(fn: Callable[[str], None] | None) -> None:
    """Where :func:`compile_notice` says its line (the CLI: stderr); None: nowhere (default)."""
    global _notice, _announced
    _notice, _announced = fn, False


def _cache_dirs(source: Path) -> list[Path]:
    """Where numba keeps the on-disk cache of ``source``'s ``cache=True`` functions: beside it
    in ``__pycache__``, or under ``$NUMBA_CACHE_DIR`` / the user's cache folder in a folder
    named after the source's folder and the SHA-1 of its absolute path (numba's
    ``_CacheLocator.get_suitable_cache_subpath``)."""
    parent = os.path.dirname(os.path.abspath(source))
    sub = os.path.basename(parent) + "_" + hashlib.sha1(parent.encode()).hexdigest()
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:  # numba then looks nowhere else
        return [Path(env) / sub]
    return [source.parent / "__pycache__", Path.home() / ".cache" / "numba" / sub]


def kernel_cached(module_file: str | os.PathLike[str]) -> bool:
    """True when numba holds a cache index of the module's kernels at least as new as the module
    (else its first call compiles them). Reads file names and times only; imports nothing."""
    source = Path(module_file)
    try:
        stamp = source.stat().st_mtime
    except OSError:
        return True  # nothing to compare: say nothing
    for folder in _cache_dirs(source):
        try:
            for index in folder.glob(f"{source.stem}.*.nbi"):
                if index.stat().st_mtime >= stamp:
                    return True
        except OSError:
            continue
    return False


def compile_notice(module_file: str | os.PathLike[str]) -> None:
    """Called by a kernel module as it is imported (its numba functions compile on first call):
    when they are not cached yet, say once per process that the kernels are being built and how
    long that takes (:data:`COMPILE_WAIT`) — through the hook of :func:`set_notice`, silent
    without one."""
    global _announced
    if _notice is None or _announced or kernel_cached(module_file):
        return
    _announced = True
    _notice(
        "building roboisf's compiled kernels (numba) for the first time — "
        f"{COMPILE_WAIT}; they are cached on disk, later runs start in seconds"
    )


def background_build_notice(what: str, wait: str) -> None:
    """Say once per process (through :func:`set_notice`'s hook) that ``what`` kernels are being
    built in a background process taking ``wait``, while this run uses the numpy engine."""
    global _announced
    if _notice is None or _announced:
        return
    _announced = True
    _notice(
        f"building roboisf's compiled {what} kernels (numba) in the background ({wait}); "
        "this run uses the numpy engine, later runs the compiled one"
    )
