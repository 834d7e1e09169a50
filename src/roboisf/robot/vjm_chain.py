"""The chain walk for one pose, shared by the batch kernels and the online loop.

:func:`chain_walk` is the one implementation of the per-pose forward kinematics of
:mod:`roboisf.robot.kinematics` in scalar registers (seven fixed transforms ``F_0 .. F_6``, the
tool folded into ``F_6``; ``θ = sign·q + offset`` with the FANUC J2/J3 coupling
``θ_3 = sign_3 (q_3 + c23 q_2) + offset_3``); :func:`tip_jacobian` turns what it recorded into
the tip Jacobian, and :func:`chain_jacobian` is the two in one call. Callers:
:func:`roboisf.robot.vjm_numba._rows` (walk + Jacobian, every pose of a batch),
:func:`roboisf.robot.fk_numba._rows` (walk only: tip positions of a joint log) and
:func:`roboisf.online.kernel.fk_deflection` (:func:`chain_jacobian`, one pose per sample /
cycle).

This module imports numba only when it is installed: without it the functions are plain Python
(the online loop's fallback); with it they are compiled and inlined into their callers
(``inline="always"``), so the batch kernels' code and numbers are those of the hand-inlined walk.
The batch kernels call :func:`chain_walk` (and :func:`tip_jacobian`) themselves, one level of
inlining: through :func:`chain_jacobian`, two levels, numba takes more array references per
pose (atomic reference counts), and the batch VJM kernel measured ~6 % slower.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import njit

__all__ = ["chain_jacobian", "chain_walk", "sincos", "tip_jacobian"]

F64 = NDArray[np.float64]


_inline: Callable[[Callable[..., Any]], Callable[..., Any]] = njit(inline="always")


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


@_inline
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


@_inline
def chain_walk(
    F: F64, sign: F64, offset: F64, c23: float, q: F64, oz: F64 | None
) -> tuple[
    float, float, float, float, float, float, float, float, float, float, float, float
]:  # pragma: no cover - compiled (tested through chain_jacobian and fk_numba)
    """Forward kinematics of one pose: ``R_base_6`` (row-major) and the tip position.

    Parameters
    ----------
    F : (7, 4, 4) — the chain's fixed transforms, the tool folded into ``F[6]`` (m)
    sign, offset : (6,) — ``θ = sign·q + offset`` (offset in rad)
    c23 : float — FANUC J2/J3 coupling (−1, 0 or 1; :class:`~roboisf.robot.kinematics.Chain`)
    q : (6,) rad — the joint angles of the pose
    oz : (6, 6) or None — output for :func:`tip_jacobian`: per joint its z axis (3) and origin
        (3, m), base axes; None (positions only): not written (numba compiles the walk without
        the stores)

    Returns
    -------
    The nine entries of ``R_base_6`` (the frame after joint 6, before ``F[6]``), row-major,
    then the tip position ``p`` (3, m; after ``F[6]``), base frame.
    """
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
        if oz is not None:
            oz[j, 0] = r02
            oz[j, 1] = r12
            oz[j, 2] = r22
            oz[j, 3] = px
            oz[j, 4] = py
            oz[j, 5] = pz
        th = sign[j] * q[j] + offset[j]
        if j == 2 and c23 != 0.0:  # FANUC J2/J3 coupling: θ3 = s3 (q3 + c23 q2) + o3
            th += sign[2] * c23 * q[1]
        sn, c = sincos(th)
        r00, r01 = c * r00 + sn * r01, c * r01 - sn * r00
        r10, r11 = c * r10 + sn * r11, c * r11 - sn * r10
        r20, r21 = c * r20 + sn * r21, c * r21 - sn * r20
    t0, t1, t2 = F[6, 0, 3], F[6, 1, 3], F[6, 2, 3]
    px += r00 * t0 + r01 * t1 + r02 * t2
    py += r10 * t0 + r11 * t1 + r12 * t2
    pz += r20 * t0 + r21 * t1 + r22 * t2
    return r00, r01, r02, r10, r11, r12, r20, r21, r22, px, py, pz


@_inline
def tip_jacobian(
    sign: F64, c23: float, oz: F64, px: float, py: float, pz: float, Jl: F64
) -> None:  # pragma: no cover - compiled (tested through its callers)
    """Tip Jacobian ``Jl`` (6, 6) (base axes, at the tip) from :func:`chain_walk`'s ``oz`` and
    tip position ``(px, py, pz)`` (m).

    Column j = ``sign_j [z_j × (p − o_j); z_j]`` (rows 0–2 in m/rad); under the coupling ``c23``
    column 2 += ``c23`` × column 3.
    """
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


@_inline
def chain_jacobian(
    F: F64, sign: F64, offset: F64, c23: float, q: F64, oz: F64, Jl: F64
) -> tuple[float, float, float, float, float, float, float, float, float]:  # pragma: no cover
    """Tip Jacobian ``Jl`` (6, 6) (base axes, at the tip) of one pose; returns ``R_base_6``.

    :func:`chain_walk` then :func:`tip_jacobian`; ``oz`` (6, 6) is their scratch. Returns the
    nine entries of ``R_base_6`` (the frame after joint 6, before ``F[6]``), row-major.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22, px, py, pz = chain_walk(
        F, sign, offset, c23, q, oz
    )
    tip_jacobian(sign, c23, oz, px, py, pz, Jl)
    return r00, r01, r02, r10, r11, r12, r20, r21, r22
