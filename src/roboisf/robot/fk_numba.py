"""Compiled forward kinematics of the tool tip's position; imported on first use.

The position alignment (:mod:`roboisf.sync`) needs only where the tip was at every sample of a
joint log (250 Hz–1 kHz over a whole run: 0.5–2 M poses), not the orientation or the Jacobian.
:func:`tip_positions` walks the chain of :mod:`roboisf.robot.kinematics` (seven fixed
transforms ``F_0 .. F_6``, the tool folded into ``F_6``; ``θ = sign·q + offset``) in scalar
registers with :func:`roboisf.robot.vjm_chain.chain_walk`, the batch VJM kernel's walk, without
recording the joint axes the Jacobian needs, and writes only the (N, 3) positions, moved into
the work frame in the same loop. Same numbers as :meth:`roboisf.robot.RobotModel.fk` to
rounding (its ``sincos`` is ≤ 1 ulp from numpy's; tests/test_robot_fk_positions.py: ≤ 1e-12 m
on every preset).

Two compiled forms, the same bits: C (``fk_rows`` of ``vjm_kernel.c``, the library of
:mod:`roboisf.robot.vjm_kernel`, built at install, called through :mod:`roboisf.jit.native` —
no numba in the process) when it is built and fresh, else numba (:func:`_rows`, built at
install: :mod:`roboisf.jit.prebuild`); tests/test_native_robot.py compares them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import compile_notice, njit, run_chunks
from roboisf.robot import vjm_kernel
from roboisf.robot.vjm_chain import chain_walk
from roboisf.robot.vjm_numba import chunk

compile_notice(__file__)  # numba compiles these on first call: say so once

__all__ = ["BLOCK", "tip_positions"]

F64 = NDArray[np.float64]

#: Poses per thread's work item at least.
BLOCK = 4096


_njit = njit


@_njit()
def _rows(
    F: F64, sign: F64, offset: F64, c23: float, T: F64, q: F64, out: F64, s: int, e: int
) -> None:  # pragma: no cover - compiled (tested against RobotModel.fk)
    """Poses ``s:e``: tip position ``T[:3] @ [p_base; 1]`` into ``out`` (m)."""
    for n in range(s, e):
        px, py, pz = chain_walk(F, sign, offset, c23, q[n], None)[9:]  # no joint axes
        for i in range(3):
            out[n, i] = T[i, 0] * px + T[i, 1] * py + T[i, 2] * pz + T[i, 3]


def tip_positions(
    F_tip: F64, sign: F64, offset: F64, couple23: float, T_out_base: F64, q: F64
) -> F64:
    """Tip positions (N, 3) [m] in the frame of ``T_out_base`` (4, 4) for ``q`` (N, 6) rad.

    ``F_tip`` (7, 4, 4): the chain's fixed transforms with the tool folded into ``F_tip[6]``.
    On every core from the main thread (chunks on a thread pool), in the calling thread (no
    GIL) from any other: :func:`roboisf.jit.run_chunks`.
    """
    c = [np.ascontiguousarray(a, dtype=np.float64) for a in (F_tip, sign, offset, T_out_base, q)]
    out = np.empty((c[4].shape[0], 3))
    n = c[4].shape[0]
    lib = vjm_kernel._c()
    if lib is None:

        def rows(s: int, e: int) -> None:
            _rows(c[0], c[1], c[2], float(couple23), c[3], c[4], out, s, e)

    else:
        shapes = tuple(a.shape for a in c)
        if shapes != ((7, 4, 4), (6,), (6,), (4, 4), (n, 6)):
            raise ValueError(
                "tip_positions: F_tip (7, 4, 4), sign and offset (6,), T_out_base (4, 4), "
                f"q (N, 6) expected, got {shapes}"
            )
        c23 = float(couple23)

        def rows(s: int, e: int) -> None:
            # the pointers taken here, from arrays this closure holds: alive during the call
            F, sg, of, T, qc = (a.ctypes.data for a in c)
            lib.fk_rows(F, sg, of, c23, T, qc, out.ctypes.data, s, e)

    run_chunks(rows, n, chunk(n, BLOCK), any_thread=False)
    return out
