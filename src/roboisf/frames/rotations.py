"""Rotation parameterisations used by robot controllers and files.

All angles in radians here; degrees are converted at the file boundary (``roboisf.io``).

* RPY / KUKA ABC: ``R = Rz(yaw=A) @ Ry(pitch=B) @ Rx(roll=C)`` (intrinsic Z-Y'-X''; KUKA's
  A, B, C are exactly yaw, pitch, roll in this order).
* Quaternions: scalar first ``(w, x, y, z)`` — ABB's ``q1..q4`` order. Output quaternions are
  normalised with ``w ≥ 0``.

The conversions between matrices, quaternions and rotation vectors are scipy's
(``scipy.spatial.transform.Rotation``, 1.17: the formulas of its ``_rotation_xp.py``, in the same
order, with the C library's sin, cos and atan2), written out here: importing scipy.spatial
(with scipy.sparse and scipy.linalg) took 0.2 s of the interpreter lock in the thread of
``analyze``'s first scan, whose registration converts one rotation. They are scipy 1.17's
numbers bit for bit (tests/test_rotations_conventions.py compares them on 20 000 rotations,
small angles, half-turns and matrices that are not quite orthogonal; another scipy may round
one differently in the last place). Euler angles (:func:`matrix_to_rpy`)
still come from scipy.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

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
    """scipy's ``Rotation`` (for Euler angles), imported on first use: ``roboisf.frames`` is
    imported by almost every command, and scipy.spatial (with scipy.sparse and scipy.linalg) is
    ~0.2 s and ~60 MB of start-up that one converting no rotation need not pay (``robot show``,
    reading a study: docs/speed.md)."""
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
    if q.shape == (4,):  # one rotation (the online loop's, every cycle): Python floats
        w, x, y, z = q.tolist()
        if not all(map(math.isfinite, (w, x, y, z))) or math.hypot(w, x, y, z) < 1e-12:
            raise ValueError("quaternion must be finite and non-zero")
        n = math.sqrt(x * x + y * y + z * z + w * w)  # scipy's order: x, y, z, w
        return _quat_as_matrix1(x / n, y / n, z / n, w / n)
    flat = q.reshape(-1, 4)
    norm = np.linalg.norm(flat, axis=1)
    if np.any(norm < 1e-12) or not np.all(np.isfinite(flat)):
        raise ValueError("quaternion must be finite and non-zero")
    xyzw = flat[:, [1, 2, 3, 0]]
    xyzw = xyzw / np.linalg.norm(xyzw, axis=1, keepdims=True)
    return _quat_as_matrix(xyzw).reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(R: ArrayLike) -> F64:
    """Rotation matrix (..., 3, 3) → unit quaternion ``(w, x, y, z)`` with ``w ≥ 0``."""
    R = np.asarray(R, dtype=float)
    one = _quat_from_matrix1(R) if R.shape == (3, 3) else None
    xyzw = np.array([one]) if one is not None else _quat_from_matrix(R.reshape(-1, 3, 3))
    wxyz = xyzw[:, [3, 0, 1, 2]]
    wxyz *= np.where(wxyz[:, :1] < 0, -1.0, 1.0)
    return wxyz.reshape(*R.shape[:-2], 4)


def rotvec_to_matrix(phi: ArrayLike) -> F64:
    """Rotation vector (axis·angle) [rad], (..., 3) → (..., 3, 3)."""
    phi = np.asarray(phi, dtype=float)
    if phi.shape == (3,):
        return _quat_as_matrix1(*_quat_from_rotvec1(*phi.tolist()))
    return _quat_as_matrix(_quat_from_rotvec(phi.reshape(-1, 3))).reshape(*phi.shape[:-1], 3, 3)


def matrix_to_rotvec(R: ArrayLike) -> F64:
    """Rotation matrix (..., 3, 3) → rotation vector [rad] (..., 3)."""
    R = np.asarray(R, dtype=float)
    one = _quat_from_matrix1(R) if R.shape == (3, 3) else None
    if one is not None:
        return np.array(_quat_as_rotvec1(*one))
    return _quat_as_rotvec(_quat_from_matrix(R.reshape(-1, 3, 3))).reshape(*R.shape[:-2], 3)


# scipy.spatial.transform.Rotation's conversions (scipy 1.17, ``_rotation_xp.py``: the same
# formulas and order of operations; module docstring), on scalar-last quaternions
# (x, y, z, w), (M, 4)


def _libm(f: Any, nin: int) -> Any:
    """``f`` (a ``math`` function) element by element on float arrays: the C library's result,
    as scipy's compiled conversions get it (numpy's own vectorised sin, cos, arctan2 may differ
    in the last bit on some CPUs)."""
    uf = np.frompyfunc(f, nin, 1)

    def call(*args: Any) -> F64:
        return np.asarray(uf(*args), dtype=float)

    return call


def _sin(v: float) -> float:
    return math.sin(v) if math.isfinite(v) else math.nan  # (math.sin(inf) raises; C's is NaN)


def _cos(v: float) -> float:
    return math.cos(v) if math.isfinite(v) else math.nan


_libm_sin = _libm(_sin, 1)
_libm_cos = _libm(_cos, 1)
_libm_atan2 = _libm(math.atan2, 2)


def _quat_from_matrix(M: F64) -> F64:
    """Unit quaternions (M, 4) of rotation matrices (M, 3, 3): refused when a determinant is not
    positive or not finite (scipy's SVD failed on NaN with numpy's "did not converge"); a
    matrix that is not orthogonal (to 1e-12) is replaced by the nearest one (SVD)."""
    if not np.all(np.isfinite(M)):
        i = int(np.flatnonzero(~np.isfinite(M).all(axis=(1, 2)))[0])
        raise ValueError(f"rotation matrix {i} is not finite: {M[i]}")
    det = np.linalg.det(M)
    bad = det <= 0
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            "Non-positive determinant (left-handed or null coordinate frame) in rotation "
            f"matrix {i}: {M[i]}."
        )
    gram = M @ np.swapaxes(M, -1, -2)
    ortho = np.all(np.isclose(gram, np.eye(3), rtol=1e-5, atol=1e-12), axis=(-2, -1))
    if not np.all(ortho):
        M = M.copy()
        U, _, Vt = np.linalg.svd(M[~ortho], full_matrices=False)
        M[~ortho] = U @ Vt
    tr = M[:, 0, 0] + M[:, 1, 1] + M[:, 2, 2]
    choice = np.argmax(np.stack([M[:, 0, 0], M[:, 1, 1], M[:, 2, 2], tr], axis=-1), axis=-1)
    cases = (
        (1 - tr + 2 * M[:, 0, 0], M[:, 1, 0] + M[:, 0, 1], M[:, 2, 0] + M[:, 0, 2],
         M[:, 2, 1] - M[:, 1, 2]),
        (M[:, 1, 0] + M[:, 0, 1], 1 - tr + 2 * M[:, 1, 1], M[:, 2, 1] + M[:, 1, 2],
         M[:, 0, 2] - M[:, 2, 0]),
        (M[:, 2, 0] + M[:, 0, 2], M[:, 2, 1] + M[:, 1, 2], 1 - tr + 2 * M[:, 2, 2],
         M[:, 1, 0] - M[:, 0, 1]),
        (M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1], 1 + tr),
    )  # fmt: skip
    quat = np.empty((M.shape[0], 4))
    for k, case in enumerate(cases):
        quat = np.where((choice == k)[:, None], np.stack(case, axis=-1), quat)
    return quat / np.linalg.norm(quat, axis=-1, keepdims=True)


def _quat_from_rotvec(v: F64) -> F64:
    """Unit quaternions (M, 4) of rotation vectors (M, 3) [rad] (a Taylor series below 1 mrad)."""
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    small = angle <= 1e-3
    angle2 = angle**2
    small_scale = 0.5 - angle2 / 48 + angle2**2 / 3840
    large_scale = _libm_sin(angle / 2) / (angle + small.astype(float))
    scale = np.where(small, small_scale, large_scale)
    return np.concatenate([v * scale, _libm_cos(angle / 2)], axis=-1)


def _quat_as_matrix(quat: F64) -> F64:
    """Rotation matrices (M, 3, 3) of unit quaternions (M, 4)."""
    x, y, z, w = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    m = [
        x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
        2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
        2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2,
    ]  # fmt: skip
    return np.stack(m, axis=-1).reshape(-1, 3, 3)


def _quat_as_rotvec(quat: F64) -> F64:
    """Rotation vectors (M, 3) [rad, angle in [0, π]] of unit quaternions (M, 4): each first
    made canonical (w > 0, or the first non-zero of x, y, z positive where w = 0), as scipy."""
    w, x, y = quat[:, 3], quat[:, 0], quat[:, 1]
    flip = (w < 0) | ((w == 0) & (x < 0))
    flip |= (w == 0) & (x == 0) & (y < 0)
    flip |= (w == 0) & (x == 0) & (y == 0) & (quat[:, 2] < 0)
    quat = np.where(flip[:, None], -quat, quat)
    ax = np.linalg.norm(quat[:, :3], axis=-1, keepdims=True)
    angle = 2 * _libm_atan2(ax, quat[:, 3:4])
    small = angle <= 1e-3
    angle2 = angle**2
    small_scale = 2 + angle2 / 12 + 7 * angle2**2 / 2880
    large_scale = angle / (_libm_sin(angle / 2.0) + small.astype(float))
    return np.where(small, small_scale, large_scale) * quat[:, :3]


# The same conversions for one rotation in Python floats (the same operations in the same
# order, so the same bits: tests/test_rotations_conventions.py) — numpy's calls on arrays of
# one row cost 35-125 µs a conversion, in the online loop's every cycle.


def _quat_from_matrix1(M: F64) -> tuple[float, float, float, float] | None:
    """:func:`_quat_from_matrix` of one matrix (3, 3); None when it is not orthogonal (to
    1e-12: the array form's SVD) or not finite."""
    (a, b, c), (d, e, f), (g, h, i) = M.tolist()
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not math.isfinite(det):
        return None
    if det <= 0:
        raise ValueError(
            "Non-positive determinant (left-handed or null coordinate frame) in rotation "
            f"matrix 0: {M}."
        )
    rows = ((a, b, c), (d, e, f), (g, h, i))
    for r in range(3):
        for k in range(r, 3):
            dot = rows[r][0] * rows[k][0] + rows[r][1] * rows[k][1] + rows[r][2] * rows[k][2]
            # scipy's test (np.isclose(M Mᵀ, I, atol=1e-12)) with a margin for the rounding
            # of this sum: near its limit the array form decides, as scipy does
            if abs(dot - (1.0 if r == k else 0.0)) > 0.9e-12 + (1e-5 if r == k else 0.0):
                return None
    tr = a + e + i
    choice = max(range(4), key=lambda k: ((a, e, i, tr)[k], -k))  # the first of equal ones
    if choice == 0:
        q = (1 - tr + 2 * a, d + b, g + c, h - f)
    elif choice == 1:
        q = (d + b, 1 - tr + 2 * e, h + f, c - g)
    elif choice == 2:
        q = (g + c, h + f, 1 - tr + 2 * i, d - b)
    else:
        q = (h - f, c - g, d - b, 1 + tr)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _quat_from_rotvec1(vx: float, vy: float, vz: float) -> tuple[float, float, float, float]:
    angle = math.sqrt(vx * vx + vy * vy + vz * vz)
    if angle <= 1e-3:
        angle2 = angle * angle
        scale = 0.5 - angle2 / 48 + angle2 * angle2 / 3840
    else:
        scale = _sin(angle / 2) / angle
    return (vx * scale, vy * scale, vz * scale, _cos(angle / 2))


def _quat_as_matrix1(x: float, y: float, z: float, w: float) -> F64:
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return np.array(
        [
            [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
            [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
            [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2],
        ]
    )


def _quat_as_rotvec1(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    if w < 0 or (w == 0 and (x < 0 or (x == 0 and (y < 0 or (y == 0 and z < 0))))):
        x, y, z, w = -x, -y, -z, -w
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        angle2 = angle * angle
        scale = 2 + angle2 / 12 + 7 * (angle2 * angle2) / 2880
    else:
        scale = angle / _sin(angle / 2.0)
    return (scale * x, scale * y, scale * z)


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
