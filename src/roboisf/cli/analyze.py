"""``roboisf analyze`` and ``roboisf virtual-cell``."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import DIR_HELP, Overwrite, Png, output_dir, study_inputs
from roboisf.errors import InputError

if TYPE_CHECKING:
    from roboisf.decompose.pipeline import AnalysisResult
    from roboisf.virtual.cell import VirtualCell
    from roboisf.virtual.equipment import Equipment

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``analyze`` and ``virtual-cell`` to ``app``."""
    app.command("analyze")(analyze_command)
    app.command("virtual-cell")(virtual_cell_command)


def analyze_command(
    study: Annotated[
        Path, typer.Argument(help="Study folder (with study.toml) or the study.toml.")
    ],
    output: Annotated[
        Path, typer.Option("--output", "-o", help=f"Results folder. {DIR_HELP}")
    ] = Path("results"),
    overwrite: Overwrite = False,
    png: Png = False,
    run: Annotated[
        str | None,
        typer.Option(
            help="With several robot runs: analyse only this one (default: each in turn, "
            "the report is the last run's with the iteration history)."
        ),
    ] = None,
) -> None:
    """Split a robot-formed part's error: springback, tool, tool holder, robot compliance.

    A study with several robot runs ([runs.robot], [runs.robot_2], … — successive
    compensated parts) is analysed run by run: the report and files are the last run's, with
    an Iterations section (per run and term: RMS, max, share; the improvement) and
    iterations.csv.

    Reads the study folder (docs/study.md): the part, tool and holder compliance, robot and
    placement, and a CNC and a robot run with their toolpath, force log, joint log and scan.
    Writes report.html, contributions.csv (mm, %), contributions_normal.csv, per_point.parquet,
    summary.json (versioned, schema_version; its fields and JSON Schema: docs/summary.md) and,
    with --png, figures/*.png. summary.json's diagnosis gives each suspect (robot
    stiffness; the force sensor's gain, bias, axial crosstalk, moment crosstalk and moment bias;
    the robot scan's shift and rotation; the robot's work object, its tilt and a thermal drift;
    springback coupling) a verdict — fault, ok or cannot_tell, the last also where two suspects
    leave the same trace — with a 95 % interval (docs/diagnosis.md). Ends with the warnings, the
    verdicts (study kind, robot model check, diagnosis) and the next command to run.
    """
    output_dir(output, "analyze", overwrite, study_inputs(study))
    from roboisf.decompose.pipeline import write_results

    state.imports_done()
    progress = state.progress()
    if _robot_only(study, run, output, progress):
        return
    result = _analyze_runs(study, run, progress)
    write_results(result, output, png=png, progress=progress)
    summary = result.summary.to_dict()  # the file's object, as the report reads it
    _print_table(result.contributions, summary)
    _print_verdicts(summary, study, output)


# virtual-cell's options, one named type each (typer reads the help from the Annotated metadata)
_PartOpt = Annotated[
    str | None,
    typer.Argument(
        help="cone (the paper's 71° cone), vwacf, or pyramid (a square truncated "
        "pyramid, 100 × 100 mm, 60°, 40 mm deep, 10 mm corner radius unless the "
        "--top-length … options say otherwise); or give --part instead."
    ),
]
_OutputOpt = Annotated[
    Path, typer.Option("--output", "-o", help=f"Study folder to write. {DIR_HELP}")
]
_ScanPointsOpt = Annotated[int, typer.Option(help="Points per scan.")]
_ForceRateOpt = Annotated[float, typer.Option(help="Force log sample rate [Hz].")]
_JointRateOpt = Annotated[
    float | None, typer.Option(help="Joint log sample rate [Hz] (default 250).")
]
_StepDownOpt = Annotated[
    float | None,
    typer.Option(
        help="Toolpath step-down [mm] (default 0.5). A coarse path (2) with "
        "--spacing 4 and few scan points makes a small demo cell in seconds."
    ),
]
_SpacingOpt = Annotated[float | None, typer.Option(help="Toolpath point spacing [mm] (default 1).")]
_RobotOpt = Annotated[str, typer.Option(help="Robot preset (roboisf robot list).")]
_StiffnessOpt = Annotated[
    Path | None,
    typer.Option(
        "--stiffness",
        help="Joint stiffness TOML ([stiffness] K = 6 values, N·m/rad, as `roboisf robot "
        "identify` writes): the robot's, for a preset without a published one (the KUKA and "
        "FANUC presets); written into the study's [robot] joint_stiffness.",
    ),
]
_ToolRotationOpt = Annotated[float, typer.Option(help="Tool rotation about its axis [deg].")]
_FeOpt = Annotated[
    bool, typer.Option("--fe/--beam", help="Tool/holder compliance by FE or beam model.")
]
_SeedOpt = Annotated[int, typer.Option(help="Random seed.")]
_LogFormatOpt = Annotated[
    str,
    typer.Option(
        help="Force and joint logs as parquet (SI, float32 channels, ~4.7x smaller "
        "than CSV; docs/study.md) or csv (the roboisf CSV with a '# units:' line)."
    ),
]
_PartFileOpt = Annotated[
    Path | None,
    typer.Option(
        "--part",
        help="Any part file (roboisf part …): the paper-like cell around it (Ø10 mm "
        "ball, IRB 7600 at 2.2 m, Aerens force). Instead of PART.",
    ),
]
_TopLengthOpt = Annotated[
    float | None, typer.Option(help="pyramid: opening along x [mm] (default 100).")
]
_TopWidthOpt = Annotated[
    float | None, typer.Option(help="pyramid: opening along y [mm] (default: square).")
]
_WallAngleOpt = Annotated[
    float | None, typer.Option(help="pyramid: wall angle [deg] (default 60).")
]
_DepthOpt = Annotated[float | None, typer.Option(help="pyramid: depth [mm] (default 40).")]
_CornerRadiusOpt = Annotated[
    float | None,
    typer.Option(help="pyramid: corner radius of the opening [mm] (default 10)."),
]
_TruthFileOpt = Annotated[
    Path | None,
    typer.Option(
        "--truth",
        help="Truth TOML: how the simulated cell differs from the model the study "
        "carries (joint stiffness scale, link compliance, kinematic error, sensor bias/"
        "gain/crosstalk, tool weight, scan misregistration, springback coupling and "
        "geometry rule, CNC compliance; mm, deg, N, N·m, kg). Keys override "
        "--scenario's. See "
        "docs/virtual-cell.md.",
    ),
]
_ScenarioOpt = Annotated[
    str | None,
    typer.Option(
        help="A truth shipped with roboisf: 'paper' (cone, vwacf) is set so the analysis "
        "reproduces the paper's Table 5 (robot share 40.28 % / 59.98 %)."
    ),
]
_ClockScaleOpt = Annotated[
    float,
    typer.Option(
        help="Log clock rate: log seconds per real second (1.02 = the controller's "
        "clock runs 2 % fast). With any clock option the runs get sync = "
        '"position" (robot, joint log) and "force" (CNC).',
        rich_help_panel="Equipment logs",
    ),
]
_ClockOffsetOpt = Annotated[
    float,
    typer.Option(
        help="Log time (s) at which the program starts (the logger runs before).",
        rich_help_panel="Equipment logs",
    ),
]
_PauseOpt = Annotated[
    list[str] | None,
    typer.Option(
        help="A stop: TIME,DURATION in s (nominal toolpath time, real seconds; the "
        "tool stands pressing). Repeat for more.",
        rich_help_panel="Equipment logs",
    ),
]
_ForceClockOffsetOpt = Annotated[
    float | None,
    typer.Option(
        help="The force logger has its own clock (a separate DAQ): its time (s) when "
        'the controller log starts; the study then says forces.clock = "own".',
        rich_help_panel="Equipment logs",
    ),
]
_ForceClockScaleOpt = Annotated[
    float,
    typer.Option(
        help="Own force clock: its seconds per real second.",
        rich_help_panel="Equipment logs",
    ),
]
_CncForceProfileOpt = Annotated[
    str,
    typer.Option(
        help="File layout of the CNC force log: roboisf, ati (Net F/T CSV) or kistler "
        "(DynoWare text, 3 components, decimal comma).",
        rich_help_panel="Equipment logs",
    ),
]
_RobotForceProfileOpt = Annotated[
    str,
    typer.Option(
        help="File layout of the robot's force log: roboisf, ati or kistler.",
        rich_help_panel="Equipment logs",
    ),
]
_JointProfileOpt = Annotated[
    str,
    typer.Option(
        help="File layout of the joint log: roboisf, abb (Time,J1..J6) or kuka "
        "(trace CSV, A1..A6, semicolons, decimal comma).",
        rich_help_panel="Equipment logs",
    ),
]
_ToolpathOpt = Annotated[
    Path | None,
    typer.Option(
        "--toolpath",
        help="Form the robot part with this commanded path instead of the nominal: a "
        "compensated program (roboisf compensate's compensated.csv, .mod, .src, .ls, "
        ".nc or any CAM program) with one forming move per toolpath point. Give the "
        "same options as the study it was computed from (same cell, truth, seed).",
        rich_help_panel="Re-forming (the loop)",
    ),
]
_FromStudyOpt = Annotated[
    Path | None,
    typer.Option(
        "--from",
        help="With --toolpath: copy this virtual-cell study (all its runs) and add the "
        "new part as its next robot run, robot_<k> — the iteration's history in one "
        "study. Checked to be the same cell.",
        rich_help_panel="Re-forming (the loop)",
    ),
]


def virtual_cell_command(
    part: _PartOpt = None,
    output: _OutputOpt = Path("study"),
    overwrite: Overwrite = False,
    scan_points: _ScanPointsOpt = 2_000_000,
    force_rate: _ForceRateOpt = 1000.0,
    joint_rate: _JointRateOpt = None,
    step_down: _StepDownOpt = None,
    spacing: _SpacingOpt = None,
    robot: _RobotOpt = "irb7600-500-2.55",
    stiffness: _StiffnessOpt = None,
    tool_rotation: _ToolRotationOpt = 0.0,
    fe: _FeOpt = False,
    seed: _SeedOpt = 0,
    log_format: _LogFormatOpt = "parquet",
    part_file: _PartFileOpt = None,
    top_length: _TopLengthOpt = None,
    top_width: _TopWidthOpt = None,
    wall_angle: _WallAngleOpt = None,
    depth: _DepthOpt = None,
    corner_radius: _CornerRadiusOpt = None,
    truth_file: _TruthFileOpt = None,
    scenario: _ScenarioOpt = None,
    clock_scale: _ClockScaleOpt = 1.0,
    clock_offset: _ClockOffsetOpt = 0.0,
    pause: _PauseOpt = None,
    force_clock_offset: _ForceClockOffsetOpt = None,
    force_clock_scale: _ForceClockScaleOpt = 1.0,
    cnc_force_profile: _CncForceProfileOpt = "roboisf",
    robot_force_profile: _RobotForceProfileOpt = "roboisf",
    joint_profile: _JointProfileOpt = "roboisf",
    toolpath: _ToolpathOpt = None,
    from_study: _FromStudyOpt = None,
) -> None:
    """Write a synthetic study (CNC and robot runs with known ground truth in truth/).

    The paper's parts, a pyramid, or any part file (--part PART.toml from `roboisf part …`,
    lengths in mm: cone, vwacf, profile, pyramid, an STL/STEP mesh) on a virtual IRB 7600:
    Aerens forming force (wall angle from the part's surface), VJM robot, tool and holder
    compliance, springback, 25 µm laser scans. Analyse it with `roboisf analyze`.

    Example: roboisf virtual-cell pyramid --wall-angle 50 --depth 30 -o S && roboisf analyze S

    Logs as real equipment keeps time (analyze must align them, docs/study.md):
    roboisf virtual-cell cone --clock-scale 1.02 --clock-offset 7 --pause 300,30 -o S

    The loop — form, compensate, re-form in the same cell (docs/compensate.md):
    roboisf virtual-cell pyramid --truth T.toml -o S1 && roboisf compensate S1 -o C1 &&
    roboisf virtual-cell pyramid --truth T.toml --toolpath C1/compensated.mod --from S1 -o S2
    """
    from roboisf.robot import load_stiffness
    from roboisf.virtual.cell import build_study

    if from_study is not None and toolpath is None:
        raise InputError("--from needs --toolpath (the program to re-form)", field="--from")
    output_dir(
        output,
        "virtual-cell",
        overwrite,
        [p for p in (toolpath, from_study, truth_file, part_file, stiffness) if p is not None],
    )
    shape = {
        "top_length": top_length,
        "top_width": top_width,
        "wall_angle": wall_angle,
        "depth": depth,
        "corner_radius": corner_radius,
    }
    _check_part_choice(part, part_file, shape)
    truth_kw = _truth_settings(truth_file, scenario, part if part_file is None else None)
    make = _cell_maker(part, part_file, shape)
    path_kw = _path_settings(step_down, spacing, joint_rate, tool_rotation)
    cell = make(
        scan_points=scan_points,
        **path_kw,
        force_rate=force_rate,
        robot=robot,
        joint_stiffness=None if stiffness is None else load_stiffness(stiffness, robot=robot),
        tool_rotation=math.radians(tool_rotation),
        compliance_method="fe" if fe else "beam",
        seed=seed,
        **truth_kw,
    )
    logs = functools.partial(
        _equipment,
        clock_scale=clock_scale,
        clock_offset=clock_offset,
        pause=pause,
        force_clock_offset=force_clock_offset,
        force_clock_scale=force_clock_scale,
        cnc_force_profile=cnc_force_profile,
        robot_force_profile=robot_force_profile,
        joint_profile=joint_profile,
    )
    if toolpath is not None:
        logs(check_clean=True)
        _reform(cell, toolpath, from_study, output, log_format)
        return
    equipment = logs()
    build_study(cell, output, progress=state.progress(), equipment=equipment, log_format=log_format)
    state.info(f"wrote the study {cell.name!r} to {output}/ (analyse: roboisf analyze {output})")


#: the built-in parts of ``virtual-cell PART``
def _built_in_parts() -> tuple[str, ...]:
    """The built-in virtual cells' names (:data:`roboisf.virtual.builtin.BUILTIN_CELLS`)."""
    from roboisf.virtual.builtin import BUILTIN_CELLS

    return tuple(BUILTIN_CELLS)


def _check_part_choice(
    part: str | None, part_file: Path | None, shape: dict[str, float | None]
) -> None:
    """PART or --part, one of the built-in parts, and the pyramid's shape options only with
    the built-in pyramid (mm, deg)."""
    given = [k for k, v in shape.items() if v is not None]
    if given and part != "pyramid":
        raise InputError(
            "applies to the built-in pyramid only (PART = pyramid); a part file carries "
            "its own shape",
            field="--" + given[0].replace("_", "-"),
        )
    if (part is None) == (part_file is None):
        raise InputError("give either PART (cone or vwacf) or --part PART.toml", field="PART")
    names = _built_in_parts()
    if part is not None and part not in names:
        raise InputError(
            f"unknown part {part!r}; expected one of {', '.join(names)} (or --part FILE)",
            field="PART",
        )


def _cell_maker(
    part: str | None, part_file: Path | None, shape: dict[str, float | None]
) -> Callable[..., VirtualCell]:
    """The virtual-cell factory of the chosen part (checked by :func:`_check_part_choice`):
    a part file in the paper-like cell, the pyramid of ``shape`` (mm, deg; None: the default)
    or a paper part."""
    from roboisf.parts import Pyramid, load_part
    from roboisf.virtual.builtin import BUILTIN_CELLS
    from roboisf.virtual.cell import PYRAMID, part_cell, pyramid_cell

    if part_file is not None:
        p = load_part(part_file)
        return functools.partial(part_cell, part_file.stem, p)
    if part == "pyramid":
        top_length, top_width = shape["top_length"], shape["top_width"]
        wall_angle, depth = shape["wall_angle"], shape["depth"]
        corner_radius = shape["corner_radius"]
        length = PYRAMID.top_length if top_length is None else top_length * 1e-3
        pyr = Pyramid(
            length,
            length if top_width is None else top_width * 1e-3,
            PYRAMID.wall_angle if wall_angle is None else math.radians(wall_angle),
            PYRAMID.depth if depth is None else depth * 1e-3,
            corner_radius=PYRAMID.corner_radius if corner_radius is None else corner_radius * 1e-3,
        )
        return functools.partial(pyramid_cell, pyr)
    assert part is not None
    return BUILTIN_CELLS[part].make


def _path_settings(
    step_down: float | None, spacing: float | None, joint_rate: float | None, tool_rotation: float
) -> dict[str, float]:
    """The toolpath's keyword arguments (SI) from --step-down, --spacing [mm] and --joint-rate
    [Hz], each checked; --tool-rotation [deg] checked plausible."""
    coarse = {"step_down": step_down, "spacing": spacing}
    for key, mm in coarse.items():
        if mm is not None and not (math.isfinite(mm) and mm > 0):
            raise InputError(f"must be > 0 mm, got {mm}", field="--" + key.replace("_", "-"))
    from roboisf.plausible import check_plausible

    check_plausible(tool_rotation, "angle", field="--tool-rotation")
    path_kw: dict[str, float] = {k: v * 1e-3 for k, v in coarse.items() if v is not None}
    if joint_rate is not None:
        path_kw["joint_rate"] = joint_rate
    return path_kw


def _equipment(
    *,
    clock_scale: float,
    clock_offset: float,
    pause: list[str] | None,
    force_clock_offset: float | None,
    force_clock_scale: float,
    cnc_force_profile: str,
    robot_force_profile: str,
    joint_profile: str,
    check_clean: bool = False,
) -> Equipment | None:
    """How the virtual equipment keeps time and lays out its logs (clocks in s, the force
    logger's own clock when --force-clock-offset or --force-clock-scale is given); with
    ``check_clean`` (a re-formed part, --toolpath: written with clean roboisf logs) the
    equipment-log options are refused and None returned."""
    from roboisf.virtual.equipment import Equipment, parse_pauses

    if check_clean:
        clean = (clock_scale, clock_offset, force_clock_scale) == (1.0, 0.0, 1.0) and not (
            pause or force_clock_offset is not None
        )
        profiles = {cnc_force_profile, robot_force_profile, joint_profile}
        if not clean or profiles != {"roboisf"}:
            raise InputError(
                "a re-formed part is written with clean roboisf logs; leave out the "
                "equipment-log options",
                field="--toolpath",
            )
        return None

    own = force_clock_offset is not None or force_clock_scale != 1.0
    return Equipment(
        clock_scale=clock_scale,
        offset=clock_offset,
        pauses=parse_pauses(pause),
        force_clock="own" if own else "joint",
        force_offset=force_clock_offset or 0.0,
        force_clock_scale=force_clock_scale,
        cnc_force_profile=cnc_force_profile,
        robot_force_profile=robot_force_profile,
        joint_profile=joint_profile,
    )


def _robot_only(study_path: Path, run: str | None, output: Path, progress: object) -> bool:
    """A study without a CNC run: the model-based springback of its robot run (the last, or
    ``run``) written to ``output``; False for a study with a CNC run."""
    from roboisf.study import load_study

    study = load_study(study_path)
    if study.has_cnc:
        return False
    from roboisf.decompose.robot_only import analyze_robot_only, write_robot_only

    sub = study.for_run(study.robot_runs[-1].name if run is None else run)
    result = analyze_robot_only(sub, progress=progress)
    write_robot_only(result, output, progress=progress)
    sb = result.estimate
    if sb.separable:
        st = sb.stats
        state.info(
            f"{sub.robot_run.name}: springback (model-based, no CNC run) mean |dn| "
            f"{st['mean_abs_dn'] * 1e3:.3f} mm (model interval {st['mean_abs_dn_lo'] * 1e3:.3f}"
            f"–{st['mean_abs_dn_hi'] * 1e3:.3f}); {sb.reason}"
        )
    else:
        state.info(f"{sub.robot_run.name}: springback not separable: {sb.reason}")
    state.info(f"report: {output / 'report.html'}")
    return True


def _analyze_runs(study_path: Path, run: str | None, progress: object) -> AnalysisResult:
    """The analysis of ``run`` or, with several robot runs, of each with the history
    (``summary.iterations``) on the last one's result."""
    import dataclasses

    from roboisf.decompose.pipeline import analyze
    from roboisf.study import load_study

    study = load_study(study_path)
    names = [r.name for r in study.robot_runs]
    if run is not None:
        names = [study.for_run(run).robot_run.name]
    rows, result = [], None
    for name in names:
        sub = study.for_run(name)
        result = analyze(sub, progress=progress)  # type: ignore[arg-type]
        # the report's tables (pandas) after the analysis: not loaded under the scans' peak
        from roboisf.report.iterations import history_row

        row = history_row(
            name,
            sub.robot_run.toolpath.name,
            result.per_point,
            result.contributions_normal,
        )
        rows.append(row)
        if len(names) > 1:
            state.info(
                f"{name} ({row['program']}): mean |dn| {row['mean_abs_dn_mm']:.3f} mm, "
                f"{100 * (1 - row['mean_abs_dn_mm'] / rows[0]['mean_abs_dn_mm']):.1f} % below "
                "the first run"
            )
    assert result is not None
    summary = dataclasses.replace(
        result.summary,
        robot_run=names[-1],  # compensate --results checks it
        iterations=rows if len(rows) > 1 else None,
    )
    return dataclasses.replace(result, summary=summary)


def _reform(
    cell: VirtualCell, program: Path, previous: Path | None, output: Path, log_format: str
) -> None:
    """``virtual-cell --toolpath``: the commanded part in the same cell (clean logs)."""
    from roboisf.virtual.reform import reform_study

    _, run = reform_study(
        cell, program, output, previous=previous, log_format=log_format, progress=state.progress()
    )
    state.info(
        f"wrote the study {cell.name!r} to {output}/, robot run {run!r} formed with "
        f"{program.name} (analyse: roboisf analyze {output})"
    )


def _truth_settings(
    truth_file: Path | None, scenario: str | None, part: str | None
) -> dict[str, object]:
    """``{"truth": TruthSpec}`` for the cell (empty when neither --truth nor --scenario)."""
    if truth_file is None and scenario is None:
        return {}
    from roboisf.virtual.truth import load_truth

    if scenario is not None and part is None:
        raise InputError(
            "a scenario exists for the built-in parts (cone, vwacf) only; use --truth FILE",
            field="--scenario",
        )
    return {"truth": load_truth(truth_file, scenario=scenario, part=part)}


def _print_table(df: object, summary: dict) -> None:
    if state.verbosity < 1:  # quiet: no table to build (rich's table: 0.02-0.07 s)
        return
    import pandas as pd
    from rich.markup import escape
    from rich.table import Table

    assert isinstance(df, pd.DataFrame)
    t = Table(title=f"{escape(str(summary['study']))}: contributions (per-axis, mm)")
    for c in ("factor", "|δx|", "|δy|", "|δz|", "R_m", "share %"):
        t.add_column(c, justify="left" if c == "factor" else "right")
    for r in df.itertuples():
        t.add_row(
            str(r.factor),
            f"{r.mean_abs_dx:.3f}",
            f"{r.mean_abs_dy:.3f}",
            f"{r.mean_abs_dz:.3f}",
            f"{r.R_m:.3f}",
            f"{r.share_percent:.1f}",
        )
    state.out.print(t)


def next_command(summary: dict, study: Path, output: Path) -> str:
    """The command to run after ``analyze``: compensate the study from these results — with the
    stiffness identified from the run when the robot model check failed (``mismatch``) and one
    was written."""
    import shlex

    args = ["roboisf", "compensate", str(study), "--results", str(output)]
    vc = summary.get("vjm_check") or {}
    if vc.get("verdict") == "mismatch" and summary.get("identified_stiffness"):
        args += ["--stiffness", str(output / "identified_stiffness.toml")]
    cmd = " ".join(shlex.quote(a) for a in args)
    if unattributed_offset(summary):  # compensate refuses to guess whose it is: the user says
        cmd += " --offset SCAN_OR_PART"
    return cmd + " -o compensated"


def unattributed_offset(summary: dict) -> bool:
    """The diagnosis found an offset of the robot part beyond its limit that it cannot
    attribute (the robot scan's registration or the robot's work object): ``compensate`` then
    needs ``--offset scan|part``. Not where the robot's own compliance may carry the offset as
    well (:data:`~roboisf.decompose.diagnose.ROBOT_MISFIT`): compensate corrects it with the
    robot term (docs/diagnosis.md)."""
    from roboisf.decompose.diagnose import ROBOT_MISFIT

    for e in summary.get("diagnosis") or []:
        if not isinstance(e, dict) or e.get("suspect") not in (
            "scan_shift",
            "scan_rotation",
            "work_object_tilt",
        ):
            continue
        lo, lim = e.get("ci_low"), (e.get("detection_limits") or [None, None])[1]
        if ROBOT_MISFIT in str(e.get("explanation", "")):
            continue
        if e.get("verdict") == "cannot_tell" and lo is not None and lim is not None and lo > lim:
            return True
    return False


def _print_verdicts(summary: dict, study: Path, output: Path) -> None:
    """The end of ``analyze``'s output: the warnings, the verdicts (study kind, model check,
    diagnosis), the report and the next command."""
    from roboisf.report.statements import verdict_lines

    for line in summary.get("warnings") or []:
        state.warn(str(line))
    for line in verdict_lines(summary):
        state.info(line)
    state.info(f"report: {output / 'report.html'}")
    diagnosis = summary.get("diagnosis")
    faults = [
        e
        for e in (diagnosis if isinstance(diagnosis, list) else [])
        if isinstance(e, dict)
        and e.get("verdict") == "fault"
        and e.get("suspect") != "robot_stiffness"
    ]
    cmd = next_command(summary, study, output)
    if faults:
        from roboisf.report.statements import suspect_name

        names = ", ".join(suspect_name(str(e["suspect"])) for e in faults)
        state.info(f"next: check the {names} the diagnosis names (report.html), then: {cmd}")
    elif unattributed_offset(summary):
        state.info(
            "next: check the robot scan's reference marks, or measure the robot's work object "
            "(whose is the offset the diagnosis cannot attribute), then, with --offset scan or "
            "--offset part: " + cmd
        )
    else:
        state.info(f"next: {cmd}")
