"""Compiled (numba) tracking of a logged tool path along the toolpath, for the position alignment.

Used by :func:`roboisf.sync.position._track` when numba is there (a dependency;
``ROBOISF_NUMBA=0`` switches it off); otherwise the numpy path runs. Two kernels:

* :func:`project_segments` — the nearest point of a window of toolpath segments to each sample;
* :func:`track_blocks` — the whole tracking loop of :func:`roboisf.sync.position._track` (blocks
  of logged travel, the search window that follows the progress, the running maximum) run
  without returning to Python until the tool leaves the window and has to be re-acquired, which
  the caller does with its k-d tree and then resumes the kernel.

Same arithmetic in the same order as the numpy path (clip of the segment parameter, squared
distance, first minimum), so progress agrees to rounding (tests/test_sync_kernel.py checks
<= 1e-12 m against numpy, and that the compiled loop gives the same bits as the Python loop
over the compiled projection).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from roboisf.jit import HAVE_NUMBA, compile_notice, njit

__all__ = ["HAVE_NUMBA", "build", "project_segments", "track_blocks"]

if HAVE_NUMBA:
    compile_notice(__file__)  # numba compiles these on first call: say so once


_inline: Callable[[Callable[..., Any]], Callable[..., Any]] = njit(inline="always")


@_inline
def _nearest(
    P: Any, b: int, A: Any, D: Any, L2: Any, S0: Any, seglen: Any, j0: int, j1: int
) -> tuple[float, float]:  # pragma: no cover - compiled (tested through its callers)
    """Nearest point of segments ``j0:j1`` to sample ``P[b]``: (progress [m], distance [m])."""
    best = np.inf
    bj = j0
    bu = 0.0
    for w in range(j0, j1):
        r0 = P[b, 0] - A[w, 0]
        r1 = P[b, 1] - A[w, 1]
        r2 = P[b, 2] - A[w, 2]
        den = L2[w] if L2[w] > 0 else 1.0
        u = (r0 * D[w, 0] + r1 * D[w, 1] + r2 * D[w, 2]) / den
        u = min(max(u, 0.0), 1.0)
        e0 = r0 - u * D[w, 0]
        e1 = r1 - u * D[w, 1]
        e2 = r2 - u * D[w, 2]
        d2 = e0 * e0 + e1 * e1 + e2 * e2
        if d2 < best:
            best = d2
            bj = w
            bu = u
    return S0[bj] + bu * seglen[bj], math.sqrt(best)


def _project_py(P: Any, A: Any, D: Any, L2: Any, S0: Any, seglen: Any) -> tuple[Any, Any]:
    """(M, 3) samples, (W, 3) segment starts/directions [m] -> progress [m], distance [m]."""
    M, W = P.shape[0], A.shape[0]
    s = np.empty(M)
    d = np.empty(M)
    for b in range(M):
        s[b], d[b] = _nearest(P, b, A, D, L2, S0, seglen, 0, W)
    return s, d


def _track_py(
    P: Any,
    travel: Any,
    A: Any,
    D: Any,
    L2: Any,
    S0: Any,
    seglen: Any,
    tol: float,
    block: float,
    margin: float,
    max_block: int,
    s: Any,
    k: int,
    s_prev: float,
    last_on: int,
) -> tuple[int, float, int]:  # pragma: no cover - compiled (tested against the Python loop)
    """Track samples from ``k`` on while the tool stays in the search window.

    Writes the monotone progress of the samples on the path into ``s``; returns
    ``(k, s_prev, last_on)``: ``k == len(P)`` when done, else the first sample of the block
    whose window held no sample within ``tol`` (or ``s_prev`` not yet finite): the caller
    re-acquires there. The loop body is that of :func:`roboisf.sync.position._track`.
    """
    M = P.shape[0]
    nseg = S0.shape[0]
    sb = np.empty(max_block)
    db = np.empty(max_block)
    while k < M:
        if not np.isfinite(s_prev):
            return k, s_prev, last_on
        k2 = int(np.searchsorted(travel, travel[k] + block, side="right"))
        k2 = max(k + 1, min(k2, k + max_block, M))
        ahead = travel[k2 - 1] - travel[last_on] + margin
        j0 = max(int(np.searchsorted(S0, s_prev - margin, side="right")) - 1, 0)
        j1 = min(int(np.searchsorted(S0, s_prev + ahead, side="right")), nseg)
        j1 = max(j1, j0 + 1)
        hit = False
        for b in range(k, k2):
            sb[b - k], db[b - k] = _nearest(P, b, A, D, L2, S0, seglen, j0, j1)
            if db[b - k] <= tol:
                hit = True
        if not hit:
            return k, s_prev, last_on
        for b in range(k, k2):
            if db[b - k] <= tol:
                s_prev = max(s_prev, sb[b - k])
                s[b] = s_prev
                last_on = b
        k = k2
    return k, s_prev, last_on


project_segments: Any = njit()(_project_py)
track_blocks: Any = njit()(_track_py)


def build() -> None:
    """Compile (and so cache) these kernels through their caller, on a short synthetic path
    and log: the background builder of :mod:`roboisf.jit.background` (group "sync")."""
    from roboisf.sync.position import _project, _track

    s = np.linspace(0.0, 0.1, 200)
    tip = np.column_stack([0.05 * np.cos(20 * s), 0.05 * np.sin(20 * s), -0.1 * s])
    S = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(tip, axis=0), axis=1))])
    P = tip[::3] + 1e-5
    _track(P, tip, S, 1e-3)
    A, D = tip[:-1], np.diff(tip, axis=0)
    seglen = np.linalg.norm(D, axis=1)
    _project(P, A, D, seglen**2, S[:-1], seglen)
