"""Compiled passes over a force log: row norms, and the running trapezoid integral read at
chosen samples; imported on first use. Two compiled forms, the same bits: C
(``forcelog_kernel.c``, built at install, called through :mod:`roboisf.jit.native` — no numba in
the process) when it is built and fresh, else numba (built at install:
:mod:`roboisf.jit.prebuild`).

A 1 kHz log of a paper-scale part has 2.3 M samples (110 MB per (N, 6) float64 array). The numpy
forms of these steps allocate several arrays of the log's size each (``norm`` squares all
components before summing; the window averages keep an (N, 6) running sum): every such array is
memory the analysis touches once and page faults it pays for. These kernels stream over the log
once and allocate only their results. Same arithmetic in the same order as the numpy forms, so
the same bits (tests/test_forcelog_kernel.py):

* :func:`row_norms` — ``sqrt((x0 − c0)² + (x1 − c1)² + (x2 − c2)²)`` of three columns, as
  ``np.linalg.norm(X[:, j:j+3] − c, axis=1)`` (numpy sums three terms left to right);
* :func:`onset` — the largest ``|F − c|`` of a log and the first row above a threshold set by
  it, as :func:`roboisf.sensor.unloaded_samples` finds them from :func:`row_norms`;
* :func:`running_integral_at` — rows ``ks`` of ``concatenate([0, cumsum((y[1:] + y[:-1]) ·
  (0.5 Δt))])``, the running sum of :func:`roboisf.logs.forcelog.window_average`, without the
  (N, K) array.
"""

from __future__ import annotations

import ctypes
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import compile_notice, native, njit

compile_notice(__file__)  # numba compiles these on first call: say so once

__all__ = ["build", "onset", "row_norms", "running_integral_at"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: The C functions of ``forcelog_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    "row_norms": (None, [_P, _I, _I, _I, _I, _P, _P]),
    "onset": (_I, [_P, _I, _I, _I, _P, _D, _P]),
    "running_at": (ctypes.c_int, [_P, _I, _P, _I, _I, _I, _P, _I, _P]),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


def _strides(a: NDArray[Any]) -> tuple[int, ...]:
    """``a``'s strides in elements (an array of float64 views: always whole elements)."""
    return tuple(s // a.itemsize for s in a.strides)


def _f64(a: NDArray[Any], name: str) -> NDArray[np.float64]:
    if a.dtype != np.float64:
        raise TypeError(f"{name}: float64 expected, got {a.dtype}")
    return a


@njit()
def _row_norms(X: Any, j: int, c: Any, out: Any) -> None:  # pragma: no cover - compiled
    for i in range(X.shape[0]):
        d0 = X[i, j] - c[0]
        d1 = X[i, j + 1] - c[1]
        d2 = X[i, j + 2] - c[2]
        out[i] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit()
def _onset(X: Any, c: Any, noise: float) -> tuple[float, int]:  # pragma: no cover - compiled
    """(span, onset) of :func:`onset`: the largest ``|F − c|`` (the square root of the largest
    square: sqrt is monotone and correctly rounded, so the same number), then the first row
    above ``max(5 noise, 0.01 span)`` (−1: none), its norm computed as :func:`_row_norms`
    does."""
    m2 = 0.0
    for i in range(X.shape[0]):
        d0 = X[i, 0] - c[0]
        d1 = X[i, 1] - c[1]
        d2 = X[i, 2] - c[2]
        m2 = max(m2, d0 * d0 + d1 * d1 + d2 * d2)
    span = math.sqrt(m2)
    thr = max(5.0 * noise, 0.01 * span)
    for i in range(X.shape[0]):
        d0 = X[i, 0] - c[0]
        d1 = X[i, 1] - c[1]
        d2 = X[i, 2] - c[2]
        if math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) > thr:
            return span, i
    return span, -1


def onset(X: F64, centre: F64, noise: float) -> tuple[float, int]:
    """For a log's wrench X (N, ≥ 3): ``span`` = max over rows of ``|F − centre|`` and the
    first row whose ``|F − centre|`` exceeds ``max(5 noise, 0.01 span)`` (−1: none) — what
    :func:`roboisf.sensor.unloaded_samples` asks of the whole log, in two passes without the
    (N,) distances (the second stops at the onset, near the log's start)."""
    c = np.ascontiguousarray(centre, dtype=np.float64)
    lib = _c()
    if lib is None:
        span, i = _onset(X, c, float(noise))
        return float(span), int(i)
    X = _f64(X, "X")
    rs, cs = _strides(X)
    out = ctypes.c_double()
    i = lib.onset(X.ctypes.data, X.shape[0], rs, cs, c.ctypes.data, float(noise), ctypes.byref(out))
    return float(out.value), int(i)


def row_norms(X: F64, j: int = 0, centre: F64 | None = None) -> F64:
    """``|X[:, j:j+3] − centre|`` per row (N,), one pass; ``centre`` (3,) defaults to 0."""
    c = np.zeros(3) if centre is None else np.ascontiguousarray(centre, dtype=np.float64)
    out = np.empty(X.shape[0])
    lib = _c()
    if lib is None:
        _row_norms(X, int(j), c, out)
        return out
    X = _f64(X, "X")
    rs, cs = _strides(X)
    lib.row_norms(X.ctypes.data, X.shape[0], rs, cs, int(j), c.ctypes.data, out.ctypes.data)
    return out


@njit()
def _running_at(t: Any, y: Any, ks: Any, out: Any) -> None:  # pragma: no cover - compiled
    m = ks.shape[0]
    K = y.shape[1]
    acc = np.zeros(K)
    r = 0
    while r < m and ks[r] == 0:
        out[r, :] = 0.0
        r += 1
    i = 1
    while r < m:
        h = 0.5 * (t[i] - t[i - 1])
        for c in range(K):
            acc[c] += (y[i, c] + y[i - 1, c]) * h
        while r < m and ks[r] == i:
            for c in range(K):
                out[r, c] = acc[c]
            r += 1
        i += 1


def running_integral_at(t: F64, y: F64, ks: I64) -> F64:
    """Rows ``ks`` (sorted, unique sample indices) of the running trapezoid integral of ``y``
    (N, K) over ``t`` (N,): (len(ks), K); the pass stops at the last index asked for."""
    out = np.empty((ks.shape[0], y.shape[1]))
    ks = np.ascontiguousarray(ks, dtype=np.int64)
    lib = _c()
    if lib is None:
        _running_at(t, y, ks, out)
        return out
    t, y = _f64(t, "t"), _f64(y, "y")
    (ts,) = _strides(t)
    ys0, ys1 = _strides(y)
    if ks.size and (ks[-1] >= t.shape[0] or ks[0] < 0):
        raise IndexError(f"sample index out of range 0..{t.shape[0] - 1}")
    ok = lib.running_at(
        t.ctypes.data,
        ts,
        y.ctypes.data,
        y.shape[1],
        ys0,
        ys1,
        ks.ctypes.data,
        ks.size,
        out.ctypes.data,
    )
    if not ok:
        raise MemoryError("running_integral_at: no memory for the running sum")
    return out


def build() -> None:
    """Compile (and so cache) these kernels through their callers, on a small log: the
    background builder of :mod:`roboisf.jit.background` (group "forcelog")."""
    from roboisf.logs.forcelog import window_average

    t = np.linspace(0.0, 1.0, 50)
    W = np.cos(np.outer(t, np.arange(1.0, 7.0)))
    row_norms(W, 0)
    row_norms(W, 3, np.ones(3))
    # a log read backwards (its unloaded end: roboisf.sensor.unloaded_stretches), another array
    # layout: without it the first analyze compiled this in the foreground (0.2 s)
    row_norms(W[::-1], 0, np.ones(3))
    # the unloaded approach's onset, of a log and of it read backwards (its end)
    onset(W, np.ones(3), 0.1)
    onset(W[::-1], np.ones(3), 0.1)
    window_average(t, W, np.array([0.1, 0.5]), np.array([0.3, 0.9]))
    window_average(t, W[:, :3], np.array([0.1]), np.array([0.3]))
