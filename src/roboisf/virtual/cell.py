"""The virtual forming cell: synthetic CNC and robot experiments with known ground truth.

:func:`build_study` writes a complete study folder in exactly the format ``roboisf analyze``
reads (``docs/study.md``) — force logs in the sensors' frames, a joint log as the controller
would write it, binary PLY scans — plus ``truth/`` with every contribution per toolpath point.
It is the demo, the end-to-end test bed, and a way to plan a part before forming it.

What is simulated, per toolpath point (wrenches at the tool tip, deflections of the ball centre
— :func:`roboisf.cell.at_ball_centre` —, work axes, SI):

1. the forming wrench W on the tool (:mod:`roboisf.cell.forces`); the robot run's force is
   a little lower at the start (the paper: "slightly less ... during the initial stage"),
   ``W_robot = W · (1 − deficit · exp(−depth / 15 mm))``;
2. tool and holder deflection ``k · W`` (compliances from the beam model or FE, moved to the tip
   by the serial assembly);
3. the robot's deflection by the VJM at the IK configuration of the commanded tip
   (``roboisf.robot``); the CNC is rigid;
4. springback, a normal field (:mod:`roboisf.virtual.springback`);
5. the formed wall: the nominal moved along its normal by ``dn = n · δ + s``; the scans
   sample it (:func:`roboisf.scan.synthetic_scan`) with 25 µm noise, outliers, holes and a small
   misplacement (a z-shift and tilts: the part rests on the fixture plane).

Any part kind (:class:`~roboisf.parts.Part`): axisymmetric parts keep the generatrix toolpath and
the (lap, angle) formed-surface field; every other part (pyramid, mesh, CAD) gets the sliced
toolpath (:mod:`roboisf.toolpath.slice`), the point field
:class:`~roboisf.virtual.formed.PointField` and scans sampled on its surface. Every study
declares the fixture registration (:func:`roboisf.scan.register`, any part).

The controller logs the *commanded* joint angles (motor encoders do not see the elastic joint
deflection), so the joint log is IK of the toolpath.

By default the cell *is* the model the study describes (everything above with the nominal robot),
so an analysis agrees with ``truth/`` by construction. :attr:`VirtualCell.truth`
(:class:`~roboisf.virtual.truth.TruthSpec`, ``--truth`` / ``--scenario``) makes it differ: a
softer robot, bending links (:mod:`roboisf.virtual.links`), a kinematic error or drift, a biased
and cross-talking flange sensor carrying the tool's weight, a misregistered robot scan,
springback coupled to the machine's deflection, a compliant CNC — while ``study.toml`` still
carries the nominal model.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import tomli_w
from numpy.typing import NDArray

from roboisf.cam.toolpath_csv import write_toolpath_csv
from roboisf.cell import (
    DEFAULT_HOLDER,
    PAPER_CELL_PLACEMENT,
    SENSOR_STACK,
    Cell,
    ForceModel,
    at_ball_centre,
    make_cell,
    tip_compliances,
    tip_wrench,
)
from roboisf.errors import InputError
from roboisf.fem import ComplianceResult, save_compliance_json
from roboisf.frames import (
    invert,
    make_transform,
    rpy_to_matrix,
    transform_wrench,
    vertical_tool,
)
from roboisf.frames.pose import format_pose
from roboisf.io.atomic import atomic_path, atomic_write, staged_directory
from roboisf.logs.forcelog import ForceLog, write_force_log
from roboisf.logs.jointlog import write_joint_log
from roboisf.logs.thickness import write_thickness_csv
from roboisf.parts import (
    VWACF,
    AxisymmetricPart,
    Cone,
    MeshPart,
    Part,
    ProfilePart,
    Pyramid,
    sine_law_thickness,
)
from roboisf.progress import Progress, task
from roboisf.robot import RobotModel, ik_toolpath, load_robot
from roboisf.robot.kinematics import chain_from_opw
from roboisf.scan import default_rim_band, synthetic_scan, write_ply
from roboisf.study.spec import ForceSensorSpec
from roboisf.toolpath import Toolpath
from roboisf.virtual.equipment import Equipment, apply_equipment
from roboisf.virtual.formed import NormalField, PointField
from roboisf.virtual.springback import SpringbackModel
from roboisf.virtual.truth import TruthSpec

__all__ = [
    "DEFAULT_HOLDER",
    "PAPER_CELL_PLACEMENT",
    "PAPER_TABLE5",
    "SENSOR_STACK",
    "CellTruth",
    "VirtualCell",
    "build_study",
    "cell_toolpath",
    "paper_cone_cell",
    "paper_scenario_cell",
    "paper_vwacf_cell",
    "part_cell",
    "pyramid_cell",
    "quantize_wrench",
    "sensor_wrench",
    "simulate",
    "virtual_cell",
]

F64 = NDArray[np.float64]
#: m/s² — standard gravity (the tool's weight on the flange sensor)
STANDARD_GRAVITY = 9.80665

#: Keyword arguments of :func:`virtual_cell` that describe the physical cell (:func:`make_cell`);
#: the others are the synthetic experiment's settings (:class:`VirtualCell` fields).
CELL_KEYS = (
    "tool",
    "holder",
    "compliance_method",
    "robot",
    "joint_stiffness",
    "T_base_work",
    "tool_rotation",
    "force",
)


@dataclass(frozen=True, eq=False)
class VirtualCell:
    """A synthetic experiment: the physical :class:`~roboisf.cell.Cell` (part, tool, holder,
    robot, placement, force model) and how it is formed and measured (SI).

    Build one with :func:`virtual_cell`; the two paper studies are :func:`paper_cone_cell` and
    :func:`paper_vwacf_cell`. ``step_down``, ``spacing`` and ``max_wall_step`` [m] make the nominal
    toolpath; the rest models the process (robot force deficit, springback) and the measurement
    (log rates [Hz], force-sensor resolution [N, N·m], scan density, noise [m], holes, misplacement
    [m, rad], sensor poses, gauged thickness, seed).
    """

    name: str
    cell: Cell
    step_down: float = 0.5e-3
    spacing: float = 1e-3
    max_wall_step: float | None = None
    robot_force_deficit: float = 0.06
    springback: SpringbackModel = field(default_factory=SpringbackModel)
    force_rate: float = 1000.0  # Hz
    #: (force [N], moment [N·m]) — the force sensors' resolution: logged wrenches are rounded
    #: to multiples of it, as an F/T sensor's converter counts do (1/16 N and 1/1024 N·m, the
    #: step of a 16-bit converter over about ±2 kN and ±32 N·m; 1/32 of the simulated noise's
    #: σ, so the analysis does not see it). Powers of two are exact in the float32 Parquet
    #: columns and let them compress (~2× smaller logs); 0 keeps the continuous value.
    force_resolution: tuple[float, float] = (2.0**-4, 2.0**-10)
    joint_rate: float = 250.0  # Hz
    scan_points: int = 2_000_000
    scan_noise: float = 25e-6
    outlier_fraction: float = 0.01
    n_holes: int = 2
    hole_radius: float = 2.5e-3
    misplacement: tuple[float, float, float] = (0.4e-3, math.radians(0.15), math.radians(-0.1))
    fixture_sensor_pose: F64 = field(
        default_factory=lambda: make_transform(
            rpy_to_matrix([0.0, 0.0, math.radians(90)]), [0.0, 0.0, -0.060]
        )
    )
    #: measured thinning near the rim, as a fraction of the sine-law thickness at the sheet
    #: plane, decaying over ``rim_thinning_depth`` (the paper's cone: 1.22 → 0.25 mm at the rim,
    #: stable 0.4 mm below 20 mm: 0.375 over 8 mm); 0 for a gradual wall (VWACF)
    rim_thinning: float = 0.375
    rim_thinning_depth: float = 8e-3
    seed: int = 0
    #: how the simulated cell differs from the model written into study.toml (default: it is
    #: the model; :mod:`roboisf.virtual.truth`)
    truth: TruthSpec = field(default_factory=TruthSpec)

    def __post_init__(self) -> None:
        if not isinstance(self.cell, Cell):
            raise InputError(f"expected a Cell, got {type(self.cell).__name__}", field="cell")
        if self.cell.force is None:
            raise InputError("the virtual cell needs a force model", field="cell.force")
        for name in ("force_rate", "joint_rate"):
            if not getattr(self, name) > 0:
                raise InputError("must be > 0 Hz", field=name)
        if len(self.force_resolution) != 2 or not all(
            math.isfinite(r) and r >= 0 for r in self.force_resolution
        ):
            raise InputError(
                f"expected (force N, moment N·m) ≥ 0, got {self.force_resolution!r}",
                field="force_resolution",
            )
        if self.scan_points < 1000:
            raise InputError("need at least 1000 scan points", field="scan_points")
        if not 0 <= self.robot_force_deficit < 1:
            raise InputError("must be in [0, 1)", field="robot_force_deficit")
        if not isinstance(self.truth, TruthSpec):
            raise InputError(
                f"expected a TruthSpec, got {type(self.truth).__name__}", field="truth"
            )

    @property
    def part(self) -> Part:
        return self.cell.part

    @property
    def force(self) -> ForceModel:
        assert self.cell.force is not None
        return self.cell.force

    @property
    def tool_rotation(self) -> float:
        return self.cell.tool_rotation

    @property
    def T_flange_tip(self) -> F64:
        """(4, 4) m — the tool tip in the flange frame (the cell robot's tool)."""
        return self.cell.T_flange_tip

    @property
    def path_settings(self) -> dict[str, Any]:
        """The nominal toolpath's settings as :meth:`roboisf.cell.Cell.toolpath` and
        :func:`roboisf.plan.problem_from_cell` take them (``step``, ``spacing``,
        ``max_wall_step``; m)."""
        return {
            "step": self.step_down,
            "spacing": self.spacing,
            "max_wall_step": self.max_wall_step,
        }

    @property
    def T_tip_sensor(self) -> F64:
        """The flange F/T sensor, mid-stack, turned 30° about the tool axis (tip frame)."""
        z = -(self.T_flange_tip[2, 3] - SENSOR_STACK / 2)
        return make_transform(rpy_to_matrix([0.0, 0.0, math.radians(30)]), [0.0, 0.0, z])


def virtual_cell(name: str, part: Part, **settings: Any) -> VirtualCell:
    """A virtual cell for ``part``: the keys of :data:`CELL_KEYS` build the physical cell
    (:func:`roboisf.cell.make_cell`; ``force`` defaults to :class:`ForceModel`), the others are
    :class:`VirtualCell` settings."""
    cell_kw = {k: settings.pop(k) for k in CELL_KEYS if k in settings}
    cell_kw.setdefault("force", ForceModel())
    return VirtualCell(name, make_cell(part, **cell_kw), **settings)


def paper_cone_cell(**overrides: Any) -> VirtualCell:
    """The paper's cone: Ø87 mm, 71°, 102.97 mm deep, AA1050 1.22 mm, Ø10 ball, IRB 7600."""
    return virtual_cell("cone-71", Cone(), **{"T_base_work": PAPER_CELL_PLACEMENT, **overrides})


def paper_vwacf_cell(**overrides: Any) -> VirtualCell:
    """The paper's VWACF: Ø88.15 mm, 0 → 90° (39 mm arc), fracture at 78°, force peak 475 N."""
    settings: dict[str, Any] = {
        "T_base_work": PAPER_CELL_PLACEMENT,
        "max_wall_step": 0.5e-3,
        "force": ForceModel(mode="variable"),
        "springback": SpringbackModel(amplitude=0.96e-3),
        "rim_thinning": 0.0,
    }
    return virtual_cell("vwacf", VWACF(), **{**settings, **overrides})


#: The paper's Table 5 (Bharti et al. 2024): robot-compliance share [%] and springback R_m [mm]
#: that the ``paper`` scenario reproduces (docs/virtual-cell.md, "The paper scenario").
PAPER_TABLE5: dict[str, dict[str, float]] = {
    "cone": {
        "robot_share_percent": 40.28,
        "springback_R_m_mm": 1.132,
        # Δ = mean|δ_exp| − mean|δ_VJM| per axis (mm), the paper's VJM-vs-experiment comparison
        "delta_x_mm": 0.311,
        "delta_y_mm": 0.5,
        "delta_z_mm": -0.840,
    },
    "vwacf": {
        "robot_share_percent": 59.98,
        "springback_R_m_mm": 0.530,
        "delta_x_mm": 0.36,
        "delta_y_mm": 0.4,
        "delta_z_mm": -0.6,
    },
}


def paper_scenario_cell(part: str, **overrides: Any) -> VirtualCell:
    """The paper's cone or VWACF (``part`` = ``"cone"`` / ``"vwacf"``) with the ``paper``
    scenario's truth (:mod:`roboisf.virtual.truth`, package data ``scenarios/paper_*.toml``):
    the cell whose analysis reproduces the paper's Table 5. ``truth=`` in ``overrides`` wins."""
    from roboisf.virtual.builtin import BUILTIN_CELLS, paper_scenario_names
    from roboisf.virtual.truth import load_truth

    names = paper_scenario_names()
    if part not in names:
        expected = " or ".join(repr(n) for n in names)
        raise InputError(f"expected {expected}, got {part!r}", field="part")
    settings = {"truth": load_truth(scenario="paper", part=part), **overrides}
    return BUILTIN_CELLS[part].make(**settings)


#: The built-in pyramid of ``roboisf virtual-cell pyramid``: the common ISF benchmark's size, a
#: square 100 × 100 mm opening, 60° walls, 40 mm deep, 10 mm corner radius (shrinking with the
#: wall), 10 mm flange, 1.22 mm AA1050 (the paper's sheet). A choice, not data from the paper.
PYRAMID = Pyramid(100e-3, 100e-3, math.radians(60.0), 40e-3, corner_radius=10e-3)


def part_cell(name: str, part: Part, **overrides: Any) -> VirtualCell:
    """The paper-like cell (Ø10 ball, IRB 7600 at :data:`PAPER_CELL_PLACEMENT`, Aerens force,
    the cone's springback model) around any ``part`` — a part file's
    (``roboisf virtual-cell --part``, ``compensate --virtual PART.toml``)."""
    return virtual_cell(name, part, **{"T_base_work": PAPER_CELL_PLACEMENT, **overrides})


def pyramid_cell(part: Pyramid = PYRAMID, **overrides: Any) -> VirtualCell:
    """:func:`part_cell` around a pyramid (default :data:`PYRAMID`)."""
    return part_cell("pyramid", part, **overrides)


@dataclass(frozen=True)
class CellTruth:
    """Everything the cell knows, per toolpath point (work frame, SI)."""

    toolpath: Toolpath
    wrench_cnc: F64
    wrench_robot: F64
    q: F64
    tool_cnc: F64
    tool_robot: F64
    holder_robot: F64
    robot: F64
    springback: F64
    dn_cnc: F64
    dn_robot: F64
    tool_compliance: ComplianceResult
    holder_compliance: ComplianceResult | None
    T_base_work: F64
    fracture_depth: float
    #: (N, 3) m — commanded tip − nominal tip (zeros for the nominal command)
    command_offset: F64 | None = None
    #: (N, 3) m — the true robot's geometric error and thermal drift at the tip (truth file)
    robot_kinematic: F64 | None = None
    #: (N,) m — the robot run's springback (differs from ``springback`` with a deflection
    #: coupling; None: the same)
    springback_robot: F64 | None = None
    #: (N, 3) m — the CNC's own deflection (truth file; None: rigid)
    cnc_machine: F64 | None = None


def cell_toolpath(cell: VirtualCell) -> Toolpath:
    """The nominal toolpath the cell forms (step-down; cut 1 mm past a fracture)."""
    tp = cell.cell.toolpath(**cell.path_settings)
    frac = cell.force.fracture_depth(tp)
    if math.isfinite(frac):
        # forming stops shortly after the sheet fractures: keep the laps up to 1 mm past it
        last = (
            int(tp.lap[np.argmax(tp.depth >= frac + 1e-3)])
            if np.any(tp.depth >= frac + 1e-3)
            else tp.n_laps
        )
        keep = tp.lap <= last
        tp = Toolpath.from_contact(
            tp.contact[keep],
            tp.normal[keep],
            tp.wall_angle[keep],
            tp.lap[keep],
            tp.tool_radius,
            tp.feed,
            {**tp.meta, "fracture_depth": frac},
        )
    return tp


def _contour_curvature(tp: Toolpath) -> F64:
    from roboisf.toolpath.geometry import contour_curvature

    return contour_curvature(tp.contact, tp.normal, tp.lap)


def simulate(
    cell: VirtualCell,
    *,
    commanded: Toolpath | None = None,
    progress: Progress | None = None,
) -> CellTruth:
    """Run the virtual experiments (no files): forces, deflections, springback, formed surface.

    ``commanded`` — a commanded (e.g. compensated) version of the cell's toolpath: the same
    contact points, another ``tip``. The robot run then forms with it::

        dn_robot = n · (C_cmd − C_nominal) + n · δ(at the commanded configuration) + s

    Model assumptions: the forming wrench and the springback ``s`` are those of the nominal path
    (a command a millimetre off does not change the force or the springback — displacement
    adjustment iterates on exactly this assumption); the CNC run keeps the nominal path.
    """
    part = cell.part
    tp = cell_toolpath(cell)
    frac = float(tp.meta.get("fracture_depth", math.inf))  # type: ignore[arg-type]
    sb = replace(cell.springback, fracture_depth=frac) if math.isfinite(frac) else cell.springback
    if cell.truth.springback_amplitude is not None:
        sb = replace(sb, amplitude=cell.truth.springback_amplitude)
    # the wrench of the nominal path: the moment arm is contact − tip of the ball as it touches
    W = tip_wrench(tp, cell.force, thickness=part.sheet_thickness, step_down=cell.step_down)
    W_rob = W * (1.0 - cell.robot_force_deficit * np.exp(-tp.depth / 15e-3))[:, None]
    cmd_offset = np.zeros_like(tp.tip)
    if commanded is not None:
        if len(commanded) != len(tp) or np.max(np.abs(commanded.contact - tp.contact)) > 1e-9:
            raise InputError(
                f"the commanded toolpath ({len(commanded)} points) is not a version of the "
                f"cell's toolpath ({len(tp)} points, same contact points expected)",
                field="commanded",
            )
        cmd_offset = commanded.tip - tp.tip
        tp = tp.with_tip(commanded.tip)

    with task(progress, "tool and holder compliance"):
        k_tool, k_holder, k_t, k_th = tip_compliances(cell.cell, progress=progress)
    # every deflection at the ball centre, the point whose normal motion forms the part
    R_ball = cell.cell.tool.radius
    tool_cnc = at_ball_centre(W @ k_t.T, R_ball)
    tool_rob = at_ball_centre(W_rob @ k_t.T, R_ball)
    holder_rob = at_ball_centre(W_rob @ k_th.T, R_ball)

    truth = cell.truth
    with task(progress, "robot IK and VJM"):
        model, T_bw = cell.cell.robot, cell.cell.T_base_work
        ik = ik_toolpath(model, tp.tip, T_bw, tool_rotation=cell.tool_rotation)
        robot = true_robot_deflection(model, truth, ik.q, W_rob, T_bw, R_ball)
        kin = true_robot_kinematic_error(model, truth, ik.q, T_bw, tp.time)

    # the CNC: rigid unless the truth gives it a translational compliance
    cnc = W[:, :3] * truth.cnc_compliance[None, :]
    n = tp.normal
    if truth.springback_curvature_gain:  # the geometry rule (docs/virtual-cell.md)
        sb = replace(sb, curvature_gain=truth.springback_curvature_gain)
        sb = replace(sb, curvature_length=truth.springback_curvature_length)
    s = sb.normal(tp.depth, tp.wall_angle, _contour_curvature(tp) if sb.curvature_gain else None)
    # springback that depends on the machine's own deflection: the sheet recovers a fraction c
    # of the machine's normal deflection (docs/virtual-cell.md, "Truth beyond the model")
    c = truth.coupling_at(tp.depth)
    s_cnc = s - c * np.einsum("ij,ij->i", cnc, n)
    s_rob = s - c * np.einsum("ij,ij->i", robot, n)
    dn_cnc = np.einsum("ij,ij->i", tool_cnc + cnc, n) + s_cnc
    dn_rob = np.einsum("ij,ij->i", tool_rob + holder_rob + robot + kin + cmd_offset, n) + s_rob
    return CellTruth(
        tp,
        W,
        W_rob,
        ik.q,
        tool_cnc,
        tool_rob,
        holder_rob,
        robot,
        s_cnc,
        dn_cnc,
        dn_rob,
        k_tool,
        k_holder,
        T_bw,
        frac,
        cmd_offset,
        kin,
        s_rob,
        cnc,
    )


def true_robot_deflection(
    model: RobotModel,
    truth: TruthSpec,
    q: F64,
    W: F64,
    T_base_work: F64,
    ball_radius: float = 0.0,
) -> F64:
    """The true robot's elastic deflection (N, 3) m of the ball centre (``ball_radius`` above
    the tip; 0: the tip), work axes, for tip wrenches ``W`` (N, 6) [N, N·m] in work axes at
    configurations ``q`` (N, 6) rad: the VJM with the truth's joint stiffness
    (``joint_stiffness_scale`` × the model's), plus the links' bending when
    ``truth.link_compliance``."""
    true_model = model
    if np.any(truth.joint_stiffness_scale != 1):
        true_model = model.with_stiffness(
            model.joint_stiffness * truth.joint_stiffness_scale, source="truth"
        )
    d = true_model.deflection(q, W, T_base_work=T_base_work)
    if truth.link_compliance:
        from roboisf.virtual.links import link_deflection

        if not model.name.startswith("irb7600"):
            raise InputError(
                f"link sections are estimated for the IRB 7600 only, not {model.name!r}; "
                "leave link_compliance off for this robot",
                field="robot.link_compliance",
            )
        d = d + link_deflection(model, q, W, T_base_work)
    return at_ball_centre(d, ball_radius)


def true_robot_kinematic_error(
    model: RobotModel, truth: TruthSpec, q: F64, T_base_work: F64, time: F64
) -> F64:
    """Where the true robot's tip is minus where the model puts it (N, 3) m, work axes, at the
    commanded angles ``q`` (N, 6) rad: the geometric error (joint zero offsets, OPW parameter
    errors, a mis-taught work object) and a thermal drift growing linearly with ``time`` (N,) s
    over the run."""
    out = np.zeros((q.shape[0], 3))
    if truth.kinematic_error:
        true_model = model
        if truth.opw_error:
            if model.opw is None:
                raise InputError(
                    f"OPW parameter errors need an OPW robot; {model.name!r} has a general chain",
                    field="robot.kinematic_error",
                )
            geo = replace(
                model.opw,
                **{k: getattr(model.opw, k) + v for k, v in truth.opw_error.items()},
            )
            true_model = replace(
                model, opw=geo, chain=chain_from_opw(geo, model.chain.sign, model.chain.offset)
            )
        q_true = q + truth.joint_offset * model.chain.sign  # θ = sign·q + offset
        T_true = true_model.fk(q_true, check_limits=False, T_base_work=T_base_work)
        T_nom = model.fk(q, check_limits=False, T_base_work=T_base_work)
        out += T_true[:, :3, 3] - T_nom[:, :3, 3]
        if np.any(truth.work_object_error):
            # the robot forms in the taught frame T_err of the blank's true frame: the tip the
            # program puts at p lands at R p + t (rotations about the work origin)
            e = truth.work_object_error
            tip = T_nom[:, :3, 3]
            out += tip @ rpy_to_matrix(e[3:]).T + e[:3] - tip
    if np.any(truth.thermal_drift) and len(time):
        span = max(float(time[-1] - time[0]), 1e-12)
        out += ((time - time[0]) / span)[:, None] * truth.thermal_drift[None, :]
    return out


def _thickness(cell: VirtualCell, tp: Toolpath, path: Path, rng: np.random.Generator) -> None:
    """A gauged thickness profile: sine law with near-rim thinning, 10 µm gauge noise, every mm."""
    depth = np.arange(1e-3, tp.depth.max(), 1e-3)
    angle = np.interp(depth, tp.depth[np.argsort(tp.depth)], tp.wall_angle[np.argsort(tp.depth)])
    t = sine_law_thickness(angle, cell.part.sheet_thickness) * (
        1 - cell.rim_thinning * np.exp(-depth / cell.rim_thinning_depth)
    )
    write_thickness_csv(path, depth, t + rng.normal(scale=10e-6, size=depth.size))


def _log_times(tp: Toolpath, rate: float) -> F64:
    """Sample times at ``rate`` [Hz] covering the whole toolpath: one sample past its end, as a
    logger that is stopped after the program finishes."""
    n = math.ceil(tp.time[-1] * rate) + 2
    return np.arange(n) / rate


#: Samples of a synthesised force log computed at a time (:func:`_force_log`): the interpolated
#: wrench and tips, the sensor's frame change and the noise are a few MB per block instead of
#: ≈ 0.5 GB of temporaries for a 1 kHz paper log — fresh memory, which on a virtual machine costs
#: about as much as the arithmetic (docs/analyze.md).
_LOG_BLOCK = 1 << 17


def _force_log(
    cell: VirtualCell,
    tp: Toolpath,
    W_tip: F64,
    sensor: ForceSensorSpec,
    rng: np.random.Generator,
    truth: TruthSpec | None = None,
) -> ForceLog:
    """The log ``sensor`` writes along ``tp``: the tip wrenches ``W_tip`` (N_tp, 6) interpolated
    at the log's rate, in the sensor's frame, with noise (the force noise of every sample drawn
    first, then the moments': the generator's stream as one draw of each), through the truth's
    calibration and the tool's weight, rounded to the sensor's counts. Row blocks of
    :data:`_LOG_BLOCK` samples, the same numbers as whole arrays.

    The knots' slopes are computed once per log (:class:`_Knots`), the frame change writes into
    the log's columns, and the noise is drawn as standard normals into one reused block, scaled
    in place and added channel by channel (contiguous columns): ``normal(scale=σ)`` is
    ``0 + σ·z`` of the same ``z`` stream, the same numbers."""
    t = _log_times(tp, cell.force_rate)
    n = t.size
    R = vertical_tool(cell.tool_rotation)
    W_s = np.empty((6, n)).T  # each channel contiguous, as the log's columns are written
    blocks = [(a, min(a + _LOG_BLOCK, n)) for a in range(0, n, _LOG_BLOCK)]
    wrench_knots, tip_knots = _Knots(tp.time, W_tip), _Knots(tp.time, tp.tip)
    frame = _SensorFrame(sensor, R)

    def tips(a: int, b: int, where: _Intervals | None = None) -> F64:
        return tip_knots.at(t[a:b], where)

    for a, b in blocks:
        where = _intervals(t[a:b], tp.time)  # searched once for the wrench and the tips
        frame.apply(wrench_knots.at(t[a:b], where), tips(a, b, where), out=W_s[a:b])
    noise = cell.force.noise
    z = np.empty((min(_LOG_BLOCK, n), 3))
    for cols, scale in ((range(3), noise), (range(3, 6), noise * 5e-3)):  # ~5 mm lever
        for a, b in blocks:
            zb = z[: b - a]
            rng.standard_normal(out=zb)
            np.multiply(zb, scale, out=zb)
            for k, c in enumerate(cols):
                W_s[a:b, c] += zb[:, k]
    if truth is not None and not truth.sensor_ideal:
        # the transducer's noise passes through the same calibration as the load
        for a, b in blocks:
            weight = (
                tool_weight_at_sensor(cell, truth, sensor, tips(a, b), R)
                if truth.tool_mass
                else None
            )
            W_s[a:b] = sensor_reading(truth, W_s[a:b], weight)
    return ForceLog(t, quantize_wrench(W_s, cell.force_resolution), "sensor")


#: where each query time falls among the knots: (interval j, t − time[j], before, after)
_Intervals = tuple[NDArray[np.intp], F64, NDArray[np.bool_], NDArray[np.bool_]]


def _intervals(t: F64, time: F64) -> _Intervals:
    """The knot interval of each query time ``t`` (M,) in ``time`` (N,) (non-decreasing):
    ``j = searchsorted(time, t, side="right") − 1`` clipped to ``0 … N − 2``, ``t − time[j]``
    and whether ``t`` lies before the first or at/after the last knot.

    For increasing ``t`` (a log's clock) the same ``j`` by counting: the N knots are searched
    among the M times (N ≪ M: a toolpath's 35 k points against 1.5 M log samples) and each
    time's count of knots at or before it is a running sum — the same integers without M
    binary searches."""
    n = time.size
    if t.size > 1 and n < t.size and bool(np.all(t[1:] > t[:-1])):
        # knots ≤ t[i]  ⇔  knots whose count of times below them is ≤ i (t strictly increasing)
        below = np.searchsorted(t, time, side="left")
        j = np.cumsum(np.bincount(below, minlength=t.size + 1)[: t.size]) - 1
    else:
        j = np.searchsorted(time, t, side="right") - 1
    before, after = j < 0, j >= n - 1
    np.clip(j, 0, max(n - 2, 0), out=j)
    return j, t - time[j], before, after


class _Knots:
    """Columns of ``values`` (N, k) at the knots ``time`` (N,) (increasing), with each column's
    interval slopes computed once: :meth:`at` interpolates any number of query blocks."""

    def __init__(self, time: F64, values: F64) -> None:
        self.n = time.size
        self.cols = [np.ascontiguousarray(values[:, c]) for c in range(values.shape[1])]
        self.slopes: list[F64] = []
        if self.n > 1:
            dtime = np.diff(time)
            with np.errstate(divide="ignore", invalid="ignore"):  # a repeated time: an interval
                # no query falls in (searchsorted skips it)
                self.slopes = [np.diff(v) / dtime for v in self.cols]
        self.time = time

    def at(self, t: F64, where: _Intervals | None = None) -> F64:
        """(M, k) column-major: ``np.interp``'s numbers (its formula ``slope·(t − tⱼ) + vⱼ``,
        the same operations in the same order), constant beyond the knots' ends."""
        j, dt, before, after = _intervals(t, self.time) if where is None else where
        out = np.empty((len(self.cols), t.size))
        if self.n == 1:
            for c, v in enumerate(self.cols):
                out[c] = v[0]
            return out.T
        # the few samples beyond the knots (a prefix and a suffix for a log's clock): found
        # once for every column
        i_before, i_after = np.flatnonzero(before), np.flatnonzero(after)
        vj = np.empty(t.size)
        for c, (v, slope) in enumerate(zip(self.cols, self.slopes, strict=True)):
            o = out[c]
            np.take(slope, j, out=o)
            o *= dt
            o += np.take(v, j, out=vj)
            o[i_before] = v[0]
            o[i_after] = v[-1]
        return out.T


def _interp_columns(t: F64, time: F64, values: F64, where: _Intervals | None = None) -> F64:
    """Each column of ``values`` (N, k) at the times ``t`` (M,) → (M, k), linear in ``time``
    (increasing), constant beyond its ends; column-major (each channel contiguous, as the log's
    columns are written). ``np.interp``'s numbers (its formula ``slope·(t − tⱼ) + vⱼ``, the
    same operations in the same order) with the interval of each time found once for all
    columns (:func:`_intervals`; ``where``: found already, for the same ``t`` and ``time``)
    instead of once per column (9 binary searches of 1.5 M log times on the paper cone)."""
    return _Knots(time, values).at(t, where)


def _times_matrix(W: F64, A: F64, out: F64 | None = None) -> F64:
    """``W @ A`` for a long (M, 6) ``W`` and a (6, 6) ``A``, computed as ``(Aᵀ Wᵀ)ᵀ``: BLAS is
    several times faster on the wide (6, M) product than on the tall one. ``out`` (M, 6): written
    there (a block of a column-major log: the same product, without the copy)."""
    if out is not None:
        np.matmul(A.T, W.T, out=out.T)
        return out
    return np.asarray((A.T @ W.T).T, dtype=float)


class _SensorFrame:
    """:func:`sensor_wrench` for one sensor and tool orientation, its (6, 6) frame change made
    once for every block of a log."""

    def __init__(self, sensor: ForceSensorSpec, R_work_tip: F64) -> None:
        sign = -1.0 if sensor.load_on == "workpiece" else 1.0
        A = transform_wrench(np.eye(6), invert(sensor.pose))  # row i: the image of e_i
        self.fixture = sensor.mount == "fixture"
        if not self.fixture:
            R = np.asarray(R_work_tip, dtype=float)
            A = transform_wrench(np.eye(6), make_transform(R.T)) @ A
        self.A = sign * A

    def apply(self, W: F64, tip_work: F64, out: F64 | None = None) -> F64:
        """What the sensor reads for tip wrenches ``W`` (M, 6) at tips ``tip_work`` (M, 3);
        overwrites ``W``; into ``out`` (M, 6) when given."""
        if self.fixture:
            # moments about the work origin: m += tip × f
            r, f = tip_work, W[:, :3]
            W[:, 3] += r[:, 1] * f[:, 2] - r[:, 2] * f[:, 1]
            W[:, 4] += r[:, 2] * f[:, 0] - r[:, 0] * f[:, 2]
            W[:, 5] += r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]
        return _times_matrix(W, self.A, out)


def sensor_wrench(W_tip: F64, sensor: ForceSensorSpec, tip_work: F64, R_work_tip: F64) -> F64:
    """What ``sensor`` reads (M, 6) [N, N·m] for tip wrenches ``W_tip`` (M, 6) in work axes at
    tips ``tip_work`` (M, 3) m with one tool orientation ``R_work_tip`` (3, 3):
    :func:`roboisf.study.sensors.tip_to_sensor` for a whole log — the frame change is one
    constant (6, 6) product, the fixture sensor's moment about the work origin is added in
    place. Overwrites ``W_tip``; the same numbers as ``tip_to_sensor`` to rounding."""
    return _SensorFrame(sensor, R_work_tip).apply(W_tip, tip_work)


def quantize_wrench(W: F64, resolution: tuple[float, float]) -> F64:
    """``W`` (M, 6) [N, N·m] rounded to multiples of ``resolution`` = (force step [N], moment
    step [N·m]) — a sensor's counts; a step of 0 leaves those columns continuous. Rounds in place
    and returns ``W``.

    With both steps set, each operation runs once over the whole array with a per-column step
    (the same operation on every number; ~3.5× faster on a row-major log than on its two
    strided halves)."""
    if resolution[0] > 0 and resolution[1] > 0 and W.ndim == 2 and W.shape[1] == 6:
        steps = np.repeat(np.asarray(resolution, dtype=float), 3)  # (f, f, f, m, m, m)
        np.divide(W, steps, out=W)
        np.rint(W, out=W)  # half to even, as np.round
        np.multiply(W, steps, out=W)
        return W
    for cols, step in ((slice(0, 3), resolution[0]), (slice(3, 6), resolution[1])):
        if step > 0:
            block = W[:, cols]
            np.divide(block, step, out=block)
            np.rint(block, out=block)  # half to even, as np.round
            np.multiply(block, step, out=block)
    return W


def tool_weight_at_sensor(
    cell: VirtualCell, truth: TruthSpec, sensor: ForceSensorSpec, tip: F64, R_work_tip: F64
) -> F64:
    """The tool's weight as the flange sensor sees it (M, 6) [N, N·m], sensor axes, at tip
    positions ``tip`` (M, 3) m with the tool orientation ``R_work_tip`` (3, 3): the force
    ``m·g`` along −z of the work frame (the work frame's z is up, as the blank lies) acting at
    the centre of gravity ``truth.tool_cog`` (flange frame). Zeros when ``tool_mass`` is 0."""
    if truth.tool_mass == 0:
        return np.zeros((len(tip), 6))
    T_tip_flange = np.linalg.inv(cell.T_flange_tip)
    cog_tip = T_tip_flange[:3, :3] @ truth.tool_cog + T_tip_flange[:3, 3]
    r = R_work_tip @ cog_tip  # tip → cog, work axes
    f = np.array([0.0, 0.0, -truth.tool_mass * STANDARD_GRAVITY])
    W = np.tile(np.concatenate([f, np.cross(r, f)]), (len(tip), 1))
    return sensor_wrench(W, sensor, np.asarray(tip, dtype=float), R_work_tip)


def sensor_reading(truth: TruthSpec, W_sensor: F64, weight: F64 | None = None) -> F64:
    """What the flange sensor logs (M, 6) for the true load ``W_sensor`` (M, 6) [N, N·m] in its
    axes: ``diag(gain) · (I + crosstalk) · (W + weight) + bias``."""
    W = W_sensor if weight is None else W_sensor + weight
    return _times_matrix(W, truth.sensor_matrix().T) + truth.sensor_bias[None, :]


def _scan(
    cell: VirtualCell,
    truth: CellTruth,
    dn: F64,
    path: Path,
    rng: np.random.Generator,
    seed: int,
    misregistration: F64 | None = None,
) -> None:
    part = cell.part
    tp = truth.toolpath
    # holes where the analysis looks: below the rim band (20 mm on the paper's parts)
    wall = tp.contact[tp.depth > default_rim_band(part.depth)]
    holes = [
        (wall[i], cell.hole_radius) for i in rng.choice(len(wall), size=cell.n_holes, replace=False)
    ]
    dz, tx, ty = cell.misplacement
    T_scan_work = make_transform(rpy_to_matrix([tx, ty, 0.0]), [0.0, 0.0, dz])
    if misregistration is not None:
        T_scan_work = T_scan_work @ misregistration
    common: dict[str, Any] = {
        "noise": cell.scan_noise,
        "outlier_fraction": cell.outlier_fraction,
        "holes": holes,
        "T_scan_work": T_scan_work,
        "seed": seed,
    }
    if isinstance(part, AxisymmetricPart):
        field_ = NormalField.from_toolpath(part, tp, dn)
        scan = synthetic_scan(part, cell.scan_points, offset=field_.offset(part), **common)
    else:
        scan = synthetic_scan(
            part, cell.scan_points, offset_at=PointField.from_toolpath(tp, dn), **common
        )
    write_ply(scan.points, path, unit="mm")


#: File formats of the virtual cell's force and joint logs (``build_study(log_format=...)``).
LOG_FORMATS = {"parquet": ".parquet", "csv": ".csv"}


def scan_misregistration(truth: TruthSpec) -> F64 | None:
    """(4, 4) — the robot scan's misregistration ``T = [R | shift]`` applied to the formed part
    in work coordinates before the scanner's misplacement (rotations about work x, y, z, in
    that order); None when the truth has none."""
    if not (np.any(truth.scan_shift) or np.any(truth.scan_rotation)):
        return None
    return make_transform(rpy_to_matrix(truth.scan_rotation), truth.scan_shift)


def build_study(
    cell: VirtualCell,
    out_dir: str | Path,
    *,
    progress: Progress | None = None,
    log_format: str = "parquet",
    equipment: Equipment | None = None,
    commanded: Toolpath | None = None,
    robot_toolpath: str | None = None,
    compensation: Path | None = None,
) -> Path:
    """Write the study folder for ``cell`` into ``out_dir`` (replaced atomically). Returns it.

    ``commanded`` — the robot run formed with this commanded version of the cell's toolpath
    (:func:`simulate`; e.g. an online loop's corrected path): its joint log holds the commanded
    joints and its scan the part so formed; ``toolpath.csv`` keeps the nominal path (the program
    both runs follow; the correction is the controller's) and the truth gains the
    ``command_offset`` columns. With ``robot_toolpath`` (a file name) the commanded path is
    written there instead and is the robot run's toolpath — a compensated program, the robot's
    own (``roboisf virtual-cell --toolpath``); ``compensation`` (the ``per_point.csv`` of the
    ``roboisf compensate`` output that wrote it) is copied beside it as the run's
    ``compensation`` (:mod:`roboisf.virtual.reform`).

    ``log_format``: the force and joint logs as Parquet (default: SI, exact, ~4× smaller than
    the CSV; ``roboisf.logs.logparquet``) or as the roboisf CSV (``"csv"``).
    ``equipment`` (:mod:`roboisf.virtual.equipment`) rewrites the logs as real loggers keep
    time (clock drift, offset, pauses) and in their file layouts, and sets the runs' ``sync``;
    equipment logs are text files as the instruments write them, so they are CSV whatever
    ``log_format`` says."""
    out_dir = Path(out_dir)
    if log_format not in LOG_FORMATS:
        raise InputError(
            f"log format must be one of {', '.join(LOG_FORMATS)}, got {log_format!r}",
            field="log_format",
        )
    if equipment is not None and not equipment.is_clean:
        log_format = "csv"  # the equipment's layouts are instruments' text exports
    ext = LOG_FORMATS[log_format]
    rng = np.random.default_rng(cell.seed)
    truth = simulate(cell, progress=progress, commanded=commanded)
    tp = truth.toolpath if commanded is None else cell_toolpath(cell)
    # the robot's logs keep the time of the path it ran: its own program's, or the nominal's
    # when the correction is the controller's (an online loop)
    tp_rob = truth.toolpath if robot_toolpath is not None else tp
    cnc_sensor = ForceSensorSpec(
        Path(f"cnc_forces{ext}"), "fixture", cell.fixture_sensor_pose, "workpiece"
    )
    rob_sensor = ForceSensorSpec(Path(f"robot_forces{ext}"), "flange", cell.T_tip_sensor, "tool")
    with staged_directory(out_dir, "virtual-cell") as d:
        (d / "truth").mkdir()
        with task(progress, "toolpath and compliances"):
            write_toolpath_csv(
                tp, d / "toolpath.csv", generator=f"roboisf virtual-cell ({cell.name})"
            )
            run_files: dict[str, str] = {}
            if commanded is not None and robot_toolpath is not None:
                write_toolpath_csv(
                    truth.toolpath, d / robot_toolpath, generator=f"commanded ({cell.name})"
                )
                run_files["toolpath"] = robot_toolpath
                if compensation is not None:
                    run_files["compensation"] = f"{Path(robot_toolpath).stem}_compensation.csv"
                    shutil.copyfile(compensation, d / run_files["compensation"])
            save_compliance_json(truth.tool_compliance, d / "tool_compliance.json")
            if truth.holder_compliance is not None:
                save_compliance_json(truth.holder_compliance, d / "holder_compliance.json")
        with task(progress, "force logs"):
            write_force_log(
                _force_log(cell, tp, truth.wrench_cnc, cnc_sensor, rng), d / cnc_sensor.file
            )
            write_force_log(
                _force_log(cell, tp_rob, truth.wrench_robot, rob_sensor, rng, cell.truth),
                d / rob_sensor.file,
            )
        with task(progress, "joint log"):
            t = _log_times(tp_rob, cell.joint_rate)
            q = np.column_stack([np.interp(t, tp_rob.time, truth.q[:, j]) for j in range(6)])
            write_joint_log(d / f"robot_joints{ext}", t, q)
        with task(progress, "thickness"):
            _thickness(cell, tp, d / "robot_thickness.csv", rng)
        with task(progress, "scans"):
            _scan(cell, truth, truth.dn_cnc, d / "cnc_scan.ply", rng, cell.seed + 1)
            _scan(
                cell,
                truth,
                truth.dn_robot,
                d / "robot_scan.ply",
                rng,
                cell.seed + 2,
                scan_misregistration(cell.truth),
            )
        _write_study_toml(
            cell,
            truth,
            cnc_sensor,
            rob_sensor,
            d / "study.toml",
            joints=f"robot_joints{ext}",
            robot_files=run_files,
        )
        if equipment is not None:
            with task(progress, "equipment logs"):
                apply_equipment(equipment, cell, truth, d, cnc_sensor, rob_sensor)
        _write_truth(cell, truth, d / "truth")
    return out_dir


#: The mesh of a mesh part, copied into the study folder (binary PLY, float64, metres).
PART_MESH = "part_mesh.ply"


def _part_table(part: Part, folder: Path) -> dict[str, object]:
    """The study's ``[part]`` table; a mesh part's mesh is written into the study folder
    (:data:`PART_MESH`, exact float64 vertices in m, faces as oriented) and a profile part's
    generatrix into the table, so the study stands alone whatever file the part came from."""
    if not isinstance(part, MeshPart):
        if isinstance(part, ProfilePart) and part.source is not None:
            # the generatrix written inline (r, z in mm), not the CSV path the part file named:
            # relative to the part file's folder, it was not in the study, which analyze refused
            from dataclasses import replace

            return replace(part, source=None).to_dict()
        return part.to_dict()
    V = np.ascontiguousarray(part.vertices, dtype="<f8")
    F = np.ascontiguousarray(part.faces, dtype="<i4")
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment roboisf virtual-cell: the part's mesh, m\n"
        f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
        f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    rows = np.empty(len(F), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    rows["n"], rows["v"] = 3, F
    with atomic_write(folder / PART_MESH, "wb") as fh:
        fh.write(header.encode("ascii") + V.tobytes() + rows.tobytes())
    return {
        "kind": "mesh",
        "file": PART_MESH,
        "unit": "m",
        "orient": "winding",
        "sheet_thickness": part.sheet_thickness * 1e3,
    }


def _write_study_toml(
    cell: VirtualCell,
    truth: CellTruth,
    cnc: ForceSensorSpec,
    rob: ForceSensorSpec,
    path: Path,
    *,
    joints: str = "robot_joints.csv",
    robot_files: dict[str, str] | None = None,
) -> None:
    c = cell.cell
    robot: dict[str, Any] = {
        "model": c.robot_name,
        "placement": format_pose(c.T_base_work),
        "flange_to_tip": format_pose(c.T_flange_tip),
        "tool_rotation": math.degrees(c.tool_rotation),
    }
    if c.tip_link is not None:
        robot["tip_link"] = c.tip_link
    preset = load_robot(c.robot_name, tip_link=c.tip_link).stiffness
    K = c.robot.stiffness
    if K is not None and (preset is None or not np.array_equal(K, preset)):
        robot["joint_stiffness"] = [float(k) for k in K]
    data: dict[str, Any] = {
        "study": {
            "name": cell.name,
            "description": f"virtual cell: {cell.name} (roboisf virtual-cell)",
        },
        "units": {"length": "mm", "angle": "deg", "force": "N", "moment": "N*m", "time": "s"},
        "part": _part_table(c.part, path.parent),
        "tool": {
            "ball_diameter": c.tool.ball_diameter * 1e3,
            "compliance": "tool_compliance.json",
        },
        "tool_holder": {"rigid": True}
        if c.holder.rigid
        else {"compliance": "holder_compliance.json", "offset": c.holder.offset * 1e3},
        "robot": robot,
        "analysis": {
            "rim_band": default_rim_band(c.part.depth) * 1e3,  # 20 mm unless the part is shallow
            "registration": "fixture",  # z and tilts from the clamped flange, any part
            **_max_distance(truth),
        },
        "runs": {
            "cnc": {
                "machine": "cnc",
                "toolpath": "toolpath.csv",
                "scan": "cnc_scan.ply",
                "scan_unit": "mm",
                "forces": {
                    "file": str(cnc.file),
                    "mount": cnc.mount,
                    "pose": format_pose(cnc.pose),
                    "load_on": cnc.load_on,
                },
            },
            "robot": {
                "machine": "robot",
                "toolpath": "toolpath.csv",
                "joints": joints,
                "scan": "robot_scan.ply",
                "scan_unit": "mm",
                "thickness": "robot_thickness.csv",
                "forces": {
                    "file": str(rob.file),
                    "mount": rob.mount,
                    "pose": format_pose(rob.pose),
                    "load_on": rob.load_on,
                },
                **(robot_files or {}),
            },
        },
    }
    with atomic_write(path, "wb") as fh:
        fh.write(tomli_w.dumps(data).encode())


def _truth_extras(truth: CellTruth) -> list[tuple[str, F64]]:
    """The truth file's extra terms as per-point columns (only those present)."""
    n = truth.toolpath.normal
    out = []
    if truth.robot_kinematic is not None and np.any(truth.robot_kinematic):
        out.append(("robot_kinematic", truth.robot_kinematic))
    if truth.springback_robot is not None and np.any(truth.springback_robot != truth.springback):
        out.append(("springback_robot", truth.springback_robot[:, None] * n))
    if truth.cnc_machine is not None and np.any(truth.cnc_machine):
        out.append(("cnc_machine", truth.cnc_machine))
    if truth.command_offset is not None and np.any(truth.command_offset):
        out.append(("command_offset", truth.command_offset))
    return out


def _max_distance(truth: CellTruth) -> dict[str, float]:
    """``[analysis] max_distance`` when the formed part deviates more than the analysis's 3 mm
    default keeps (a paper-scale robot error on top of the springback): the largest normal
    deviation + 2 mm for noise and misplacement, in mm. A user whose part deviates that much sets
    it the same way (docs/study.md); below it the study keeps the default."""
    worst = float(max(np.max(np.abs(truth.dn_robot)), np.max(np.abs(truth.dn_cnc))))
    if worst <= 2.5e-3:
        return {}
    return {"max_distance": math.ceil((worst + 2e-3) * 1e3)}


def cell_settings(cell: VirtualCell) -> dict[str, Any]:
    """What makes the cell this cell (JSON values; mm, deg, Hz): recorded in
    ``truth/truth.json`` so that a re-formed run (:mod:`roboisf.virtual.reform`) can be checked
    to come from the same cell, truth and seed."""
    c = cell.cell
    settings = {
        "name": cell.name,
        "part": c.part.to_dict() if not isinstance(c.part, MeshPart) else "mesh",
        "robot": c.robot_name,
        "placement": format_pose(c.T_base_work),
        "flange_to_tip": format_pose(c.T_flange_tip),
        "tool_rotation_deg": math.degrees(c.tool_rotation),
        "step_down_mm": cell.step_down * 1e3,
        "spacing_mm": cell.spacing * 1e3,
        "seed": cell.seed,
        "scan_points": cell.scan_points,
        "force_rate_hz": cell.force_rate,
        "joint_rate_hz": cell.joint_rate,
        "truth": cell.truth.to_table(),
    }
    out: dict[str, Any] = json.loads(json.dumps(settings))
    return out


def _write_truth(cell: VirtualCell, truth: CellTruth, folder: Path) -> None:
    tp = truth.toolpath
    n = tp.normal
    cols: dict[str, Any] = {"index": np.arange(len(tp)), "lap": tp.lap}
    for name, v in (
        ("tool", truth.tool_robot),
        ("tool_cnc", truth.tool_cnc),
        ("tool_holder", truth.holder_robot),
        ("robot_compliance", truth.robot),
        ("springback", truth.springback[:, None] * n),
        *_truth_extras(truth),
    ):
        for j, ax in enumerate("xyz"):
            cols[f"{name}_d{ax}"] = v[:, j] * 1e3
        cols[f"{name}_dn"] = np.einsum("ij,ij->i", v, n) * 1e3
    cols["dn_cnc"] = truth.dn_cnc * 1e3
    cols["dn_robot"] = truth.dn_robot * 1e3
    df = pd.DataFrame(cols)
    with atomic_path(folder / "per_point.parquet") as tmp:
        df.to_parquet(tmp, index=False)
    meta = {
        "units": "mm",
        "cell": cell.name,
        "fracture_depth_mm": truth.fracture_depth * 1e3
        if math.isfinite(truth.fracture_depth)
        else None,
        "springback_model": {
            "amplitude_mm": (
                cell.springback.amplitude
                if cell.truth.springback_amplitude is None
                else cell.truth.springback_amplitude
            )
            * 1e3
        },
        "robot": cell.cell.robot_name,
        "cell_settings": cell_settings(cell),
        # how the cell differs from the model in study.toml (file units; all off: is_model)
        "truth": cell.truth.to_table(),
        # read by analyze: a VJM check on a cell whose truth is the model holds by construction
        "model_equals_truth": bool(cell.truth.is_model),
        "true_joint_stiffness": (
            cell.cell.robot.joint_stiffness * cell.truth.joint_stiffness_scale
        ).tolist()
        if cell.cell.robot.stiffness is not None
        else None,
    }
    with atomic_write(folder / "truth.json") as fh:
        json.dump(meta, fh, indent=2)
