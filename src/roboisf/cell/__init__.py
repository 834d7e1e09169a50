"""The forming cell as one value (:class:`Cell`): part, tool, holder, robot, placement and force
model — built from a study (:func:`cell_from_study`) or from a part (:func:`make_cell`), consumed
by ``decompose``, ``compensate`` and ``plan`` (``docs/conventions.md``, "The cell")."""

from roboisf.cell.forces import ForceModel, aerens_axial_force, tip_wrench
from roboisf.cell.model import (
    DEFAULT_HOLDER,
    PAPER_CELL_PLACEMENT,
    SENSOR_STACK,
    Cell,
    CellHolder,
    CellTool,
    at_ball_centre,
    build_robot,
    flange_to_tip,
    make_cell,
    nominal_toolpath,
    tip_compliances,
)
from roboisf.cell.study import cell_from_study

__all__ = [
    "DEFAULT_HOLDER",
    "PAPER_CELL_PLACEMENT",
    "SENSOR_STACK",
    "Cell",
    "CellHolder",
    "CellTool",
    "ForceModel",
    "aerens_axial_force",
    "at_ball_centre",
    "build_robot",
    "cell_from_study",
    "flange_to_tip",
    "make_cell",
    "nominal_toolpath",
    "tip_compliances",
    "tip_wrench",
]
