"""``roboisf toolpath``: generate a forming toolpath and write it as CSV, G-code, RAPID or KRL.

Examples (mm and degrees)::

    roboisf toolpath cone --opening-diameter 87 --wall-angle 71 --depth 102.97 \\
        --step-down 0.5 --tool-diameter 10 -o cone.csv
    roboisf toolpath vwacf --opening-diameter 88.15 --arc-radius 40 -o vwacf.mod --spiral
    roboisf toolpath profile profile.csv -o part.src --tool 250 --placement 2200,0,200
    roboisf toolpath --part part.toml -o path.mod --placement study/ --tool study/
    roboisf toolpath --part part.toml -o path.nc          # any part: cone … pyramid, mesh
    roboisf toolpath --part pyramid.toml --scallop-height 0.01 -o path.csv

The format follows the ``-o`` suffix (.csv, .nc/.gcode, .mod, .src, .ls) unless ``--format`` is
given. A robot program (.mod, .src, .ls) needs the work-object placement and the tool: there is no
default robot-base frame (``--placement base`` says so explicitly).
"""

from __future__ import annotations

import inspect
import math
import typing
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import typer

from roboisf import parts  # lazy: the geometry loads when a command builds a part
from roboisf.cli.console import state
from roboisf.cli.lazy import FullHelpGroup
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.cli.part import (
    ArcRadius,
    ConeDiameter,
    Depth,
    FinalWallAngle,
    ProfileCsv,
    VwacfDiameter,
    WallAngle,
)
from roboisf.cli.robot import TipLink
from roboisf.errors import InputError
from roboisf.io.atomic import check_not_input
from roboisf.parts.defaults import VWACF_DEFAULT_ARC_RADIUS
from roboisf.toolpath.limits import MAX_POINTS

# numpy, the geometry and the writers are imported by the command that runs (fast --help)
if typing.TYPE_CHECKING:
    import numpy as np

    from roboisf.cam.program import RobotTool
    from roboisf.parts import AxisymmetricPart, Part
    from roboisf.path.toolpath import Toolpath
    from roboisf.robot.model import RobotModel

__all__ = ["PathOptions", "generate", "register", "warn_truncated"]

# -- options shared by every toolpath command (mm, deg, mm/min) ---------------------------------
Output = Annotated[
    Path,
    typer.Option("--output", "-o", help=f"Output file; its suffix picks the format. {FILE_HELP}"),
]
OptOutput = Annotated[
    Path | None,
    typer.Option("--output", "-o", help=f"Output file; its suffix picks the format. {FILE_HELP}"),
]


def _format_help() -> str:
    """``--format``'s help: every registered format (roboisf.programs.registry) and its suffixes."""
    from roboisf.programs.registry import program_formats

    listed = ", ".join(f"{f.name} ({' '.join(f.suffixes)})" for f in program_formats())
    return f"One of {listed} (default: from -o)."


Format = Annotated[str | None, typer.Option("--format", "-f", help=_format_help())]
StepDown = Annotated[float, typer.Option(help="Depth step between laps [mm].")]
ToolDiameter = Annotated[float, typer.Option(help="Ball diameter [mm].")]
Spiral = Annotated[bool, typer.Option("--spiral", help="Spiral path (z ramps within each lap).")]
Spacing = Annotated[float, typer.Option(help="Max. distance between points along a lap [mm].")]
Feed = Annotated[float, typer.Option(help="Feed rate [mm/min].")]
MaxWallStep = Annotated[
    float | None,
    typer.Option(help="Max. distance between laps along the wall [mm] (shallow walls)."),
]
ScallopHeight = Annotated[
    float | None,
    typer.Option(
        help="Space the laps for this cusp height between them [mm]: Δz = 2 sin α "
        "sqrt(h(2R − h)) per lap from its shallowest wall, ≤ --step-down (any part)."
    ),
]
ToolLength = Annotated[
    float | None,
    typer.Option(help="Flange to ball tip [mm] (robot programs; same as --tool LENGTH)."),
]
MaxPoints = Annotated[
    int,
    typer.Option(
        min=1,
        help="Refuse, before generating, a path estimated above this many points (≈ 1 kB each "
        "to generate and write).",
    ),
]
ToolOpt = Annotated[
    str | None,
    typer.Option(
        "--tool",
        help="The tool of a robot program: flange to ball tip [mm], or a study folder / "
        "study.toml whose [robot] flange_to_tip is used. Required for .mod/.src/.ls.",
    ),
]
Placement = Annotated[
    str | None,
    typer.Option(
        "--placement",
        help="Work object (blank centre, sheet plane) in the robot base: 'X,Y,Z' or "
        "'X,Y,Z,RX,RY,RZ' [mm, deg; R = Rz(RZ)Ry(RY)Rx(RX), as study.toml], 'base' for the "
        "robot base itself, or a study folder / study.toml (its [robot] placement). Required "
        "for .mod/.src/.ls.",
    ),
]
Robot = Annotated[
    str | None,
    typer.Option(
        "--robot",
        help="Robot preset or file: IK along the path gives the configuration data "
        "(confdata, S/T, CONFIG). Default: the study's with --placement STUDY, else none.",
    ),
]
ToolMass = Annotated[float, typer.Option(help="Tool + holder mass [kg] (robot programs).")]
WorkOffset = Annotated[
    str,
    typer.Option(
        help="G-code work offset holding the blank centre (G54 … G59); the program also calls "
        "T1 M06 and G43 H1 (length to the ball tip)."
    ),
]
ArmConfigOpt = Annotated[
    str | None,
    typer.Option(
        "--arm-config",
        help="With --robot: the arm configuration of the first point, which the whole program "
        "then keeps (continuous): ABB confdata 'cf1,cf4,cf6,cfx', KUKA 'S,T', or joints "
        "'q1,...,q6' (deg, the nearest solution). Default: front, elbow up, no flip.",
    ),
]
ToolRotation = Annotated[
    float, typer.Option(help="Rotation of the tool about its own axis [deg] (RAPID/KRL).")
]
WorkFrame = Annotated[
    str | None,
    typer.Option(
        help="Work frame in the robot base as 'X,Y,Z,A,B,C' [mm, deg; R = Rz(A)Ry(B)Rx(C), "
        "KUKA's order] — the same as --placement with the angles given the KUKA way."
    ),
]
SafeHeight = Annotated[float, typer.Option(help="Approach/retract height [mm].")]


@dataclass(frozen=True)
class PathOptions:
    """Toolpath and program options as given on the command line (mm, deg, mm/min)."""

    step_down: float = 0.5
    tool_diameter: float = 10.0
    spiral: bool = False
    spacing: float = 1.0
    feed: float = 750.0
    max_wall_step: float | None = None
    scallop_height: float | None = None
    max_points: int = MAX_POINTS
    tool_length: float | None = None
    tool_mass: float = 2.0
    tool_rotation: float = 0.0
    work_frame: str | None = None
    safe_height: float = 10.0
    placement_: str | None = None
    tool: str | None = None
    robot: str | None = None
    work_offset: str = "G54"
    arm_config: str | None = None
    tip_link: str | None = None

    def check(self) -> None:
        for flag, v in (
            ("--step-down", self.step_down),
            ("--tool-diameter", self.tool_diameter),
            ("--spacing", self.spacing),
            ("--feed", self.feed),
            ("--tool-length", 1.0 if self.tool_length is None else self.tool_length),
            ("--tool-mass", self.tool_mass),
            ("--safe-height", self.safe_height),
        ):
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v:g}", field=flag)
        from roboisf.plausible import check_plausible

        check_plausible(self.tool_diameter, "ball_diameter", field="--tool-diameter")
        if self.max_wall_step is not None and not (
            math.isfinite(self.max_wall_step) and self.max_wall_step > 0
        ):
            raise InputError(f"must be > 0, got {self.max_wall_step:g}", field="--max-wall-step")
        h = self.scallop_height
        if h is not None and not (math.isfinite(h) and 0 < h < self.tool_diameter / 2):
            raise InputError(
                f"must be > 0 and < the ball radius {self.tool_diameter / 2:g} mm, got {h:g}",
                field="--scallop-height",
            )
        if not math.isfinite(self.tool_rotation):
            raise InputError("must be finite", field="--tool-rotation")

    def placement(self) -> np.ndarray | None:
        """``T_base_work`` (4, 4) m from ``--placement`` or ``--work-frame`` (None: not given)."""
        import numpy as np

        from roboisf.frames.pose import XYZ_ABC_MM_DEG, XYZ_RPY_MM_DEG, parse_pose

        if self.placement_ is not None and self.work_frame is not None:
            raise InputError("give --placement or --work-frame, not both", field="--placement")
        if self.work_frame is not None:
            return parse_pose(self.work_frame, XYZ_ABC_MM_DEG, field="--work-frame")
        if self.placement_ is None:
            return None
        text = self.placement_.strip()
        if text.lower() == "base":
            return np.eye(4)
        if _is_study(text):
            return _study_robot(text).T_base_work
        return parse_pose(
            text,
            XYZ_RPY_MM_DEG,
            field="--placement",
            position_only=True,
            alternatives="'base' or a study",
        )

    def robot_tool(self) -> RobotTool | None:
        """The tool from ``--tool`` / ``--tool-length`` (None: not given)."""
        import numpy as np

        from roboisf.cam.program import RobotTool

        if self.tool is not None and self.tool_length is not None:
            raise InputError("give --tool or --tool-length, not both", field="--tool")
        length = self.tool_length
        if self.tool is not None:
            if _is_study(self.tool):
                T_ft = _study_robot(self.tool).T_flange_tip
                if T_ft is None:
                    raise InputError(
                        "the study's [robot] table has no flange_to_tip", field="--tool"
                    )
                off_axis = np.abs(T_ft[:2, 3]).max() > 1e-9
                if off_axis or np.abs(T_ft[:3, :3] - np.eye(3)).max() > 1e-9:
                    raise InputError(
                        "only a straight tool on the flange axis is written to programs",
                        field="--tool",
                    )
                length = float(T_ft[2, 3]) * 1e3
            else:
                length = float(_numbers(self.tool, "--tool", (1,), "a length in mm or a study")[0])
            if not length > 0:
                raise InputError(f"must be > 0 mm, got {length:g}", field="--tool")
        if length is None:
            return None
        from roboisf.plausible import check_plausible

        # --tool 0.306 (the 306 mm tool in m) wrote a program with a 0.306 mm tool
        flag = "--tool-length" if self.tool is None else "--tool"
        check_plausible(length, "tool_length", field=flag)
        return RobotTool(length=length * 1e-3, mass=self.tool_mass)

    def robot_model(self) -> RobotModel | None:
        """The robot for the configuration data: ``--robot``, else the study of ``--placement``
        (its ``[robot] tip_link`` unless ``--tip-link`` names one)."""
        from roboisf.robot.presets import load_robot

        if self.robot is not None:
            return load_robot(self.robot, tip_link=self.tip_link)
        if self.placement_ is not None and _is_study(self.placement_):
            r = _study_robot(self.placement_)
            return load_robot(r.model, tip_link=self.tip_link or r.tip_link)
        if self.tip_link is not None:
            raise InputError(
                "names the flange link of a URDF robot: give --robot or --placement STUDY",
                field="--tip-link",
            )
        return None


def _numbers(text: str, flag: str, counts: tuple[int, ...], expected: str) -> list[float]:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) not in counts or not all(math.isfinite(x) for x in v):
        raise InputError(f"expected {expected}, got {text!r}", field=flag)
    return v


def _is_study(text: str) -> bool:
    p = Path(text)
    return p.is_dir() or p.suffix.lower() == ".toml"


def _study_robot(text: str) -> Any:
    from roboisf.study.spec import load_study

    study = load_study(Path(text))
    if study.robot is None:
        raise InputError("the study has no [robot] table (placement, flange_to_tip)", file=text)
    return study.robot


def generate(part: Part, opts: PathOptions) -> Toolpath:
    """The toolpath for ``part`` with the command-line options (converted to SI here).

    Axisymmetric parts (cone, VWACF, profile) use the generatrix generator
    (:mod:`roboisf.toolpath.generate`); every other part — and any part with
    ``--scallop-height`` — the ball-centre slicer (:mod:`roboisf.toolpath.slice`).
    """
    from roboisf.toolpath import toolpath_for_part

    opts.check()
    try:
        return toolpath_for_part(
            part,
            opts.tool_diameter / 2 * 1e-3,
            opts.step_down * 1e-3,
            spacing=opts.spacing * 1e-3,
            feed=opts.feed / 60e3,
            spiral=opts.spiral,
            max_wall_step=None if opts.max_wall_step is None else opts.max_wall_step * 1e-3,
            scallop_height=None if opts.scallop_height is None else opts.scallop_height * 1e-3,
            max_points=opts.max_points,
        )
    except InputError as e:
        # the generators name their SI parameters; the user typed the options (their messages
        # already give mm)
        if e.file is None and e.field in _OPTION_OF:
            raise InputError(e.message, field=_OPTION_OF[e.field], line=e.line) from None
        raise


#: The toolpath generators' parameter names → the command-line options that set them.
_OPTION_OF = {
    "step_down": "--step-down",
    "spacing": "--spacing",
    "tool_radius": "--tool-diameter",
    "max_wall_step": "--max-wall-step",
    "scallop_height": "--scallop-height",
}


def warn_truncated(tp: Toolpath, tool_diameter: float) -> None:
    """Tell the user when the ball does not fit down to the part's full depth."""
    if tp.meta.get("truncated"):
        z = float(tp.meta["reachable_tip_z"])  # type: ignore[arg-type]
        state.warn(
            f"a Ø{tool_diameter:g} mm ball does not fit in the part below tip z = {z * 1e3:.3f} mm "
            "(it would touch the wall across the axis); the toolpath stops there"
        )


def write(tp: Toolpath, output: Path, fmt: str | None, opts: PathOptions) -> tuple[str, list[Path]]:
    """Write ``tp`` with the program options; return the format used and every file written
    (a RAPID program too long for one module is a main module and its part modules).

    A robot program needs ``--placement`` and ``--tool``; with a robot (``--robot`` or the
    study's) IK along the path gives the configuration data.
    """
    from roboisf.frames.se3 import make_transform
    from roboisf.programs.export import infer_format, write_toolpath
    from roboisf.robot.armconfig import parse_arm_config, program_config

    fmt = infer_format(output, fmt)
    T, tool, model = program_frames(fmt, opts, output)
    config = None
    if opts.arm_config is not None:
        parse_arm_config(opts.arm_config)  # a malformed one is refused, whatever else is given
        if model is None:  # it was dropped without a word
            raise InputError(
                "--arm-config needs a robot: give --robot (or a study with one)",
                field="--arm-config",
            )
    if model is not None and T is not None and tool is not None:
        model = model.with_tool(make_transform(p=[0.0, 0.0, tool.length]))
        config = program_config(
            model, tp, T, math.radians(opts.tool_rotation), **parse_arm_config(opts.arm_config)
        )
    fmt, paths = write_toolpath(
        tp,
        output,
        fmt,
        T_base_work=T,
        tool=tool,
        tool_rotation=math.radians(opts.tool_rotation),
        config=config,
        safe_height=opts.safe_height * 1e-3,
        work_offset=opts.work_offset,
    )
    return fmt, paths


def program_frames(
    fmt: str, opts: PathOptions, output: Path
) -> tuple[np.ndarray | None, RobotTool | None, RobotModel | None]:
    """Placement, tool and robot of a program; a robot program must have the first two and a
    file name that is a valid program name."""
    from roboisf.cam.gcode import WORK_OFFSETS
    from roboisf.programs.export import check_program_name
    from roboisf.programs.registry import get_format

    check_program_name(output, fmt)
    if opts.work_offset not in WORK_OFFSETS:
        raise InputError(
            f"expected one of {', '.join(WORK_OFFSETS)}, got {opts.work_offset!r}",
            field="--work-offset",
        )
    T = opts.placement()
    tool = opts.robot_tool()
    model = None
    if get_format(fmt).kind == "robot":
        if T is None:
            raise InputError(
                "a robot program needs the work-object placement: --placement X,Y,Z[,RX,RY,RZ] "
                "(mm, deg), --placement STUDY, or --placement base for the robot base itself",
                field="--placement",
            )
        if tool is None:
            raise InputError(
                "a robot program needs the tool: --tool LENGTH (flange to ball tip, mm) or "
                "--tool STUDY",
                field="--tool",
            )
        model = opts.robot_model()
    return T, tool, model


def _run(
    part_factory, output: Path, fmt: str | None, opts: PathOptions, inputs: list[Path]
) -> None:
    from roboisf.programs.export import infer_format

    check_not_input(output, inputs)
    fmt = infer_format(output, fmt)  # fail before the (possibly long) generation
    opts.check()
    program_frames(fmt, opts, output)  # name, placement, tool, robot: before the generation
    part = part_factory()
    tp = generate(part, opts)
    warn_truncated(tp, opts.tool_diameter)
    fmt, paths = write(tp, output, fmt, opts)
    extra = [p.name for p in paths[1:]]  # a KRL .dat, a long RAPID program's part modules
    more = (
        f" and {len(extra)} more file{'s' if len(extra) > 1 else ''} beside it ("
        + ", ".join(extra[:3])
        + (" …" if len(extra) > 3 else "")
        + ")"
        if extra
        else ""
    )
    state.info(
        f"wrote {output}{more} ({fmt}): {len(tp)} points, {tp.n_laps} laps, "
        f"{tp.path_length[-1]:.2f} m of path, {tp.time[-1] / 60:.1f} min at {opts.feed:g} mm/min"
    )


_SHARED: list[tuple[str, Any, Any]] = [
    ("fmt", Format, None),
    ("step_down", StepDown, 0.5),
    ("tool_diameter", ToolDiameter, 10.0),
    ("spiral", Spiral, False),
    ("spacing", Spacing, 1.0),
    ("feed", Feed, 750.0),
    ("max_wall_step", MaxWallStep, None),
    ("scallop_height", ScallopHeight, None),
    ("max_points", MaxPoints, MAX_POINTS),
    ("tool_length", ToolLength, None),
    ("tool_mass", ToolMass, 2.0),
    ("tool_rotation", ToolRotation, 0.0),
    ("work_frame", WorkFrame, None),
    ("safe_height", SafeHeight, 10.0),
    ("placement_", Placement, None),
    ("tool", ToolOpt, None),
    ("robot", Robot, None),
    ("work_offset", WorkOffset, "G54"),
    ("arm_config", ArmConfigOpt, None),
    ("tip_link", TipLink, None),
]


def _claim_output(kwargs: dict[str, Any], overwrite: bool) -> None:
    """Check and lock -o (and the companion files of its format, a KRL program's .dat) before
    generating anything."""
    from roboisf.programs.registry import find_format

    output = kwargs.get("output")
    if output is None:
        return
    inputs = [kwargs.get("part"), kwargs.get("profile")]
    output_file(output, "toolpath", overwrite, inputs)
    fmt = find_format(output, kwargs.get("fmt"))
    for companion in fmt.output_files(output)[1:] if fmt is not None else []:
        output_file(companion, "toolpath", overwrite, inputs)


def _with_path_options(fn: Callable[..., None]) -> Callable[..., None]:
    """Give a command the shared toolpath/program options.

    ``fn`` declares only its own parameters plus ``fmt`` and ``opts``; typer sees them followed
    by every option in ``_SHARED`` (one definition, so all commands stay in step), and ``fn``
    receives them bundled as a :class:`PathOptions`.
    """
    hints = typing.get_type_hints(fn, include_extras=True)
    own = [
        p.replace(annotation=hints.get(p.name, p.annotation))
        for p in inspect.signature(fn).parameters.values()
        if p.name not in ("fmt", "opts")
    ]
    shared = [
        inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, annotation=a, default=d)
        for n, a, d in _SHARED
    ]
    shared.append(
        inspect.Parameter(
            "overwrite", inspect.Parameter.KEYWORD_ONLY, annotation=Overwrite, default=False
        )
    )

    def command(**kwargs: Any) -> None:
        _claim_output(kwargs, kwargs.pop("overwrite"))
        fmt = kwargs.pop("fmt")
        opts = PathOptions(**{n: kwargs.pop(n) for n, _, _ in _SHARED[1:]})
        fn(**kwargs, fmt=fmt, opts=opts)

    command.__signature__ = inspect.Signature(own + shared)  # type: ignore[attr-defined]
    command.__name__ = fn.__name__
    command.__doc__ = fn.__doc__
    return command


toolpath_app = typer.Typer(
    help="Generate a forming toolpath (step-down or spiral); write CSV, G-code, RAPID or KRL.\n\n"
    "Give the part as a subcommand (cone, vwacf, profile) or as a part file of any kind "
    "(also pyramid, mesh from STL/OBJ/PLY/STEP; see 'roboisf part'): "
    "roboisf toolpath --part part.toml -o path.csv",
    no_args_is_help=True,
    invoke_without_command=True,
    cls=FullHelpGroup,
)


@toolpath_app.callback()
@_with_path_options
def _toolpath_from_part_file(
    ctx: typer.Context,
    part: Annotated[
        Path | None, typer.Option("--part", help="Part TOML file (see 'roboisf part').")
    ] = None,
    output: OptOutput = None,
    *,
    fmt: str | None,
    opts: PathOptions,
) -> None:
    if ctx.invoked_subcommand is not None:
        if part is not None or output is not None or fmt is not None or opts != PathOptions():
            raise InputError(
                f"give the part either as --part FILE or as the subcommand "
                f"{ctx.invoked_subcommand!r}, and put -o and the other options after the "
                "subcommand",
                field="--part",
            )
        return
    if part is None:
        raise InputError(
            "no part given: use --part part.toml or a subcommand (cone, vwacf, profile)"
        )
    if output is None:
        raise InputError("missing -o/--output", field="--output")
    from roboisf.parts.io import part_files

    _run(lambda: parts.load_part(part), output, fmt, opts, part_files(part))


def _named_as_options(build: Callable[[], Part], names: tuple[str, ...]) -> Callable[[], Part]:
    """``build`` whose InputError about one of ``names`` — the part's parameters, which the
    subcommand takes as options of the same name — names the option the user typed
    (``--wall-angle``, not the part file's ``wall_angle``)."""

    def make() -> Part:
        try:
            return build()
        except InputError as e:
            if e.file is None and e.field in names:
                raise InputError(e.message, field="--" + e.field.replace("_", "-")) from None
            raise

    return make


@toolpath_app.command("cone")
@_with_path_options
def _cone(
    output: Output,
    opening_diameter: ConeDiameter = 87.0,
    wall_angle: WallAngle = 71.0,
    depth: Depth = 102.97,
    *,
    fmt: str | None,
    opts: PathOptions,
) -> None:
    """Truncated cone of constant wall angle (defaults: the paper's Ø87 mm, 71°, 102.97 mm)."""
    _run(
        _named_as_options(
            lambda: parts.Cone(opening_diameter * 1e-3, math.radians(wall_angle), depth * 1e-3),
            ("opening_diameter", "wall_angle", "depth"),
        ),
        output,
        fmt,
        opts,
        [],
    )


@toolpath_app.command("vwacf")
@_with_path_options
def _vwacf(
    output: Output,
    opening_diameter: VwacfDiameter = 88.15,
    arc_radius: ArcRadius = VWACF_DEFAULT_ARC_RADIUS * 1e3,
    final_wall_angle: FinalWallAngle = 90.0,
    *,
    fmt: str | None,
    opts: PathOptions,
) -> None:
    """Variable-wall-angle frustum: arc generatrix tangent to the sheet at the rim (0° → final)."""
    _run(
        _named_as_options(
            lambda: parts.VWACF(
                opening_diameter * 1e-3, arc_radius * 1e-3, math.radians(final_wall_angle)
            ),
            ("opening_diameter", "arc_radius", "final_wall_angle"),
        ),
        output,
        fmt,
        opts,
        [],
    )


@toolpath_app.command("profile")
@_with_path_options
def _profile(
    profile: ProfileCsv,
    output: Output,
    *,
    fmt: str | None,
    opts: PathOptions,
) -> None:
    """Any axisymmetric part from a generatrix polyline (CSV r,z in mm)."""

    def make() -> AxisymmetricPart:
        from roboisf.parts import ProfilePart, read_profile_csv

        r, z = read_profile_csv(profile)
        return ProfilePart(r=tuple(r), z=tuple(z), source=str(profile))

    _run(make, output, fmt, opts, [profile])


def _import_command() -> None:
    """Register ``roboisf toolpath import`` (the work is in roboisf.toolpath.importer)."""
    from roboisf.cli.toolpath_import import import_command

    doc = import_command.__doc__ or ""
    help_text = "\n\n".join(" ".join(par.split()) for par in doc.split("\n\n"))
    toolpath_app.command("import", help=help_text, no_args_is_help=True)(import_command)


_import_command()


def register(app: typer.Typer) -> None:
    """Add ``roboisf toolpath`` to ``app``."""
    app.add_typer(toolpath_app, name="toolpath")
