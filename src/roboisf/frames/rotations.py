"""Rotation parameterisations used by robot controllers and files.

All angles in radians here; degrees are converted at the file boundary (``roboisf.io``).

* RPY / KUKA ABC: ``R = Rz(yaw=A) @ Ry(pitch=B) @ Rx(roll=C)`` (intrinsic Z-Y'-X''; KUKA's
  A, B, C are exactly yaw, pitch, roll in this order).
* Quaternions: scalar first ``(w, x, y, z)`` — ABB's ``q1..q4`` order. Output quaternions are
  normalised with ``w ≥ 0``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

__all__ = [
    "abc_to_matrix",
    "axis_angle_to_matrix",
    "matrix_to_abc",
    "matrix_to_quat",
    "matrix_to_rotvec",
    "matrix_to_rpy",
    "quat_to_matrix",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotvec_to_matrix",
    "rpy_to_matrix",
    "vertical_tool",
]

F64 = NDArray[np.float64]


def _rotation() -> type[Rotation]:
    """scipy's ``Rotation``, imported on first use: ``roboisf.frames`` is imported by almost
    every command, and scipy.spatial (with scipy.sparse and scipy.linalg) is ~0.2 s and ~60 MB
    of start-up that one converting no rotation need not pay (``robot show``, reading a study:
    docs/speed.md)."""
    from scipy.spatial.transform import Rotation as R

    return R


def _elementary(angle: ArrayLike, axis: int) -> F64:
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((*a.shape, 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def rot_x(angle: ArrayLike) -> F64:
    """Rotation about x by ``angle`` [rad]; (...,) → (..., 3, 3)."""
    return _elementary(angle, 0)


def rot_y(angle: ArrayLike) -> F64:
    """Rotation about y by ``angle`` [rad]; (...,) → (..., 3, 3)."""
    return _elementary(angle, 1)


def rot_z(angle: ArrayLike) -> F64:
    """Rotation about z by ``angle`` [rad]; (...,) → (..., 3, 3)."""
    return _elementary(angle, 2)


def rpy_to_matrix(rpy: ArrayLike) -> F64:
    """``rpy = (roll, pitch, yaw)`` [rad], (..., 3) → ``Rz(yaw) Ry(pitch) Rx(roll)`` (..., 3, 3)."""
    rpy = np.asarray(rpy, dtype=float)
    return rot_z(rpy[..., 2]) @ rot_y(rpy[..., 1]) @ rot_x(rpy[..., 0])


def matrix_to_rpy(R: ArrayLike) -> F64:
    """Inverse of :func:`rpy_to_matrix`; pitch in [-π/2, π/2]. (..., 3, 3) → (..., 3)."""
    R = np.asarray(R, dtype=float)
    ypr = _rotation().from_matrix(R.reshape(-1, 3, 3)).as_euler("ZYX")
    return ypr[:, ::-1].reshape(*R.shape[:-2], 3)


def abc_to_matrix(abc: ArrayLike) -> F64:
    """KUKA ``(A, B, C)`` [rad], (..., 3) → ``Rz(A) Ry(B) Rx(C)`` (..., 3, 3)."""
    abc = np.asarray(abc, dtype=float)
    return rot_z(abc[..., 0]) @ rot_y(abc[..., 1]) @ rot_x(abc[..., 2])


def matrix_to_abc(R: ArrayLike) -> F64:
    """Inverse of :func:`abc_to_matrix`. (..., 3, 3) → (..., 3) [rad]."""
    return matrix_to_rpy(R)[..., ::-1].copy()


def quat_to_matrix(q: ArrayLike) -> F64:
    """Unit quaternion ``(w, x, y, z)`` (ABB q1..q4), (..., 4) → (..., 3, 3). Normalises input."""
    q = np.asarray(q, dtype=float)
    flat = q.reshape(-1, 4)
    norm = np.linalg.norm(flat, axis=1)
    if np.any(norm < 1e-12) or not np.all(np.isfinite(flat)):
        raise ValueError("quaternion must be finite and non-zero")
    return _rotation().from_quat(flat[:, [1, 2, 3, 0]]).as_matrix().reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(R: ArrayLike) -> F64:
    """Rotation matrix (..., 3, 3) → unit quaternion ``(w, x, y, z)`` with ``w ≥ 0``."""
    R = np.asarray(R, dtype=float)
    xyzw = _rotation().from_matrix(R.reshape(-1, 3, 3)).as_quat()
    wxyz = xyzw[:, [3, 0, 1, 2]]
    wxyz *= np.where(wxyz[:, :1] < 0, -1.0, 1.0)
    return wxyz.reshape(*R.shape[:-2], 4)


def rotvec_to_matrix(phi: ArrayLike) -> F64:
    """Rotation vector (axis·angle) [rad], (..., 3) → (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    return _rotation().from_rotvec(phi.reshape(-1, 3)).as_matrix().reshape(*phi.shape[:-1], 3, 3)


def matrix_to_rotvec(R: ArrayLike) -> F64:
    """Rotation matrix (..., 3, 3) → rotation vector [rad] (..., 3)."""
    R = np.asarray(R, dtype=float)
    return _rotation().from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(*R.shape[:-2], 3)


def vertical_tool(tool_rotation: ArrayLike = 0.0) -> F64:
    """``R_work_tool = Rx(π) · Rz(γ)``: the tool's z-axis along −z_work (pointing down into the
    sheet), turned by ``tool_rotation`` γ [rad] about its own axis (positive γ turns it clockwise
    seen from above). (...,) → (..., 3, 3)."""
    g = np.asarray(tool_rotation, dtype=float)
    c, s = np.cos(g), np.sin(g)
    R = np.zeros((*g.shape, 3, 3))
    R[..., 0, 0], R[..., 0, 1] = c, -s
    R[..., 1, 0], R[..., 1, 1] = -s, -c
    R[..., 2, 2] = -1.0
    return R


def axis_angle_to_matrix(axis: ArrayLike, angle: ArrayLike) -> F64:
    """Rotation about unit ``axis`` (..., 3) by ``angle`` [rad] (...,) → (..., 3, 3)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    return rotvec_to_matrix(axis * np.asarray(angle, dtype=float)[..., None])
