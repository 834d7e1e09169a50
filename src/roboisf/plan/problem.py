"""What a placement study evaluates: the toolpath, the wrench on the tool and the robot, plus the
feasibility limits and the tool-rotation smoothing parameters (all SI)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames import make_transform, rot_z
from roboisf.parts import Symmetry
from roboisf.robot.model import RobotModel

__all__ = ["PlanProblem", "placement_grid", "placement_transforms"]

F64 = NDArray[np.float64]
Objective = Literal["mean", "max", "normal"]
_NO_SYMMETRY = Symmetry(1)


def _array(a: ArrayLike, shape: tuple[int | None, ...], name: str) -> F64:
    arr = np.array(a, dtype=float)
    if arr.ndim != len(shape) or any(
        s is not None and s != d for s, d in zip(shape, arr.shape, strict=False)
    ):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(f"expected shape {want}, got {arr.shape}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class PlanProblem:
    """A part's toolpath under its forming wrench, and the robot that is to form it.

    Attributes
    ----------
    model : RobotModel — with tool (``T_flange_tip``), joint stiffness and OPW geometry
    tip : (N, 3) float, m — programmed tool-tip points, work frame
    normal : (N, 3) float — unit surface normals (tool side), work frame; ``δ·n`` is what a scan
        of the formed part sees
    lap : (N,) int — lap index per point, non-decreasing (the tool rotation is chosen per lap)
    wrench : (N, 6) float, [N; N·m] — the sheet's wrench on the tool, about the tip, work axes
    tool_compliance : (6, 6) float or None — tool (+ holder) compliance at the tip, in the tool's
        own axes (z up the tool axis, x along the tip frame's x), m/N …; added to the robot's
        deflection, turned with the tool rotation γ
    sigma_threshold : float — singularity margin: smallest singular value of the scaled Jacobian
        (as :func:`roboisf.robot.ik_toolpath`) allowed along the path
    max_joint_step : float, rad — largest joint change between consecutive points (continuity)
    max_rotation_step : float, rad — largest change of the tool rotation from one lap to the next
    ramp_points : int — a change of γ between laps is ramped linearly over at least this many
        points at the start of the new lap (more when needed so γ steps ≤ max_joint_step / 2 per
        point; at most the whole lap)
    smoothness : float ≥ 0 — penalty on changing γ: a change of π costs this fraction of an
        average lap's summed |δ|
    objective : "mean" (mean |δ|), "max" (max |δ|) or "normal" (mean |δ·n|) — what is ranked
    ball_radius : float ≥ 0, m — every δ is that of the ball centre, this far above the tip along
        the work z (the tool vertical): ``δ_tip + θ × R ẑ``, as the analysis
        (:func:`roboisf.cell.at_ball_centre`); 0 scores the tip itself
    symmetry : Symmetry — the part's rotational symmetry about the work z axis
        (:attr:`roboisf.parts.Part.symmetry`; default: none). A surface of revolution turned
        about its axis is the same part, so :func:`~roboisf.plan.plan_placements` evaluates
        candidates that differ in yaw alone once
    """

    model: RobotModel
    tip: F64
    normal: F64
    lap: NDArray[np.intp]
    wrench: F64
    tool_compliance: F64 | None = None
    sigma_threshold: float = 0.02
    max_joint_step: float = math.radians(5.0)
    max_rotation_step: float = math.radians(30.0)
    ramp_points: int = 50
    smoothness: float = 0.05
    objective: Objective = "mean"
    ball_radius: float = 0.0
    symmetry: Symmetry = _NO_SYMMETRY
    lap_start: NDArray[np.intp] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        tip = _array(self.tip, (None, 3), "toolpath")
        n = tip.shape[0]
        if n < 2:
            raise InputError(f"need a toolpath of at least 2 points, got {n}", field="toolpath")
        normal = _array(self.normal, (n, 3), "normal")
        wrench = _array(self.wrench, (n, 6), "wrench")
        lap = np.asarray(self.lap)
        if lap.shape != (n,) or not np.issubdtype(lap.dtype, np.integer):
            raise InputError(f"expected ({n},) integer lap indices, got {lap.shape}", field="lap")
        if np.any(np.diff(lap) < 0):
            raise InputError("lap indices must be non-decreasing along the path", field="lap")
        lap = lap.astype(np.intp)
        lap.setflags(write=False)
        # laps renumbered 0..L-1 in path order
        start = np.flatnonzero(np.r_[True, np.diff(lap) != 0]).astype(np.intp)
        start.setflags(write=False)
        object.__setattr__(self, "tip", tip)
        object.__setattr__(self, "normal", normal)
        object.__setattr__(self, "wrench", wrench)
        object.__setattr__(self, "lap", lap)
        object.__setattr__(self, "lap_start", start)
        if self.tool_compliance is not None:
            object.__setattr__(
                self, "tool_compliance", _array(self.tool_compliance, (6, 6), "tool_compliance")
            )
        if self.model.opw is None:
            raise InputError(
                f"robot {self.model.name!r} has no OPW geometry; placement planning needs "
                "closed-form IK",
                field="robot",
            )
        self.model.joint_stiffness  # noqa: B018 - raises a clear InputError when unknown
        for name in ("sigma_threshold", "smoothness", "ball_radius"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"must be ≥ 0, got {v}", field=name)
        for name in ("max_joint_step", "max_rotation_step"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0 rad, got {v}", field=name)
        if not (isinstance(self.ramp_points, int | np.integer) and self.ramp_points >= 1):
            raise InputError(f"must be an integer ≥ 1, got {self.ramp_points}", field="ramp_points")
        if not isinstance(self.symmetry, Symmetry):
            raise InputError(f"expected a Symmetry, got {self.symmetry!r}", field="symmetry")
        if self.objective not in ("mean", "max", "normal"):
            raise InputError(
                f"must be 'mean', 'max' or 'normal', got {self.objective!r}", field="objective"
            )

    @property
    def n_points(self) -> int:
        return int(self.tip.shape[0])

    @property
    def n_laps(self) -> int:
        return int(self.lap_start.size)

    @property
    def lap_id(self) -> NDArray[np.intp]:
        """(N,) lap number 0..n_laps−1 in path order."""
        ids = np.zeros(self.n_points, dtype=np.intp)
        ids[self.lap_start[1:]] = 1
        return np.cumsum(ids)

    def tool_is_coaxial(self, tol: float = 1e-9) -> bool:
        """True when the tool axis is joint 6's axis and the tool compliance is axisymmetric.

        Then turning the tool about its own axis only turns A6: J's columns 1–5 and the joint-6
        column (along the tool axis, through the tip) are unchanged, so k_c and δ do not depend
        on γ — exactly (tested).
        """
        T = self.model.T_flange_tip
        coax = bool(np.all(np.abs(T[:2, 3]) <= tol) and abs(abs(T[2, 2]) - 1.0) <= tol)
        if self.tool_compliance is None:
            return coax
        k = self.tool_compliance
        R = rot_z(0.7)
        B = np.zeros((6, 6))
        B[:3, :3] = R
        B[3:, 3:] = R
        return coax and bool(np.max(np.abs(B @ k @ B.T - k)) <= 1e-9 * np.max(np.abs(k)))


def placement_grid(x: ArrayLike, y: ArrayLike, z: ArrayLike, yaw: ArrayLike = (0.0,)) -> F64:
    """All combinations of the given values → (M, 4) ``[x, y, z, yaw]`` (m, m, m, rad).

    Each argument is a 1-D sequence of values (use :func:`numpy.linspace` for ranges).
    """
    axes = []
    for name, v in (("x", x), ("y", y), ("z", z), ("yaw", yaw)):
        a = np.atleast_1d(np.asarray(v, dtype=float))
        if a.ndim != 1 or a.size == 0:
            raise InputError(f"needs at least one value, got {a.size}", field=f"{name} range")
        if not np.all(np.isfinite(a)):
            raise InputError("contains NaN or inf", field=f"{name} range")
        axes.append(a)
    G = np.meshgrid(*axes, indexing="ij")
    return np.stack([g.ravel() for g in G], axis=1)


def placement_transforms(placements: ArrayLike) -> F64:
    """``[x, y, z, yaw]`` rows (M, 4) → ``T_base_work`` (M, 4, 4): work frame turned by yaw about
    the base z axis (fixture level on the floor)."""
    P = np.asarray(placements, dtype=float)
    if P.ndim != 2 or P.shape[1] != 4 or P.shape[0] == 0:
        raise InputError(
            f"expected placements of shape (M, 4) [x, y, z, yaw], got {P.shape}", field="placements"
        )
    if not np.all(np.isfinite(P)):
        raise InputError("placements contain NaN or inf", field="placements")
    return make_transform(rot_z(P[:, 3]), P[:, :3])
