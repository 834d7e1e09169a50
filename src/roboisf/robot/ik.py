"""Closed-form inverse kinematics of OPW robots and IK along a forming toolpath.

Tool orientation convention for forming
---------------------------------------
The toolpath lives in the work frame (origin at the blank centre, z up along the tool axis). The
tool points *down* into the sheet, so the tool-tip frame has its z-axis along **−z_work**. With
the tool's free rotation ``γ`` about its own axis (a ball tool does not care)::

    R_work_tip = Rx(π) · Rz(γ)        (γ = 0: x_tip = x_work, y_tip = −y_work, z_tip = −z_work)

so x_tip = (cos γ, −sin γ, 0) in work axes: a positive γ turns the tool clockwise seen from above.
    T_base_flange = T_base_work · T_work_tip · T_flange_tip⁻¹

Branch: ``shoulder`` "front" (joint 1 faces the target) or "back"; ``elbow`` "up"/"down";
``wrist`` "noflip" (OPW θ5 ≥ 0) or "flip". One branch is used for the whole path, so the joint
trajectory is continuous; joints with more than ±180° of travel are unwrapped along the path and
shifted by whole turns to sit inside their limits.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError, UnreachableError, short_indices
from roboisf.frames import invert, vertical_tool
from roboisf.robot import vjm_kernel
from roboisf.robot.model import RobotModel
from roboisf.robot.singularity import scaled_jacobian
from roboisf.robot.singularity import sigma_min as _sigma_min

__all__ = [
    "IKResult",
    "NumericalIKWarning",
    "SingularityWarning",
    "ik_toolpath",
    "opw_ik",
    "tool_poses",
]

F64 = NDArray[np.float64]


class SingularityWarning(UserWarning):
    """A pose is close to a kinematic singularity (compliance there is huge and unreliable)."""


class NumericalIKWarning(UserWarning):
    """The robot has no closed-form IK: the toolpath is solved numerically (the message says why:
    ``RobotModel.ik_note``)."""


def opw_ik(
    model: RobotModel,
    T_base_flange: ArrayLike,
    *,
    shoulder: Literal["front", "back"] = "front",
    elbow: Literal["up", "down"] = "up",
    wrist: Literal["noflip", "flip"] = "noflip",
    backend: str | None = None,
) -> tuple[F64, NDArray[np.bool_]]:
    """Closed-form IK of one branch for flange poses (N, 4, 4) → (q (N, 6) rad, reachable (N,)).

    ``q`` is in the controller convention, each angle wrapped to (−π, π] (continuity and limits are
    handled by :func:`ik_toolpath`). Unreachable rows are NaN in ``q`` and False in ``reachable``.
    ``backend`` ("auto", "numba", "numpy"; default the model's :attr:`RobotModel.backend`) picks
    the engine; both give the same angles (≤ 1e-12 rad) and the same reachability.
    """
    if model.opw is None:
        raise InputError(
            f"robot {model.name!r} has no OPW geometry; closed-form IK needs it", field="robot"
        )
    _check_branch(shoulder, elbow, wrist)
    T = np.asarray(T_base_flange, dtype=float).reshape(-1, 4, 4)
    b = model.backend if backend is None else backend
    if vjm_kernel.use_c(b) or vjm_kernel.use_numba(b):  # the C form: no numba, no jit.ready
        from roboisf.robot.ik_numba import flange_ik

        return flange_ik(model, T, shoulder, elbow, wrist)
    return _opw_ik_numpy(model, T, shoulder, elbow, wrist)


def _check_branch(shoulder: str, elbow: str, wrist: str) -> None:
    for name, v, allowed in (
        ("shoulder", shoulder, ("front", "back")),
        ("elbow", elbow, ("up", "down")),
        ("wrist", wrist, ("noflip", "flip")),
    ):
        if v not in allowed:
            raise InputError(f"{name} must be one of {allowed}, got {v!r}", field=name)


def _opw_ik_numpy(
    model: RobotModel, T: F64, shoulder: str, elbow: str, wrist: str
) -> tuple[F64, NDArray[np.bool_]]:
    """The numpy engine of :func:`opw_ik` (validated flange poses T (N, 4, 4))."""
    g = model.opw
    assert g is not None
    R = T[:, :3, :3]
    # wrist centre
    C = T[:, :3, 3] - g.c4 * R[:, :, 2]
    cx, cy, cz = C[:, 0], C[:, 1], C[:, 2]
    rho2 = cx * cx + cy * cy - g.b * g.b
    ok = rho2 >= 0
    r = np.sqrt(np.where(ok, rho2, 0.0))
    front = shoulder == "front"
    xr = r if front else -r  # a1 + x in the arm plane
    th1 = np.arctan2(cy, cx) - np.arctan2(g.b, xr)
    x = xr - g.a1
    z = cz - g.c1
    kappa2 = g.a2 * g.a2 + g.c3 * g.c3
    kappa = np.sqrt(kappa2)
    D = (x * x + z * z - g.c2 * g.c2 - kappa2) / (2.0 * g.c2 * kappa)
    ok &= np.abs(D) <= 1.0 + 1e-12
    acos_d = np.arccos(np.clip(D, -1.0, 1.0))
    phi = np.arctan2(g.a2, g.c3)
    # elbow up (forearm above the upper arm, the usual working posture): θ3 + φ ≥ 0 in front
    up = elbow == "up"
    sgn = 1.0 if (up == front) else -1.0
    th3 = sgn * acos_d - phi
    s3, c3 = np.sin(th3), np.cos(th3)
    wx = g.a2 * c3 + g.c3 * s3
    wz = g.c2 - g.a2 * s3 + g.c3 * c3
    th2 = np.arctan2(x, z) - np.arctan2(wx, wz)
    # wrist: R = Rz(θ1) Ry(θ2+θ3) · Rz(θ4) Ry(θ5) Rz(θ6)
    c1, s1 = np.cos(th1), np.sin(th1)
    c23, s23 = np.cos(th2 + th3), np.sin(th2 + th3)
    # rows of (Rz(θ1) Ry(θ23))ᵀ
    e0 = np.stack([c1 * c23, s1 * c23, -s23], axis=1)
    e1 = np.stack([-s1, c1, np.zeros_like(c1)], axis=1)
    e2 = np.stack([c1 * s23, s1 * s23, c23], axis=1)
    W = np.empty_like(R)
    for i, e in enumerate((e0, e1, e2)):
        W[:, i, :] = np.einsum("nk,nkj->nj", e, R)
    th5 = np.arctan2(np.hypot(W[:, 0, 2], W[:, 1, 2]), W[:, 2, 2])
    th4 = np.arctan2(W[:, 1, 2], W[:, 0, 2])
    th6 = np.arctan2(W[:, 2, 1], -W[:, 2, 0])
    if wrist == "flip":
        th4 = th4 + np.pi
        th5 = -th5
        th6 = th6 + np.pi
    theta = np.stack([th1, th2, th3, th4, th5, th6], axis=1)
    q = model.chain.q_from_theta(theta)
    q = np.mod(q + np.pi, 2 * np.pi) - np.pi
    q[~ok] = np.nan
    return q, ok


def tool_poses(tip_work: ArrayLike, T_base_work: ArrayLike, tool_rotation: ArrayLike = 0.0) -> F64:
    """``T_base_tip`` (N, 4, 4) for tool-tip points (N, 3) m in the work frame.

    Tool z along −z_work, rotated by ``tool_rotation`` (scalar or (N,), rad) about its own axis.
    """
    p = np.asarray(tip_work, dtype=float)
    n = p.shape[0]
    g = np.broadcast_to(np.asarray(tool_rotation, dtype=float), (n,))
    T = np.zeros((n, 4, 4))
    T[:, :3, :3] = vertical_tool(g)
    T[:, :3, 3] = p
    T[:, 3, 3] = 1.0
    return np.asarray(T_base_work, dtype=float) @ T


@dataclass(frozen=True, eq=False)
class IKResult:
    """A joint trajectory along a toolpath.

    q : (N, 6) float, rad — controller convention, continuous
    T_base_tip : (N, 4, 4) float — the commanded tip poses
    near_singular : (N,) bool — ``sigma_min < singular_threshold`` (exact elimination test,
        :func:`roboisf.robot.singularity.margin_ok`, run in the fused kernel)
    length_scale : float or None, m — divides the Jacobian's linear rows (None when the check
        was skipped)
    J_scaled : (N, 6, 6) float or None — the scaled tip Jacobian; computed on first access
    sigma_min : (N,) float — smallest singular value of ``J_scaled`` (NaN when the check was
        skipped); computed on first access
    """

    q: F64
    T_base_tip: F64
    near_singular: NDArray[np.bool_]
    length_scale: float | None = None
    model: RobotModel | None = field(default=None, repr=False)

    @cached_property
    def J_scaled(self) -> F64 | None:
        """(N, 6, 6) scaled tip Jacobian, or None (see the class doc)."""
        if self.model is None or self.length_scale is None:
            return None
        return scaled_jacobian(self.model.jacobian(self.q, check_limits=False), self.length_scale)

    @cached_property
    def sigma_min(self) -> F64:
        """(N,) smallest singular value of the scaled Jacobian (see the class doc)."""
        Js = self.J_scaled
        return np.full(len(self.q), np.nan) if Js is None else _sigma_min(Js)


def ik_toolpath(
    model: RobotModel,
    tip_work: ArrayLike,
    T_base_work: ArrayLike | None = None,
    *,
    tool_rotation: ArrayLike = 0.0,
    shoulder: Literal["front", "back"] = "front",
    elbow: Literal["up", "down"] = "up",
    wrist: Literal["noflip", "flip"] = "noflip",
    singular_threshold: float | None = 0.02,
    length_scale: float | None = None,
    backend: str | None = None,
    match_q: ArrayLike | None = None,
    confdata: ArrayLike | None = None,
    kuka_st: ArrayLike | None = None,
) -> IKResult:
    """One continuous joint trajectory for tool-tip points (N, 3) m in the work frame.

    **Branch and turns.** By default the branch ``shoulder``/``elbow``/``wrist`` and, for every
    joint, the whole turn that puts the path nearest the middle of its range. Or the first point
    is matched, over all 8 OPW branches and every whole turn of every joint within its limits, to
    one of (the branch then holds along the path, the turns follow continuously):

    * ``match_q`` (6,) rad — the nearest solution to these joints (e.g. the robot's logged
      joints at the first point; largest joint difference);
    * ``confdata`` (cf1, cf4, cf6, cfx) — ABB RAPID confdata
      (:func:`roboisf.robot.armconfig.abb_confdata`);
    * ``kuka_st`` (S, T) — KUKA Status and Turn (:func:`roboisf.robot.armconfig.kuka_status_turn`).

    No solution with the requested configuration at the first point → InputError listing the
    ones there are. Robots without OPW geometry (a URDF that is not OPW) are solved numerically
    (:mod:`roboisf.robot.numik`, seeded point to point, so the branch holds too); there only
    ``match_q`` applies.

    ``tip_work`` may be a :class:`roboisf.toolpath.Toolpath` (its ``tip`` is used).
    ``T_base_work`` defaults to the model's ``default_placement``. Raises
    :class:`~roboisf.errors.UnreachableError` listing the indices of points that are out of
    reach or beyond the joint limits; emits :class:`SingularityWarning` when the smallest singular
    value of the scaled Jacobian drops below ``singular_threshold``. ``singular_threshold=None``
    skips the singularity check (``sigma_min`` NaN, nothing flagged) for callers that check the
    margin themselves (``roboisf.plan``). ``backend`` ("auto", "numba", "numpy"; default the
    model's :attr:`RobotModel.backend`) picks the IK engine: "numba" runs tool poses, the OPW
    branch, unwrapping and the limit shift in one compiled pass per path; both engines give the
    same angles (≤ 1e-12 rad), the same unreachable indices and the same limit verdicts.
    """
    tip = getattr(tip_work, "tip", tip_work)
    tip = np.asarray(tip, dtype=float)
    if tip.ndim != 2 or tip.shape[1] != 3 or tip.shape[0] == 0:
        raise InputError(
            f"expected tool-tip points of shape (N, 3), got {tip.shape}", field="toolpath"
        )
    if not np.all(np.isfinite(tip)):
        raise InputError("tool-tip points contain NaN or inf", field="toolpath")
    if T_base_work is None:
        if model.default_placement is None:
            raise InputError(
                f"robot {model.name!r} has no default placement; give T_base_work",
                field="placement",
            )
        T_base_work = model.default_placement
    T_bw = np.asarray(T_base_work, dtype=float)
    chosen = [x is not None for x in (match_q, confdata, kuka_st)]
    if sum(chosen) > 1:
        raise InputError(
            "give at most one of match_q, confdata, kuka_st (the configuration of the first point)",
            field="branch",
        )
    if model.opw is None:
        warnings.warn(
            NumericalIKWarning(
                model.ik_note
                or f"robot {model.name!r} has no OPW geometry: IK along the toolpath is numerical"
            ),
            stacklevel=2,
        )
        return _numerical_path(
            model, tip, T_bw, tool_rotation, match_q, any(chosen[1:]), singular_threshold,
            length_scale,
        )  # fmt: skip
    q_first: F64 | None = None
    if any(chosen):
        T0 = tool_poses(tip[:1], T_bw, np.asarray(tool_rotation, dtype=float).reshape(-1)[:1])
        br, q_first = choose_start(
            model, T0[0], match_q=match_q, confdata=confdata, kuka_st=kuka_st
        )
        shoulder, elbow, wrist = cast(Any, br)
    _check_branch(shoulder, elbow, wrist)
    gam = np.asarray(tool_rotation, dtype=float)
    if gam.ndim > 1 or (gam.ndim == 1 and gam.shape[0] not in (1, tip.shape[0])):
        raise InputError(
            f"tool_rotation must be a scalar or one angle per point ({tip.shape[0]},), "
            f"got shape {gam.shape}",
            field="tool_rotation",
        )
    if not np.all(np.isfinite(gam)):
        raise InputError("tool_rotation contains NaN or inf", field="tool_rotation")
    b = model.backend if backend is None else backend
    # the C form (ik_numba calls it) needs neither numba nor jit.ready("robot")
    compiled = T_bw.shape == (4, 4) and (vjm_kernel.use_c(b) or vjm_kernel.use_numba(b))
    if compiled:
        from roboisf.robot.ik_numba import path_ik

        q, ok, within, T_opt = path_ik(
            model,
            tip,
            T_bw,
            invert(model.T_flange_tip),
            gam.reshape(-1),
            shoulder,
            elbow,
            wrist,
        )
        assert T_opt is not None
        T_tip = T_opt
    else:
        T_tip = tool_poses(tip, T_bw, gam)
        T_flange = T_tip @ invert(model.T_flange_tip)
        q, ok = _opw_ik_numpy(model, T_flange, shoulder, elbow, wrist)
        within = False  # tested below
    if not np.all(ok):
        raise_out_of_reach(model, ok, (shoulder, elbow, wrist))
    if not compiled:
        q = _continuous(model, q)
    if q_first is not None:  # the chosen turns at the first point, continuous from there
        q = q + 2 * np.pi * np.round((q_first - q[0]) / (2 * np.pi))
        within = False
    if not within:  # (the compiled pass checked the limits already)
        raise_beyond_limits(model, q)
    # stacklevel 2 from here: the warning points at the caller of ik_toolpath
    return _checked_result(model, q, T_tip, singular_threshold, length_scale, stacklevel=2)


BRANCHES: tuple[tuple[str, str, str], ...] = tuple(
    (s, e, w) for s in ("front", "back") for e in ("up", "down") for w in ("noflip", "flip")
)


def start_candidates(model: RobotModel, T_base_tip: F64) -> list[tuple[tuple[str, str, str], F64]]:
    """Every IK solution of one tip pose (4, 4): (branch, q (6,) rad) for the 8 OPW branches and
    every whole turn of every joint that stays within the limits."""
    from itertools import product

    T_fl = (np.asarray(T_base_tip, dtype=float) @ invert(model.T_flange_tip))[None]
    out: list[tuple[tuple[str, str, str], F64]] = []
    for br in BRANCHES:
        q, ok = _opw_ik_numpy(model, T_fl, *br)
        if not ok[0]:
            continue
        options = []
        for j in range(6):
            ks = np.arange(-3, 4)
            v = q[0, j] + 2 * np.pi * ks
            options.append(v[(v >= model.q_min[j] - 1e-9) & (v <= model.q_max[j] + 1e-9)])
        for combo in product(*options):
            out.append((br, np.array(combo)))
    return out


def choose_start(
    model: RobotModel,
    T_base_tip: F64,
    *,
    match_q: ArrayLike | None = None,
    confdata: ArrayLike | None = None,
    kuka_st: ArrayLike | None = None,
) -> tuple[tuple[str, str, str], F64]:
    """The (branch, q (6,) rad) of one tip pose matching logged joints, ABB confdata or KUKA S/T
    (see :func:`ik_toolpath`)."""
    from roboisf.robot.armconfig import abb_confdata, arm_config, kuka_status_turn

    cands = start_candidates(model, T_base_tip)
    if not cands:
        raise UnreachableError(
            f"the first toolpath point is out of reach of {model.name} (no IK branch, or none "
            "within the joint limits)",
            indices=[0],
        )
    if match_q is not None:
        ref = np.asarray(match_q, dtype=float).reshape(-1)
        if ref.shape != (6,) or not np.all(np.isfinite(ref)):
            raise InputError(f"expected 6 finite joint angles (rad), got {ref}", field="match_q")
        dist = [float(np.max(np.abs(q - ref))) for _, q in cands]
        return cands[int(np.argmin(dist))]
    qs = np.array([q for _, q in cands])
    cfg = arm_config(model, qs)
    if confdata is not None:
        want = np.asarray(confdata).reshape(-1)
        have = abb_confdata(cfg)
        what, field = "confdata [cf1, cf4, cf6, cfx]", "confdata"
    else:
        want = np.asarray(kuka_st).reshape(-1)
        have = kuka_status_turn(cfg)
        what, field = "KUKA (S, T)", "kuka_st"
    if want.shape != (have.shape[1],) or not np.all(np.isfinite(want.astype(float))):
        raise InputError(f"expected {what} as {have.shape[1]} integers, got {want}", field=field)
    hit = np.flatnonzero(np.all(have == want.astype(np.int64), axis=1))
    if hit.size == 0:
        avail = sorted({tuple(int(x) for x in h) for h in have})
        raise InputError(
            f"no IK solution at the first toolpath point has {what} = {want.tolist()}; "
            f"available there: {avail}",
            field=field,
        )
    return cands[int(hit[0])]


def _numerical_path(
    model: RobotModel,
    tip: F64,
    T_bw: F64,
    tool_rotation: ArrayLike,
    match_q: ArrayLike | None,
    config_given: bool,
    singular_threshold: float | None,
    length_scale: float | None,
) -> IKResult:
    """:func:`ik_toolpath` for a robot without OPW geometry (numerical IK)."""
    from roboisf.robot.numik import numerical_ik_path

    if config_given:
        raise InputError(
            f"robot {model.name!r} has no OPW geometry: its IK is numerical and the configuration "
            "can be chosen only by joints (match_q / --start-joints), not by confdata or S/T",
            field="branch",
        )
    gam = np.asarray(tool_rotation, dtype=float)
    T_tip = tool_poses(tip, T_bw, gam if gam.ndim == 0 else gam.reshape(-1))
    q0 = None if match_q is None else np.asarray(match_q, dtype=float).reshape(6)
    q, ok = numerical_ik_path(model, T_tip, q0)
    if not np.all(ok):
        bad = np.flatnonzero(~ok)
        raise UnreachableError(
            f"{bad.size} of {len(ok)} toolpath points: the numerical IK of {model.name} did not "
            "converge (out of reach, or a jump the path cannot follow) at indices "
            f"{short_indices(bad)}",
            indices=bad.tolist(),
        )
    if q0 is None:
        q = _continuous(model, q)
    raise_beyond_limits(model, q)
    # stacklevel 3 from here (ik_toolpath → _numerical_path): the caller of ik_toolpath
    return _checked_result(model, q, T_tip, singular_threshold, length_scale, stacklevel=3)


def _checked_result(
    model: RobotModel,
    q: F64,
    T_tip: F64,
    singular_threshold: float | None,
    length_scale: float | None,
    *,
    stacklevel: int,
) -> IKResult:
    """The :class:`IKResult` of joints ``q`` (N, 6) rad and tip poses ``T_tip`` (N, 4, 4), with
    the singularity-margin check when ``singular_threshold`` is given (length scale in m; the
    robot's own when None): a :class:`SingularityWarning` naming the points near a singularity.

    ``stacklevel`` is the one the calling function would pass to :func:`warnings.warn` itself
    (this function adds its own frame), so the warning keeps pointing at the user's call.
    """
    if singular_threshold is None:
        return IKResult(q=q, T_base_tip=T_tip, near_singular=np.zeros(len(q), dtype=bool))
    L = length_scale if length_scale is not None else _length_scale(model)
    near = ~model.singularity_margin_ok(q, L, singular_threshold)
    if np.any(near):
        idx = np.flatnonzero(near)
        warnings.warn(
            f"{idx.size} toolpath points are near a singularity (σ_min < {singular_threshold}) "
            f"at indices {short_indices(idx)}; the compliance there is unreliable",
            SingularityWarning,
            stacklevel=stacklevel + 1,
        )
    return IKResult(q=q, T_base_tip=T_tip, near_singular=near, length_scale=L, model=model)


def raise_out_of_reach(model: RobotModel, ok: NDArray[np.bool_], branch: tuple[str, ...]) -> None:
    """Raise the :class:`UnreachableError` naming the points with ``ok`` False."""
    bad = np.flatnonzero(~ok)
    raise UnreachableError(
        f"{bad.size} of {len(ok)} toolpath points are out of reach of {model.name} "
        f"(branch {'/'.join(branch)}) at indices {short_indices(bad)}",
        indices=bad.tolist(),
    )


def raise_beyond_limits(model: RobotModel, q: F64) -> None:
    """Raise the :class:`UnreachableError` naming the points of ``q`` (N, 6) rad beyond the
    joint limits (± 1e-9 rad); return when there are none."""
    out = (q < model.q_min - 1e-9) | (q > model.q_max + 1e-9)
    if np.any(out):
        bad = np.flatnonzero(np.any(out, axis=1))
        joints = sorted({int(j) + 1 for j in np.nonzero(out)[1]})
        raise UnreachableError(
            f"{bad.size} of {len(q)} toolpath points need joint angles beyond the limits of "
            f"{model.name} (axes {joints}) at indices {short_indices(bad)}; try another placement, "
            "tool rotation or branch",
            indices=bad.tolist(),
        )


def _length_scale(model: RobotModel) -> float:
    """c2 + c3 (m) of an OPW robot; else the distance from joint 2 to the flange at q = 0."""
    g = model.opw
    if g is not None:
        return g.c2 + g.c3
    T = np.eye(4)
    for i in range(2):
        T = T @ model.chain.F[i]
    T2 = T
    th = model.chain.theta(np.zeros((1, 6)))[0]
    T = np.eye(4)
    for i in range(6):
        T = T @ model.chain.F[i]
        c, s = np.cos(th[i]), np.sin(th[i])
        R = np.eye(4)
        R[:2, :2] = [[c, -s], [s, c]]
        T = T @ R
    T = T @ model.chain.F[6]
    return max(float(np.linalg.norm(T[:3, 3] - T2[:3, 3])), 1e-3)


def _continuous(model: RobotModel, q: F64) -> F64:
    """Unwrap every joint along the path, then shift by whole turns into the limits."""
    q = np.unwrap(q, axis=0)
    two_pi = 2 * np.pi
    mid = 0.5 * (model.q_min + model.q_max)
    # the whole-turn shift that brings the path's mean closest to the middle of the range
    k = np.round((mid - q.mean(axis=0)) / two_pi)
    q = q + k * two_pi
    # if the path still leaves the range, try the neighbouring turns
    for j in range(6):
        for dk in (0.0, 1.0, -1.0):
            qj = q[:, j] + dk * two_pi
            if np.all(qj >= model.q_min[j] - 1e-9) and np.all(qj <= model.q_max[j] + 1e-9):
                q[:, j] = qj
                break
    return q
