"""The :class:`~roboisf.cell.Cell` of a study folder (``study.toml``: part, tool, holder, robot)."""

from __future__ import annotations

from roboisf.cell.model import Cell, CellHolder, CellTool, build_robot
from roboisf.errors import InputError
from roboisf.fem import BallEndTool, load_compliance_json
from roboisf.study.spec import Study

__all__ = ["cell_from_study"]


def cell_from_study(study: Study) -> Cell:
    """The cell a validated study describes (compliance JSON files are read here).

    A study's cell has no force model (its forces are measured). Raises InputError when the study
    has no ``[robot]`` table (the decomposition, compensation and planning need one).
    """
    if study.robot is None:
        raise InputError(
            "the study needs a [robot] table (model, placement)", file=study.root / "study.toml"
        )
    t = study.tool
    tool = CellTool(
        t.ball_diameter,
        compliance=None if t.compliance is None else load_compliance_json(t.compliance),
        geometry=None
        if t.free_length is None
        else BallEndTool(t.ball_diameter, t.free_length, t.shank_diameter),
        method=t.method,
    )
    h = study.holder
    holder = (
        CellHolder()
        if h.rigid or h.compliance is None
        else CellHolder(compliance=load_compliance_json(h.compliance), offset=h.offset)
    )
    r = study.robot
    model = build_robot(
        r.model,
        T_flange_tip=r.T_flange_tip,
        joint_stiffness=r.joint_stiffness,
        stiffness_source="study.toml",
        tip_link=r.tip_link,
    )
    return Cell(
        study.part,
        tool,
        holder,
        model,
        r.T_base_work,
        r.model,
        r.tool_rotation,
        tip_link=r.tip_link,
    )
