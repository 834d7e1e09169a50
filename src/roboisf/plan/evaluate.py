"""Score one work-object placement: IK along the path, feasibility, VJM (+ tool) deflection, and
the smooth per-lap tool-rotation schedule.

Tool rotation γ (about the ball tool's own axis, :mod:`roboisf.robot.ik` convention)
----------------------------------------------------------------------------------
Each candidate γ is evaluated as a constant over the whole path (one IK + VJM pass). Per lap
that gives a cost (summed |δ| of the lap's points, or its max |δ| / summed |δ·n| for the other
objectives) and a feasibility flag (singularity margin, joint continuity). A Viterbi pass over the
laps then picks one γ per lap minimising ``Σ cost + smoothness · |Δγ|/π · (average lap cost)``
with ``|Δγ| ≤ max_rotation_step`` between consecutive laps. Why per lap and not per point: the
force direction turns once per lap, so per-lap choice captures what γ can gain, while a per-point
choice would trade accuracy for a jerky wrist; the rate limit and penalty keep A4–A6 smooth. A
change of γ is ramped linearly over the first ``ramp_points`` points of the new lap, and the
schedule actually commanded (with its ramps) is solved and scored once more — the numbers
reported are those of the realised path, never of the per-lap approximation. If the realised
path fails a check, the best feasible constant γ is used instead.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.cell.model import at_ball_centre
from roboisf.errors import UnreachableError
from roboisf.frames import rot_z
from roboisf.plan.problem import PlanProblem
from roboisf.robot import ik_toolpath, rotate_6, vjm_kernel
from roboisf.robot.ik import raise_beyond_limits, raise_out_of_reach
from roboisf.robot.singularity import margin_ok, scaled_jacobian, sigma_min
from roboisf.robot.vjm_kernel import single_blas_thread

__all__ = [
    "PlacementScore",
    "evaluate_batch",
    "evaluate_placement",
    "margin_ok",
    "path_sigma_min",
    "sigma_min",
    "smooth_schedule",
]

F64 = NDArray[np.float64]

#: Status values of a :class:`PlacementScore`.
STATUSES = ("ok", "unreachable", "singular", "discontinuous")


@dataclass(frozen=True, eq=False)
class PlacementScore:
    """The prediction for one placement (SI).

    status : "ok", "unreachable" (out of reach / joint limits for every γ), "singular" (σ_min
        below the margin on some lap for every γ), "discontinuous" (joint jump)
    reason : str — why it is not "ok" (empty when ok)
    mean_abs, max_abs : float, m — mean and max |δ| along the path (robot + tool if given)
    mean_abs_normal : float, m — mean |δ·n|, the part a scan sees
    mean_robot, max_robot : float, m — the robot's share alone
    sigma_min : float — smallest singular value of the scaled Jacobian along the path; every "ok"
        candidate passed the exact margin test, the value itself is computed for the shortlist
        only (``plan_placements(detail=…)``), NaN otherwise
    max_joint_step : float, rad — largest joint change between consecutive points
    gamma : (n_laps,) float, rad — tool rotation per lap (the ramps between laps are implied)
    """

    status: str
    reason: str
    mean_abs: float = math.nan
    max_abs: float = math.nan
    mean_abs_normal: float = math.nan
    mean_robot: float = math.nan
    max_robot: float = math.nan
    sigma_min: float = math.nan
    max_joint_step: float = math.nan
    gamma: F64 | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def objective(self, kind: str) -> float:
        """The ranked figure: "mean" → mean_abs, "max" → max_abs, "normal" → mean_abs_normal."""
        v = {"mean": self.mean_abs, "max": self.max_abs, "normal": self.mean_abs_normal}[kind]
        return v if self.ok else math.inf


@dataclass(frozen=True, eq=False)
class _PathEval:
    q: F64
    margin_ok: NDArray[np.bool_]  # (N,) σ_min ≥ threshold (exact test)
    problem: PlanProblem
    d_total: F64  # (N, 3) work axes
    d_robot: F64
    steps: F64  # (N,) largest joint change from the previous point
    abs_total: F64  # (N,) |d_total|
    abs_robot: F64  # (N,) |d_robot|
    abs_normal: F64  # (N,) |d_total·n|

    @cached_property
    def J_scaled(self) -> F64:
        """(N, 6, 6) Jacobian, linear rows divided by the length scale (on demand: the margin
        test runs inside the VJM kernel)."""
        J = self.problem.model.jacobian(self.q, check_limits=False)
        return scaled_jacobian(J, _length_scale(self.problem))


def _length_scale(problem: PlanProblem) -> float:
    g = problem.model.opw
    assert g is not None  # PlanProblem requires OPW geometry
    return g.c2 + g.c3  # as roboisf.robot.ik_toolpath


def _solve(problem: PlanProblem, T_base_work: F64, gamma: ArrayLike) -> _PathEval:
    """IK (raises UnreachableError), the singularity-margin test and the tip deflection in work
    axes for a tool rotation γ (scalar or (N,), rad)."""
    model = problem.model
    b = model.backend  # the C form first: no numba, no jit.ready("robot")
    if (vjm_kernel.use_c(b) or vjm_kernel.use_numba(b)) and model.stiffness is not None:
        return _solve_compiled(problem, T_base_work, gamma)
    # the margin is tested here (exact, per point, no warnings: thread-safe)
    ik = ik_toolpath(model, problem.tip, T_base_work, tool_rotation=gamma, singular_threshold=None)
    R = T_base_work[:3, :3]
    W_b = rotate_6(problem.wrench, R)
    # VJM δ = J K⁻¹ Jᵀ W and the singularity-margin test in one pass (RobotModel.vjm)
    r = model.vjm(ik.q, W_b, margin=(_length_scale(problem), problem.sigma_threshold))
    ok = r.margin_ok
    assert ok is not None
    rb = problem.ball_radius
    # rows Rᵀ δ: base → work axes; then the ball centre (δ + θ × R ẑ) when rb > 0
    d_robot = r.d[:, :3] @ R
    if rb > 0.0:
        d_robot = at_ball_centre(np.concatenate([d_robot, r.d[:, 3:] @ R], axis=1), rb)
    d_total = d_robot
    if problem.tool_compliance is not None:
        # tool axes → work: z stays, x_tool = (cos γ, −sin γ, 0), i.e. R_work_tool = Rz(−γ)
        R_wt = rot_z(-np.asarray(gamma, dtype=float))  # (3, 3) or (N, 3, 3)
        back, fwd = ("nji,nj->ni", "nij,nj->ni") if R_wt.ndim == 3 else ("ji,nj->ni", "ij,nj->ni")
        W = problem.wrench
        W_t = np.concatenate(
            [np.einsum(back, R_wt, W[:, :3]), np.einsum(back, R_wt, W[:, 3:])], axis=1
        )
        t = W_t @ problem.tool_compliance.T  # (N, 6) tool axes [m; rad]
        d_tool = np.einsum(fwd, R_wt, t[:, :3])
        if rb > 0.0:
            d_tool = at_ball_centre(np.concatenate([d_tool, np.einsum(fwd, R_wt, t[:, 3:])], 1), rb)
        d_total = d_robot + d_tool
    return _PathEval(
        ik.q,
        ok,
        problem,
        d_total,
        d_robot,
        _joint_steps(ik.q),
        np.sqrt(np.einsum("ij,ij->i", d_total, d_total)),
        np.linalg.norm(d_robot, axis=1),
        np.abs(np.einsum("ij,ij->i", d_total, problem.normal)),
    )


#: per problem, writeable C-contiguous copies of its per-point arrays for the compiled kernels:
#: the problem's own are read-only, and the kernels' inputs are writeable float64 (one compiled
#: signature), so without these every placement copied tip, wrench and normals (~6 % of its CPU)
_KERNEL_INPUTS: weakref.WeakKeyDictionary[PlanProblem, tuple[F64, F64, F64]] = (
    weakref.WeakKeyDictionary()
)


def _kernel_inputs(problem: PlanProblem) -> tuple[F64, F64, F64]:
    """(tip, wrench, normal) of ``problem`` as the kernels take them (only read by them)."""
    got = _KERNEL_INPUTS.get(problem)
    if got is None:
        tip, wrench, normal = (
            np.array(a, dtype=np.float64, order="C")
            for a in (problem.tip, problem.wrench, problem.normal)
        )
        got = _KERNEL_INPUTS[problem] = (tip, wrench, normal)
    return got


def _solve_compiled(problem: PlanProblem, T_base_work: F64, gamma: ArrayLike) -> _PathEval:
    """:func:`_solve` as one compiled pass per path (:func:`roboisf.robot.ik_numba.path_vjm`):
    the same numbers (≤ 1e-12 rad, ~1e-15 relative in δ), the same errors."""
    from roboisf.robot.ik_numba import path_vjm

    model = problem.model
    g = np.asarray(gamma, dtype=float).reshape(-1)
    tip, wrench, normal = _kernel_inputs(problem)
    r = path_vjm(
        model,
        tip,
        T_base_work,
        g,
        wrench,
        problem.tool_compliance,
        (_length_scale(problem), problem.sigma_threshold),
        normal=normal,
        ball_radius=problem.ball_radius,
    )
    if r.status == 1:
        raise_out_of_reach(model, r.reachable, ("front", "up", "noflip"))
    if r.status == 2:
        raise_beyond_limits(model, r.q)
    assert r.margin_ok is not None and r.d_total is not None and r.d_robot is not None
    assert r.steps is not None and r.abs_total is not None
    assert r.abs_robot is not None and r.abs_normal is not None
    return _PathEval(
        r.q,
        r.margin_ok,
        problem,
        r.d_total,
        r.d_robot,
        r.steps,
        r.abs_total,
        r.abs_robot,
        r.abs_normal,
    )


def _joint_steps(q: F64) -> F64:
    """(N,) largest joint change from the previous point (0 at the first point)."""
    s = np.zeros(q.shape[0])
    s[1:] = np.max(np.abs(np.diff(q, axis=0)), axis=1)
    return s


def _point_cost(problem: PlanProblem, ev: _PathEval) -> F64:
    if problem.objective == "normal":
        return ev.abs_normal
    return ev.abs_total


def _lap_reduce(problem: PlanProblem, values: F64, how: str) -> F64:
    starts = problem.lap_start
    if how == "sum":
        return np.add.reduceat(values, starts)
    if how == "max":
        return np.maximum.reduceat(values, starts)
    return np.minimum.reduceat(values, starts)


def smooth_schedule(
    cost: ArrayLike,
    feasible: ArrayLike,
    gammas: ArrayLike,
    *,
    max_step: float,
    penalty: float,
) -> NDArray[np.intp] | None:
    """Viterbi choice of one candidate γ per lap: minimise ``Σ_k cost[γ_k, k] + Σ pen(Δγ)``.

    cost : (G, L) — per-candidate, per-lap cost; feasible : (G, L) bool
    gammas : (G,) rad; a transition with wrapped |Δγ| > ``max_step`` is forbidden, otherwise it
    costs ``penalty · |Δγ| / π``. Returns the (L,) candidate index per lap, or None if no
    feasible sequence exists. Deterministic: ties go to the lower index.
    """
    C = np.asarray(cost, dtype=float)
    F = np.asarray(feasible, dtype=bool)
    g = np.asarray(gammas, dtype=float)
    G, L = C.shape
    dg = np.abs(np.angle(np.exp(1j * (g[:, None] - g[None, :]))))  # wrapped |Δγ| (G, G)
    trans = np.where(dg <= max_step + 1e-12, penalty * dg / math.pi, np.inf)
    cols = np.arange(G)
    acc = np.where(F[:, 0], C[:, 0], np.inf)
    back = np.zeros((L, G), dtype=np.intp)
    for k in range(1, L):
        tot = acc[:, None] + trans  # [from, to]
        j = np.argmin(tot, axis=0)
        acc = np.where(F[:, k], tot[j, cols] + C[:, k], np.inf)
        back[k] = j
    if not np.any(np.isfinite(acc)):
        return None
    path = np.empty(L, dtype=np.intp)
    path[-1] = int(np.argmin(acc))
    for k in range(L - 1, 0, -1):
        path[k - 1] = back[k, path[k]]
    return path


def _realise(problem: PlanProblem, gamma_lap: F64) -> F64:
    """Per-point γ (N,): constant per lap, ramped over the first points of a lap after a change
    (``ramp_points``, more if needed so that γ steps ≤ max_joint_step / 2 per point; at most the
    lap).

    γ is unwrapped along the laps first, so a ramp takes the short way round.
    """
    g = np.unwrap(gamma_lap)
    lap_id = problem.lap_id
    out = g[lap_id].copy()
    starts = problem.lap_start
    ends = np.r_[starts[1:], problem.n_points]
    for k in np.flatnonzero(np.diff(g) != 0) + 1:
        s, e = starts[k], ends[k]
        # long enough that γ itself never steps more than half the joint-step limit
        need = math.ceil(abs(g[k] - g[k - 1]) / (0.5 * problem.max_joint_step))
        r = min(max(problem.ramp_points, need), e - s)
        t = (np.arange(r) + 1) / r
        out[s : s + r] = g[k - 1] + t * (g[k] - g[k - 1])
    return out


def _score(problem: PlanProblem, ev: _PathEval, gamma_lap: F64) -> PlacementScore:
    a, ar, dn = ev.abs_total, ev.abs_robot, ev.abs_normal  # per point, from the solve
    return PlacementScore(
        "ok",
        "",
        float(a.mean()),
        float(a.max()),
        float(dn.mean()),
        float(ar.mean()),
        float(ar.max()),
        math.nan,  # filled for the shortlist (sweep.plan_placements)
        float(ev.steps.max()),
        gamma_lap,
    )


def _check(problem: PlanProblem, ev: _PathEval) -> str:
    """'' when the path passes the singularity and continuity checks, else the reason."""
    if not np.all(ev.margin_ok):
        i = int(np.argmin(ev.margin_ok))
        J_i = problem.model.jacobian(ev.q[i : i + 1], check_limits=False)
        smin = float(sigma_min(scaled_jacobian(J_i, _length_scale(problem)))[0])
        return f"near a singularity: σ_min = {smin:.4f} < {problem.sigma_threshold:g} at point {i}"
    steps = ev.steps
    if steps.max() > problem.max_joint_step:
        i = int(np.argmax(steps))
        return (
            f"joint jump of {math.degrees(steps[i]):.2f}° at point {i} "
            f"(limit {math.degrees(problem.max_joint_step):.2f}°)"
        )
    return ""


def evaluate_placement(
    problem: PlanProblem, T_base_work: ArrayLike, tool_rotations: ArrayLike = (0.0,)
) -> PlacementScore:
    """Score one placement ``T_base_work`` (4, 4) over candidate tool rotations (G,) rad.

    Never raises for an infeasible placement: the returned score says why (``status``,
    ``reason``).
    """
    T = np.asarray(T_base_work, dtype=float)
    gammas = np.atleast_1d(np.asarray(tool_rotations, dtype=float))
    L = problem.n_laps
    evals: list[_PathEval | None] = []
    reasons: list[str] = []
    for g in gammas:
        try:
            evals.append(_solve(problem, T, float(g)))
        except UnreachableError as e:
            evals.append(None)
            reasons.append(f"γ = {math.degrees(g):g}°: {e}")
    if all(e is None for e in evals):
        return PlacementScore(
            "unreachable", reasons[0] if len(reasons) == 1 else "; ".join(reasons)
        )
    if gammas.size == 1:
        ev0 = evals[0]
        assert ev0 is not None
        why = _check(problem, ev0)
        if why:
            status = "singular" if why.startswith("near") else "discontinuous"
            return PlacementScore(status, f"γ = {math.degrees(gammas[0]):g}°: {why}")
        return _score(problem, ev0, np.full(L, gammas[0]))
    cost = np.full((gammas.size, L), np.inf)
    feas = np.zeros((gammas.size, L), dtype=bool)
    for i, ev in enumerate(evals):
        if ev is None:
            continue
        c = _point_cost(problem, ev)
        # "max": the sum of the laps' maxima (a smooth proxy the Viterbi pass can add up)
        cost[i] = _lap_reduce(problem, c, "max" if problem.objective == "max" else "sum")
        sig_ok = _lap_reduce(problem, (~ev.margin_ok).astype(float), "max") == 0.0
        step_ok = _lap_reduce(problem, ev.steps, "max") <= problem.max_joint_step
        feas[i] = sig_ok & step_ok
    finite = np.where(np.isfinite(cost), cost, np.nan)
    scale = float(np.nanmin(finite, axis=0).mean()) if np.any(np.isfinite(finite)) else 1.0
    path = smooth_schedule(
        cost,
        feas,
        gammas,
        max_step=problem.max_rotation_step,
        penalty=problem.smoothness * scale,
    )
    # best feasible constant γ (the fallback, and the answer when the schedule is constant)
    const_ok = np.all(feas, axis=1)
    const_cost = cost.sum(axis=1)
    const_cost = np.where(const_ok, const_cost, np.inf)
    best_const = int(np.argmin(const_cost)) if np.any(const_ok) else -1
    if path is not None and np.all(path == path[0]):
        best_const = int(path[0])
        path = None
    if path is not None:
        gamma_lap = gammas[path]
        try:
            ev = _solve(problem, T, _realise(problem, gamma_lap))
            if not _check(problem, ev):
                return _score(problem, ev, gamma_lap)
        except UnreachableError:
            # the ramped per-lap schedule is out of reach: fall back to the best constant γ below
            # (documented in docs/plan.md)
            path = None
    if best_const >= 0:
        ev_c = evals[best_const]
        assert ev_c is not None
        if not _check(problem, ev_c):
            return _score(problem, ev_c, np.full(L, gammas[best_const]))
    # nothing feasible: report the first candidate's reason
    for i, ev in enumerate(evals):
        if ev is not None:
            why = _check(problem, ev)
            status = "singular" if why.startswith("near") else "discontinuous"
            return PlacementScore(
                status,
                f"no feasible tool-rotation schedule; γ = {math.degrees(gammas[i]):g}°: {why}",
            )
    raise AssertionError("unreachable")  # pragma: no cover


def evaluate_batch(
    problem: PlanProblem, T_base_work: ArrayLike, tool_rotations: ArrayLike
) -> list[PlacementScore]:
    """:func:`evaluate_placement` for placements (B, 4, 4) — one Dask task's worth of work."""
    with single_blas_thread():  # the placements are the parallel work: idle BLAS threads spin
        return _evaluate_many(problem, T_base_work, tool_rotations)


def _evaluate_many(
    problem: PlanProblem, T_base_work: ArrayLike, tool_rotations: ArrayLike
) -> list[PlacementScore]:
    """:func:`evaluate_batch` without pinning BLAS (the caller has)."""
    Ts = np.asarray(T_base_work, dtype=float).reshape(-1, 4, 4)
    return [evaluate_placement(problem, T, tool_rotations) for T in Ts]


def path_sigma_min(problem: PlanProblem, T_base_work: ArrayLike, gamma_lap: ArrayLike) -> float:
    """Smallest singular value of the scaled Jacobian along the realised path of a placement with
    the per-lap tool rotations ``gamma_lap`` (n_laps,) rad (the value, for reports).

    The value of ``sigma_min`` over every point, found without the eigenvalues of every point:
    ``σ_min`` of every 64th point gives an upper bound ``s``; the exact elimination test
    (``RobotModel.singularity_margin_ok``) at ``s + 1e-6`` keeps only the points that could lie
    below it, whose ``σ_min`` is then computed. The margin of 1e-6 exceeds ``eigvalsh``'s
    absolute error (~1e-8 · σ_max), so the minimum is the one of all points (tested equal).
    """
    T = np.asarray(T_base_work, dtype=float)
    g = np.asarray(gamma_lap, dtype=float)
    gp = float(g[0]) if np.all(g == g[0]) else _realise(problem, g)
    ik = ik_toolpath(problem.model, problem.tip, T, tool_rotation=gp, singular_threshold=None)
    ls = _length_scale(problem)

    def smin(idx: NDArray[np.intp]) -> F64:
        J = problem.model.jacobian(ik.q[idx], check_limits=False)
        return sigma_min(scaled_jacobian(J, ls))

    s = float(smin(np.arange(0, ik.q.shape[0], 64)).min())
    low = np.flatnonzero(~problem.model.singularity_margin_ok(ik.q, ls, s + 1e-6))
    return min(s, float(smin(low).min())) if low.size else s


def _path_sigma_min_all(
    problem: PlanProblem, T_base_work: ArrayLike, gamma_lap: ArrayLike
) -> float:
    """:func:`path_sigma_min` from the eigenvalues of every point (the reference of the tests)."""
    T = np.asarray(T_base_work, dtype=float)
    g = np.asarray(gamma_lap, dtype=float)
    gp = float(g[0]) if np.all(g == g[0]) else _realise(problem, g)
    ik = ik_toolpath(problem.model, problem.tip, T, tool_rotation=gp, singular_threshold=None)
    Js = scaled_jacobian(problem.model.jacobian(ik.q, check_limits=False), _length_scale(problem))
    return float(sigma_min(Js).min())
