"""Moving wrenches [f; m] between frames and reference points.

A force sensor measures ``W_s = [f_s; m_s]`` in its own frame *s*, moments about its origin. The
wrench acting at the tool tip *t* (forces in *t*'s axes, moments about *t*'s origin) is

    f_t = R_t_s f_s
    m_t = R_t_s (m_s + (p_s − p_t) × f_s)

where ``p_s − p_t`` is the vector from the tip to the sensor origin in sensor coordinates. This
equals ``Ad(T_s_t)ᵀ W_s`` — the inverse-transpose of the twist adjoint — so power ``Vᵀ W`` is the
same in both frames. Which wrench is it? The one the *environment exerts on the tool*; the one the
tool exerts on the sheet is its negative (documented per file format in ``roboisf.logs``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.frames.se3 import adjoint

__all__ = ["shift_wrench", "transform_wrench", "wrench_transform_matrix"]

F64 = NDArray[np.float64]


def wrench_transform_matrix(T_s_t: ArrayLike) -> F64:
    """6×6 matrix ``X`` with ``W_t = X @ W_s``; equals ``Ad(T_s_t)ᵀ``. (..., 4, 4) → (..., 6, 6)."""
    return np.swapaxes(adjoint(T_s_t), -1, -2)


def transform_wrench(W_s: ArrayLike, T_t_s: ArrayLike) -> F64:
    """Express a wrench measured in frame *s* in frame *t* (moments about *t*'s origin).

    Parameters
    ----------
    W_s : (N, 6) or (6,) float, [N, N·m]
        ``[f; m]`` in *s*, moments about *s*'s origin.
    T_t_s : (4, 4) or (N, 4, 4)
        Pose of *s* in *t*.

    Returns
    -------
    W_t : same shape as ``W_s``, [N, N·m]
    """
    W = np.asarray(W_s, dtype=float)
    T = np.asarray(T_t_s, dtype=float)
    R = T[..., :3, :3]
    p = T[..., :3, 3]
    f_t = np.einsum("...ij,...j->...i", R, W[..., :3])
    m_t = np.einsum("...ij,...j->...i", R, W[..., 3:]) + np.cross(p, f_t)
    return np.concatenate([f_t, m_t], axis=-1)


def shift_wrench(W: ArrayLike, from_point: ArrayLike, to_point: ArrayLike) -> F64:
    """Move the moment reference of a wrench without rotating it.

    ``m_to = m_from + (from − to) × f``. Points (..., 3) [m] in the wrench's own axes.
    """
    W = np.asarray(W, dtype=float)
    r = np.asarray(from_point, dtype=float) - np.asarray(to_point, dtype=float)
    m = W[..., 3:] + np.cross(r, W[..., :3])
    return np.concatenate([W[..., :3], np.broadcast_to(m, W[..., 3:].shape)], axis=-1)
