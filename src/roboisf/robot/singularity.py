"""Singularity margin of scaled Jacobians: the exact test by elimination, and the value.

The scaled Jacobian ``J_s`` divides the linear rows of the tip Jacobian by a length (c2 + c3
for OPW robots), so that its singular values are dimensionless. A pose keeps a margin
``threshold`` from singularities when ``σ_min(J_s) > threshold``. Since
``σ_min² = λ_min(J_sᵀ J_s)``, that is "``J_sᵀ J_s − threshold² I`` is positive definite": all
pivots of its LDLᵀ elimination are > 0 — a few dozen flops per pose, ~4× cheaper than the
eigenvalues (:func:`sigma_min`), which are computed only where the value itself is wanted.
:func:`roboisf.robot.ik_toolpath` and ``roboisf.plan`` both use :func:`margin_ok`.
"""

from __future__ import annotations

import threading

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.robot import vjm_kernel
from roboisf.robot.vjm_kernel import _PRANGE, _njit

__all__ = ["margin_ok", "scaled_jacobian", "sigma_min"]

F64 = NDArray[np.float64]


def scaled_jacobian(J: ArrayLike, length_scale: float) -> F64:
    """A copy of tip Jacobians (N, 6, 6) with the linear rows divided by ``length_scale`` (m)."""
    Js = np.array(J, dtype=float)
    Js[:, :3] /= length_scale
    return Js


def sigma_min(J_scaled: ArrayLike) -> F64:
    """Smallest singular value (N,) of scaled Jacobians (N, 6, 6) (``eigvalsh`` of ``J_sᵀJ_s``;
    absolute accuracy ~1e-8·σ_max, ample for margins of order 1e-2)."""
    Js = _check(J_scaled)
    lam = np.linalg.eigvalsh(np.swapaxes(Js, 1, 2) @ Js)[:, 0]
    return np.sqrt(np.clip(lam, 0.0, None))


def margin_ok(J_scaled: ArrayLike, threshold: float, *, backend: str = "auto") -> NDArray[np.bool_]:
    """Exact test ``σ_min(J_s) > threshold`` (N,) bool per pose for scaled Jacobians (N, 6, 6).

    All LDLᵀ pivots of ``J_sᵀ J_s − threshold² I`` are > 0 (see the module doc). ``backend``:
    "auto" (compiled when numba is installed), "numba" or "numpy" (vectorised over N in
    component-major arrays); both the same elimination.
    """
    Js = _check(J_scaled)
    c = float(threshold) ** 2
    if vjm_kernel.use_numba(backend):
        ok = np.empty(Js.shape[0], dtype=np.bool_)
        Jc = np.ascontiguousarray(Js)
        if threading.current_thread() is threading.main_thread():
            _margin_parallel(Jc, c, ok)
        else:
            _margin_serial(Jc, c, ok, 0, Jc.shape[0])
        return ok
    return _margin_numpy(Js, c)


def _check(J: ArrayLike) -> F64:
    Js = np.asarray(J, dtype=float)
    if Js.ndim != 3 or Js.shape[1:] != (6, 6):
        raise InputError(f"expected Jacobians of shape (N, 6, 6), got {Js.shape}", field="J")
    return Js


def _margin_numpy(Js: F64, c: float) -> NDArray[np.bool_]:
    Jt = np.ascontiguousarray(Js.transpose(1, 2, 0))  # (6 rows, 6 cols, N)
    n = Js.shape[0]
    M = np.empty((6, 6, n))
    for i in range(6):
        for j in range(i, 6):
            v = np.einsum("kn,kn->n", Jt[:, i], Jt[:, j])
            M[i, j] = v
            M[j, i] = v
    for i in range(6):
        M[i, i] -= c
    ok = np.ones(n, dtype=bool)
    for k in range(6):
        piv = M[k, k]
        ok &= piv > 0.0
        if k == 5:
            break
        inv = 1.0 / np.where(piv > 0.0, piv, 1.0)
        lk = M[k + 1 :, k] * inv  # (m, N)
        M[k + 1 :, k + 1 :] -= lk[:, None, :] * M[k, k + 1 :][None, :, :]
    return ok


@_njit()
def _margin_serial(
    Js: F64, c: float, ok: NDArray[np.bool_], s: int, e: int
) -> None:  # pragma: no cover - compiled (tested against the numpy elimination and eigvalsh)
    M = np.empty((6, 6))
    for n in range(s, e):
        for i in range(6):
            for j in range(i, 6):
                acc = 0.0
                for k in range(6):
                    acc += Js[n, k, i] * Js[n, k, j]
                M[i, j] = acc
            M[i, i] -= c
        good = True
        for k in range(6):
            piv = M[k, k]
            if not piv > 0.0:
                good = False
                break
            for i in range(k + 1, 6):
                lk = M[k, i] / piv  # upper triangle holds the symmetric matrix
                for j in range(i, 6):
                    M[i, j] -= lk * M[k, j]
        ok[n] = good


@_njit(parallel=True)
def _margin_parallel(Js: F64, c: float, ok: NDArray[np.bool_]) -> None:  # pragma: no cover
    n = Js.shape[0]
    nb = (n + 4095) // 4096
    for b in _PRANGE(nb):
        _margin_serial(Js, c, ok, b * 4096, min(n, (b + 1) * 4096))
