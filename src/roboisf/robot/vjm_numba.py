"""The compiled (numba) engine of :mod:`roboisf.robot.vjm_kernel`; imported on first use.

Kept apart so that ``import roboisf.robot`` does not import numba (≈ 0.4–0.6 s). See
:mod:`roboisf.robot.vjm_kernel` for what the kernels compute and how they are chosen.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import compile_notice, cores, njit, run_chunks
from roboisf.robot.vjm_chain import chain_walk, sincos, tip_jacobian

compile_notice(__file__)  # numba compiles these on first call: say so once

__all__ = ["BLOCK", "chunk", "kernel", "margin_numba", "margin_pivots_ok", "sincos"]

F64 = NDArray[np.float64]

#: Poses per work item at least (:func:`chunk`).
BLOCK = 1024


def chunk(n: int, block: int = BLOCK) -> int:
    """Poses per thread's work item for ``n`` poses: about four items per core (uneven cores
    even out), whole ``block`` s. The rows are independent: the chunks do not change the
    numbers."""
    per = -(-n // (4 * cores()))
    return max(block, -(-per // block) * block)


_njit = njit


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
        # the walk and the Jacobian called here, not through chain_jacobian: one level of
        # inlining (see roboisf.robot.vjm_chain)
        px, py, pz = chain_walk(F, sign, offset, c23, q[n], oz)[9:]
        tip_jacobian(sign, c23, oz, px, py, pz, Jl)
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


def margin_numba(Js: F64, lin_scale: float, c: float) -> NDArray[np.bool_]:
    """:func:`margin_pivots_ok` over Jacobians (N, 6, 6) (on every core from the main thread,
    in the calling thread from any other: :func:`roboisf.jit.run_chunks`)."""
    n = Js.shape[0]
    ok = np.empty(n, dtype=np.bool_)
    Jc = _c64(Js)
    ls, cc = float(lin_scale), float(c)
    run_chunks(lambda s, e: _margin_rows(Jc, ls, cc, ok, s, e), n, chunk(n), any_thread=False)
    return ok


def _kernel_threads(
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
) -> None:
    """:func:`_rows` of every pose, in chunks on every core (the kernel releases the GIL)."""
    n = q.shape[0]

    def rows(s: int, e: int) -> None:
        _rows(F, sign, offset, c23, kinv, q, W, s, e, d, k, J, margin, ok)

    run_chunks(rows, n, chunk(n))


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
    """The VJM kernel for this thread: on every core from the main thread (chunks on a thread
    pool), serial (no GIL) from any other, so that a caller's own threads are not
    oversubscribed. The same numbers either way."""
    if threading.current_thread() is threading.main_thread():
        return _kernel_threads
    return _kernel_serial


def build() -> None:
    """Compile (and so cache) the robot kernels — this module's, :mod:`roboisf.robot.fk_numba`'s
    and :mod:`roboisf.robot.ik_numba`'s — by running them once on a few poses of a preset (the
    background builder of :mod:`roboisf.jit.background`, group "robot")."""
    from roboisf.robot.ik import ik_toolpath
    from roboisf.robot.maps import stiffness_map
    from roboisf.robot.presets import list_robots, load_robot

    models = [load_robot(n) for n in list_robots()]
    model = next(m for m in models if m.stiffness is not None).with_backend("numba")
    mid = 0.5 * (model.q_min + model.q_max)
    q = mid + np.linspace(-0.2, 0.2, 4)[:, None] * (model.q_max - model.q_min) / 2
    model.vjm(q, np.ones(6), want_compliance=True, want_jacobian=True)
    model.tip_positions(q)
    stiffness_map(model, n=3, half_width=0.1)
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])
    if model.default_placement is not None:
        ik_toolpath(model, pts, backend="numba")
        # roboisf.plan's inner loop (IK, VJM and the tool's deflection in one compiled pass):
        # without it the first plan after this build compiled it in the foreground (~1.5 s)
        from roboisf.robot.ik_numba import path_vjm

        W = np.tile([0.0, 0.0, -500.0, 0.0, 0.0, 0.0], (len(pts), 1))
        up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
        path_vjm(model, pts, model.default_placement, np.zeros(1), W, None, (1.0, 0.0), normal=up)
