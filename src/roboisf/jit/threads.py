"""A compiled kernel's rows on every core, from Python threads.

roboisf's kernels are serial and release the GIL (:func:`roboisf.jit.njit` sets ``nogil``): a
caller splits its rows into chunks and runs them on a thread pool. This replaced numba's
``parallel=True`` / ``prange`` in the robot kernels (2026-11-28): the same rows computed by the
same serial code, so the same bits, without numba's parallel compile (≈ 4 s of the robot group's
11 s cold build: each ``prange`` wrapper compiled its row kernel a second time inside a gufunc)
and without starting numba's threading layer in every process (≈ 0.1 s on the first call).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

__all__ = ["cores", "run_chunks"]


def cores() -> int:
    """CPUs this process may run on (its affinity mask; ``os.cpu_count()`` elsewhere)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1  # pragma: no cover - not on Linux


def run_chunks(
    rows: Callable[[int, int], object],
    n: int,
    chunk: int,
    *,
    workers: int | None = None,
    any_thread: bool = True,
) -> None:
    """``rows(s, e)`` for the chunks ``[0, chunk), [chunk, 2·chunk), …`` of ``0 … n`` (the last
    one shorter), on a pool of ``workers`` threads (default: :func:`cores`) when there are two
    chunks or more, else in this thread.

    ``rows`` must write disjoint rows of its outputs, so that the result does not depend on the
    chunks (compiled kernels that release the GIL: the threads run them side by side).
    ``any_thread=False``: called from a thread other than the main one, everything runs in that
    thread — a caller that already runs several threads (a plan sweep, the scan comparison
    beside the logs) is not multiplied by a second pool. An exception of ``rows`` is raised
    here once every chunk has ended.
    """
    if n <= 0:
        return
    if chunk < 1:
        raise ValueError(f"chunk must be ≥ 1, got {chunk}")
    nw = min(workers or cores(), -(-n // chunk))
    if nw <= 1 or (not any_thread and threading.current_thread() is not threading.main_thread()):
        for s in range(0, n, chunk):
            rows(s, min(n, s + chunk))
        return
    with ThreadPoolExecutor(max_workers=nw, thread_name_prefix="roboisf-rows") as pool:
        done = [pool.submit(rows, s, min(n, s + chunk)) for s in range(0, n, chunk)]
    for f in done:
        f.result()
