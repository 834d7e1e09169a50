"""``roboisf compensate``: the compensated toolpath and robot programs, with a before/after report.

Examples (mm)::

    roboisf compensate study/ -o compensated/                 # runs analyze first
    roboisf compensate study/ --results results/ -o comp/     # reuse an analyze output
    roboisf compensate --virtual cone --iterations 3 -o comp/ # iterate on the virtual cell
    roboisf compensate study/ --no-springback -o comp/        # robot/tool pre-deflection only
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import DIR_HELP, Overwrite, output_dir, study_inputs
from roboisf.errors import InputError

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``compensate`` to ``app``."""

    @app.command("compensate")
    def _compensate(
        study: Annotated[
            Path | None,
            typer.Argument(help="Study folder (or its study.toml) whose robot part to correct."),
        ] = None,
        output: Annotated[
            Path, typer.Option("--output", "-o", help=f"Output folder. {DIR_HELP}")
        ] = Path("compensated"),
        overwrite: Overwrite = False,
        results: Annotated[
            Path | None,
            typer.Option(
                help="An `roboisf analyze` results folder of STUDY to reuse; refused when its "
                "fingerprint (summary.json) is not that of STUDY as its files are now."
            ),
        ] = None,
        previous: Annotated[
            Path | None,
            typer.Option(
                help="The compensate output that formed STUDY's robot part (next iteration)."
            ),
        ] = None,
        virtual: Annotated[
            str | None,
            typer.Option(
                help="Iterate on the virtual cell instead: cone, vwacf or pyramid (the "
                "virtual-cell pyramid: 100 mm, 60°, 40 mm deep)."
            ),
        ] = None,
        iterations: Annotated[
            int, typer.Option(help="Virtual cell: form–measure–adjust iterations.")
        ] = 3,
        step_down: Annotated[
            float, typer.Option(help="Virtual cell: step-down between laps [mm].")
        ] = 0.5,
        spacing: Annotated[
            float, typer.Option(help="Virtual cell: point spacing along a lap [mm].")
        ] = 1.0,
        compliance: Annotated[
            bool,
            typer.Option(
                "--compliance/--no-compliance", help="Pre-deflect for robot, tool and holder."
            ),
        ] = True,
        springback: Annotated[
            bool,
            typer.Option(
                "--springback/--no-springback",
                help="Displacement adjustment from the measured deviation.",
            ),
        ] = True,
        gain: Annotated[float, typer.Option(help="Adjustment gain λ, in (0, 2).")] = 0.8,
        smooth_along: Annotated[
            float, typer.Option(help="Gaussian σ of the deviation along a lap [mm].")
        ] = 3.0,
        smooth_across: Annotated[
            float, typer.Option(help="Gaussian σ of the deviation across laps [mm].")
        ] = 1.0,
        hold_gaps: Annotated[
            bool,
            typer.Option(
                "--hold-gaps",
                help="Keep points without data in reach uncompensated (flagged) "
                "instead of failing.",
            ),
        ] = False,
        relax: Annotated[float, typer.Option(help="Fixed-point under-relaxation ω.")] = 0.8,
        max_iter: Annotated[int, typer.Option(help="Fixed-point iterations at most.")] = 50,
        tol: Annotated[float, typer.Option(help="Fixed-point tolerance [mm].")] = 1e-4,
        partial: Annotated[
            bool,
            typer.Option(
                "--partial",
                help="Write a non-converged compensation with per-point flags "
                "(complete=false) instead of failing.",
            ),
        ] = False,
        max_overbend: Annotated[
            float, typer.Option(help="Largest intended over-bend into the part [mm].")
        ] = 2.0,
        rim_blend: Annotated[
            float,
            typer.Option(
                help="Last part of the rim band over which the springback offset of the first "
                "lap below it ramps in [mm] (0: a hard edge, a step in the command).",
            ),
        ] = 5.0,
        tool_mass: Annotated[float, typer.Option(help="Tool + holder mass [kg].")] = 2.0,
        stiffness: Annotated[
            Path | None,
            typer.Option(
                "--stiffness",
                help="Joint stiffness TOML ([stiffness] K = [6] N*m/rad) replacing the study's: "
                "`roboisf robot identify`, or identified_stiffness.toml of `roboisf analyze` "
                "(identified from the forming run).",
            ),
        ] = None,
        png: Annotated[bool, typer.Option("--png/--no-png", help="Also write the PNG.")] = True,
    ) -> None:
        """Compensate the toolpath: robot/tool/holder pre-deflection and springback adjustment.

        Writes compensated.csv, compensated.mod (RAPID; + part modules compensated_<k>.mod for
        long paths), compensated.src/.dat (KRL), compensated.ls (FANUC) — all in the study's
        frames (placement, tool) with the configuration data of its IK branch —,
        compensated.nc (G-code: nominal + springback adjustment only, no robot pre-deflection),
        per_point.csv (mm, flags), compensation.json and compensation.html/.png (mean |dn| per
        lap before/after, commanded offset per lap, the largest lap-to-lap step).
        """
        study_inputs(study)  # a mistyped STUDY reported before the numeric stack is imported
        import numpy as np

        from roboisf.compensate import CompensationOptions, write_compensation

        for flag, v in (
            ("--smooth-along", smooth_along),
            ("--smooth-across", smooth_across),
            ("--tol", tol),
            ("--max-overbend", max_overbend),
            ("--rim-blend", rim_blend),
            ("--step-down", step_down),
            ("--spacing", spacing),
        ):
            if not (math.isfinite(v) and v >= 0) or (
                flag in ("--step-down", "--spacing") and v == 0
            ):
                raise InputError(f"must be ≥ 0 (step and spacing > 0), got {v:g}", field=flag)
            if (
                v > 1000
            ):  # lengths along a part: more than a metre is a unit slip (roboisf.plausible)
                raise InputError(
                    f"{v:g} mm is longer than any forming part; check the unit (mm)", field=flag
                )
        if not (math.isfinite(gain) and 0 < gain < 2):  # before anything is computed
            raise InputError(
                f"must be in (0, 2) for the iteration to contract, got {gain:g}", field="--gain"
            )
        opts = CompensationOptions(
            compliance=compliance,
            springback=springback,
            gain=gain,
            along=smooth_along * 1e-3,
            across=smooth_across * 1e-3,
            on_gap="hold" if hold_gaps else "raise",
            relax=relax,
            tol=tol * 1e-3,
            max_iter=max_iter,
            partial=partial,
            max_overbend=max_overbend * 1e-3,
            rim_blend=rim_blend * 1e-3,
        )
        progress = state.progress()
        if (study is None) == (virtual is None):
            raise InputError(
                "give either a STUDY folder or --virtual cone|vwacf|pyramid", field="STUDY"
            )
        if stiffness is not None and virtual is not None:
            raise InputError(
                "--stiffness applies to a STUDY (the virtual cell knows its robot)",
                field="--stiffness",
            )
        output_dir(
            output, "compensate", overwrite, [*study_inputs(study), results, previous, stiffness]
        )
        if virtual is not None:
            cell_kw = {"step_down": step_down * 1e-3, "spacing": spacing * 1e-3}
            _virtual(virtual, iterations, cell_kw, opts, output, tool_mass, png, progress)
            return
        from roboisf.compensate.study import compensate_study

        assert study is not None
        sc = compensate_study(
            study,
            results=results,
            previous=previous,
            options=opts,
            tool_mass=tool_mass,
            stiffness=stiffness,
            progress=progress,
        )
        write_compensation(
            sc.compensation,
            output,
            T_base_work=sc.T_base_work,
            tool=sc.tool,
            tool_rotation=sc.tool_rotation,
            robot=sc.robot,
            dn_before=sc.dn_before,
            dn_after=sc.dn_after,
            after_label="predicted",
            inputs=sc.inputs,
            png=png,
            progress=progress,
        )
        s = sc.compensation.summary()
        state.info(
            f"mean |dn| {np.nanmean(np.abs(sc.dn_before)) * 1e3:.3f} mm → predicted "
            f"{np.nanmean(np.abs(sc.dn_after)) * 1e3:.3f} mm; max commanded offset "
            f"{s['max_command_offset_mm']:.3f} mm; report: {output / 'compensation.html'}"
        )


def _virtual(
    name: str,
    iterations: int,
    cell_kw: dict[str, float],
    opts: object,
    output: Path,
    tool_mass: float,
    png: bool,
    progress: object,
) -> None:
    from dataclasses import replace

    from roboisf.compensate import CompensationOptions, write_compensation
    from roboisf.compensate.virtual import iterate_virtual
    from roboisf.io.program import RobotTool
    from roboisf.virtual.cell import paper_cone_cell, paper_vwacf_cell, pyramid_cell

    makers = {"cone": paper_cone_cell, "vwacf": paper_vwacf_cell, "pyramid": pyramid_cell}
    if name not in makers:
        raise InputError(
            f"unknown part {name!r}; expected cone, vwacf or pyramid", field="--virtual"
        )
    if iterations < 1:
        raise InputError(f"must be ≥ 1, got {iterations}", field="--iterations")
    assert isinstance(opts, CompensationOptions)
    cell = makers[name](**cell_kw)
    run = iterate_virtual(cell, iterations=iterations, options=opts, progress=progress)  # type: ignore[arg-type]
    comp = run.commands[-1]
    means = (run.mean_abs_dn * 1e3).tolist()
    comp = replace(comp, meta={"cell": cell.name, "mean_abs_dn_per_iteration_mm": means})
    robot, T_base_work = cell.cell.robot, cell.cell.T_base_work  # frames, tool, IK branch
    write_compensation(
        comp,
        output,
        T_base_work=T_base_work,
        tool=RobotTool(length=float(robot.T_flange_tip[2, 3]), mass=tool_mass),
        tool_rotation=cell.tool_rotation,
        robot=robot,
        dn_before=run.truths[0].dn_robot,
        dn_after=run.truths[-1].dn_robot,
        after_label="virtual cell",
        png=png,
        progress=progress,  # type: ignore[arg-type]
    )
    state.info(
        "mean |dn| per iteration [mm]: "
        + " → ".join(f"{m:.3f}" for m in means)
        + f"; report: {output / 'compensation.html'}"
    )
