"""Build a :class:`PlanProblem` from a part (+ the force model) or from a virtual cell."""

from __future__ import annotations

from typing import Any

import numpy as np

from roboisf.fem import beam_result
from roboisf.frames import to_tip
from roboisf.parts import AxisymmetricPart
from roboisf.plan.problem import PlanProblem
from roboisf.robot.model import RobotModel
from roboisf.toolpath import Toolpath, step_down
from roboisf.virtual.cell import VirtualCell
from roboisf.virtual.forces import ForceModel, tip_wrench

__all__ = ["problem_from_cell", "problem_from_part"]


def problem_from_part(
    part: AxisymmetricPart,
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

    Lengths in m. ``options`` go to :class:`PlanProblem` (limits, smoothing, objective).
    """
    tp = step_down(part, tool_radius, step, spacing=spacing, max_wall_step=max_wall_step)
    W = tip_wrench(tp, force or ForceModel(), thickness=part.sheet_thickness, step_down=step)
    prob = PlanProblem(
        model, tp.tip, tp.normal, tp.lap, W, tool_compliance=tool_compliance, **options
    )
    return prob, tp


def problem_from_cell(
    cell: VirtualCell,
    *,
    with_tool: bool = True,
    model: RobotModel | None = None,
    **options: Any,
) -> tuple[PlanProblem, Toolpath]:
    """The virtual cell's part, toolpath, force model, robot (with its tool) and — with
    ``with_tool`` — the beam-model tool + holder compliance at the tip, as
    :func:`roboisf.virtual.simulate` uses them (γ = 0: the same axes). ``model`` replaces the
    cell's robot (e.g. another tool mounting)."""
    from roboisf.robot import load_robot

    if model is None:
        model = load_robot(cell.robot).with_tool(cell.T_flange_tip)
    k = None
    if with_tool:
        kt = beam_result(cell.tool)
        kh = beam_result(cell.holder)
        k = kt.compliance + to_tip(
            kh.compliance, np.array([0.0, 0.0, -cell.tool.length]) - kh.reference_point
        )
    return problem_from_part(
        cell.part,
        model,
        tool_radius=cell.tool.radius,
        step=cell.step_down,
        spacing=cell.spacing,
        max_wall_step=cell.max_wall_step,
        force=cell.force,
        tool_compliance=k,
        **options,
    )
