"""Compiled tracking of a logged tool path along the toolpath, for the position alignment.

Used by :func:`roboisf.sync.position._track` when compiled (:func:`roboisf.jit.ready` of group
"sync"); otherwise the numpy path runs. Two compiled forms, the same bits: C
(``position_kernel.c``, built at install, called through :mod:`roboisf.jit.native` — no numba in
the process) when it is built and fresh, else numba (``ROBOISF_NUMBA=0`` switches it off; built
at install: :mod:`roboisf.jit.prebuild`). Two kernels:

* :func:`project_segments` — the nearest point of a window of toolpath segments to each sample;
* :func:`track_blocks` — the whole tracking loop of :func:`roboisf.sync.position._track` (blocks
  of logged travel, the search window that follows the progress, the running maximum) run
  without returning to Python until the tool leaves the window and has to be re-acquired, which
  the caller does with its k-d tree and then resumes the kernel.

Same arithmetic in the same order as the numpy path (clip of the segment parameter, squared
distance, first minimum), so progress agrees to rounding (tests/test_sync_kernel.py checks
<= 1e-12 m against numpy, and that the compiled loop gives the same bits as the Python loop
over the compiled projection); the C form gives the numba form's bits
(tests/test_native_position.py).
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, njit

__all__ = ["HAVE_NUMBA", "build", "project_segments", "track_blocks"]

if HAVE_NUMBA:
    compile_notice(__file__)  # numba compiles these on first call: say so once

F64 = NDArray[np.float64]

_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: An array's C arguments: 2-D (pointer, row and column strides in elements), 1-D (pointer,
#: stride); the segments: A, D (2-D), L2, S0, seglen (1-D).
_ARR2, _ARR1 = [_P, _I, _I], [_P, _I]
_SEGS = [*_ARR2, *_ARR2, *_ARR1, *_ARR1, *_ARR1]

#: The C functions of ``position_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    # P, M, its strides; the segments, W; s, d
    "project_segments": (None, [_P, _I, _I, _I, *_SEGS, _I, _P, _P]),
    # P, M, its strides; travel, its stride, its length; the segments, nseg; tol, block,
    # margin, max_block; s, its stride; k; &s_prev, &last_on
    "track_blocks": (
        _I,
        [_P, _I, _I, _I, _P, _I, _I, *_SEGS, _I, _D, _D, _D, _I, _P, _I, _I, _P, _P],
    ),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


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


#: The numba forms (the fallback, and the C form's oracle in the tests).
_project_segments: Any = njit()(_project_py)
_track_blocks: Any = njit()(_track_py)


def _f64(a: Any, name: str, ndim: int) -> F64:
    """``a`` checked as a float64 array of ``ndim`` dimensions (and ≥ 3 columns when 2-D),
    copied to C order only when a stride is not whole elements (a field of a record array)."""
    if not isinstance(a, np.ndarray) or a.dtype != np.float64:
        raise TypeError(f"{name}: a float64 array expected, got {getattr(a, 'dtype', type(a))}")
    if a.ndim != ndim or (ndim == 2 and a.shape[1] < 3):
        raise ValueError(f"{name}: {'(n, 3)' if ndim == 2 else '(n,)'} expected, got {a.shape}")
    if any(st % a.itemsize for st in a.strides):
        a = np.ascontiguousarray(a)
    return a


def _strides(a: F64) -> tuple[int, ...]:
    """``a``'s strides in elements."""
    return tuple(st // a.itemsize for st in a.strides)


def _segments(A: Any, D: Any, L2: Any, S0: Any, seglen: Any, n: int) -> tuple[list[F64], list[int]]:
    """The segment arrays checked to have ``n`` rows at least (the C code reads rows
    0..n − 1 of each), and their C arguments (pointer, strides ...); keep the arrays alive
    for the call (one may be a copy: :func:`_f64`)."""
    arrays: list[F64] = []
    args: list[int] = []
    for a, name, ndim in (
        (A, "A", 2),
        (D, "D", 2),
        (L2, "L2", 1),
        (S0, "S0", 1),
        (seglen, "seglen", 1),
    ):
        a = _f64(a, name, ndim)
        if a.shape[0] < n:
            raise IndexError(f"{name}: {n} segments expected, got {a.shape[0]}")
        arrays.append(a)
        args += [a.ctypes.data, *_strides(a)]
    return arrays, args


def project_segments(P: F64, A: F64, D: F64, L2: F64, S0: F64, seglen: F64) -> tuple[F64, F64]:
    """The nearest point of the segments ``A + u D`` (u in [0, 1]; (W, 3) starts and
    directions, squared lengths ``L2``, arc length at each start ``S0``, lengths ``seglen``) to
    each sample of ``P`` (M, 3): (progress [m], distance [m]), each (M,); the first nearest
    segment wins."""
    lib = _c()
    if lib is None:
        s, d = _project_segments(P, A, D, L2, S0, seglen)
        return s, d
    P = _f64(P, "P", 2)
    M, W = P.shape[0], _f64(A, "A", 2).shape[0]
    s = np.empty(M)
    d = np.empty(M)
    if M == 0:
        return s, d
    if W == 0:
        raise ValueError("project_segments: no segments")
    keep, seg = _segments(A, D, L2, S0, seglen, W)
    lib.project_segments(P.ctypes.data, M, *_strides(P), *seg, W, s.ctypes.data, d.ctypes.data)
    del keep  # alive until here
    return s, d


def track_blocks(
    P: F64,
    travel: F64,
    A: F64,
    D: F64,
    L2: F64,
    S0: F64,
    seglen: F64,
    tol: float,
    block: float,
    margin: float,
    max_block: int,
    s: F64,
    k: int,
    s_prev: float,
    last_on: int,
) -> tuple[int, float, int]:
    """Track samples ``P`` (M, 3) from ``k`` on while the tool stays in the search window
    (:func:`_track_py`; ``travel`` (M,) the logged travel, the segments as for
    :func:`project_segments`, ``S0`` naming how many): the progress into ``s`` (M,); returns
    ``(k, s_prev, last_on)`` — ``k == M`` when done, else where the caller re-acquires."""
    lib = _c()
    if lib is None:
        k, s_prev, last_on = _track_blocks(
            P, travel, A, D, L2, S0, seglen, tol, block, margin, max_block, s, k, s_prev,
            last_on,
        )  # fmt: skip
        return int(k), float(s_prev), int(last_on)
    P = _f64(P, "P", 2)
    travel = _f64(travel, "travel", 1)
    M, nt, nseg = P.shape[0], travel.shape[0], _f64(S0, "S0", 1).shape[0]
    if not isinstance(s, np.ndarray) or s.dtype != np.float64 or s.ndim != 1:
        raise TypeError("s: a (M,) float64 array expected")
    if any(st % s.itemsize for st in s.strides) or not s.flags.writeable:
        raise ValueError("s: a writeable array of whole-element strides expected")
    k, s_prev, last_on, max_block = int(k), float(s_prev), int(last_on), int(max_block)
    if k >= M:
        return k, s_prev, last_on
    if nt < M or s.shape[0] < M:
        raise IndexError(f"travel and s: {M} samples expected, got {nt} and {s.shape[0]}")
    if k < 0 or not 0 <= last_on < nt:
        raise IndexError(f"k = {k} or last_on = {last_on} out of range 0..{M - 1}")
    if max_block < 1:
        raise ValueError(f"max_block must be >= 1, got {max_block}")
    if nseg == 0 and math.isfinite(s_prev):
        raise ValueError("track_blocks: no segments")
    keep, seg = _segments(A, D, L2, S0, seglen, nseg)
    sp = ctypes.c_double(s_prev)
    lo = ctypes.c_int64(last_on)
    k = lib.track_blocks(
        P.ctypes.data, M, *_strides(P), travel.ctypes.data, *_strides(travel), nt, *seg, nseg,
        float(tol), float(block), float(margin), min(max_block, M), s.ctypes.data,
        *_strides(s), k, ctypes.byref(sp), ctypes.byref(lo),
    )  # fmt: skip
    if k < 0:
        raise MemoryError("track_blocks: no memory for a block's projections")
    del keep  # alive until here
    return int(k), float(sp.value), int(lo.value)


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
