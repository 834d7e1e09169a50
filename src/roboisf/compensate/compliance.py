"""Compliance pre-deflection: command the tip where the loaded tool lands on the target.

Under the forming wrench ``W`` the tool tip gives way by ``δ(p) = k_c(q(p)) W + (k_t + k_th) W``
— the robot's VJM compliance at the IK configuration ``q(p)`` of the commanded tip ``p`` plus the
tool and holder compliance at the tip (:mod:`roboisf.frames.compliance`). The commanded tip
``p_cmd`` solves, per toolpath point, the fixed point ::

    p_cmd + δ(p_cmd) = p_target
    p ← p − ω (p + δ(p) − p_target)          (under-relaxed, 0 < ω ≤ 1)

with the joint configurations re-solved (IK) for the whole commanded path at every iteration.
The iteration contracts as long as ``ω ‖∂δ/∂p‖ < 1``; δ changes with the configuration only
slowly (a millimetre of command changes ``k_c`` by far less than a percent), so a few iterations
reach a tenth of a micrometre.

Only the translation of the tip is compensated: the tool's small rotation under load
(θ ≈ 1e-4 rad) moves the ball centre by ``θ × R ẑ`` ≈ 0.5 µm, below the tolerance of any scan.
The wrench is held fixed (predicted for, or measured on, the nominal path).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.cell.model import at_ball_centre
from roboisf.errors import ConvergenceError, InputError, short_indices
from roboisf.path.toolpath import Toolpath
from roboisf.progress import Progress, task
from roboisf.robot import RobotModel, ik_toolpath

__all__ = ["ComplianceCompensation", "DeflectionModel", "precompensate"]

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class DeflectionModel:
    """What gives way between the robot base and the tool tip (SI, work frame).

    Attributes
    ----------
    robot : RobotModel — with the tool (``T_flange_tip``) and joint stiffness
    T_base_work : (4, 4) float, m — placement of the work frame in the robot base
    k_tip : (6, 6) float — tool + holder compliance at the tip, work axes [m/N, 1/N, rad/(N·m)]
    tool_rotation : float or (N,) float, rad — tool rotation about its own axis (IK)
    include_robot : bool — False to compensate the tool and holder only
    ball_radius : float, m — the deflection is that of the ball centre, this far above the tip
        (the point whose motion forms the part; 0: the tip itself)
    """

    robot: RobotModel
    T_base_work: F64
    k_tip: F64 = field(default_factory=lambda: np.zeros((6, 6)))
    tool_rotation: float | F64 = 0.0
    include_robot: bool = True
    ball_radius: float = 0.0

    def __post_init__(self) -> None:
        T = np.asarray(self.T_base_work, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InputError("expected a finite (4, 4) placement", field="T_base_work")
        k = np.asarray(self.k_tip, dtype=float)
        if k.shape != (6, 6) or not np.all(np.isfinite(k)):
            raise InputError("expected a finite (6, 6) compliance", field="k_tip")
        object.__setattr__(self, "T_base_work", T)
        object.__setattr__(self, "k_tip", k)
        if self.include_robot:
            _ = self.robot.joint_stiffness  # raises an InputError naming the fix when unknown

    def deflection(self, tip: ArrayLike, wrench: ArrayLike) -> tuple[F64, F64]:
        """Deflection ``δ`` (N, 3) m of the ball centre (:attr:`ball_radius`) under ``wrench``
        (N, 6) [N; N·m] with the tip commanded at ``tip`` (N, 3) m; also the joint angles
        (N, 6) rad of the IK there.

        Raises :class:`~roboisf.errors.UnreachableError` (with indices) for tips out of reach.
        """
        p = np.asarray(tip, dtype=float)
        W = np.asarray(wrench, dtype=float)
        ik = ik_toolpath(self.robot, p, self.T_base_work, tool_rotation=self.tool_rotation)
        d = W @ self.k_tip.T
        if self.include_robot:
            d = d + self.robot.deflection(ik.q, W, T_base_work=self.T_base_work)
        return at_ball_centre(d, self.ball_radius), ik.q


@dataclass(frozen=True, eq=False)
class ComplianceCompensation:
    """Result of :func:`precompensate` (work frame, SI).

    Attributes
    ----------
    target : (N, 3) float, m — where the loaded tip must land
    commanded : (N, 3) float, m — the commanded tip
    deflection : (N, 3) float, m — predicted δ at the commanded configuration
    q : (N, 6) float, rad — IK of the commanded path
    residual : (N,) float, m — ``‖p_cmd + δ(p_cmd) − p_target‖`` at the end
    converged : (N,) bool — ``residual ≤ tol``
    iterations : int — fixed-point updates made
    history : (iterations + 1,) float, m — max residual before each update and at the end
    tol : float, m
    """

    target: F64
    commanded: F64
    deflection: F64
    q: F64
    residual: F64
    converged: NDArray[np.bool_]
    iterations: int
    history: F64
    tol: float

    @property
    def not_converged(self) -> NDArray[np.int64]:
        """Indices (0-based) of the points that did not converge."""
        return np.flatnonzero(~self.converged)

    def report(self) -> dict[str, object]:
        """The convergence report (JSON-able; lengths in mm)."""
        return {
            "iterations": self.iterations,
            "tolerance_mm": self.tol * 1e3,
            "max_residual_mm": float(self.residual.max()) * 1e3,
            "max_residual_per_iteration_mm": (self.history * 1e3).tolist(),
            "converged": bool(self.converged.all()),
            "not_converged_indices": self.not_converged.tolist(),
            "max_predeflection_mm": float(
                np.linalg.norm(self.commanded - self.target, axis=1).max() * 1e3
            ),
        }


def precompensate(
    target: ArrayLike | Toolpath,
    wrench: ArrayLike,
    model: DeflectionModel,
    *,
    relax: float = 0.8,
    tol: float = 1e-7,
    max_iter: int = 50,
    partial: bool = False,
    progress: Progress | None = None,
) -> ComplianceCompensation:
    """Solve ``p_cmd + δ(p_cmd) = p_target`` per point (vectorised; loop over iterations only).

    Parameters
    ----------
    target : (N, 3) float, m — target tips (or a Toolpath: its ``tip``)
    wrench : (N, 6) float — tip wrench on the tool [f; m], N and N·m, work axes
    model : DeflectionModel
    relax : under-relaxation ω in (0, 1]
    tol : m — residual at which a point has converged
    max_iter : maximum number of updates
    partial : return a result with per-point ``converged`` flags instead of raising

    Raises
    ------
    ConvergenceError
        when points have not converged after ``max_iter`` updates (unless ``partial``); the
        message lists their indices.
    UnreachableError
        when a target or an intermediate command is out of the robot's reach (indices).
    """
    p_t = np.asarray(getattr(target, "tip", target), dtype=float)
    if p_t.ndim != 2 or p_t.shape[1] != 3 or not np.all(np.isfinite(p_t)):
        raise InputError(f"expected finite target tips (N, 3), got {p_t.shape}", field="target")
    W = np.asarray(wrench, dtype=float)
    if W.shape != (len(p_t), 6) or not np.all(np.isfinite(W)):
        raise InputError(
            f"expected a finite wrench per point ({len(p_t)}, 6), got {W.shape}", field="wrench"
        )
    if not 0 < relax <= 1:
        raise InputError(f"must be in (0, 1], got {relax:g}", field="relax")
    if not tol > 0:
        raise InputError(f"must be > 0, got {tol:g}", field="tol")
    if max_iter < 1:
        raise InputError(f"must be ≥ 1, got {max_iter}", field="max_iter")
    p = p_t.copy()
    history = []
    with task(progress, "compliance pre-deflection", max_iter + 1) as advance:
        for it in range(max_iter + 1):
            d, q = model.deflection(p, W)
            r = p + d - p_t
            res = np.linalg.norm(r, axis=1)
            history.append(float(res.max()))
            advance(1)
            if res.max() <= tol or it == max_iter:
                break
            p = p - relax * r
    converged = res <= tol
    out = ComplianceCompensation(p_t, p, d, q, res, converged, it, np.asarray(history), float(tol))
    if not partial and not converged.all():
        bad = out.not_converged
        raise ConvergenceError(
            f"compliance pre-deflection did not converge at {bad.size} of {len(p)} points after "
            f"{it} iterations (ω = {relax:g}; residual up to {res.max() * 1e6:.3g} µm > "
            f"{tol * 1e6:.3g} µm) at indices {short_indices(bad)}; nothing was written — raise "
            "max_iter, lower ω, or check the stiffness"
        )
    return out
