"""Compiled (numba) nearest point of a window of toolpath segments, for the position alignment.

Optional: used by :func:`roboisf.sync.position._project` when numba is installed
(``pip install roboisf[fast]``); otherwise the numpy path runs. Same arithmetic in the same order
as the numpy path (clip of the segment parameter, squared distance, first minimum), so progress
agrees to rounding (tests/test_sync_kernel.py checks <= 1e-12 m).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["HAVE_NUMBA", "project_segments"]

try:
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - numba is a test dependency
    HAVE_NUMBA = False


def _project_py(P: Any, A: Any, D: Any, L2: Any, S0: Any, seglen: Any) -> tuple[Any, Any]:
    """(M, 3) samples, (W, 3) segment starts/directions [m] -> progress [m], distance [m]."""
    M, W = P.shape[0], A.shape[0]
    s = np.empty(M)
    d = np.empty(M)
    for b in range(M):
        best = np.inf
        bj = 0
        bu = 0.0
        for w in range(W):
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
        s[b] = S0[bj] + bu * seglen[bj]
        d[b] = np.sqrt(best)
    return s, d


project_segments: Any = (
    numba.njit(nogil=True, cache=True)(_project_py) if HAVE_NUMBA else _project_py
)
