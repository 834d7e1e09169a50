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

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.robot import vjm_kernel

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
    "auto" (compiled: C when built, else numba when installed), "numba" or "numpy"
    (vectorised over N in component-major arrays); the same elimination, which the fused VJM
    kernel also runs (``RobotModel.vjm(..., margin=…)``).
    """
    Js = _check(J_scaled)
    c = float(threshold) ** 2
    if vjm_kernel.use_c(backend):  # the C form of margin_numba: no numba
        return vjm_kernel.margin_c(Js, 1.0, c)
    if vjm_kernel.use_numba(backend):
        from roboisf.robot.vjm_numba import margin_numba

        return margin_numba(Js, 1.0, c)
    return vjm_kernel.margin_numpy(Js, c)


def _check(J: ArrayLike) -> F64:
    Js = np.asarray(J, dtype=float)
    if Js.ndim != 3 or Js.shape[1:] != (6, 6):
        raise InputError(f"expected Jacobians of shape (N, 6, 6), got {Js.shape}", field="J")
    return Js
