"""The deflection model of a :class:`~roboisf.cell.Cell`: robot, placement, tool + holder."""

from __future__ import annotations

from roboisf.cell import Cell, tip_compliances
from roboisf.compensate.compliance import DeflectionModel
from roboisf.progress import Progress

__all__ = ["cell_deflection_model"]


def cell_deflection_model(
    cell: Cell, *, include_robot: bool = True, progress: Progress | None = None
) -> DeflectionModel:
    """The cell's robot (with its tool and joint stiffness) at ``cell.T_base_work``, its tool
    rotation, and the tool + holder compliance at the tip ``k_t + k_th`` (6, 6) SI."""
    _, _, k_t, k_th = tip_compliances(cell, progress=progress)
    return DeflectionModel(
        cell.robot,
        cell.T_base_work,
        k_t + k_th,
        tool_rotation=cell.tool_rotation,
        include_robot=include_robot,
        ball_radius=cell.tool.radius,
    )
