"""The compiled (numba) engine of :mod:`roboisf.robot.vjm_kernel`; imported on first use.

Kept apart so that ``import roboisf.robot`` does not import numba (≈ 0.4–0.6 s). See
:mod:`roboisf.robot.vjm_kernel` for what the kernels compute and how they are chosen.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = ["BLOCK", "kernel", "margin_numba", "margin_pivots_ok", "sincos"]

F64 = NDArray[np.float64]

#: Poses per parallel work item.
BLOCK = 1024


def _njit(**kw: Any) -> Any:
    return numba.njit(cache=True, nogil=True, **kw)


_PRANGE: Any = numba.prange


# sin/cos of one argument with a shared argument reduction (fdlibm's ``__kernel_sin`` /
# ``__kernel_cos`` minimax polynomials on |r| ≤ π/4 after a three-part Cody–Waite reduction by
# π/2, the parts of ``__ieee754_rem_pio2``): ≤ 1 ulp from numpy's sin/cos (tested), half the cost
# of calling both (the trig functions were ~40 % of the kernel).
_PIO2_1 = 1.57079632673412561417e00  # first 33 bits of π/2: n·_PIO2_1 exact for |n| < 2**20
_PIO2_2 = 6.07710050630396597660e-11  # next 33 bits
_PIO2_3 = 2.02226624879595063154e-21  # π/2 − _PIO2_1 − _PIO2_2
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11


@_njit(inline="always")
def sincos(x: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """``(sin x, cos x)``; exact-enough reduction for |x| < 1e5 rad, libm beyond."""
    if not abs(x) < 1e5:
        return math.sin(x), math.cos(x)
    n = round(x * 0.636619772367581343)  # x / (π/2)
    r = ((x - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_3
    z = r * r
    s = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (
        ((1.0 - w) - hz) + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    )
    k = int(n) & 3
    if k == 0:
        return s, c
    if k == 1:
        return c, -s
    if k == 2:
        return -s, -c
    return -c, s


@_njit()
def _rows(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    q: F64,
    W: F64,
    s: int,
    e: int,
    d: F64,
    k: F64,
    J: F64,
    margin: F64,
    ok: NDArray[np.bool_],
) -> None:  # pragma: no cover - compiled (its results are tested against the numpy engine)
    """Poses ``s:e``: δ into ``d``; k_c into ``k``, J into ``J`` and the singularity-margin test
    into ``ok`` when those have N rows.

    ``F`` (7, 4, 4) with the tool folded into ``F[6]``; ``W`` (N, 6) or (1, 6) (one wrench for
    every pose); ``k``/``J``/``ok`` of zero rows are not written; ``margin`` = (1 / length
    scale, threshold²) of :func:`margin_pivots_ok`.
    """
    want_k = k.shape[0] > 0
    want_j = J.shape[0] > 0
    want_ok = ok.shape[0] > 0
    one_w = W.shape[0] == 1
    oz = np.empty((6, 6))  # per joint: z axis (3) and origin (3), base frame
    M = np.empty((12, 6))
    Jl = np.empty((6, 6))
    a = np.empty(6)
    for n in range(s, e):
        r00, r01, r02 = F[0, 0, 0], F[0, 0, 1], F[0, 0, 2]
        r10, r11, r12 = F[0, 1, 0], F[0, 1, 1], F[0, 1, 2]
        r20, r21, r22 = F[0, 2, 0], F[0, 2, 1], F[0, 2, 2]
        px, py, pz = F[0, 0, 3], F[0, 1, 3], F[0, 2, 3]
        for j in range(6):
            if j > 0:
                t0, t1, t2 = F[j, 0, 3], F[j, 1, 3], F[j, 2, 3]
                px += r00 * t0 + r01 * t1 + r02 * t2
                py += r10 * t0 + r11 * t1 + r12 * t2
                pz += r20 * t0 + r21 * t1 + r22 * t2
                f00, f01, f02 = F[j, 0, 0], F[j, 0, 1], F[j, 0, 2]
                f10, f11, f12 = F[j, 1, 0], F[j, 1, 1], F[j, 1, 2]
                f20, f21, f22 = F[j, 2, 0], F[j, 2, 1], F[j, 2, 2]
                r00, r01, r02 = (
                    r00 * f00 + r01 * f10 + r02 * f20,
                    r00 * f01 + r01 * f11 + r02 * f21,
                    r00 * f02 + r01 * f12 + r02 * f22,
                )
                r10, r11, r12 = (
                    r10 * f00 + r11 * f10 + r12 * f20,
                    r10 * f01 + r11 * f11 + r12 * f21,
                    r10 * f02 + r11 * f12 + r12 * f22,
                )
                r20, r21, r22 = (
                    r20 * f00 + r21 * f10 + r22 * f20,
                    r20 * f01 + r21 * f11 + r22 * f21,
                    r20 * f02 + r21 * f12 + r22 * f22,
                )
            oz[j, 0] = r02
            oz[j, 1] = r12
            oz[j, 2] = r22
            oz[j, 3] = px
            oz[j, 4] = py
            oz[j, 5] = pz
            th = sign[j] * q[n, j] + offset[j]
            if j == 2 and c23 != 0.0:  # FANUC J2/J3 coupling: θ3 = s3 (q3 + c23 q2) + o3
                th += sign[2] * c23 * q[n, 1]
            sn, c = sincos(th)
            r00, r01 = c * r00 + sn * r01, c * r01 - sn * r00
            r10, r11 = c * r10 + sn * r11, c * r11 - sn * r10
            r20, r21 = c * r20 + sn * r21, c * r21 - sn * r20
        t0, t1, t2 = F[6, 0, 3], F[6, 1, 3], F[6, 2, 3]
        px += r00 * t0 + r01 * t1 + r02 * t2
        py += r10 * t0 + r11 * t1 + r12 * t2
        pz += r20 * t0 + r21 * t1 + r22 * t2
        # column j = sign_j [z_j × (p − o_j); z_j]
        for j in range(6):
            zx, zy, zz = oz[j, 0], oz[j, 1], oz[j, 2]
            rx, ry, rz = px - oz[j, 3], py - oz[j, 4], pz - oz[j, 5]
            sj = sign[j]
            Jl[0, j] = sj * (zy * rz - zz * ry)
            Jl[1, j] = sj * (zz * rx - zx * rz)
            Jl[2, j] = sj * (zx * ry - zy * rx)
            Jl[3, j] = sj * zx
            Jl[4, j] = sj * zy
            Jl[5, j] = sj * zz
        if c23 != 0.0:  # ∂/∂q2 also turns joint 3: column 2 += c23 × column 3
            for i in range(6):
                Jl[i, 1] += c23 * Jl[i, 2]
        w = 0 if one_w else n
        for j in range(6):
            tau = 0.0
            for i in range(6):
                tau += Jl[i, j] * W[w, i]
            a[j] = tau * kinv[j]
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += Jl[i, j] * a[j]
            d[n, i] = acc
        if want_k:
            for i in range(6):
                for m in range(i, 6):
                    acc = 0.0
                    for j in range(6):
                        acc += Jl[i, j] * kinv[j] * Jl[m, j]
                    k[n, i, m] = acc
                    k[n, m, i] = acc
        if want_j:
            for i in range(6):
                for j in range(6):
                    J[n, i, j] = Jl[i, j]
        if want_ok:
            ok[n] = margin_pivots_ok(Jl, margin[0], margin[1], M)


@_njit()
def margin_pivots_ok(J: F64, lin_scale: float, c: float, M: F64) -> bool:  # pragma: no cover
    """``σ_min(J_s) > √c`` for one Jacobian (6, 6), ``J_s`` = J with rows 0–2 times
    ``lin_scale``: all LDLᵀ pivots of ``J_sᵀJ_s − c I`` are > 0 (``M`` (12, 6) scratch).

    The one compiled form of :func:`roboisf.robot.singularity.margin_ok` (same elimination as
    the numpy form: the multipliers use the pivot's reciprocal).
    """
    for i in range(6):  # rows 6..11: columns of J_s, contiguous
        for r in range(3):
            M[6 + i, r] = J[r, i] * lin_scale
        for r in range(3, 6):
            M[6 + i, r] = J[r, i]
    for i in range(6):
        for j in range(i, 6):
            acc = 0.0
            for r in range(6):
                acc += M[6 + i, r] * M[6 + j, r]
            M[i, j] = acc
        M[i, i] -= c
    for p in range(6):
        piv = M[p, p]
        if not piv > 0.0:
            return False
        inv = 1.0 / piv
        for i in range(p + 1, 6):
            lk = M[p, i] * inv  # the upper triangle holds the symmetric matrix
            for j in range(i, 6):
                M[i, j] -= lk * M[p, j]
    return True


@_njit()
def _margin_rows(
    Js: F64, lin_scale: float, c: float, ok: NDArray[np.bool_], s: int, e: int
) -> None:  # pragma: no cover - compiled
    M = np.empty((12, 6))
    for n in range(s, e):
        ok[n] = margin_pivots_ok(Js[n], lin_scale, c, M)


@_njit(parallel=True)
def _margin_parallel(
    Js: F64, lin_scale: float, c: float, ok: NDArray[np.bool_]
) -> None:  # pragma: no cover - compiled
    n = Js.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    for b in _PRANGE(nb):
        _margin_rows(Js, lin_scale, c, ok, b * BLOCK, min(n, (b + 1) * BLOCK))


def margin_numba(Js: F64, lin_scale: float, c: float) -> NDArray[np.bool_]:
    """:func:`margin_pivots_ok` over Jacobians (N, 6, 6) (parallel from the main thread)."""
    ok = np.empty(Js.shape[0], dtype=np.bool_)
    Jc = _c64(Js)
    if threading.current_thread() is threading.main_thread():
        _margin_parallel(Jc, float(lin_scale), float(c), ok)
    else:
        _margin_rows(Jc, float(lin_scale), float(c), ok, 0, Jc.shape[0])
    return ok


@_njit(parallel=True)
def _kernel_parallel(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    q: F64,
    W: F64,
    d: F64,
    k: F64,
    J: F64,
    margin: F64,
    ok: NDArray[np.bool_],
) -> None:  # pragma: no cover - compiled
    n = q.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    for b in _PRANGE(nb):
        s = b * BLOCK
        _rows(F, sign, offset, c23, kinv, q, W, s, min(n, s + BLOCK), d, k, J, margin, ok)


@_njit()
def _kernel_serial(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    q: F64,
    W: F64,
    d: F64,
    k: F64,
    J: F64,
    margin: F64,
    ok: NDArray[np.bool_],
) -> None:  # pragma: no cover - compiled
    _rows(F, sign, offset, c23, kinv, q, W, 0, q.shape[0], d, k, J, margin, ok)


def _c64(a: Any) -> F64:
    """C-contiguous, writeable float64 (one compiled signature for every call)."""
    arr = np.asarray(a, dtype=np.float64)
    if not arr.flags.c_contiguous or not arr.flags.writeable:
        arr = np.array(arr, dtype=np.float64, order="C")
    return arr


def kernel() -> Any:
    """The VJM kernel for this thread: parallel (``prange``) from the main thread, serial (no
    GIL) from any other, so that a caller's own threads are not oversubscribed and numba's
    threading layer is never entered from two threads at once."""
    if threading.current_thread() is threading.main_thread():
        return _kernel_parallel
    return _kernel_serial
