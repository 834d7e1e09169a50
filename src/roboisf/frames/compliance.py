"""Compliance matrices and their serial assembly at the tool tip.

A compliance ``k`` (6×6) maps a wrench ``[f; m]`` applied at its reference point to the small
displacement ``[δ; θ]`` of that point: ``[δ; θ] = k @ [f; m]``. Units of the blocks:
``k[:3, :3]`` m/N, ``k[:3, 3:]`` and ``k[3:, :3]`` 1/N (rad/N = m/(N·m)), ``k[3:, 3:]`` rad/(N·m).

Moving a compliance given at point *i* to the tool tip (same axes), with ``v_i = tip − point_i``::

    J_i = [[I, −[v_i]×],
           [0,  I     ]]          k_tip = J_i k_i J_iᵀ

Why: a rotation θ at *i* moves the tip by ``θ × v_i = −[v_i]× θ``; and the tip wrench seen at *i*
is ``Jᵢᵀ W`` (same force, moment ``m + v_i × f``). ``J_i`` is the twist adjoint of a pure
translation by ``−v_i``, so the general (rotated) case is :func:`transform_compliance`.

Serial chain (robot, tool holder, tool), all at the tip: ``k_ef = Σ J_i k_i J_iᵀ`` (eq. 2);
the robot part back out: ``k_r = k_ef − J_th k_th J_thᵀ − J_t k_t J_tᵀ`` (eq. 3).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames.se3 import adjoint, skew

__all__ = [
    "check_compliance",
    "point_jacobian",
    "robot_part",
    "serial_assembly",
    "to_tip",
    "transform_compliance",
]

F64 = NDArray[np.float64]


def point_jacobian(v: ArrayLike) -> F64:
    """``J = [[I, −[v]×], [0, I]]`` for ``v = tip − point`` (..., 3) [m] → (..., 6, 6)."""
    v = np.asarray(v, dtype=float)
    J = np.zeros((*v.shape[:-1], 6, 6))
    J[..., :3, :3] = np.eye(3)
    J[..., 3:, 3:] = np.eye(3)
    J[..., :3, 3:] = -skew(v)
    return J


def to_tip(k_i: ArrayLike, v_i: ArrayLike) -> F64:
    """Compliance given at point *i* → at the tip (same axes). ``J k Jᵀ``; (..., 6, 6)."""
    J = point_jacobian(v_i)
    return J @ np.asarray(k_i, dtype=float) @ np.swapaxes(J, -1, -2)


def transform_compliance(k_b: ArrayLike, T_a_b: ArrayLike) -> F64:
    """Compliance at *b*'s origin in *b*'s axes → at *a*'s origin in *a*'s axes.

    ``k_a = Ad(T_a_b) k_b Ad(T_a_b)ᵀ``. (..., 6, 6), T (..., 4, 4).
    """
    Ad = adjoint(T_a_b)
    return Ad @ np.asarray(k_b, dtype=float) @ np.swapaxes(Ad, -1, -2)


def serial_assembly(parts: Sequence[tuple[ArrayLike, ArrayLike]]) -> F64:
    """``k_ef = Σ J_i k_i J_iᵀ`` for parts ``[(k_i, v_i), ...]`` with ``v_i = tip − point_i``.

    Each ``k_i`` may be (6, 6) or (N, 6, 6); each ``v_i`` (3,) or (N, 3) [m].
    """
    if not parts:
        raise InputError("serial_assembly needs at least one compliance")
    return sum((to_tip(k, v) for k, v in parts), start=np.zeros((6, 6)))


def robot_part(k_ef: ArrayLike, others: Sequence[tuple[ArrayLike, ArrayLike]]) -> F64:
    """Eq. (3): the robot's compliance from the end-effector total minus holder and tool terms."""
    k = np.array(k_ef, dtype=float, copy=True)
    for k_i, v_i in others:
        k = k - to_tip(k_i, v_i)
    return k


def check_compliance(k: ArrayLike, name: str = "compliance", *, rtol: float = 1e-6) -> F64:
    """Validate a (..., 6, 6) compliance: finite, symmetric to ``rtol``, positive semi-definite.

    Returns it as a float array; raises :class:`~roboisf.errors.InputError` naming ``name``.
    """
    k = np.asarray(k, dtype=float)
    if k.shape[-2:] != (6, 6):
        raise InputError(f"expected a 6×6 matrix, got shape {k.shape}", field=name)
    if not np.all(np.isfinite(k)):
        raise InputError("contains NaN or inf", field=name)
    scale = np.max(np.abs(k), axis=(-1, -2), keepdims=True)
    asym = np.abs(k - np.swapaxes(k, -1, -2))
    if np.any(asym > rtol * np.maximum(scale, 1e-300)):
        raise InputError("is not symmetric (a compliance must be)", field=name)
    # PSD test on the scaled matrix: units differ by block, so equilibrate first
    d = np.sqrt(np.clip(np.abs(np.diagonal(k, axis1=-2, axis2=-1)), 1e-300, None))
    ks = k / (d[..., :, None] * d[..., None, :])
    eig = np.linalg.eigvalsh(0.5 * (ks + np.swapaxes(ks, -1, -2)))
    if np.any(eig < -1e-9):
        raise InputError("is not positive semi-definite", field=name)
    return k
