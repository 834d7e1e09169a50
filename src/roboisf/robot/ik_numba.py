"""The compiled engine of :mod:`roboisf.robot.ik`; imported on first use.

Two compiled forms, the same bits: C (``roboisf/robot/vjm_kernel.c``, the library of
:mod:`roboisf.robot.vjm_kernel`, built at install and called through :mod:`roboisf.jit.native`
— no numba in the process) when it is built and fresh, else the numba kernels below (numba
imported only when one is first called). Kept apart so that ``import roboisf.robot`` does not
import numba. Same arithmetic as the numpy
path of :func:`roboisf.robot.ik.opw_ik` / :func:`roboisf.robot.ik.ik_toolpath` (tested to
≤ 1e-12 rad with identical branch choices, reachability and limit flags), in scalar registers
per pose, with no temporary arrays:

* :func:`path_ik` — tool-tip points in the work frame → ``T_base_tip`` → ``T_base_flange`` → the
  chosen OPW branch → controller angles wrapped to (−π, π] (chunks of poses on a thread pool
  from the main thread, the same loop in the calling thread from any other: bit-identical);
  then, serially along the path, ``np.unwrap`` and the whole-turn shift into the joint limits of
  :func:`roboisf.robot.ik._continuous`, and the limit check.
* :func:`flange_ik` — the same OPW branch for given flange poses (what ``opw_ik`` returns).
* :func:`path_vjm` — ``roboisf.plan``'s inner loop: :func:`path_ik`, then per block of poses the
  VJM kernel of :mod:`roboisf.robot.vjm_numba` (δ and the singularity-margin test), δ in work
  axes, the tool's own deflection, |δ| and the joint steps — no numpy temporaries.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import compile_notice, njit, run_chunks
from roboisf.robot.vjm_numba import _c64, chunk, sincos
from roboisf.robot.vjm_numba import _rows as _vjm_kernel_rows

compile_notice(__file__)  # numba compiles these on first call: say so once

__all__ = ["PathVJM", "flange_ik", "path_ik", "path_vjm"]

F64 = NDArray[np.float64]

_TWO_PI = 2.0 * np.pi
_PI = np.pi


#: The helpers below (atan2, _wrap, _opw, …) are plain compiled functions that LLVM inlines into
#: the row kernels, not numba-level ``inline="always"``: that re-typed _opw's five atan2 and six
#: wraps inside each caller and made _tip_rows and _flange_rows take 10–12 s each to compile
#: (the robot kernels' cold build 30 s → 11 s); the same bits and the same speed (measured:
#: IK of 200,000 points 0.052 → 0.050 s, equal arrays).
_njit = njit


# atan / atan2 after fdlibm's ``s_atan.c`` / ``e_atan2.c`` (reduction to |x| < 7/16 with the
# atanhi/atanlo table, an 11-term odd minimax polynomial): ≤ 1–2 ulp from glibc's correctly
# rounded atan2 (tested through the IK, ≤ 1e-12 rad), ~3× faster (5 of them per pose were about
# 60 % of the IK kernel).
_ATANHI = (4.63647609000806093515e-01, 7.85398163397448278999e-01, 9.82793723247329054082e-01)
_ATANLO = (2.26987774529616870924e-17, 3.06161699786838301793e-17, 1.39033110312309984516e-17)
_HALF_PI_HI, _HALF_PI_LO = 1.57079632679489655800e00, 6.12323399573676603587e-17
_PI_LO = 1.2246467991473531772e-16
_AT0, _AT1 = 3.33333333333329318027e-01, -1.99999999998764832476e-01
_AT2, _AT3 = 1.42857142725034663711e-01, -1.11111104054623557880e-01
_AT4, _AT5 = 9.09088713343650656196e-02, -7.69187620504482999495e-02
_AT6, _AT7 = 6.66107313738753120669e-02, -5.83357013379057348645e-02
_AT8 = 4.97687799461593236017e-02
_AT9, _AT10 = -3.65315727442169155270e-02, 1.62858201153657823623e-02


@_njit()
def _atan_pos(x: float) -> float:  # pragma: no cover - compiled
    """atan(x) for finite x ≥ 0 (fdlibm)."""
    if x >= 7.3786976294838206464e19:  # 2**66
        return _HALF_PI_HI + _HALF_PI_LO
    if x < 0.4375:
        if x < 7.450580596923828e-09:  # 2**-27
            return x
        ident = -1
    elif x < 1.1875:
        if x < 0.6875:
            ident = 0
            x = (2.0 * x - 1.0) / (2.0 + x)
        else:
            ident = 1
            x = (x - 1.0) / (x + 1.0)
    elif x < 2.4375:
        ident = 2
        x = (x - 1.5) / (1.0 + 1.5 * x)
    else:
        ident = 3
        x = -1.0 / x
    z = x * x
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    if ident < 0:
        return x - x * (s1 + s2)
    if ident == 0:
        hi, lo = _ATANHI[0], _ATANLO[0]
    elif ident == 1:
        hi, lo = _ATANHI[1], _ATANLO[1]
    elif ident == 2:
        hi, lo = _ATANHI[2], _ATANLO[2]
    else:
        hi, lo = _HALF_PI_HI, _HALF_PI_LO
    return hi - ((x * (s1 + s2) - lo) - x)


@_njit()
def atan2(y: float, x: float) -> float:  # pragma: no cover - compiled
    """``atan2(y, x)`` (fdlibm); libm for zeros, infinities and NaN."""
    if x == 0.0 or y == 0.0 or not (abs(x) < np.inf and abs(y) < np.inf):
        return math.atan2(y, x)
    r = abs(y / x)
    if r > 1.152921504606847e18:  # |y/x| > 2**60
        return _HALF_PI_HI + 0.5 * _PI_LO if y > 0.0 else -(_HALF_PI_HI + 0.5 * _PI_LO)
    z = 0.0 if (x < 0.0 and r < 8.673617379884035e-19) else _atan_pos(r)  # 2**-60
    if x > 0.0:
        return z if y > 0.0 else -z
    if y > 0.0:
        return _PI - (z - _PI_LO)
    return (z - _PI_LO) - _PI


@_njit()
def _wrap(x: float) -> float:  # pragma: no cover - compiled
    """``np.mod(x + π, 2π) − π`` (numpy's float modulo: the sign of the divisor).

    The same bits without ``fmod`` and its division (6 per pose were ~1/4 of the IK kernel) for
    ``x + π`` in (−2π, 4π), i.e. every angle the OPW solution forms: there ``fmod`` is the
    argument itself or, on [2π, 4π), ``y − 2π``, which is exact (Sterbenz) as is ``fmod``; on
    (−2π, 0) Python's modulo adds 2π to ``fmod``'s result, the same rounded addition."""
    y = x + _PI
    if 0.0 < y < _TWO_PI:
        return y - _PI
    if _TWO_PI <= y < 2.0 * _TWO_PI:
        return (y - _TWO_PI) - _PI
    if -_TWO_PI < y < 0.0:
        return (y + _TWO_PI) - _PI
    return y % _TWO_PI - _PI  # Python's float modulo = numpy's


@_njit()
def _opw(
    r00: float,
    r01: float,
    r02: float,
    r10: float,
    r11: float,
    r12: float,
    r20: float,
    r21: float,
    r22: float,
    px: float,
    py: float,
    pz: float,
    geo: F64,
    flags: F64,
    sign: F64,
    offset: F64,
    cpl: float,
    q: F64,
    n: int,
) -> bool:  # pragma: no cover - compiled
    """One flange pose (R, p) → ``q[n]`` (controller angles, wrapped) of the branch ``flags``
    = (front, sgn, flip); returns reachability (the row is NaN when False), as ``opw_ik``."""
    a1, a2, b, c1, c2, c3g, c4 = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5], geo[6]
    kappa2, kappa, phi = geo[7], geo[8], geo[9]  # a2² + c3², its root, atan2(a2, c3)
    front = flags[0] > 0.0
    sgn = flags[1]
    flip = flags[2] > 0.0
    cx = px - c4 * r02
    cy = py - c4 * r12
    cz = pz - c4 * r22
    rho2 = cx * cx + cy * cy - b * b
    ok = rho2 >= 0
    r = math.sqrt(rho2) if ok else 0.0
    xr = r if front else -r
    # θ1 = atan2(cy, cx) − atan2(b, xr), as one atan2 of the rotated vector (the same angle up
    # to a whole turn, which the wrap removes); its sine and cosine without trigonometry
    u = cx * xr + cy * b
    v = cy * xr - cx * b
    th1 = atan2(v, u)
    h2 = u * u + v * v
    if h2 > 0.0:
        h = 1.0 / math.sqrt(h2)
        cc1, s1 = u * h, v * h
    else:  # wrist centre on the A1 axis (b = 0): θ1 is arbitrary, as atan2(0, 0) = 0
        s1, cc1 = sincos(th1)
    x = xr - a1
    z = cz - c1
    D = (x * x + z * z - c2 * c2 - kappa2) / (2.0 * c2 * kappa)
    ok = ok and abs(D) <= 1.0 + 1e-12
    acos_d = math.acos(min(max(D, -1.0), 1.0))
    th3 = sgn * acos_d - phi
    s3, cc3 = sincos(th3)
    wx = a2 * cc3 + c3g * s3
    wz = c2 - a2 * s3 + c3g * cc3
    # θ2 = atan2(x, z) − atan2(wx, wz), one atan2 (up to a whole turn; θ2 + θ3 only enters
    # through its sine and cosine, and θ2 is wrapped)
    th2 = atan2(x * wz - z * wx, z * wz + x * wx)
    s23, c23 = sincos(th2 + th3)
    # W = (Rz(θ1) Ry(θ23))ᵀ R: rows e0 = (c1 c23, s1 c23, −s23), e1 = (−s1, c1, 0),
    # e2 = (c1 s23, s1 s23, c23); only the entries the wrist angles need
    e00, e01, e02 = cc1 * c23, s1 * c23, -s23
    e20, e21, e22 = cc1 * s23, s1 * s23, c23
    w02 = e00 * r02 + e01 * r12 + e02 * r22
    w12 = -s1 * r02 + cc1 * r12
    w20 = e20 * r00 + e21 * r10 + e22 * r20
    w21 = e20 * r01 + e21 * r11 + e22 * r21
    w22 = e20 * r02 + e21 * r12 + e22 * r22
    th5 = atan2(math.sqrt(w02 * w02 + w12 * w12), w22)
    th4 = atan2(w12, w02)
    th6 = atan2(w21, -w20)
    if flip:
        th4 = th4 + _PI
        th5 = -th5
        th6 = th6 + _PI
    if not ok:
        for j in range(6):
            q[n, j] = np.nan
        return False
    q[n, 0] = _wrap((th1 - offset[0]) * sign[0])
    q[n, 1] = _wrap((th2 - offset[1]) * sign[1])
    # FANUC J2/J3 coupling: θ3 = s3 (q3 + cpl q2) + o3 → q3 = s3 (θ3 − o3) − cpl q2 (cpl is
    # −1, 0 or 1, so a whole turn of θ2 is a whole turn of q3, which the wrap removes)
    q[n, 2] = _wrap((th3 - offset[2]) * sign[2] - cpl * ((th2 - offset[1]) * sign[1]))
    q[n, 3] = _wrap((th4 - offset[3]) * sign[3])
    q[n, 4] = _wrap((th5 - offset[4]) * sign[4])
    q[n, 5] = _wrap((th6 - offset[5]) * sign[5])
    return True


@_njit()
def _flange_rows(
    T: F64,
    geo: F64,
    flags: F64,
    sign: F64,
    offset: F64,
    c23: float,
    q: F64,
    ok: NDArray[np.bool_],
    s: int,
    e: int,
) -> None:  # pragma: no cover - compiled
    for n in range(s, e):
        ok[n] = _opw(
            T[n, 0, 0],
            T[n, 0, 1],
            T[n, 0, 2],
            T[n, 1, 0],
            T[n, 1, 1],
            T[n, 1, 2],
            T[n, 2, 0],
            T[n, 2, 1],
            T[n, 2, 2],
            T[n, 0, 3],
            T[n, 1, 3],
            T[n, 2, 3],
            geo,
            flags,
            sign,
            offset,
            c23,
            q,
            n,
        )


@_njit()
def _tip_rows(
    A: F64,
    B: F64,
    tip: F64,
    gam: F64,
    geo: F64,
    flags: F64,
    sign: F64,
    offset: F64,
    c23: float,
    q: F64,
    ok: NDArray[np.bool_],
    T_tip: F64,
    s: int,
    e: int,
) -> None:  # pragma: no cover - compiled
    """Poses ``s:e``: ``T_base_tip = A · [vertical_tool(γ), tip]``, ``T_base_flange = T_base_tip
    · B`` (``A`` = T_base_work, ``B`` = T_flange_tip⁻¹), then the OPW branch; ``T_tip`` is
    written when it has N rows."""
    one_g = gam.shape[0] == 1
    want_t = T_tip.shape[0] > 0
    sg, cg = sincos(gam[0])  # one γ for the path: once
    for n in range(s, e):
        if not one_g:
            sg, cg = sincos(gam[n])
        # vertical_tool(γ) = [[c, −s, 0], [−s, −c, 0], [0, 0, −1]]
        t0, t1, t2 = tip[n, 0], tip[n, 1], tip[n, 2]
        m00 = A[0, 0] * cg - A[0, 1] * sg
        m01 = -A[0, 0] * sg - A[0, 1] * cg
        m02 = -A[0, 2]
        m10 = A[1, 0] * cg - A[1, 1] * sg
        m11 = -A[1, 0] * sg - A[1, 1] * cg
        m12 = -A[1, 2]
        m20 = A[2, 0] * cg - A[2, 1] * sg
        m21 = -A[2, 0] * sg - A[2, 1] * cg
        m22 = -A[2, 2]
        p0 = A[0, 0] * t0 + A[0, 1] * t1 + A[0, 2] * t2 + A[0, 3]
        p1 = A[1, 0] * t0 + A[1, 1] * t1 + A[1, 2] * t2 + A[1, 3]
        p2 = A[2, 0] * t0 + A[2, 1] * t1 + A[2, 2] * t2 + A[2, 3]
        if want_t:
            T_tip[n, 0, 0], T_tip[n, 0, 1], T_tip[n, 0, 2], T_tip[n, 0, 3] = m00, m01, m02, p0
            T_tip[n, 1, 0], T_tip[n, 1, 1], T_tip[n, 1, 2], T_tip[n, 1, 3] = m10, m11, m12, p1
            T_tip[n, 2, 0], T_tip[n, 2, 1], T_tip[n, 2, 2], T_tip[n, 2, 3] = m20, m21, m22, p2
            T_tip[n, 3, 0], T_tip[n, 3, 1], T_tip[n, 3, 2], T_tip[n, 3, 3] = 0.0, 0.0, 0.0, 1.0
        ok[n] = _opw(
            m00 * B[0, 0] + m01 * B[1, 0] + m02 * B[2, 0],
            m00 * B[0, 1] + m01 * B[1, 1] + m02 * B[2, 1],
            m00 * B[0, 2] + m01 * B[1, 2] + m02 * B[2, 2],
            m10 * B[0, 0] + m11 * B[1, 0] + m12 * B[2, 0],
            m10 * B[0, 1] + m11 * B[1, 1] + m12 * B[2, 1],
            m10 * B[0, 2] + m11 * B[1, 2] + m12 * B[2, 2],
            m20 * B[0, 0] + m21 * B[1, 0] + m22 * B[2, 0],
            m20 * B[0, 1] + m21 * B[1, 1] + m22 * B[2, 1],
            m20 * B[0, 2] + m21 * B[1, 2] + m22 * B[2, 2],
            m00 * B[0, 3] + m01 * B[1, 3] + m02 * B[2, 3] + p0,
            m10 * B[0, 3] + m11 * B[1, 3] + m12 * B[2, 3] + p1,
            m20 * B[0, 3] + m21 * B[1, 3] + m22 * B[2, 3] + p2,
            geo,
            flags,
            sign,
            offset,
            c23,
            q,
            n,
        )


@_njit()
def _round_half_even(x: float) -> float:  # pragma: no cover - compiled
    r = math.floor(x + 0.5) * 1.0
    if r - x == 0.5 and r % 2.0 != 0.0:
        r -= 1.0
    return r


@_njit()
def _continuous(q: F64, q_min: F64, q_max: F64) -> bool:  # pragma: no cover - compiled
    """In place: ``np.unwrap`` along axis 0, the whole-turn shift of
    :func:`roboisf.robot.ik._continuous`; returns True when every angle is within the limits
    (± 1e-9 rad).

    Two passes per joint: the unwrap also sums the column and tracks its extremes (the limit
    tests on the shifted column follow from those exactly, rounding being monotonic), then one
    pass applies the shift — the same additions, in the same order, as unwrap, sum, shift and
    test done one after another."""
    n = q.shape[0]
    all_in = True
    for j in range(6):
        # np.unwrap: period 2π, discont π, the ambiguous boundary to +π when the step is > 0
        acc = 0.0
        prev = q[0, j]
        tot = prev
        lo_q = prev
        hi_q = prev
        for i in range(1, n):
            cur = q[i, j]
            dd = cur - prev
            prev = cur
            if not abs(dd) < _PI:  # np.unwrap corrects only these steps
                ddmod = (dd + _PI) % _TWO_PI - _PI
                if ddmod == -_PI and dd > 0:
                    ddmod = _PI
                acc += ddmod - dd
            v = cur + acc
            q[i, j] = v
            tot += v
            if v < lo_q:
                lo_q = v
            if v > hi_q:
                hi_q = v
        mean = tot / n
        mid = 0.5 * (q_min[j] + q_max[j])
        k = _round_half_even((mid - mean) / _TWO_PI)
        lo = q_min[j] - 1e-9
        hi = q_max[j] + 1e-9
        sh = k * _TWO_PI
        lo_s = lo_q + sh  # extremes of the shifted column (fl(x + c) is monotonic in x)
        hi_s = hi_q + sh
        dk = 0.0
        for t in range(3):
            dt = 0.0 if t == 0 else (1.0 if t == 1 else -1.0)
            a = lo_s + dt * _TWO_PI
            b = hi_s + dt * _TWO_PI
            if a >= lo and a <= hi and b >= lo and b <= hi:
                dk = dt
                break
        ds = dk * _TWO_PI
        for i in range(n):
            q[i, j] = q[i, j] + sh
            if dk != 0.0:
                q[i, j] = q[i, j] + ds
        if lo_s + ds < lo or hi_s + ds > hi:
            all_in = False
    return all_in


def _args(model: Any, shoulder: str, elbow: str, wrist: str) -> tuple[F64, F64, F64, F64, float]:
    g = model.opw
    kappa2 = g.a2 * g.a2 + g.c3 * g.c3
    geo = np.array(
        [g.a1, g.a2, g.b, g.c1, g.c2, g.c3, g.c4, kappa2, np.sqrt(kappa2), np.arctan2(g.a2, g.c3)],
        dtype=np.float64,
    )
    front = shoulder == "front"
    up = elbow == "up"
    flags = np.array(
        [1.0 if front else 0.0, 1.0 if up == front else -1.0, 1.0 if wrist == "flip" else 0.0]
    )
    return geo, flags, _c64(model.chain.sign), _c64(model.chain.offset), model.chain.couple23


def _lib() -> Any:
    """The C form of this module's kernels (in ``roboisf/robot/vjm_kernel.c``), or None."""
    from roboisf.robot.vjm_kernel import _c

    return _c()


def _need(what: str, a: Any, shape: tuple[int, ...], dtype: Any = np.float64) -> None:
    """Before a C call: ``a`` is C-contiguous, of ``dtype`` and ``shape`` (−1: any length)."""
    if not (
        isinstance(a, np.ndarray)
        and a.dtype == dtype
        and a.flags.c_contiguous
        and a.ndim == len(shape)
        and all(w in (-1, g) for g, w in zip(a.shape, shape, strict=True))
    ):
        got = getattr(a, "shape", None), getattr(a, "dtype", None)
        raise ValueError(f"{what}: {shape} {np.dtype(dtype).name} C-contiguous expected, got {got}")


def _need_branch(geo: F64, flags: F64, sign: F64, offset: F64) -> None:
    _need("geometry", geo, (10,))
    _need("branch flags", flags, (3,))
    _need("sign", sign, (6,))
    _need("offset", offset, (6,))


def flange_ik(
    model: Any, T_base_flange: F64, shoulder: str, elbow: str, wrist: str
) -> tuple[F64, NDArray[np.bool_]]:
    """``opw_ik`` on the compiled engine: flange poses (N, 4, 4) → (q (N, 6) rad, ok (N,))."""
    T = _c64(T_base_flange)
    n = T.shape[0]
    q = np.empty((n, 6))
    ok = np.empty(n, dtype=np.bool_)
    geo, flags, sign, offset, c23 = _args(model, shoulder, elbow, wrist)
    lib = _lib()
    if lib is not None:
        _need("flange poses", T, (n, 4, 4))
        _need_branch(geo, flags, sign, offset)
        c23 = float(c23)

        def rows(s: int, e: int) -> None:
            lib.flange_rows(
                T.ctypes.data,
                geo.ctypes.data,
                flags.ctypes.data,
                sign.ctypes.data,
                offset.ctypes.data,
                c23,
                q.ctypes.data,
                ok.ctypes.data,
                s,
                e,
            )
    else:

        def rows(s: int, e: int) -> None:
            _flange_rows(T, geo, flags, sign, offset, c23, q, ok, s, e)

    run_chunks(rows, n, chunk(n), any_thread=False)
    return q, ok


def path_ik(
    model: Any,
    tip: F64,
    T_base_work: F64,
    T_flange_tip_inv: F64,
    gamma: F64,
    shoulder: str,
    elbow: str,
    wrist: str,
    *,
    want_tip_poses: bool = True,
) -> tuple[F64, NDArray[np.bool_], bool, F64 | None]:
    """IK along a path: tip points (N, 3) m (work), ``T_base_work`` (4, 4), ``T_flange_tip⁻¹``
    (4, 4), γ (N,) or (1,) rad → (q (N, 6) rad, reachable (N,), within limits, T_base_tip
    (N, 4, 4) or None).

    When every point is reachable, ``q`` is the continuous trajectory (unwrapped and shifted by
    whole turns as :func:`roboisf.robot.ik._continuous`) and ``within`` says whether it stays
    inside the joint limits; otherwise ``q`` is the wrapped per-point solution (NaN where
    unreachable) and ``within`` is False.
    """
    tip = _c64(tip)
    n = tip.shape[0]
    q = np.empty((n, 6))
    ok = np.empty(n, dtype=np.bool_)
    T_tip = np.empty((n if want_tip_poses else 0, 4, 4))
    geo, flags, sign, offset, c23 = _args(model, shoulder, elbow, wrist)
    args = (
        _c64(T_base_work),
        _c64(T_flange_tip_inv),
        tip,
        _c64(gamma),
        geo,
        flags,
        sign,
        offset,
        c23,
    )
    lib = _lib()
    if lib is not None:
        A, B, _, gam, geo, flags, sign, offset, c23 = args
        _need("T_base_work", A, (4, 4))
        _need("T_flange_tip⁻¹", B, (4, 4))
        _need("tip", tip, (n, 3))
        if gam.shape not in ((1,), (n,)):
            raise ValueError(f"gamma: (1,) or ({n},) expected, got {gam.shape}")
        _need_branch(geo, flags, sign, offset)
        ng, c23 = gam.shape[0], float(c23)

        def rows(s: int, e: int) -> None:
            lib.tip_rows(
                A.ctypes.data,
                B.ctypes.data,
                tip.ctypes.data,
                gam.ctypes.data,
                ng,
                geo.ctypes.data,
                flags.ctypes.data,
                sign.ctypes.data,
                offset.ctypes.data,
                c23,
                q.ctypes.data,
                ok.ctypes.data,
                T_tip.ctypes.data if want_tip_poses else None,
                s,
                e,
            )
    else:

        def rows(s: int, e: int) -> None:
            _tip_rows(*args, q, ok, T_tip, s, e)

    run_chunks(rows, n, chunk(n), any_thread=False)
    within = False
    if n == 0:  # no angle (the kernel would read a first row that is not there)
        within = True
    elif bool(ok.all()):
        q_min, q_max = _c64(model.q_min), _c64(model.q_max)
        if lib is not None:
            _need("q_min", q_min, (6,))
            _need("q_max", q_max, (6,))
            within = bool(lib.continuous(q.ctypes.data, n, q_min.ctypes.data, q_max.ctypes.data))
        else:
            within = bool(_continuous(q, q_min, q_max))
    return q, ok, within, (T_tip if want_tip_poses else None)


@_njit()
def _row6(
    C: F64, i: int, a0: float, a1: float, a2: float, a3: float, a4: float, a5: float
) -> float:  # pragma: no cover - compiled
    return a0 * C[i, 0] + a1 * C[i, 1] + a2 * C[i, 2] + a3 * C[i, 3] + a4 * C[i, 4] + a5 * C[i, 5]


@_njit()
def _vjm_rows(
    F: F64,
    sign: F64,
    offset: F64,
    c23: float,
    kinv: F64,
    q: F64,
    W_work: F64,
    A: F64,
    C_tool: F64,
    gam: F64,
    mg: F64,
    rb: float,
    W_base: F64,
    d: F64,
    margin_ok: NDArray[np.bool_],
    d_robot: F64,
    d_total: F64,
    abs_total: F64,
    steps: F64,
    nrm: F64,
    abs_robot: F64,
    abs_normal: F64,
    s: int,
    e: int,
) -> None:  # pragma: no cover - compiled
    """Poses ``s:e`` of a solved path: the wrench into base axes, the VJM kernel of
    :mod:`roboisf.robot.vjm_numba` (δ and the margin test), δ back into work axes, the tool's
    own deflection (``C_tool`` (6, 6) in tool axes, ``R_work_tool = Rz(−γ)``; none when it has
    no rows), both moved to the ball centre ``rb`` above the tip (``δ + θ × rb ẑ``, work axes;
    not when ``rb`` is 0), |δ|, the robot's |δ| and |δ·n| (``nrm`` (N, 3) work; skipped when it
    has no rows) and the largest joint step from the previous pose — the per-point figures a
    placement's score reduces, so that no numpy pass over the path follows the kernel."""
    one_w = W_work.shape[0] == 1
    one_g = gam.shape[0] == 1
    want_tool = C_tool.shape[0] > 0
    want_normal = nrm.shape[0] > 0
    for n in range(s, e):
        w = 0 if one_w else n
        for i in range(3):
            W_base[n, i] = A[i, 0] * W_work[w, 0] + A[i, 1] * W_work[w, 1] + A[i, 2] * W_work[w, 2]
            W_base[n, 3 + i] = (
                A[i, 0] * W_work[w, 3] + A[i, 1] * W_work[w, 4] + A[i, 2] * W_work[w, 5]
            )
    no_k = np.empty((0, 6, 6))
    sg, cg = sincos(gam[0])  # one γ for the path: once
    _vjm_kernel_rows(F, sign, offset, c23, kinv, q, W_base, s, e, d, no_k, no_k, mg, margin_ok)
    for n in range(s, e):
        x0 = d[n, 0] * A[0, 0] + d[n, 1] * A[1, 0] + d[n, 2] * A[2, 0]
        x1 = d[n, 0] * A[0, 1] + d[n, 1] * A[1, 1] + d[n, 2] * A[2, 1]
        x2 = d[n, 0] * A[0, 2] + d[n, 1] * A[1, 2] + d[n, 2] * A[2, 2]
        if rb != 0.0:  # the ball centre: + θ × (0, 0, rb), θ in work axes
            h0 = d[n, 3] * A[0, 0] + d[n, 4] * A[1, 0] + d[n, 5] * A[2, 0]
            h1 = d[n, 3] * A[0, 1] + d[n, 4] * A[1, 1] + d[n, 5] * A[2, 1]
            x0 = x0 + h1 * rb
            x1 = x1 - h0 * rb
        d_robot[n, 0], d_robot[n, 1], d_robot[n, 2] = x0, x1, x2
        abs_robot[n] = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if want_tool:
            if not one_g:
                sg, cg = sincos(gam[n])
            w = 0 if one_w else n
            f0, f1 = W_work[w, 0], W_work[w, 1]
            m0, m1 = W_work[w, 3], W_work[w, 4]
            wt0 = cg * f0 - sg * f1
            wt1 = sg * f0 + cg * f1
            wt3 = cg * m0 - sg * m1
            wt4 = sg * m0 + cg * m1
            f2, m2 = W_work[w, 2], W_work[w, 5]
            t0 = _row6(C_tool, 0, wt0, wt1, f2, wt3, wt4, m2)
            t1 = _row6(C_tool, 1, wt0, wt1, f2, wt3, wt4, m2)
            t2 = _row6(C_tool, 2, wt0, wt1, f2, wt3, wt4, m2)
            y0 = cg * t0 + sg * t1
            y1 = -sg * t0 + cg * t1
            if rb != 0.0:  # the tool's rotation, tool → work axes, moves the ball centre
                t3 = _row6(C_tool, 3, wt0, wt1, f2, wt3, wt4, m2)
                t4 = _row6(C_tool, 4, wt0, wt1, f2, wt3, wt4, m2)
                y0 = y0 + (-sg * t3 + cg * t4) * rb
                y1 = y1 - (cg * t3 + sg * t4) * rb
            x0 += y0
            x1 += y1
            x2 += t2
        d_total[n, 0], d_total[n, 1], d_total[n, 2] = x0, x1, x2
        abs_total[n] = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if want_normal:
            # summed in the order numpy's einsum("ij,ij->i") uses (the numpy solve's figure)
            abs_normal[n] = abs((x0 * nrm[n, 0] + x2 * nrm[n, 2]) + x1 * nrm[n, 1])
        st = 0.0
        if n > 0:
            for j in range(6):
                st = max(st, abs(q[n, j] - q[n - 1, j]))
        steps[n] = st


class PathVJM(NamedTuple):
    """What :func:`path_vjm` computed for one placement (work axes).

    q : (N, 6) rad — continuous when ``status`` is 0; reachable : (N,) bool
    status : 0 solved within the limits, 1 some point out of reach, 2 beyond the joint limits
    (the arrays below are filled only for status 0)
    margin_ok : (N,) bool; d_robot, d_total : (N, 3) m; abs_total, steps : (N,) (m, rad)
    abs_robot : (N,) m — |d_robot|; abs_normal : (N,) m — |d_total·n| (None without normals)
    """

    q: F64
    reachable: NDArray[np.bool_]
    status: int
    margin_ok: NDArray[np.bool_] | None = None
    d_robot: F64 | None = None
    d_total: F64 | None = None
    abs_total: F64 | None = None
    steps: F64 | None = None
    abs_robot: F64 | None = None
    abs_normal: F64 | None = None


def path_vjm(
    model: Any,
    tip: F64,
    T_base_work: F64,
    gamma: F64,
    W_work: F64,
    C_tool: F64 | None,
    margin: tuple[float, float],
    shoulder: str = "front",
    elbow: str = "up",
    wrist: str = "noflip",
    normal: F64 | None = None,
    ball_radius: float = 0.0,
) -> PathVJM:
    """IK, continuity, joint limits, VJM δ, the singularity-margin test and the tool's deflection
    along one placement's path, compiled end to end (``roboisf.plan``'s inner loop).

    tip (N, 3) m work; T_base_work (4, 4); γ (N,) or (1,) rad; W_work (N, 6) or (1, 6) [N; N·m]
    in work axes; C_tool (6, 6) tool compliance in tool axes (its force-to-displacement rows
    are used) or None; margin = (length scale m, threshold); normal (N, 3) unit work-axes
    normals for ``abs_normal`` or None; ball_radius m: δ of the ball centre this far above the
    tip along the work z (0: the tip).
    """
    from roboisf.frames import invert

    T_bw = _c64(T_base_work)
    q, ok, within, _ = path_ik(
        model,
        tip,
        T_bw,
        invert(model.T_flange_tip),
        gamma,
        shoulder,
        elbow,
        wrist,
        want_tip_poses=False,
    )
    if not bool(ok.all()):
        return PathVJM(q, ok, 1)
    if not within:
        return PathVJM(q, ok, 2)
    n = q.shape[0]
    F = model.chain.F.copy()
    F[6] = F[6] @ model.T_flange_tip
    args = (
        _c64(F),
        _c64(model.chain.sign),
        _c64(model.chain.offset),
        model.chain.couple23,
        _c64(1.0 / model.joint_stiffness),
        q,
        _c64(W_work),
        _c64(T_bw[:3, :3]),
        np.empty((0, 6)) if C_tool is None else _c64(C_tool),
        _c64(gamma),
        np.array([1.0 / margin[0], float(margin[1]) ** 2]),
        float(ball_radius),
    )
    out = (
        np.empty((n, 6)),  # W_base (scratch)
        np.empty((n, 6)),  # δ base
        np.empty(n, dtype=np.bool_),
        np.empty((n, 3)),
        np.empty((n, 3)),
        np.empty(n),
        np.empty(n),
        np.empty((0, 3)) if normal is None else _c64(normal),
        np.empty(n),  # |δ_robot|
        np.empty(n if normal is not None else 0),  # |δ·n|
    )
    lib = _lib()
    if lib is not None:
        rows = _c_vjm_rows(lib, args, out, n)
    else:

        def rows(s: int, e: int) -> None:
            _vjm_rows(*args, *out, s, e)

    run_chunks(rows, n, chunk(n), any_thread=False)
    abs_normal = None if normal is None else out[9]
    return PathVJM(q, ok, 0, out[2], out[3], out[4], out[5], out[6], out[8], abs_normal)


def _c_vjm_rows(lib: Any, args: tuple[Any, ...], out: tuple[Any, ...], n: int) -> Any:
    """``rows(s, e)``: :func:`_vjm_rows` of poses ``s:e`` in C (``path_vjm_rows``), after
    checking what reaches it."""
    F, sign, offset, c23, kinv, q, W_work, A, C_tool, gam, mg, rb = args
    W_base, d, margin_ok, d_robot, d_total, abs_total, steps, nrm, abs_robot, abs_normal = out
    _need("F", F, (7, 4, 4))
    for what, a in (("sign", sign), ("offset", offset), ("kinv", kinv)):
        _need(what, a, (6,))
    _need("q", q, (n, 6))
    if W_work.shape[0] not in (1, n):
        raise ValueError(f"W_work: (1, 6) or ({n}, 6) expected, got {W_work.shape}")
    _need("W_work", W_work, (-1, 6))
    _need("R_base_work", A, (3, 3))
    if C_tool.shape[0]:
        _need("C_tool", C_tool, (6, 6))
    if gam.shape not in ((1,), (n,)):
        raise ValueError(f"gamma: (1,) or ({n},) expected, got {gam.shape}")
    _need("gamma", gam, (-1,))
    _need("margin", mg, (2,))
    for what, a, shape, dtype in (
        ("W_base", W_base, (n, 6), np.float64),
        ("d", d, (n, 6), np.float64),
        ("margin_ok", margin_ok, (n,), np.bool_),
        ("d_robot", d_robot, (n, 3), np.float64),
        ("d_total", d_total, (n, 3), np.float64),
        ("abs_total", abs_total, (n,), np.float64),
        ("steps", steps, (n,), np.float64),
        ("abs_robot", abs_robot, (n,), np.float64),
    ):
        _need(what, a, shape, dtype)
    want_normal = nrm.shape[0] > 0
    if want_normal:
        _need("normal", nrm, (n, 3))
        _need("abs_normal", abs_normal, (n,))
    c23, rb, nw, ng = float(c23), float(rb), W_work.shape[0], gam.shape[0]

    def rows(s: int, e: int) -> None:
        lib.path_vjm_rows(
            F.ctypes.data,
            sign.ctypes.data,
            offset.ctypes.data,
            c23,
            kinv.ctypes.data,
            q.ctypes.data,
            W_work.ctypes.data,
            nw,
            A.ctypes.data,
            C_tool.ctypes.data if C_tool.shape[0] else None,
            gam.ctypes.data,
            ng,
            mg.ctypes.data,
            rb,
            W_base.ctypes.data,
            d.ctypes.data,
            margin_ok.ctypes.data,
            d_robot.ctypes.data,
            d_total.ctypes.data,
            abs_total.ctypes.data,
            steps.ctypes.data,
            nrm.ctypes.data if want_normal else None,
            abs_robot.ctypes.data,
            abs_normal.ctypes.data if want_normal else None,
            s,
            e,
        )

    return rows


@_njit()
def _wrap_many(x: F64) -> F64:  # pragma: no cover - compiled (for the tests)
    out = np.empty(x.shape[0])
    for i in range(x.shape[0]):
        out[i] = _wrap(x[i])
    return out


@_njit()
def _atan2_many(y: F64, x: F64) -> F64:  # pragma: no cover - compiled (for the tests)
    out = np.empty(y.shape[0])
    for i in range(y.shape[0]):
        out[i] = atan2(y[i], x[i])
    return out
