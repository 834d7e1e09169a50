"""Draw the report's PNG figures in worker processes while the parent writes the HTML.

Issue #16: matplotlib's draw + PNG encode of the nine figures is ~2/3 of the report's CPU time
and runs on one core. :class:`PngRenderer` starts worker processes first, so they draw while the
parent assembles the plotly HTML; the parent then draws figures from the same job queue until it
is empty, so the split balances itself whatever each figure costs on a given machine.

Start method: ``fork`` on Linux — the workers inherit the imported modules (no second matplotlib
import) and the report's input frames copy-on-write (the pages are shared, not copied; a worker
writes only its own figures' memory). Elsewhere ``spawn``: the inputs are pickled and each worker
imports the report modules itself. Each figure is written atomically by the process that draws
it (:func:`roboisf.report.static.save_png`); the result is the same bytes as drawn in-process (a
test compares them).

Errors: an exception in a worker comes back to the parent and is raised there (its own type when
it can be pickled, else a :class:`RuntimeError` naming the figure and the worker's message); a
worker that dies (signal, out of memory) is reported as such. Ctrl-C: workers ignore SIGINT; the
parent's :class:`KeyboardInterrupt` terminates them (SIGTERM, which a worker turns into a clean
exit that removes its temporary file) and waits for them.
"""

from __future__ import annotations

import gc
import multiprocessing as mp
import os
import pickle
import queue
import signal
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any

from roboisf.report import aggregate as agg

__all__ = ["PngRenderer", "default_processes"]

#: Environment variable: number of worker processes for the PNGs (0 = draw them in-process).
PROCESSES_ENV = "ROBOISF_REPORT_PROCESSES"

#: the figures by their drawing cost (heaviest first, measured on the paper cone): the queue
#: hands them out in this order so that the last ones to finish are the short ones
_COST_ORDER = (
    "factors_depth",
    "deviation_depth",
    "deviation_top",
    "deviation_map",
    "contributions",
    "vjm_polar",
    "vjm_contour",
    "forces",
    "vjm_path",
    "thickness",
)


def default_processes() -> int:
    """Worker processes for the PNGs: ``$ROBOISF_REPORT_PROCESSES`` if set, else one fewer
    than the CPUs this process may run on (at most 3; 0 on a single CPU, and 0 where workers
    cannot be forked: a spawned worker re-imports the report's modules, ~1–2 s, and needs the
    caller's script guarded by ``if __name__ == "__main__"``)."""
    env = os.environ.get(PROCESSES_ENV, "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            from roboisf.errors import InputError

            raise InputError(
                f"expected a whole number of processes (0 = none), got {env!r}",
                field=PROCESSES_ENV,
            ) from None
        if n < 0:
            from roboisf.errors import InputError

            raise InputError(f"expected 0 or more processes, got {n}", field=PROCESSES_ENV)
        return n
    if _context().get_start_method() != "fork":
        return 0
    from roboisf.jit import cores

    return max(0, min(cores() - 1, 3))


def _context() -> Any:
    fork = sys.platform.startswith("linux") and "fork" in mp.get_all_start_methods()
    return mp.get_context("fork" if fork else "spawn")


#: what a worker needs to draw: either the figure builders themselves (fork: inherited, never
#: pickled) or the reduced report inputs to rebuild them from (spawn: pickled)
_Source = Mapping[str, Any] | tuple[Any, ...]


def _builders(source: _Source) -> Mapping[str, Any]:
    if isinstance(source, tuple):  # spawn: rebuild the figure specs from the inputs
        from roboisf.report.document import _figures

        return _figures(*source)
    return source


def _on_sigterm(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)  # unwinds: atomic_path removes its temporary file


def _take(jobs: Any, ids: Sequence[str]) -> str | None:
    """The next figure nobody has taken (``jobs``: a shared counter), or None."""
    with jobs.get_lock():
        k = int(jobs.value)
        if k >= len(ids):
            return None
        jobs.value = k + 1
    return ids[k]


def _worker(jobs: Any, ids: list[str], results: Any, folder: str, source: _Source) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, _on_sigterm)
    with agg.reused():
        builders = None
        while (fid := _take(jobs, ids)) is not None:
            try:
                if builders is None:
                    builders = _builders(source)
                _draw(builders[fid], fid, Path(folder))
            except Exception as exc:  # handed to the parent, raised there
                results.put((fid, _portable(exc)))
                return
            results.put((fid, None))


def _draw(spec: Any, fid: str, folder: Path) -> None:
    from roboisf.report import static as st

    st.save_png(spec.png(), folder / f"{fid}.png")


def _portable(exc: BaseException) -> bytes | str:
    try:
        data = pickle.dumps(exc)
        pickle.loads(data)
        return data
    except Exception:  # not picklable: its text
        return f"{type(exc).__name__}: {exc}"


class PngRenderer:
    """Draw ``figures/<id>.png`` for ``ids`` in ``processes`` workers plus the caller.

    Use as a context manager: on entry the workers start drawing; the caller does its own work
    (the HTML) and then calls :meth:`finish`, which draws what is left in the calling process
    and waits for the workers. Leaving the block early (an exception, Ctrl-C) terminates the
    workers.

    Parameters
    ----------
    folder
        The ``figures`` folder (created by the caller).
    ids
        Figure ids to draw.
    figures
        ``{id: spec}`` with ``spec.png()`` returning a matplotlib Figure (the parent's builders).
    rebuild
        Arguments of :func:`roboisf.report.document._figures` (used by spawned workers only).
    processes
        Worker processes; 0 draws everything in the calling process (in :meth:`finish`).
    on_done
        Called once per figure written (progress).
    """

    def __init__(
        self,
        folder: Path,
        ids: Sequence[str],
        figures: Mapping[str, Any],
        rebuild: tuple[Any, ...],
        processes: int,
        on_done: Callable[[], None] | None = None,
    ) -> None:
        self.folder = folder
        self.ids = sorted(ids, key=lambda f: _COST_ORDER.index(f) if f in _COST_ORDER else 0)
        self.figures = figures
        self.rebuild = rebuild
        self.processes = max(0, min(processes, len(self.ids)))
        self.on_done = on_done or (lambda: None)
        self._workers: list[Any] = []
        self._jobs: Any = None
        self._results: Any = None

    def __enter__(self) -> PngRenderer:
        if self.processes == 0:
            return self
        ctx = _context()
        self._jobs = ctx.Value("i", 0)  # index of the next figure to draw in self.ids
        self._results = ctx.Queue()
        source: _Source = self.figures if ctx.get_start_method() == "fork" else self.rebuild
        # the parent's objects to the permanent generation: the workers' garbage collector then
        # never walks them, so their pages stay shared with the parent instead of being copied
        gc.freeze()
        try:
            for _ in range(self.processes):
                p = ctx.Process(
                    target=_worker,
                    args=(self._jobs, self.ids, self._results, str(self.folder), source),
                    name="roboisf-report-png",
                    daemon=True,
                )
                p.start()
                self._workers.append(p)
        finally:
            gc.unfreeze()
        return self

    def finish(self) -> None:
        """Draw the figures no worker has taken, then wait for the workers; raise the first
        worker error."""
        if not self._workers:
            for fid in self.ids:
                _draw(self.figures[fid], fid, self.folder)
                self.on_done()
            return
        done: set[str] = set()
        while (mine := _take(self._jobs, self.ids)) is not None:  # the caller's share
            _draw(self.figures[mine], mine, self.folder)
            done.add(mine)
            self.on_done()
        while len(done) < len(self.ids):
            try:
                fid, err = self._results.get(timeout=0.2)
            except queue.Empty:
                if all(not p.is_alive() for p in self._workers):
                    try:  # a result may have been put just before the worker exited
                        fid, err = self._results.get(timeout=1.0)
                    except queue.Empty:
                        codes = sorted({p.exitcode for p in self._workers})
                        missing = [f for f in self.ids if f not in done]
                        raise RuntimeError(
                            "the PNG worker process stopped (exit codes "
                            f"{', '.join(map(str, codes))}) before drawing "
                            + ", ".join(f"figures/{f}.png" for f in missing)
                        ) from None
                else:
                    continue
            if err is not None:
                raise _reraise(fid, err)
            done.add(fid)
            self.on_done()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        for p in self._workers:
            if p.is_alive():
                if exc_type is not None:
                    p.terminate()
                p.join(timeout=None if exc_type is None else 10.0)
                if p.is_alive():
                    p.kill()
                    p.join()
        if self._results is not None:
            self._results.close()
            self._results.join_thread()
        self._workers.clear()


def _reraise(fid: str, err: bytes | str) -> BaseException:
    if isinstance(err, bytes):
        exc: BaseException = pickle.loads(err)
        exc.add_note(f"(raised while drawing figures/{fid}.png in a worker process)")
        return exc
    return RuntimeError(f"drawing figures/{fid}.png failed in a worker process: {err}")
