"""The forming cell as one value: part, tool, holder, robot, placement and force model.

A :class:`Cell` is what ``decompose``, ``compensate`` and ``plan`` need to know about the physical
set-up, whatever produced it: :func:`roboisf.cell.cell_from_study` builds it from a study folder,
:func:`make_cell` (the virtual-cell factory and ``plan --part``) from a part and defaults. The
files of a study (runs, logs, scans) and the settings of a synthetic experiment (scan density,
noise, seeds) are not part of the cell.

Compliance at the tool tip (``docs/conventions.md``, Bharti et al. 2024, eq. 2)::

    k_ef = J_r k_r J_rᵀ + J_th k_th J_thᵀ + J_t k_t J_tᵀ

:func:`tip_compliances` returns the robot-independent part, ``J_t k_t J_tᵀ`` (tool) and
``J_th k_th J_thᵀ`` (holder, whose reference point sits ``holder.offset`` above the tip); the
robot's ``J_r k_r J_rᵀ`` depends on the configuration and comes from
:meth:`roboisf.robot.RobotModel.compliance`. Tool and holder compliances are given in their FE/beam
frame (z up the tool axis); the tool is vertical in the work frame, so those are the work axes.

All lengths in m, angles in rad, compliances in SI (m/N, 1/N, rad/(N·m)).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.cell.forces import ForceModel
from roboisf.errors import InputError
from roboisf.fem.geometry import PAPER_TOOL_LENGTH, BallEndTool, HolderSection, ToolHolder
from roboisf.fem.result import ComplianceResult
from roboisf.frames import check_rigid, make_transform, to_tip
from roboisf.parts import Part
from roboisf.progress import Progress
from roboisf.robot import RobotModel, load_robot
from roboisf.toolpath import Toolpath, toolpath_for_part

__all__ = [
    "DEFAULT_HOLDER",
    "PAPER_CELL_PLACEMENT",
    "SENSOR_STACK",
    "Cell",
    "CellHolder",
    "CellTool",
    "at_ball_centre",
    "build_robot",
    "flange_to_tip",
    "make_cell",
    "nominal_toolpath",
    "tip_compliances",
]

F64 = NDArray[np.float64]
Method = Literal["beam", "fe"]

#: Default holder: a Ø40 mm steel shank, 200 mm from flange adapter to nose, loaded through the
#: tool's Ø10 mm footprint — beam model 1.03e-7 m/N lateral, the paper's holder is 1.07e-7.
DEFAULT_HOLDER = ToolHolder((HolderSection(0.200, 0.040),), coupling_diameter=0.010)
#: Distance from the flange to the holder's top (F/T sensor and adapter) [m].
SENSOR_STACK = 0.040
#: Where the paper-like cells put the blank: 2.2 m in front of an IRB 7600 base, 0.5 m to its
#: right (−y), 0.2 m up, axes parallel to the base. The paper does not give its placement; far out
#: (88 % of the robot's reach) the robot term is of the paper's order, and off the base's x-axis
#: the compliance couples F_z into δy (k_yz ≈ −1.1e-7 m/N: −0.05 mm from the cone's 490 N,
#: against +0.22 mm from F_y), the coupling of the paper's Table 4, which the symmetric placement
#: on the x-axis (k_yz = 0) could not show. A choice, documented, not data.
PAPER_CELL_PLACEMENT = make_transform(p=[2.2, -0.5, 0.2])


def _method(method: str, name: str) -> None:
    if method not in ("beam", "fe"):
        raise InputError(f"must be 'beam' or 'fe', got {method!r}", field=name)


@dataclass(frozen=True)
class CellTool:
    """The ball tool and the source of its 6×6 compliance.

    Attributes
    ----------
    ball_diameter : float, m
    compliance : ComplianceResult or None — a given compliance (a ``tool-stiffness`` JSON) about
        its reference point; it wins over ``geometry``
    geometry : BallEndTool or None — computed by ``method`` when no compliance is given
    method : "beam" or "fe"
    """

    ball_diameter: float
    compliance: ComplianceResult | None = None
    geometry: BallEndTool | None = None
    method: Method = "beam"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.ball_diameter) and self.ball_diameter > 0):
            raise InputError(f"must be > 0 m, got {self.ball_diameter}", field="tool.ball_diameter")
        _method(self.method, "tool.method")
        if self.compliance is None and self.geometry is None:
            raise InputError(
                "give a compliance (JSON) or the tool geometry to compute it", field="tool"
            )
        if self.geometry is not None and not math.isclose(
            self.geometry.ball_diameter, self.ball_diameter, rel_tol=1e-9
        ):
            raise InputError(
                f"the tool geometry has a Ø{self.geometry.ball_diameter * 1e3:g} mm ball, the cell "
                f"Ø{self.ball_diameter * 1e3:g} mm",
                field="tool.geometry",
            )

    @property
    def radius(self) -> float:
        """Ball radius [m]."""
        return self.ball_diameter / 2

    def result(self, progress: Progress | None = None) -> ComplianceResult:
        """The tool's compliance about its reference point (given, beam model or FE)."""
        if self.compliance is not None:
            return self.compliance
        assert self.geometry is not None
        # the FE and beam models load scipy.sparse (~0.14 s): not for compliances given as files
        from roboisf.fem.stiffness import beam_result, tool_compliance

        if self.method == "fe":
            return tool_compliance(self.geometry, progress=progress)
        return beam_result(self.geometry)


@dataclass(frozen=True)
class CellHolder:
    """The tool holder: its compliance source, or rigid when it has none.

    Attributes
    ----------
    compliance : ComplianceResult or None — about the holder's reference point (its nose)
    geometry : ToolHolder or None — computed by ``method`` when no compliance is given
    method : "beam" or "fe"
    offset : float, m — from the holder's reference point down the tool axis to the tool tip
    """

    compliance: ComplianceResult | None = None
    geometry: ToolHolder | None = None
    method: Method = "beam"
    offset: float = 0.0

    def __post_init__(self) -> None:
        _method(self.method, "tool_holder.method")
        if not (math.isfinite(self.offset) and self.offset >= 0):
            raise InputError(f"must be ≥ 0 m, got {self.offset}", field="tool_holder.offset")

    @property
    def rigid(self) -> bool:
        """No compliance and no geometry: the holder does not deflect."""
        return self.compliance is None and self.geometry is None

    def result(self, progress: Progress | None = None) -> ComplianceResult | None:
        """The holder's compliance about its reference point (None when rigid)."""
        if self.compliance is not None:
            return self.compliance
        if self.geometry is None:
            return None
        from roboisf.fem.stiffness import beam_result, holder_compliance

        if self.method == "fe":
            return holder_compliance(self.geometry, progress=progress)
        return beam_result(self.geometry)


def _rigid_transform(T: ArrayLike, name: str) -> F64:
    A = np.array(T, dtype=float)
    if A.shape != (4, 4) or not np.all(np.isfinite(A)):
        raise InputError(f"expected a finite 4×4 transform, got shape {A.shape}", field=name)
    check_rigid(A, name)
    A.setflags(write=False)
    return A


@dataclass(frozen=True, eq=False)
class Cell:
    """One forming cell (work frame, SI). Validated at construction; arrays are read-only.

    Attributes
    ----------
    part : Part — the nominal part (any part kind)
    tool : CellTool — ball and tool compliance source
    holder : CellHolder — holder compliance source (or rigid) and its offset above the tip
    robot : RobotModel — kinematics, joint stiffness and the tool (``robot.T_flange_tip``)
    T_base_work : (4, 4) float, m — placement of the work frame in the robot base
    robot_name : str — the preset name or robot file the model came from (``[robot].model``)
    tip_link : str or None — the URDF link taken as the flange (``[robot].tip_link``)
    tool_rotation : float, rad — rotation of the tool about its own axis
    force : ForceModel or None — the forming-force model (the virtual cell, ``plan --part``);
        None for a real study, whose forces are measured
    """

    part: Part
    tool: CellTool
    holder: CellHolder
    robot: RobotModel
    T_base_work: F64
    robot_name: str = ""
    tool_rotation: float = 0.0
    force: ForceModel | None = field(default=None)
    tip_link: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.part, Part):
            raise InputError(
                f"expected a part (cone, vwacf, profile, mesh …), got {type(self.part).__name__}",
                field="part",
            )
        if not isinstance(self.robot, RobotModel):
            raise InputError(
                f"expected a RobotModel, got {type(self.robot).__name__}", field="robot"
            )
        object.__setattr__(self, "T_base_work", _rigid_transform(self.T_base_work, "T_base_work"))
        if not math.isfinite(self.tool_rotation):
            raise InputError(f"must be finite, got {self.tool_rotation}", field="tool_rotation")
        if not self.robot_name:
            object.__setattr__(self, "robot_name", self.robot.name)

    @property
    def T_flange_tip(self) -> F64:
        """(4, 4) float, m — the tool tip in the flange frame (the robot model's tool)."""
        return self.robot.T_flange_tip

    def toolpath(
        self,
        step: float = 0.5e-3,
        *,
        spacing: float = 1e-3,
        max_wall_step: float | None = None,
    ) -> Toolpath:
        """The nominal step-down toolpath of the cell's part with its ball (see
        :func:`nominal_toolpath`)."""
        return nominal_toolpath(
            self.part, self.tool.radius, step, spacing=spacing, max_wall_step=max_wall_step
        )


def tip_compliances(
    cell: Cell, *, progress: Progress | None = None
) -> tuple[ComplianceResult, ComplianceResult | None, F64, F64]:
    """Tool and holder compliance of ``cell``, and both moved to the tool tip.

    Returns
    -------
    k_tool : ComplianceResult — the tool's, about its reference point
    k_holder : ComplianceResult or None — the holder's (None when rigid)
    k_t : (6, 6) float — ``J_t k_t J_tᵀ`` at the tip, work axes (SI)
    k_th : (6, 6) float — ``J_th k_th J_thᵀ`` at the tip (zeros when rigid)
    """
    k_tool = cell.tool.result(progress)
    k_t = to_tip(k_tool.compliance, -k_tool.reference_point)
    k_holder = cell.holder.result(progress)
    if k_holder is None:
        return k_tool, None, k_t, np.zeros((6, 6))
    k_th = to_tip(
        k_holder.compliance,
        np.array([0.0, 0.0, -cell.holder.offset]) - k_holder.reference_point,
    )
    return k_tool, k_holder, k_t, k_th


def at_ball_centre(d_tip: ArrayLike, ball_radius: float) -> F64:
    """Displacement (N, 3) m of the ball centre for tip deflection twists ``d_tip`` (N, 6)
    [m; rad] in work axes, the tool vertical (centre = tip + R ẑ_work).

    The ball is rigid, so its centre moves ``δ_tip + θ × R ẑ``. It is the deflection that
    forms the part: a rotation of the ball about its centre leaves its surface where it was, so
    the normal displacement of any contact point is ``n · δ_centre`` exactly (the paper's
    reference point). The tip's deflection differs by ``θ × R ẑ`` — ~10 % of the tool's term
    (the tool bends most at its end), ~0.6 % of the robot's.
    """
    d = np.asarray(d_tip, dtype=float)
    return np.asarray(d[:, :3] + np.cross(d[:, 3:], [0.0, 0.0, ball_radius]), dtype=float)


def build_robot(
    name: str,
    *,
    T_flange_tip: ArrayLike | None = None,
    joint_stiffness: Sequence[float] | ArrayLike | None = None,
    stiffness_source: str = "user",
    tip_link: str | None = None,
) -> RobotModel:
    """The robot model: a preset name, robot TOML or URDF, with its tool and joint stiffness.

    Parameters
    ----------
    name : preset (``roboisf robot list``) or file
    T_flange_tip : (4, 4) float, m — the tool tip in the flange frame (default: the model's)
    joint_stiffness : (6,) float, N·m/rad — replaces the model's (default: the model's)
    stiffness_source : where the stiffness came from (shown in reports)
    tip_link : a URDF robot's flange link (``[robot].tip_link``, ``--tip-link``; default: the
        URDF reader's choice); an error for a preset or robot TOML
    """
    model = load_robot(name, tip_link=tip_link)
    if T_flange_tip is not None:
        model = model.with_tool(T_flange_tip)
    if joint_stiffness is not None:
        model = model.with_stiffness(joint_stiffness, source=stiffness_source)
    return model


def flange_to_tip(tool: BallEndTool, holder: ToolHolder | None, stack: float = SENSOR_STACK) -> F64:
    """Tool straight out of the flange: tip at sensor stack + holder + tool free length (4, 4) m
    (``holder=None``: the tool right under the stack)."""
    h = 0.0 if holder is None else sum(s.length for s in holder.sections)
    L = stack + h + tool.length
    return make_transform(p=[0.0, 0.0, L])


def make_cell(
    part: Part,
    *,
    tool: BallEndTool | None = None,
    holder: ToolHolder | None = DEFAULT_HOLDER,
    compliance_method: Method = "beam",
    robot: str = "irb7600-500-2.55",
    joint_stiffness: Sequence[float] | None = None,
    T_base_work: ArrayLike | None = None,
    tool_rotation: float = 0.0,
    force: ForceModel | None = None,
    tip_link: str | None = None,
) -> Cell:
    """A cell from a part and the tool, holder and robot geometry (defaults: the paper-like cell:
    Ø10 mm ball 66 mm free, :data:`DEFAULT_HOLDER`, IRB 7600-500/2.55).

    The tool sits straight out of the flange (:func:`flange_to_tip`); ``holder=None`` is a rigid
    holder. ``T_base_work`` (4, 4) m defaults to the robot preset's default placement. Lengths m,
    angles rad. ``tip_link``: a URDF robot's flange link (default: the URDF reader's choice).
    """
    _method(compliance_method, "compliance_method")
    tool = tool if tool is not None else BallEndTool(10e-3, PAPER_TOOL_LENGTH)
    model = build_robot(
        robot,
        T_flange_tip=flange_to_tip(tool, holder),
        joint_stiffness=joint_stiffness,
        tip_link=tip_link,
    )
    T_bw = model.default_placement if T_base_work is None else T_base_work
    if T_bw is None:
        raise InputError(
            f"robot {robot!r} has no default placement; give T_base_work", field="T_base_work"
        )
    return Cell(
        part,
        CellTool(tool.ball_diameter, geometry=tool, method=compliance_method),
        CellHolder(geometry=holder, method=compliance_method, offset=tool.length)
        if holder is not None
        else CellHolder(),
        model,
        np.asarray(T_bw, dtype=float),
        robot,
        tool_rotation,
        force,
        tip_link,
    )


def nominal_toolpath(
    part: Part,
    tool_radius: float,
    step: float = 0.5e-3,
    *,
    spacing: float = 1e-3,
    max_wall_step: float | None = None,
) -> Toolpath:
    """The nominal step-down toolpath of ``part`` (lengths m): the one toolpath generator the
    cell's consumers call, whatever the part kind.

    Axisymmetric parts (cone, VWACF, profile) use the generatrix generator
    (:func:`roboisf.toolpath.step_down`; results unchanged); every other part kind (pyramid,
    mesh, CAD) z-level contours sliced from its ball-centre surface — the choice of
    :func:`roboisf.path.toolpath_for_part`, shared with ``roboisf toolpath``.
    ``max_wall_step`` (laps refined along a steep generatrix) exists only for axisymmetric parts.
    """
    return toolpath_for_part(part, tool_radius, step, spacing=spacing, max_wall_step=max_wall_step)
