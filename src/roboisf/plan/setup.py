"""Build a :class:`PlanProblem` from a part (+ the force model) or from a cell."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import Cell, ForceModel, nominal_toolpath, tip_compliances, tip_wrench
from roboisf.parts import Part
from roboisf.plan.problem import PlanProblem
from roboisf.robot.model import RobotModel
from roboisf.toolpath import Toolpath

__all__ = ["problem_from_cell", "problem_from_part", "tool_and_holder_compliance"]


def problem_from_part(
    part: Part,
    model: RobotModel,
    *,
    tool_radius: float = 5e-3,
    step: float = 0.5e-3,
    spacing: float = 1e-3,
    max_wall_step: float | None = None,
    force: ForceModel | None = None,
    tool_compliance: np.ndarray | None = None,
    **options: Any,
) -> tuple[PlanProblem, Toolpath]:
    """Step-down toolpath of ``part`` and the force model's wrench on it → (problem, toolpath).

    Lengths in m. ``tool_compliance`` (6, 6) SI at the tip. ``options`` go to
    :class:`PlanProblem` (limits, smoothing, objective); the deflections are scored at the ball
    centre (``ball_radius`` = ``tool_radius`` unless given), as the analysis; the part's
    ``symmetry`` goes with them (a round part's yaw is no degree of freedom).
    """
    options.setdefault("ball_radius", tool_radius)
    options.setdefault("symmetry", part.symmetry)
    tp = nominal_toolpath(part, tool_radius, step, spacing=spacing, max_wall_step=max_wall_step)
    W = tip_wrench(tp, force or ForceModel(), thickness=part.sheet_thickness, step_down=step)
    prob = PlanProblem(
        model, tp.tip, tp.normal, tp.lap, W, tool_compliance=tool_compliance, **options
    )
    return prob, tp


def problem_from_cell(
    cell: Cell,
    *,
    step: float = 0.5e-3,
    spacing: float = 1e-3,
    max_wall_step: float | None = None,
    with_tool: bool = True,
    model: RobotModel | None = None,
    **options: Any,
) -> tuple[PlanProblem, Toolpath]:
    """The cell's part, nominal toolpath (``step``, ``spacing``, ``max_wall_step`` m), force model
    (default :class:`ForceModel` when the cell has none), robot (with its tool) and — with
    ``with_tool`` — the tool + holder compliance at the tip (:func:`roboisf.cell.tip_compliances`,
    γ = 0: the same axes). ``model`` replaces the cell's robot (e.g. another tool mounting)."""
    return problem_from_part(
        cell.part,
        cell.robot if model is None else model,
        tool_radius=cell.tool.radius,
        step=step,
        spacing=spacing,
        max_wall_step=max_wall_step,
        force=cell.force,
        tool_compliance=tool_and_holder_compliance(cell) if with_tool else None,
        **options,
    )


def tool_and_holder_compliance(cell: Cell) -> NDArray[np.float64]:
    """The cell's tool + holder compliance at the tip (6, 6) [m/N, rad/(N·m)], as
    :class:`PlanProblem` takes it (the tool's own axes at γ = 0 are the work axes: the tool
    vertical) — :func:`roboisf.cell.tip_compliances`, summed."""
    _, _, k_t, k_th = tip_compliances(cell)
    return k_t + k_th
