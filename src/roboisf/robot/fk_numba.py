"""Compiled (numba) forward kinematics of the tool tip's position; imported on first use.

The position alignment (:mod:`roboisf.sync`) needs only where the tip was at every sample of a
joint log (250 Hz–1 kHz over a whole run: 0.5–2 M poses), not the orientation or the Jacobian.
:func:`tip_positions` walks the chain of :mod:`roboisf.robot.kinematics` (seven fixed
transforms ``F_0 .. F_6``, the tool folded into ``F_6``; ``θ = sign·q + offset``) in scalar
registers, the walk of :func:`roboisf.robot.vjm_chain.chain_jacobian` without the Jacobian, and
writes only the (N, 3) positions, moved into the work frame in the same loop. Same numbers as
:meth:`roboisf.robot.RobotModel.fk` to rounding (its ``sincos`` is ≤ 1 ulp from numpy's;
tests/test_robot_fk_positions.py: ≤ 1e-12 m on every preset).
"""

from __future__ import annotations

import threading
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray

from roboisf.robot.vjm_chain import sincos

__all__ = ["BLOCK", "tip_positions"]

F64 = NDArray[np.float64]

#: Poses per parallel work item.
BLOCK = 4096


def _njit(**kw: Any) -> Any:
    return numba.njit(cache=True, nogil=True, **kw)


@_njit()
def _rows(
    F: F64, sign: F64, offset: F64, c23: float, T: F64, q: F64, out: F64, s: int, e: int
) -> None:  # pragma: no cover - compiled (tested against RobotModel.fk)
    """Poses ``s:e``: tip position ``T[:3] @ [p_base; 1]`` into ``out`` (m)."""
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
        for i in range(3):
            out[n, i] = T[i, 0] * px + T[i, 1] * py + T[i, 2] * pz + T[i, 3]


@_njit(parallel=True)
def _parallel(
    F: F64, sign: F64, offset: F64, c23: float, T: F64, q: F64, out: F64
) -> None:  # pragma: no cover - compiled
    n = q.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    for b in numba.prange(nb):
        s = b * BLOCK
        _rows(F, sign, offset, c23, T, q, out, s, min(n, s + BLOCK))


def tip_positions(
    F_tip: F64, sign: F64, offset: F64, couple23: float, T_out_base: F64, q: F64
) -> F64:
    """Tip positions (N, 3) [m] in the frame of ``T_out_base`` (4, 4) for ``q`` (N, 6) rad.

    ``F_tip`` (7, 4, 4): the chain's fixed transforms with the tool folded into ``F_tip[6]``.
    Parallel (``prange``) from the main thread, serial without the GIL from any other.
    """
    c = [np.ascontiguousarray(a, dtype=np.float64) for a in (F_tip, sign, offset, T_out_base, q)]
    out = np.empty((c[4].shape[0], 3))
    if threading.current_thread() is threading.main_thread():
        _parallel(c[0], c[1], c[2], float(couple23), c[3], c[4], out)
    else:
        _rows(c[0], c[1], c[2], float(couple23), c[3], c[4], out, 0, c[4].shape[0])
    return out
