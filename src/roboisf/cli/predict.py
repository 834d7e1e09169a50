"""``roboisf predict``: the error map of a part not yet formed, from the cell's history.

Example::

    roboisf predict --part dome.toml --history history.db --placement 2200,-500,200,0 -o pred/
    roboisf compensate --predicted pred/ -o first_part/     # the first-part program
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import DIR_HELP, Overwrite, Png, output_dir
from roboisf.errors import InputError

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add ``predict`` to ``app``."""

    @app.command("predict")
    def _predict(
        part: Annotated[
            Path, typer.Option("--part", help="The part not yet formed (roboisf part …).")
        ],
        history: Annotated[
            str,
            typer.Option(
                "--history",
                help="The cell's history (`roboisf history add`): an SQLite file or "
                "postgresql://… URL.",
            ),
        ],
        output: Annotated[
            Path, typer.Option("--output", "-o", help=f"Output folder. {DIR_HELP}")
        ] = Path("prediction"),
        overwrite: Overwrite = False,
        robot: Annotated[str, typer.Option("--robot", "-r", help="Robot preset.")] = (
            "irb7600-500-2.55"
        ),
        placement: Annotated[
            str | None,
            typer.Option(
                help="Work frame in the robot base x,y,z,yaw (mm, deg); default: the paper "
                "cell's (2200,-500,200,0) for the IRB 7600, else the preset's."
            ),
        ] = None,
        step_down: Annotated[float, typer.Option(help="Step-down between laps [mm].")] = 0.5,
        spacing: Annotated[float, typer.Option(help="Point spacing along a lap [mm].")] = 1.0,
        material: Annotated[
            str, typer.Option(help="Sheet material as the studies declare it.")
        ] = "unknown",
        coverage: Annotated[
            float, typer.Option(help="Nominal coverage of the springback interval, in (0, 1).")
        ] = 0.9,
        fe: Annotated[
            bool, typer.Option("--fe/--beam", help="Tool/holder compliance by FE or beam model.")
        ] = False,
        use_identified: Annotated[
            bool,
            typer.Option(
                "--identified/--preset-stiffness",
                help="Robot joint stiffness identified in the history (latest part on this "
                "robot) or the preset's.",
            ),
        ] = True,
        stiffness: Annotated[
            Path | None,
            typer.Option(
                "--stiffness",
                help="Joint stiffness TOML ([stiffness] K = 6 values, N·m/rad, as `roboisf robot "
                "identify` and `analyze` write) for the robot: used instead of the history's "
                "identified one or the preset's (a robot without a published stiffness needs "
                "one of the two).",
            ),
        ] = None,
        png: Png = False,
    ) -> None:
        """Predict the error of a part before it is formed: springback learned from the history,
        tool and holder by their compliance, robot by the VJM (identified stiffness).

        Springback per toolpath point from the local geometry (wall angle, curvature along and
        across the path, depth, distance to the rim, step-down, tool radius, sheet thickness,
        material) by gradient boosting, validated by leaving each history part out, with a
        split-conformal interval. Writes prediction.parquet (per point, mm), prediction.json,
        report.html and, with --png, prediction.png. docs/history.md.
        """
        for flag, v in (("--step-down", step_down), ("--spacing", spacing)):
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0, got {v:g}", field=flag)
        if not 0 < coverage < 1:
            raise InputError(f"must be in (0, 1), got {coverage:g}", field="--coverage")
        if not part.is_file():
            raise InputError("no such part file", file=part)
        if stiffness is not None and not stiffness.is_file():
            raise InputError("no such stiffness file", file=stiffness, field="--stiffness")
        output_dir(
            output, "predict", overwrite, [part, history, *([stiffness] if stiffness else [])]
        )
        import hashlib

        import numpy as np

        from roboisf.cell import PAPER_CELL_PLACEMENT, build_robot
        from roboisf.frames.pose import XYZ_YAW_MM_DEG, parse_pose
        from roboisf.history.db import Database
        from roboisf.history.store import points_table
        from roboisf.io.atomic import atomic_path, atomic_write, staged_directory
        from roboisf.learn.predict import PredictionSetup, identified_stiffness, predict_part
        from roboisf.learn.springback import fit_springback, require_sklearn
        from roboisf.report.history import write_prediction_report
        from roboisf.scan.deviation import default_rim_band

        require_sklearn()
        if placement is not None:
            T = parse_pose(placement, XYZ_YAW_MM_DEG, field="--placement")
        elif robot.startswith("irb7600"):
            T = PAPER_CELL_PLACEMENT
        else:
            preset = build_robot(robot).default_placement
            if preset is None:
                raise InputError(f"robot {robot} has no default placement", field="--placement")
            T = preset
        progress = state.progress()
        K: list[float] | None
        with Database(history, create=False) as db:
            if stiffness is not None:  # the user's file wins over the history's and the preset's
                from roboisf.robot import load_stiffness

                name = build_robot(robot).name
                K = [float(v) for v in load_stiffness(stiffness, robot=name)]
                source = f"{stiffness.name} (--stiffness)"
            elif use_identified:
                K, source = identified_stiffness(db, robot)
            else:
                K, source = None, ""
            if K is None:
                source = "the robot preset's joint stiffness"
            table = points_table(db)
            learner = fit_springback(table, coverage=coverage)
        setup = PredictionSetup(
            part_file=str(part.resolve()),
            part_sha256=hashlib.sha256(part.read_bytes()).hexdigest(),
            robot=robot,
            T_base_work=tuple(tuple(r) for r in np.asarray(T, dtype=float).tolist()),
            step_down=step_down * 1e-3,
            spacing=spacing * 1e-3,
            compliance_method="fe" if fe else "beam",
            joint_stiffness=None if K is None else tuple(K),
            material=material,
        )
        cell, tp = setup.build()
        pred = predict_part(
            cell,
            tp,
            learner,
            step_down=setup.step_down,
            material=material,
            stiffness_source=source,
            progress=progress,
        )
        pp = pred.per_point()
        rim = default_rim_band(cell.part.depth)
        # where the history measured springback (below the rim band); above it the learned
        # springback is an extrapolation for every part (docs/history.md, Limits), so only the
        # points below it are checked against the history's range
        below = tp.depth > rim
        pp["below_rim_band"] = below
        summary = {
            "part": str(part),
            "robot": robot,
            "rim_band_mm": rim * 1e3,
            "rim_band_points": int(np.count_nonzero(~below)),
            **pred.summary(scope=below),
            "setup": setup.to_json(),
        }
        with staged_directory(output) as d:
            with atomic_path(d / "prediction.parquet") as tmp:
                pp.to_parquet(tmp, index=False)
            with atomic_write(d / "prediction.json") as f:
                json.dump(summary, f, indent=1)
            write_prediction_report(d, pp, summary, png=png)
        t = summary["terms_normal"]
        state.info(
            f"predicted RMS δn: springback {t['springback']['rms_mm']:.3f} mm (± "
            f"{learner.half_width * 1e3:.3f} mm), robot {t['robot_compliance']['rms_mm']:.3f}, "
            f"tool {t['tool']['rms_mm']:.3f}, total {t['total']['rms_mm']:.3f} mm; "
            f"report: {output / 'report.html'}"
        )
        if summary["rim_band_points"]:
            state.info(
                f"the rim band (the first {rim * 1e3:g} mm of depth, "
                f"{summary['rim_band_points']} of {len(tp)} points) is predicted by "
                "extrapolation: the history measures springback below it"
            )
        if summary["extrapolated_features"]:
            state.info(
                "outside the history's range below the rim band: "
                + ", ".join(
                    f"{k} ({100 * s:.0f} % of points)"
                    for k, s in summary["extrapolated_features"].items()
                )
            )
