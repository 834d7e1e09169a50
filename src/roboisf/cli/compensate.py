"""``roboisf compensate``: the compensated toolpath and robot programs, with a before/after report.

Examples (mm)::

    roboisf compensate study/ -o compensated/                 # runs analyze first
    roboisf compensate study/ --results results/ -o comp/     # reuse an analyze output
    roboisf compensate --virtual cone --iterations 3 -o comp/ # iterate on the virtual cell
    roboisf compensate study/ --no-springback -o comp/        # robot/tool pre-deflection only
    roboisf compensate --virtual part.toml --truth truth.toml -o comp/  # any part, a truth
    roboisf compensate study2/ -o comp2/  # the newest robot run, formed with comp/'s program:
                                          # updates its offsets (the run's `compensation` key)
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import DIR_HELP, Overwrite, Png, output_dir, study_inputs
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
                help="Iterate on the virtual cell instead: cone, vwacf, pyramid (the "
                "virtual-cell pyramid: 100 mm, 60°, 40 mm deep) or any part file "
                "(roboisf part …, e.g. a mesh part)."
            ),
        ] = None,
        truth_file: Annotated[
            Path | None,
            typer.Option(
                "--truth",
                help="Virtual cell: a truth TOML (how the cell differs from the model, "
                "docs/virtual-cell.md), e.g. [robot] joint_stiffness_scale = 0.6.",
            ),
        ] = None,
        run: Annotated[
            str | None,
            typer.Option(
                help="The robot run of STUDY to correct (default: the last, the newest part)."
            ),
        ] = None,
        target: Annotated[
            float,
            typer.Option(
                help="Stopping rule: the wall's mean |deviation| at which the part is right [mm]."
            ),
        ] = 0.05,
        predicted: Annotated[
            Path | None,
            typer.Option(
                help="A `roboisf predict` output folder: write the first-part program of a "
                "part not yet formed (pre-deflection for the predicted robot, tool and holder "
                "deflection, springback adjustment by the learned springback)."
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
        offset: Annotated[
            str | None,
            typer.Option(
                "--offset",
                help="scan or part: whose is an offset of the robot part (sideways, or turned "
                "about the part axis) that the analysis cannot attribute — the robot scan's "
                "registration (scan: the part is right, left out of the correction) or the "
                "robot's work object (part: the robot formed it displaced, corrected). Without "
                "it such an offset is refused (exit 2); check the scan's reference marks or "
                "measure the work object to tell (docs/compensate.md).",
            ),
        ] = None,
        png: Png = False,
    ) -> None:
        """Compensate the toolpath: robot/tool/holder pre-deflection and springback adjustment.

        Writes compensated.csv, compensated.mod (RAPID; + part modules compensated_<k>.mod for
        long paths), compensated.src/.dat (KRL), compensated.ls (FANUC) — all in the study's
        frames (placement, tool) with the configuration data of its IK branch —,
        compensated.nc (G-code: nominal + springback adjustment only, no robot pre-deflection),
        per_point.csv (mm, flags), compensation.json and compensation.html (and .png with --png):
        mean |dn| per lap before/after, commanded offset per lap, the largest lap-to-lap step.
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
            ("--target", target),
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
        if offset is not None and offset not in ("scan", "part"):  # before anything is computed
            raise InputError(
                f"expected scan (the robot scan's registration) or part (the robot's work "
                f"object), got {offset!r}",
                field="--offset",
            )
        if offset is not None and study is None:
            raise InputError("applies to a STUDY", field="--offset")
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
        if sum(x is not None for x in (study, virtual, predicted)) != 1:
            raise InputError(
                "give either a STUDY folder, --virtual cone|vwacf|pyramid|PART.toml or "
                "--predicted DIR",
                field="STUDY",
            )
        if predicted is not None:
            if stiffness is not None or results is not None or previous is not None:
                raise InputError(
                    "--stiffness, --results and --previous apply to a STUDY (the prediction "
                    "carries its robot and terms)",
                    field="--predicted",
                )
            output_dir(output, "compensate", overwrite, [predicted])
            _predicted(predicted, opts, output, tool_mass, png, progress)
            return
        if stiffness is not None and virtual is not None:
            raise InputError(
                "--stiffness applies to a STUDY (the virtual cell knows its robot)",
                field="--stiffness",
            )
        if truth_file is not None and virtual is None:
            raise InputError("applies to --virtual", field="--truth")
        if run is not None and study is None:
            raise InputError("applies to a STUDY", field="--run")
        output_dir(
            output,
            "compensate",
            overwrite,
            [*study_inputs(study), results, previous, stiffness, truth_file],
        )
        if virtual is not None:
            cell_kw: dict[str, object] = {"step_down": step_down * 1e-3, "spacing": spacing * 1e-3}
            _virtual(
                virtual, truth_file, iterations, cell_kw, opts, output, tool_mass, png, progress
            )
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
            run=run,
            target=target * 1e-3,
            progress=progress,
            offset=offset,
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
            f"{sc.compensation.meta['run']}: mean |dn| {np.nanmean(np.abs(sc.dn_before)) * 1e3:.3f}"
            f" mm → predicted {np.nanmean(np.abs(sc.dn_after)) * 1e3:.3f} mm; max commanded "
            f"offset {s['max_command_offset_mm']:.3f} mm; report: {output / 'compensation.html'}"
        )
        state.info(_stopping_line(sc.compensation.meta["stopping"]))
        for key in ("unattributed_offset", "thermal_drift"):  # what the diagnosis left open
            note = (sc.compensation.meta.get(key) or {}).get("note")
            if note:
                state.warn(str(note))


def _stopping_line(rec: dict) -> str:
    """The stopping rule's verdict, one line."""
    m, t = rec["mean_abs_dn_mm"], rec["target_mm"]
    if rec["reason"] == "target":
        return f"stop: mean |dn| {m:.3f} mm ≤ target {t:g} mm — the part is right"
    ratio = rec.get("ratio_to_previous")
    if rec["reason"] == "stalled":
        return (
            f"stop: mean |dn| {m:.3f} mm is {ratio:.2f}× the previous part's (not below "
            f"{rec['stall_ratio']:g}×): the iteration no longer gains; lower --gain or check "
            "the model"
        )
    gain = "" if ratio is None else f", {ratio:.2f}× the previous part's"
    return f"continue: mean |dn| {m:.3f} mm > target {t:g} mm{gain}; form the new program"


def _virtual(
    name: str,
    truth_file: Path | None,
    iterations: int,
    cell_kw: dict[str, object],
    opts: object,
    output: Path,
    tool_mass: float,
    png: bool,
    progress: object,
) -> None:
    from dataclasses import replace

    from roboisf.cam.program import RobotTool
    from roboisf.compensate import CompensationOptions, write_compensation
    from roboisf.compensate.virtual import iterate_virtual
    from roboisf.virtual.builtin import BUILTIN_CELLS

    if iterations < 1:
        raise InputError(f"must be ≥ 1, got {iterations}", field="--iterations")
    assert isinstance(opts, CompensationOptions)
    if truth_file is not None:
        from roboisf.virtual.truth import load_truth

        cell_kw = {**cell_kw, "truth": load_truth(truth_file)}
    if name in BUILTIN_CELLS:
        cell = BUILTIN_CELLS[name].make(**cell_kw)
    elif Path(name).is_file():
        from roboisf.parts import load_part
        from roboisf.virtual.cell import part_cell

        cell = part_cell(Path(name).stem, load_part(name), **cell_kw)
    else:
        raise InputError(
            f"unknown part {name!r}; expected {', '.join(BUILTIN_CELLS)} or a part file",
            field="--virtual",
        )
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


def _predicted(
    folder: Path, opts: object, output: Path, tool_mass: float, png: bool, progress: object
) -> None:
    """The first-part program from a ``roboisf predict`` folder: the predicted total normal
    error is the "measured" deviation of the nominal command (docs/history.md)."""
    import json

    import numpy as np
    import pandas as pd

    from roboisf.cam.program import RobotTool
    from roboisf.compensate import CompensationOptions, compensate, write_compensation
    from roboisf.compensate.cell import cell_deflection_model
    from roboisf.learn.predict import PredictionSetup

    assert isinstance(opts, CompensationOptions)
    meta, table = folder / "prediction.json", folder / "prediction.parquet"
    for f in (meta, table):
        if not f.is_file():
            raise InputError(f"no {f.name}: not a `roboisf predict` output", file=folder)
    try:
        summary = json.loads(meta.read_text(encoding="utf-8"))
        setup = PredictionSetup.from_json(summary["setup"], str(meta))
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise InputError(f"not a roboisf prediction ({e})", file=meta) from None
    try:
        pp = pd.read_parquet(table)
    except Exception as e:  # pyarrow raises several types for a damaged file
        raise InputError(f"not a readable Parquet table ({e})", file=table) from None
    cell, tp = setup.build()
    need = ["contact_x", "contact_y", "contact_z", "total_dn", "Fx", "Fy", "Fz", "Mx", "My", "Mz"]
    missing = [c for c in need if c not in pp.columns]
    if missing:
        raise InputError(f"missing columns {', '.join(missing)}", file=table)
    contact = pp[["contact_x", "contact_y", "contact_z"]].to_numpy(float) * 1e-3
    if len(pp) != len(tp) or np.max(np.abs(contact - tp.contact)) > 1e-6:
        raise InputError(
            "its toolpath is not the one its setup gives (edited, or another roboisf)", file=table
        )
    W = pp[["Fx", "Fy", "Fz", "Mx", "My", "Mz"]].to_numpy(float)
    dn = pp["total_dn"].to_numpy(float) * 1e-3
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(dn))):
        raise InputError("non-finite wrench or total_dn values", file=table)
    from roboisf.compensate.pipeline import rim_blend
    from roboisf.scan.deviation import default_rim_band

    rim = default_rim_band(cell.part.depth)
    comp = compensate(
        cell.part,
        tp,
        model=cell_deflection_model(cell, progress=progress),  # type: ignore[arg-type]
        wrench=W,
        deviation=dn,
        blend=rim_blend(tp.depth, rim, opts.rim_blend) if opts.rim_blend > 0 else None,
        options=opts,
        progress=progress,  # type: ignore[arg-type]
    )
    from dataclasses import replace

    comp = replace(comp, meta={"predicted": str(folder), "first_part": True})
    robot = cell.robot
    write_compensation(
        comp,
        output,
        T_base_work=cell.T_base_work,
        tool=RobotTool(length=float(robot.T_flange_tip[2, 3]), mass=tool_mass),
        tool_rotation=cell.tool_rotation,
        robot=robot,
        dn_before=dn,
        inputs=(folder,),
        png=png,
        progress=progress,  # type: ignore[arg-type]
    )
    state.info(
        f"first-part program from the prediction (mean |dn| {np.mean(np.abs(dn)) * 1e3:.3f} mm "
        f"predicted for the nominal program); report: {output / 'compensation.html'}"
    )
