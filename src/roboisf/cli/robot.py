"""``roboisf robot …``: list, show, identify, deflect."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from roboisf.cli.console import state
from roboisf.cli.lazy import FullHelpGroup
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError

if TYPE_CHECKING:  # numpy and the robot are imported by the command that runs (fast --help)
    import numpy as np

    from roboisf.robot import RobotModel

__all__ = ["register"]

robot_app = typer.Typer(
    help="Robot models, joint stiffness and VJM deflection along a toolpath.",
    no_args_is_help=True,
    cls=FullHelpGroup,
)


def register(app: typer.Typer) -> None:
    app.add_typer(robot_app, name="robot")


def _floats(text: str, n: int, field: str) -> np.ndarray:
    import numpy as np

    try:
        v = np.array([float(t) for t in text.split(",")])
    except ValueError:
        raise InputError(
            f"expected {n} comma-separated numbers, got {text!r}", field=field
        ) from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"expected {n} comma-separated finite numbers, got {text!r}", field=field)
    return v


def _ints(text: str, n: int, field: str) -> np.ndarray:
    import numpy as np

    v = _floats(text, n, field)
    if np.any(v != np.round(v)):
        raise InputError(f"expected {n} comma-separated integers, got {text!r}", field=field)
    return v.astype(np.int64)


def tool_pose(text: str, field: str = "--tool") -> np.ndarray:
    """``T_flange_tip`` (4, 4), m, of a ``--tool x,y,z`` (mm, flange frame), refused when the
    tip's distance from the flange is no tool's (:func:`roboisf.plausible.check_tool_offset`:
    a tool typed in m)."""
    from roboisf.frames.pose import XYZ_MM, parse_pose
    from roboisf.plausible import check_tool_offset

    T = parse_pose(text, XYZ_MM, field=field)
    check_tool_offset(T[:3, 3] * 1e3, field=field)
    return T


def _model(
    robot: str, stiffness: Path | None, tool: str | None, tip_link: str | None = None
) -> RobotModel:
    from roboisf.robot import load_robot, load_stiffness

    m = load_robot(robot, tip_link=tip_link)
    if stiffness is not None:
        m = m.with_stiffness(load_stiffness(stiffness, robot=m.name), source=str(stiffness))
    if tool is not None:
        m = m.with_tool(tool_pose(tool))
    return m


def _placement(text: str | None, model: RobotModel) -> np.ndarray:

    from roboisf.frames.pose import XYZ_YAW_MM_DEG, parse_pose

    if text is None:
        if model.default_placement is None:
            raise InputError(
                f"robot {model.name} has no default placement; give --placement",
                field="--placement",
            )
        return model.default_placement
    return parse_pose(text, XYZ_YAW_MM_DEG, field="--placement")


#: How far a work object's origin lies from the robot base in a real cell [mm]: nearer than
#: 100 mm the part would sit inside the robot's own base; a placement typed in m (2.2,0,0.5 for
#: 2200,0,500) lands there, and the IK then said only "beyond the joint limits".
WORK_DISTANCE_MIN_MM = 100.0


def _placement_slip(text: str | None, what: str = "") -> str:
    """What a ``--placement`` no pose could reach says of its unit: ``"--placement 2.2,0,0.5,0
    puts the work origin 2.247 mm from the robot base (…); it is 2247 mm if it was written in
    m"`` for a work origin nearer the base than any cell's, ``""`` otherwise (the preset's, or
    a placement at a real cell's distance: then the reach or the limits are the reason).
    ``what``, when given, says what such a placement does and goes before the slip."""
    from roboisf.plausible import Bound, unit_slip

    if text is None:
        return ""
    try:
        x, y, z = (float(v) for v in text.split(",")[:3])
    except ValueError:
        return ""
    d = math.sqrt(x * x + y * y + z * z)
    if not 0 < d < WORK_DISTANCE_MIN_MM:
        return ""
    slip = unit_slip(d, Bound(WORK_DISTANCE_MIN_MM, 1e4, "mm", "a work object's distance"))
    if slip.endswith("written in m"):  # the one a metre-minded user makes: show it in mm
        slip += f" (x,y,z = {x * 1e3:g},{y * 1e3:g},{z * 1e3:g} mm)"
    return (
        f"--placement {text} puts the work origin {d:.4g} mm from the robot base (a real cell's "
        f"is {WORK_DISTANCE_MIN_MM:g} mm or more away; x,y,z are in mm, yaw in deg)"
        + (f": {what}" if what else "")
        + (f"; {slip}" if slip else "")
    )


@contextmanager
def _unreachable_placement(text: str | None) -> Iterator[None]:
    """A pose out of reach or beyond the limits, with the placement's unit slip when one
    explains it (:func:`_placement_slip`): then the error names ``--placement``."""
    from roboisf.errors import UnreachableError

    try:
        yield
    except UnreachableError as e:
        hint = _placement_slip(text)
        if not hint:
            raise
        raise UnreachableError(
            f"{e.message}; {hint}", e.indices, file=e.file, line=e.line, field="--placement"
        ) from None


ROBOT_OPT = typer.Option(
    "irb7600-500-2.55", "--robot", "-r", help="Preset name, robot .toml or .urdf."
)
STIFF_OPT = typer.Option(
    None, "--stiffness", help="Joint stiffness TOML ([stiffness] K = [6] N*m/rad)."
)
PLACEMENT_OPT = typer.Option(
    None,
    "--placement",
    help="x,y,z,yaw of the work frame in the base (mm, deg); default: preset's.",
)
TOOL_OPT = typer.Option(None, "--tool", help="Tool tip in the flange frame: x,y,z (mm).")
TIP_LINK_HELP = (
    "URDF robots: the link that is the arm's flange (default tool0 or flange, else the link "
    "behind the most revolute joints); a gripper's or a 7th joint's link is not."
)
TIP_LINK_OPT = typer.Option(None, "--tip-link", help=TIP_LINK_HELP)
#: ``--tip-link`` for commands written with ``Annotated`` options (toolpath, plan, study init)
TipLink = Annotated[str | None, typer.Option("--tip-link", help=TIP_LINK_HELP)]


LIST_HELP = (
    "List the built-in robot presets: reach, payload, joint stiffness and source.\n\n"
    "Reach is the wrist-centre reach from the preset's geometry (a1 + c2 + √(a2² + c3²)). "
    "'unknown — identify': no published joint stiffness; measure it with "
    "`roboisf robot identify calib.csv -o K.toml` and pass --stiffness K.toml. Copy a preset's "
    "TOML (docs/robot.md) to describe your own robot."
)


@robot_app.command("list", help=LIST_HELP)
def list_cmd(
    sources: bool = typer.Option(
        False, "--sources", help="Also print where every preset's numbers come from."
    ),
) -> None:
    """List the built-in robot presets: reach, payload, joint stiffness and source."""
    from roboisf.robot.presets import list_robots, preset_info

    state.out.print(
        f"{'preset':18s} {'robot':34s} {'reach m':>7s} {'payload kg':>10s}  joint stiffness",
        markup=False,
        soft_wrap=True,
    )
    for name in list_robots():
        i = preset_info(name)
        reach = "—" if i.reach_m is None else f"{i.reach_m:.3f}"
        pay = "—" if i.payload_kg is None else f"{i.payload_kg:g}"
        k = "unknown — identify" if i.stiffness_source is None else i.stiffness_source
        desc = i.description.split(" (")[0]
        state.out.print(
            f"{name:18s} {desc:34s} {reach:>7s} {pay:>10s}  {k}", markup=False, soft_wrap=True
        )
        src = i.source if sources else i.source_brief
        state.out.print(f"{'':18s} source: {src}", markup=False, soft_wrap=True)


def _files(*names: str | None) -> list[Path]:
    """The robot/tool arguments that name files (inputs the output may not overwrite)."""
    return [Path(n) for n in names if n is not None and Path(n).is_file()]


#: The widest stiffness map [mm, half width]: 1e7 mm drew a 20 km map with one pixel inside the
#: robot's reach.
MAP_HALF_WIDTH_MAX = 5000.0


@robot_app.command("show")
def show_cmd(
    robot: str = ROBOT_OPT,
    stiffness: Path | None = STIFF_OPT,
    tool: str | None = TOOL_OPT,
    tip_link: str | None = TIP_LINK_OPT,
    placement: str | None = PLACEMENT_OPT,
    output: Path | None = typer.Option(
        None, "--output", "-o", help=f"Stiffness map PNG over the work area. {FILE_HELP}"
    ),
    overwrite: Overwrite = False,
    half_width: float = typer.Option(500.0, "--half-width", help="Map half width (mm)."),
) -> None:
    """Show a robot's limits and joint stiffness; optionally write a stiffness map PNG."""
    import numpy as np
    from rich.markup import escape

    if placement is not None:  # checked first, map or not (it used to pass unread without -o)
        from roboisf.frames.pose import XYZ_YAW_MM_DEG, parse_pose

        parse_pose(placement, XYZ_YAW_MM_DEG, field="--placement")
    if output is not None:
        if output.suffix.lower() != ".png":  # the map is PNG data whatever the name says
            raise InputError(
                f"the stiffness map is written as PNG; expected a .png file, got the suffix "
                f"{output.suffix or '(none)'!r}",
                file=output,
                field="--output",
            )
        if not (0 < half_width <= MAP_HALF_WIDTH_MAX):  # NaN too
            raise InputError(
                f"must be > 0 and ≤ {MAP_HALF_WIDTH_MAX:g} mm (the map covers the work area "
                f"around the placement; no robot reaches farther), got {half_width:g}",
                field="--half-width",
            )
        output_file(output, "robot show", overwrite, [stiffness, *_files(robot, tool)])
    elif placement is not None or half_width != 500.0:
        given = [
            f for f, v in (("--placement", placement), ("--half-width", half_width != 500.0)) if v
        ]
        state.warn(f"{' and '.join(given)} set the stiffness map (-o map.png): unused without -o")
    m = _model(robot, stiffness, tool, tip_link)
    if output is not None:  # the map needs the joint stiffness: refused before the table
        _ = m.joint_stiffness
    state.out.print(f"[bold]{escape(m.name)}[/bold]")
    if m.source:
        state.out.print(m.source, markup=False)
    if m.ik_note:
        state.warn(m.ik_note)
    for i in range(6):
        K = "—" if m.stiffness is None else f"{m.stiffness[i]:.4g} N·m/rad"
        state.out.print(
            f"A{i + 1}: limits [{np.degrees(m.q_min[i]):7.1f}, "
            f"{np.degrees(m.q_max[i]):7.1f}] deg   K = {K}"
        )
    if m.stiffness is None:
        state.warn(
            "joint stiffness unknown — identify it: `roboisf robot identify calib.csv -o K.toml`, "
            "then pass --stiffness K.toml (compliance and deflection need it)"
        )
    if output is not None:
        from roboisf.report.robot_maps import plot_stiffness_map
        from roboisf.robot import stiffness_map

        with _unreachable_placement(placement):
            smap = stiffness_map(m, _placement(placement, m), half_width=half_width * 1e-3)
        plot_stiffness_map(smap, output)
        state.info(f"wrote {output}")


#: ``--sigma-rot``'s default: 1e-5 rad (0.00057°), with its unit
SIGMA_ROT_DEFAULT = "1e-5rad"
#: the units ``--sigma-rot`` accepts → rad
ROTATION_STD_UNITS = {
    "rad": 1.0,
    "mrad": 1e-3,
    "urad": 1e-6,
    "µrad": 1e-6,
    "μrad": 1e-6,
    "deg": math.pi / 180.0,
    "°": math.pi / 180.0,
    "arcsec": math.pi / 180.0 / 3600.0,
}
#: the largest rotation measurement std accepted [rad] (2.9°): an inclinometer or a laser
#: tracker's 6-DoF probe reads to 1e-5–1e-3 rad; a bare number above this is degrees meant
MAX_ROTATION_STD = 0.05
#: the largest displacement measurement std accepted [mm]: a dial gauge or a laser tracker reads
#: to 0.001–0.05 mm; 10 (µm meant) widened a design's expected intervals 1000×
MAX_DISPLACEMENT_STD_MM = 1.0


def rotation_std(text: str) -> tuple[float, bool]:
    """``--sigma-rot`` → (rad, whether the number came without a unit). A bare number is read
    in rad (the option's unit before the command line's angles became degrees) and refused
    above :data:`MAX_ROTATION_STD`, where it can only be degrees; a number with a unit is taken
    in it. Refusals name the option, the unit and what was expected."""
    s = text.strip()
    i = len(s)
    while i > 0 and not (s[i - 1].isdigit() or s[i - 1] == "."):
        i -= 1
    num, unit = s[:i].strip(), s[i:].strip()
    accepted = "rad, mrad, urad, deg, arcsec"
    try:
        v = float(num)
    except ValueError:
        raise InputError(
            f"expected a standard deviation with its unit ({accepted}), e.g. 0.0006deg or "
            f"1e-5rad, got {text!r}",
            field="--sigma-rot",
        ) from None
    if unit and unit.lower() not in ROTATION_STD_UNITS and unit not in ROTATION_STD_UNITS:
        raise InputError(
            f"unknown unit {unit!r} in {text!r}; expected one of {accepted} (e.g. 0.0006deg)",
            field="--sigma-rot",
        )
    if not (math.isfinite(v) and v > 0):
        raise InputError(
            f"must be a standard deviation > 0 (with its unit: {accepted}), got {text!r}",
            field="--sigma-rot",
        )
    if not unit:
        if v > MAX_ROTATION_STD:
            raise InputError(
                f"a bare {num} is read in rad, and {v:g} rad ({math.degrees(v):.3g}°) is no "
                f"rotation measurement's standard deviation (at most {MAX_ROTATION_STD:g} rad); "
                f"if you meant {num}° ({math.radians(v):.3g} rad), write {num}deg; give the "
                f"unit either way ({accepted})",
                field="--sigma-rot",
            )
        return v, True
    rad = v * ROTATION_STD_UNITS.get(unit, ROTATION_STD_UNITS.get(unit.lower(), 1.0))
    if rad > MAX_ROTATION_STD:
        raise InputError(
            f"{text.strip()} ({rad:.3g} rad) is no rotation measurement's standard deviation "
            f"(at most {MAX_ROTATION_STD:g} rad, {math.degrees(MAX_ROTATION_STD):.2g}°); leave "
            "the rx,ry,rz columns out to identify from displacements only",
            field="--sigma-rot",
        )
    return rad, False


def _check_sigma(sigma: float) -> None:
    """``--sigma`` (mm): a standard deviation > 0 that a displacement measurement has."""
    if not (math.isfinite(sigma) and sigma > 0):
        raise InputError(f"must be a standard deviation > 0 mm, got {sigma:g}", field="--sigma")
    if sigma > MAX_DISPLACEMENT_STD_MM:
        raise InputError(
            f"{sigma:g} mm is no displacement measurement's standard deviation (a dial gauge or "
            f"a laser tracker: 0.001–0.05 mm; at most {MAX_DISPLACEMENT_STD_MM:g} mm); it is "
            f"{sigma * 1e-3:g} mm if it was written in µm",
            field="--sigma",
        )


@robot_app.command("identify")
def identify_cmd(
    calib: Path | None = typer.Argument(
        None, help="Calibration CSV (see docs/robot.md); not with --design."
    ),
    output: Path = typer.Option(
        ...,
        "--output",
        "-o",
        help=f"stiffness TOML to write (with --design: a folder). {FILE_HELP}",
    ),
    overwrite: Overwrite = False,
    robot: str = ROBOT_OPT,
    tool: str | None = TOOL_OPT,
    tip_link: str | None = TIP_LINK_OPT,
    sigma: float = typer.Option(0.01, "--sigma", help="Measurement std of displacements (mm)."),
    sigma_rot: str = typer.Option(
        SIGMA_ROT_DEFAULT,
        "--sigma-rot",
        help="Measurement std of rotations (the rx,ry,rz columns), with its unit: e.g. "
        "0.0006deg, 1e-5rad, 2arcsec (deg, rad, mrad, urad, arcsec). A bare number is read in "
        "rad, this option's unit before angles on the command line became degrees, with a "
        "warning; a bare number above 0.05 (rad: 2.9°) is refused as degrees meant.",
    ),
    design: bool = typer.Option(
        False,
        "--design",
        help="Design the experiment instead: poses and loads near the work frame that make all "
        "six joints identifiable, written into the -o folder as a measuring sheet "
        "(experiment.csv, the calibration CSV with dx,dy,dz to fill), a program that stops at "
        "each pose (experiment.mod for ABB, .src for KUKA) and the intervals it should give "
        "(design.toml).",
    ),
    placement: str | None = PLACEMENT_OPT,
    stiffness: Path | None = typer.Option(
        None,
        "--stiffness",
        help="With --design: the prior joint stiffness the intervals are predicted at (needed "
        "for a robot without published values).",
    ),
    bracket: float = typer.Option(
        250.0,
        "--bracket",
        help="With --design: the measured and loaded point sits this far (mm) along flange x "
        "from the tool tip (off joint 6's axis, which a load on it never twists).",
    ),
    force: float = typer.Option(2000.0, "--force", help="With --design: the load (N)."),
    experiments: int = typer.Option(
        24, "--experiments", help="With --design: how many experiments (load cases)."
    ),
) -> None:
    """Identify joint stiffness K_1..K_6 from elasto-static experiments, or design them.

    With --design the measuring sheet is experiment.csv: move to each pose, measure the point
    unloaded and under the load, fill dx,dy,dz (mm, base axes), then run `roboisf robot identify
    experiment.csv --tool X,Y,Z --sigma S -o K.toml` with the tool the sheet names (the
    bracket point).
    """
    if design:
        _design_cmd(
            output, overwrite, robot, tool, placement, stiffness, bracket, force, experiments, sigma
        )
        return
    if calib is None:
        raise InputError("expected a calibration CSV (or --design)", field="CALIB")
    # a standard deviation weights the residuals by 1/σ: 0 divides by zero, a negative one is
    # no standard deviation (both used to run: a ZeroDivisionError, or a silently used |σ|)
    _check_sigma(sigma)
    sigma_rot_rad, bare = rotation_std(sigma_rot)
    import warnings

    import numpy as np
    import tomli_w

    from roboisf.io.atomic import atomic_write, check_not_input
    from roboisf.robot import PoorExcitationWarning, identify_stiffness, read_calibration_csv

    check_not_input(output, [calib])
    output_file(output, "robot identify", overwrite, [calib, *_files(robot, tool)])
    m = _model(robot, None, tool, tip_link)
    data = read_calibration_csv(calib, m)
    rotations = data.displacement.shape[1] == 6
    if bare and rotations:
        state.warn(
            f"--sigma-rot {sigma_rot.strip()} has no unit: read as {sigma_rot_rad:g} rad "
            f"({math.degrees(sigma_rot_rad):.3g}°), its unit so far; angles on the command line "
            f"are degrees, so {sigma_rot.strip()} deg would be "
            f"{math.radians(sigma_rot_rad):.3g} rad: write {sigma_rot.strip()}rad (or "
            f"{math.degrees(sigma_rot_rad):.3g}deg) to say which"
        )
    elif sigma_rot != SIGMA_ROT_DEFAULT and not rotations:
        state.warn(f"--sigma-rot is not used: {calib} has no rotation columns (rx, ry, rz)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PoorExcitationWarning)
        r = identify_stiffness(
            m, data, sigma_translation=sigma * 1e-3, sigma_rotation=sigma_rot_rad
        )
    for w in caught:
        state.warn(str(w.message))
    for i in range(6):
        state.out.print(
            f"K{i + 1} = {r.K[i]:.4g} N·m/rad  95% CI [{r.K_ci[i, 0]:.4g}, {r.K_ci[i, 1]:.4g}]"
            + ("  (weakly excited)" if r.weak[i] else "")
        )
    state.out.print(
        f"residual RMS {r.residual_rms * 1e3:.4g} mm, condition number {r.condition_number:.3g}"
    )
    doc = {
        "stiffness": {
            "K": r.K.tolist(),
            "ci_low": r.K_ci[:, 0].tolist(),
            "ci_high": [float(x) if np.isfinite(x) else 1e300 for x in r.K_ci[:, 1]],
            "weak": r.weak.tolist(),
            "residual_rms_m": r.residual_rms,
            "condition_number": r.condition_number,
            "source": f"roboisf robot identify {calib.name} ({m.name})",
            "robot": m.name,  # load_stiffness refuses it for another robot
        }
    }
    with atomic_write(output, "wb", encoding=None) as f:
        f.write(b"# joint stiffness K in N*m/rad, 95 % confidence interval [ci_low, ci_high]\n")
        tomli_w.dump(doc, f)
    state.info(f"wrote {output}")


#: a design's expected relative standard error above which a joint is said to be weakly
#: identified (identify_stiffness's weak_threshold)
WEAK_DESIGN = 0.3


def _design_cmd(
    output: Path,
    overwrite: bool,
    robot: str,
    tool: str | None,
    placement: str | None,
    stiffness: Path | None,
    bracket: float,
    force: float,
    experiments: int,
    sigma: float,
) -> None:
    import numpy as np
    import tomli_w

    from roboisf.cli.outputs import output_dir
    from roboisf.frames import make_transform
    from roboisf.io.atomic import atomic_write, staged_directory
    from roboisf.programs.joint_program import joint_program_suffix, write_joint_program
    from roboisf.robot.identify import design_experiment, write_experiment_csv

    if not (force > 0 and sigma > 0 and experiments >= 7):
        raise InputError(
            "--force and --sigma must be > 0 and --experiments ≥ 7 (six joints and an error "
            "estimate)",
            field="--design",
        )
    _check_sigma(sigma)
    from roboisf.plausible import check_plausible

    # a load no robot is tested with (2e6 N) made the design's information matrix singular: a
    # LinAlgError traceback instead of one line
    check_plausible(force, "identification_load", field="--force")
    inputs = [p for p in (stiffness,) if p is not None]
    output_dir(output, "robot identify --design", overwrite, [*inputs, *_files(robot, tool)])
    m = _model(robot, stiffness, tool)
    tip = m.T_flange_tip[:3, 3] if tool is None else tool_pose(tool)[:3, 3]
    point = tip + np.array([bracket * 1e-3, 0.0, 0.0])
    m = m.with_tool(make_transform(None, point))
    T_bw = _placement(placement, m)
    # poses are drawn within 1 m of the work origin: one typed in m (1.6,0,0.8) lies inside the
    # robot's own base, and the design came out around the base without a word. A URDF's root
    # may be the cell's origin (then a work origin near it can be meant): a warning there
    urdf = m.source.startswith("URDF ")
    what = "the designed poses would gather around the robot's base" + (
        " (unless the URDF's root is not the robot's base)" if urdf else ""
    )
    near = _placement_slip(placement, what)
    if near and urdf:
        state.warn(near)
    elif near:
        raise InputError(near, field="--placement")
    d = design_experiment(m, T_bw, n_experiments=experiments, force=force, sigma=sigma * 1e-3)
    ext = joint_program_suffix(m)
    tool_mm = ",".join(f"{v:g}" for v in np.round(point * 1e3, 3))
    command = (
        f"roboisf robot identify experiment.csv --robot {robot} --tool {tool_mm} "
        f"--sigma {sigma:g} -o K.toml"
    )
    with staged_directory(output, "robot identify --design") as stage:
        write_experiment_csv(
            d,
            stage / "experiment.csv",
            m.name,
            f"{tool_mm} mm in the flange frame ({bracket:g} mm along x from the tool tip: a "
            "bracket)",
            command,
        )
        if ext is not None:
            write_joint_program(d, stage / f"experiment{ext}", "roboisf_identify")
        doc = {
            "design": {
                "robot": m.name,
                "tool_mm": [float(v) for v in point * 1e3],
                "sigma_mm": sigma,
                "force_N": force,
                "experiments": len(d.q),
                "K_prior": [float(v) for v in m.joint_stiffness],
                "expected_relative_se": [float(v) for v in d.rel_se],
                "expected_ci_low": [float(v) for v in d.K_ci[:, 0]],
                "expected_ci_high": [float(v) if np.isfinite(v) else 1e300 for v in d.K_ci[:, 1]],
                "condition_number": d.condition_number,
                "identify": command,
            }
        }
        with atomic_write(stage / "design.toml", "wb", encoding=None) as f:
            tomli_w.dump(doc, f)
    for i in range(6):
        state.out.print(
            f"K{i + 1}: expected relative standard error {d.rel_se[i]:.1%} "
            f"(95 % [{d.K_ci[i, 0]:.4g}, {d.K_ci[i, 1]:.4g}] N·m/rad at the prior)"
        )
    weak = [i for i in range(6) if d.rel_se[i] > WEAK_DESIGN]
    if weak:
        names = ", ".join(f"K{i + 1} ({d.rel_se[i]:.0%})" for i in weak)
        state.warn(
            f"this design identifies {names} only weakly (expected relative standard error "
            f"above {WEAK_DESIGN:.0%}, where identify calls a joint weakly excited): a longer "
            "--bracket (joint 6 is twisted by the load's arm off its axis), more --experiments "
            "or a more precise measurement (--sigma)"
        )
    if ext is None:
        why = (
            "a URDF's joint angles are not its pendant's (signs, zeros, FANUC's J2/J3 coupling)"
            if m.source.startswith("URDF ")
            else "roboisf writes joint programs for ABB, KUKA and FANUC robots"
        )
        state.info(
            f"no robot program for {m.name}: {why}; the poses are in experiment.csv (q1…q6, deg)"
        )
    state.info(
        f"wrote {output}: {len(d.q)} experiments; measure the point {tool_mm} mm (flange "
        f"frame), then: roboisf robot identify {output / 'experiment.csv'} --tool {tool_mm} "
        f"--sigma {sigma:g} -o K.toml"
    )


#: the IK's parameters → the ``deflect`` options that give them (errors name the option)
IK_OPTIONS = {
    "tool_rotation": "--tool-rotation",
    "match_q": "--start-joints",
    "confdata": "--confdata",
    "kuka_st": "--kuka-st",
    "placement": "--placement",
}


@contextmanager
def _options_named(names: dict[str, str]) -> Iterator[None]:
    """An :class:`InputError` raised inside about a parameter of ``names`` names its option."""
    try:
        yield
    except InputError as e:
        if e.field in names:
            raise InputError(e.message, file=e.file, line=e.line, field=names[e.field]) from None
        raise


DEFLECT_HELP = (
    "VJM deflection of the tool tip along a toolpath under the logged forming wrench.\n\n"
    "The joints come from --joints, or from IK: closed form for OPW robots (presets, and URDFs "
    "whose structure fits), numerical otherwise. Without --start-joints / --confdata / --kuka-st "
    "the IK branch is front / elbow up / no flip (numerical IK: the solution nearest the middle "
    "of the joint ranges). A robot whose joint stiffness is unknown needs --stiffness (from "
    "`roboisf robot identify`).\n\n"
    "Timing: forces and joints are matched to the toolpath points by the toolpath's nominal "
    "time (path length / feed) only — right for logs on that clock (the virtual cell's clean "
    "logs). A real run's logs drift (feed override, pauses): align them in a study with "
    '`sync = "position"` / `"force"` and run `roboisf analyze` (docs/study.md, alignment). '
    "--toolpath is a roboisf toolpath CSV; convert a CAM program with `roboisf toolpath "
    "import` first.\n\n"
    "Example, a URDF robot without a joint log: roboisf robot deflect --robot arm.urdf "
    "--stiffness K.toml --toolpath P.csv --forces F.csv --placement 1600,0,800,0 "
    "--tool 0,0,300 -o deflection.csv"
)


@robot_app.command("deflect", help=DEFLECT_HELP)
def deflect_cmd(
    toolpath: Path = typer.Option(..., "--toolpath", help="Toolpath CSV (roboisf format)."),
    forces: Path = typer.Option(
        ...,
        "--forces",
        help="Force log, wrench at the tool tip in frame work, base or tip; matched to the "
        "points by nominal time (see Timing above).",
    ),
    output: Path = typer.Option(
        ..., "--output", "-o", help=f"Deflection CSV to write. {FILE_HELP}"
    ),
    overwrite: Overwrite = False,
    robot: str = ROBOT_OPT,
    stiffness: Path | None = STIFF_OPT,
    tool: str | None = TOOL_OPT,
    tip_link: str | None = TIP_LINK_OPT,
    placement: str | None = PLACEMENT_OPT,
    joints: Path | None = typer.Option(
        None,
        "--joints",
        help="Joint log (roboisf CSV, ABB J1..J6, KUKA A1..A6 …, units declared in the file) "
        "instead of IK; matched by nominal time (see Timing above).",
    ),
    tool_rotation: float = typer.Option(
        0.0, "--tool-rotation", help="Tool rotation about its own axis (deg)."
    ),
    start_joints: str | None = typer.Option(
        None,
        "--start-joints",
        help="IK: start at the solution nearest these joints q1..q6 (degrees, not rad; the "
        "controller's), e.g. the robot's pose at the first point; branch and turns then follow "
        "continuously. Said back in degrees with the first point's joints.",
    ),
    confdata: str | None = typer.Option(
        None,
        "--confdata",
        help="IK: ABB confdata cf1,cf4,cf6,cfx of the first point (as in the RAPID program).",
    ),
    kuka_st: str | None = typer.Option(
        None, "--kuka-st", help="IK: KUKA Status,Turn of the first point, e.g. 2,10."
    ),
) -> None:
    """VJM deflection of the tool tip along a toolpath under the logged forming wrench."""
    from roboisf.plausible import check_plausible

    check_plausible(tool_rotation, "angle", field="--tool-rotation")  # before numpy is loaded
    import warnings

    import numpy as np

    from roboisf.io.atomic import atomic_write, check_not_input
    from roboisf.io.table import format_rows
    from roboisf.logs.forcelog import attach_to_toolpath, read_force_log
    from roboisf.logs.jointlog import read_joint_log
    from roboisf.robot import ik_toolpath, rotate_6
    from roboisf.robot.ik import NumericalIKWarning
    from roboisf.toolpath.importer import read_toolpath_file

    inputs: list[str | Path] = [toolpath, forces]
    if joints is not None:
        inputs.append(joints)
    check_not_input(output, inputs)
    output_file(output, "robot deflect", overwrite, [*inputs, stiffness, *_files(robot, tool)])
    m = _model(robot, stiffness, tool, tip_link)
    K = m.joint_stiffness  # fail early, before IK
    del K
    T_base_work = _placement(placement, m)
    tp = read_toolpath_file(toolpath)  # a CAM program: a clear error (no part here)
    log = read_force_log(forces)
    W = attach_to_toolpath(log, tp, by="time")
    if joints is not None:
        jl = read_joint_log(joints)
        if tp.time[0] < jl.time[0] - 1e-9 or tp.time[-1] > jl.time[-1] + 1e-9:
            raise InputError(
                f"toolpath times [{tp.time[0]:.3f}, {tp.time[-1]:.3f}] s are outside the joint log "
                f"[{jl.time[0]:.3f}, {jl.time[-1]:.3f}] s",
                file=joints,
                field="time",
            )
        q = np.stack([np.interp(tp.time, jl.time, jl.q[:, j]) for j in range(6)], axis=1)
        q = m.check_q(q, field=str(joints))
    else:
        given = [x for x in (start_joints, confdata, kuka_st) if x is not None]
        if len(given) > 1:
            raise InputError(
                "give at most one of --start-joints, --confdata, --kuka-st", field="--confdata"
            )
        if m.ik_note:
            state.warn(m.ik_note)  # one line, before the (slower) numerical solve
        with (
            warnings.catch_warnings(),
            _options_named(IK_OPTIONS),
            _unreachable_placement(placement),
        ):
            warnings.simplefilter("ignore", NumericalIKWarning)  # said just above
            q = ik_toolpath(
                m,
                tp.tip,
                T_base_work,
                tool_rotation=np.radians(tool_rotation),
                match_q=None
                if start_joints is None
                else np.radians(_floats(start_joints, 6, "--start-joints")),
                confdata=None if confdata is None else _ints(confdata, 4, "--confdata"),
                kuka_st=None if kuka_st is None else _ints(kuka_st, 2, "--kuka-st"),
            ).q
        if start_joints is not None:  # said back in degrees: radians typed show at once
            given_deg = _floats(start_joints, 6, "--start-joints")
            state.info(
                f"IK from --start-joints {', '.join(f'{v:g}' for v in given_deg)} deg (degrees, "
                "the controller's angles): the first point at "
                f"{', '.join(f'{v:.2f}' for v in np.degrees(q[0]))} deg"
            )
    frame = log.frame.strip().lower()
    R_base_work = T_base_work[:3, :3]
    T_tip = m.fk(q)
    if frame == "work":
        W_base = rotate_6(W, R_base_work)
    elif frame == "base":
        W_base = W
    elif frame in ("tip", "tool"):
        W_base = rotate_6(W, T_tip[:, :3, :3])
    else:
        raise InputError(
            f"force log frame {log.frame!r}: expected work, base or tip (move sensor wrenches to "
            "the tip first, roboisf.frames.transform_wrench)",
            file=forces,
            field="frame",
        )
    d_base = m.deflection(q, W_base)
    d_work = rotate_6(d_base, R_base_work.T)
    data = np.column_stack(
        [
            np.arange(len(tp)),
            tp.time,
            tp.tip * 1e3,
            d_work[:, :3] * 1e3,
            d_work[:, 3:],
            np.degrees(q),
        ]
    )
    head = (
        f"# roboisf robot deflection ({m.name})\n"
        "# units: time=s length=mm rotation=rad angle=deg\n# frame: work\n"
        "index,time,tip_x,tip_y,tip_z,dx,dy,dz,rx,ry,rz,q1,q2,q3,q4,q5,q6\n"
    )
    with atomic_write(output) as f:
        f.write(
            head + format_rows(data, ["%d", "%.6f"] + ["%.9f"] * 6 + ["%.9e"] * 3 + ["%.9f"] * 6)
        )
    state.info(
        f"wrote {output}: {len(tp)} points, mean |δ| "
        f"{np.linalg.norm(d_work[:, :3], axis=1).mean() * 1e3:.4f} mm"
    )
