"""Numerical inverse kinematics along a path, for robots without a closed form (no OPW geometry).

Damped least squares (Levenberg–Marquardt) on the tip pose: per point, from the previous point's
solution, iterate ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e`` with ``e = [p* − p; log(R* Rᵀ)]`` (m, rad; base
axes; ``J`` the tip Jacobian of :meth:`RobotModel.fk_jacobian`), halving λ after a step that
reduces |e| and multiplying it by 10 otherwise, until |e| ≤ 1e-12 (m and rad). Seeding each
point with the previous solution keeps the IK branch and the turns of every joint along the
path (continuity, the numerical counterpart of :func:`roboisf.robot.ik.ik_toolpath`'s fixed
branch). The first point starts from ``q_start`` (e.g. the logged joints), else from the
converged solution, over a deterministic set of seeds, closest to the middle of the joint ranges.

One Python loop over the points (≈ 3 iterations each): fine for forming paths of ~10⁴–10⁵
points; OPW robots use the closed form instead.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from roboisf.robot.model import RobotModel

__all__ = ["TOL", "numerical_ik_path", "pose_error"]

F64 = NDArray[np.float64]

TOL = 1e-12


def _log_so3(R: F64) -> F64:
    """Rotation vector (3,) rad of a rotation matrix (3, 3)."""
    c = max(-1.0, min(1.0, 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    th = math.acos(c)
    if th < 1e-6:
        return 0.5 * v * (1.0 + th * th / 6.0)
    if math.pi - th < 1e-6:  # near π: from the symmetric part
        B = 0.5 * (R + np.eye(3))
        k = int(np.argmax(np.diag(B)))
        a = B[:, k] / math.sqrt(max(B[k, k], 1e-300))
        a = a if a @ v >= 0 else -a
        return th * a / np.linalg.norm(a)
    return th / (2.0 * math.sin(th)) * v


def pose_error(T_target: F64, T: F64) -> F64:
    """``[p* − p; log(R* Rᵀ)]`` (6,) m, rad (base axes)."""
    e = np.empty(6)
    e[:3] = T_target[:3, 3] - T[:3, 3]
    e[3:] = _log_so3(T_target[:3, :3] @ T[:3, :3].T)
    return e


class _Arm:
    """One-pose FK and tip Jacobian of a model's chain (4×4 products; no batch overhead)."""

    def __init__(self, model: RobotModel) -> None:
        ch = model.chain
        self.F = [np.array(f) for f in ch.F[:6]]
        self.Ft = ch.F[6] @ model.T_flange_tip
        self.sign = np.array(ch.sign)
        self.chain = ch

    def __call__(self, q: F64) -> tuple[F64, F64]:
        th = self.chain.theta(q[None])[0]
        T = np.eye(4)
        z = np.empty((6, 3))
        o = np.empty((6, 3))
        R = np.eye(4)
        for i in range(6):
            T = T @ self.F[i]
            z[i] = T[:3, 2]
            o[i] = T[:3, 3]
            c, s = math.cos(th[i]), math.sin(th[i])
            R[0, 0], R[0, 1], R[1, 0], R[1, 1] = c, -s, s, c
            T = T @ R
        T = T @ self.Ft
        J = np.empty((6, 6))
        r = T[:3, 3] - o
        J[0] = z[:, 1] * r[:, 2] - z[:, 2] * r[:, 1]
        J[1] = z[:, 2] * r[:, 0] - z[:, 0] * r[:, 2]
        J[2] = z[:, 0] * r[:, 1] - z[:, 1] * r[:, 0]
        J[3:] = z.T
        J *= self.sign
        if self.chain.couple23 != 0.0:
            J[:, 1] += self.chain.couple23 * J[:, 2]
        return T, J


def _solve(arm: _Arm, T_target: F64, q0: F64, max_iter: int) -> tuple[F64, bool]:
    q = q0.copy()
    T, J = arm(q)
    e = pose_error(T_target, T)
    err = float(np.max(np.abs(e)))
    lam = 1e-3
    for _ in range(max_iter):
        if err <= TOL:
            return q, True
        A = J @ J.T + (lam * lam) * np.eye(6)
        dq = J.T @ np.linalg.solve(A, e)
        qn = q + dq
        Tn, Jn = arm(qn)
        en = pose_error(T_target, Tn)
        errn = float(np.max(np.abs(en)))
        if errn < err:
            q, J, e, err = qn, Jn, en, errn
            lam = max(lam * 0.5, 1e-12)
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    return q, err <= TOL


def _seeds(model: RobotModel, n: int = 64) -> F64:
    lo = np.maximum(model.q_min, -np.pi)
    hi = np.minimum(model.q_max, np.pi)
    mid = 0.5 * (lo + hi)
    rng = np.random.default_rng(0)  # deterministic: the same start for the same input
    return np.vstack([mid, rng.uniform(lo, hi, (n - 1, 6))])


def numerical_ik_path(
    model: RobotModel,
    T_base_tip: F64,
    q_start: F64 | None = None,
    *,
    max_iter: int = 100,
) -> tuple[F64, NDArray[np.bool_]]:
    """Joint angles (N, 6) rad and ``converged`` (N,) for tip poses ``T_base_tip`` (N, 4, 4).

    ``q_start`` (6,) rad: the solution of the first point is sought from there (the branch and
    turns of the whole path follow). Rows that do not converge are NaN and False; the points after
    a failed one restart from the last converged solution.
    """
    n = T_base_tip.shape[0]
    q = np.full((n, 6), np.nan)
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return q, ok
    arm = _Arm(model)
    if q_start is not None:
        q0, ok0 = _solve(arm, T_base_tip[0], np.asarray(q_start, dtype=float), max_iter)
    else:
        mid = 0.5 * (model.q_min + model.q_max)
        span = np.maximum(model.q_max - model.q_min, 1e-9)
        best: tuple[float, F64] | None = None
        for s in _seeds(model):
            qs, oks = _solve(arm, T_base_tip[0], s, max_iter)
            if not oks:
                continue
            # whole turns towards the middle of the range, then the score
            qs = qs + 2 * np.pi * np.round((mid - qs) / (2 * np.pi))
            score = float(np.sum(((qs - mid) / span) ** 2))
            if best is None or score < best[0] - 1e-12:
                best = (score, qs)
        ok0 = best is not None
        q0 = best[1] if best is not None else np.full(6, np.nan)
    if ok0:
        q[0], ok[0] = q0, True
    last = q0 if ok0 else (np.asarray(q_start, dtype=float) if q_start is not None else None)
    for i in range(1, n):
        if last is None:
            break
        qi, oki = _solve(arm, T_base_tip[i], last, max_iter)
        if oki:
            q[i], ok[i] = qi, True
            last = qi
    return q, ok
