"""``roboisf plan``: stiffest work-object placement and tool rotation for a part."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from roboisf.cli.console import state
from roboisf.cli.outputs import DIR_HELP, Overwrite, output_dir, study_inputs
from roboisf.cli.robot import TIP_LINK_HELP
from roboisf.errors import InputError

if TYPE_CHECKING:  # numpy is imported by the command that runs (fast --help)
    import numpy as np

__all__ = ["MAX_CANDIDATES", "MAX_RANGE_COUNT", "parse_range", "register"]

#: Most values one range may have (``start:stop:count``): 1000:2200:100000 asked for 0.1 M x
#: values alone.
MAX_RANGE_COUNT = 10_000
#: Most candidates (placements × tool rotations) one plan evaluates: each is an IK + VJM pass
#: over the whole toolpath (docs/plan.md); a larger grid is refused before anything is computed.
MAX_CANDIDATES = 100_000


def register(app: typer.Typer) -> None:
    app.command("plan")(plan_cmd)


def parse_range(text: str, field: str) -> np.ndarray:
    """``"start:stop:count"`` (inclusive, evenly spaced) or ``"a,b,c"`` → values (CLI units)."""
    import numpy as np

    t = text.strip()
    if not t:
        raise InputError("empty range: give start:stop:count or a comma list", field=field)
    bad = InputError(
        f"expected start:stop:count or comma-separated numbers, got {text!r}", field=field
    )
    if ":" in t:
        parts = t.split(":")
        if len(parts) != 3:
            raise bad
        try:
            a, b, n = (float(x) for x in parts)
        except ValueError:
            raise bad from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise InputError(f"values must be finite, got {text!r}", field=field)
        if not (math.isfinite(n) and n == int(n) and n >= 1):
            raise InputError(
                f"the count must be a positive integer, got {parts[2]!r} in {text!r}", field=field
            )
        if b < a:
            raise InputError(f"empty range {text!r}: stop < start", field=field)
        if n == 1 and b != a:
            raise InputError(f"count 1 needs start = stop, got {text!r}", field=field)
        if n > MAX_RANGE_COUNT:
            raise InputError(
                f"{int(n):,} values in {text!r}; at most {MAX_RANGE_COUNT:,} per range (each "
                "value multiplies the candidates to evaluate): use a smaller count",
                field=field,
            )
        return np.linspace(a, b, int(n))
    try:
        v = np.array([float(x) for x in t.split(",")])
    except ValueError:
        raise bad from None
    if not np.all(np.isfinite(v)):
        raise InputError(f"values must be finite, got {text!r}", field=field)
    if v.size > MAX_RANGE_COUNT:
        raise InputError(f"{v.size:,} values; at most {MAX_RANGE_COUNT:,} per range", field=field)
    return v


def _default_range(center: float, half: float, n: int) -> str:
    return f"{center - half:g}:{center + half:g}:{n}"


def plan_cmd(
    output: Path = typer.Option(..., "--output", "-o", help=f"Output folder. {DIR_HELP}"),
    overwrite: Overwrite = False,
    part: Path | None = typer.Option(None, "--part", help="Part TOML (force model forces)."),
    study: Path | None = typer.Option(
        None, "--study", help="Study folder/study.toml: its toolpath, robot-run forces, robot."
    ),
    robot: str = typer.Option("irb7600-500-2.55", "--robot", "-r", help="Preset, .toml or .urdf."),
    tip_link: str | None = typer.Option(
        None,
        "--tip-link",
        help=f"{TIP_LINK_HELP} With --part only: a study's is its [robot] tip_link.",
    ),
    stiffness: Path | None = typer.Option(None, "--stiffness", help="Joint stiffness TOML."),
    tool: str | None = typer.Option(
        None, "--tool", help="Tool tip in the flange frame x,y,z (mm); default: the paper cell's."
    ),
    x_range: str | None = typer.Option(
        None,
        "--x-range",
        help="start:stop:count or list (mm); each range ≤ 10 000 values, the whole grid ≤ "
        "100 000 candidates (placements × tool rotations).",
    ),
    y_range: str | None = typer.Option(None, "--y-range", help="start:stop:count or list (mm)."),
    z_range: str | None = typer.Option(None, "--z-range", help="start:stop:count or list (mm)."),
    yaw_range: str = typer.Option("0", "--yaw-range", help="start:stop:count or list (deg)."),
    tool_rotations: str = typer.Option(
        "0", "--tool-rotations", help="Candidate tool rotations about the tool axis (deg)."
    ),
    baseline: str | None = typer.Option(
        None,
        "--baseline",
        help="Reference placement x,y,z,yaw (mm, deg); default: the study's, else the paper cell's "
        "(2200,-500,200,0) for the IRB 7600, else the preset's.",
    ),
    objective: str = typer.Option("mean", "--objective", help="Rank by mean, max or normal."),
    sigma_min: float = typer.Option(0.02, "--sigma-min", help="Singularity margin (σ_min)."),
    max_joint_step: float = typer.Option(
        5.0, "--max-joint-step", help="Largest joint change between points (deg)."
    ),
    no_tool_compliance: bool = typer.Option(
        False, "--no-tool-compliance", help="Robot only (no tool/holder beam compliance)."
    ),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        help="Where the placements run: 'threads' (threads of this process, the default with "
        "the compiled kernels or on ≤ 2 CPUs), 'local' (a Dask cluster of worker processes, the "
        "default otherwise) or a Dask scheduler address tcp://host:8786.",
    ),
    serial: bool = typer.Option(False, "--serial", help="One placement at a time, this process."),
    workers: int = typer.Option(
        2, "--workers", help="Threads ('threads') or worker processes ('local')."
    ),
    top: int = typer.Option(10, "--top", help="Candidates shown in the summary."),
) -> None:
    """Rank work-object placements (x, y, z, yaw) and tool rotations by predicted deflection."""
    if (part is None) == (study is None):
        raise InputError("give exactly one of --part or --study", field="--part/--study")
    if study is not None and tip_link is not None:
        raise InputError(
            "goes with --part; a study's robot takes its flange link from [robot] tip_link",
            field="--tip-link",
        )
    for flag, v in (("--workers", workers), ("--top", top)):
        if v < 1:
            raise InputError(f"must be ≥ 1, got {v}", field=flag)
    if objective not in ("mean", "max", "normal"):
        raise InputError(f"expected mean, max or normal, got {objective!r}", field="--objective")
    if not (math.isfinite(max_joint_step) and max_joint_step > 0):
        raise InputError(f"must be > 0, got {max_joint_step}", field="--max-joint-step")
    if not (math.isfinite(sigma_min) and sigma_min >= 0):
        raise InputError(f"must be ≥ 0, got {sigma_min}", field="--sigma-min")
    inputs = [p for p in (part, study, stiffness) if p is not None]
    output_dir(output, "plan", overwrite, [*inputs, *study_inputs(study)])
    if state.own_process:
        # each placement makes and drops the same temporaries: keep freed memory for the next
        # one instead of faulting fresh pages in (numpy engine 9.0 → 7.6 s, docs/plan.md)
        from roboisf.jit.heap import hold_freed_memory

        hold_freed_memory()
    # the numeric stack only now: a bad option or a mistyped STUDY is reported at once
    import numpy as np

    from roboisf.frames import make_transform, rot_z
    from roboisf.io.atomic import staged_directory
    from roboisf.plan import evaluated_candidates, placement_grid, plan_placements
    from roboisf.report.plan_maps import plot_placement_map, write_plan_html
    from roboisf.report.robot_maps import plot_stiffness_map
    from roboisf.robot import stiffness_map

    gammas = np.radians(parse_range(tool_rotations, "--tool-rotations"))
    # the grid's size before the problem is built: the default x, y, z ranges have 7, 5, 5
    sizes = [
        parse_range(text, flag).size if text is not None else default
        for text, flag, default in (
            (x_range, "--x-range", 7),
            (y_range, "--y-range", 5),
            (z_range, "--z-range", 5),
            (yaw_range, "--yaw-range", 1),
        )
    ] + [gammas.size]
    n_cand = math.prod(sizes)
    if n_cand > MAX_CANDIDATES:
        raise InputError(
            "{} x × {} y × {} z × {} yaw × {} tool rotations = {:,} candidates, more than the "
            "{:,} one plan evaluates (each an IK + VJM pass over the whole toolpath): plan on a "
            "coarse grid first, then on a fine one around the best".format(
                *sizes, n_cand, MAX_CANDIDATES
            ),
            field="--x-range/--y-range/--z-range",
        )
    opts: dict[str, Any] = {
        "objective": objective,
        "sigma_threshold": sigma_min,
        "max_joint_step": math.radians(max_joint_step),
    }
    prob, model, base_T, source = _problem(
        part, study, robot, stiffness, tool, not no_tool_compliance, opts, tip_link, baseline
    )
    base_T = _baseline(baseline, base_T, model)
    c = model.default_placement if model.default_placement is not None else base_T
    cx, cy, cz = (float(v) * 1e3 for v in c[:3, 3])
    xs = (
        parse_range(x_range if x_range is not None else _default_range(cx, 600, 7), "--x-range")
        * 1e-3
    )
    ys = (
        parse_range(y_range if y_range is not None else _default_range(cy, 400, 5), "--y-range")
        * 1e-3
    )
    zs = (
        parse_range(z_range if z_range is not None else _default_range(cz, 400, 5), "--z-range")
        * 1e-3
    )
    yaw_deg = parse_range(yaw_range, "--yaw-range")
    # 0 and 360 (or -180 and 180) are one placement: ranked twice, they were two candidates
    _, first = np.unique(np.round(np.mod(yaw_deg, 360.0), 9) % 360.0, return_index=True)
    if first.size < yaw_deg.size:
        state.info(
            f"--yaw-range: {yaw_deg.size - first.size} yaw(s) 360° from another left out (the "
            "same placement)"
        )
        yaw_deg = yaw_deg[np.sort(first)]
    yaws = np.radians(yaw_deg)
    P = placement_grid(xs, ys, zs, yaws)
    # what is evaluated, not the grid asked for: a round part's yaws collapse into one (its
    # others becoming tool rotations with an off-axis tool), a coaxial tool's γ into one
    P_ev, g_ev, _ = evaluated_candidates(prob, P, gammas)
    asked = (
        f" (of {len(P)} × {gammas.size} asked for: see the note below)"
        if (len(P_ev), g_ev.size) != (len(P), gammas.size)
        else ""
    )
    state.info(
        f"{len(P_ev)} placements × {g_ev.size} tool rotations evaluated{asked}, "
        f"{prob.n_points} toolpath points ({source})"
    )
    sched: Any = "serial" if serial else (scheduler or "auto")
    if sched == "auto":  # named in plan.json as what ran
        from roboisf.plan.sweep import default_scheduler

        sched = default_scheduler(prob)
    res = plan_placements(
        prob,
        P,
        gammas,
        baseline=base_T,
        scheduler=sched,
        n_workers=workers,
        progress=state.progress(),
    )
    edge = _on_the_edge(res.best_placement, xs, ys, zs) if res.order.size else []
    if edge:
        from dataclasses import replace

        res = replace(res, notes=[*res.notes, *edge])
    for n in res.notes:
        state.warn(n)
    summary = _summary(res, model.name, source, sched if isinstance(sched, str) else "client")
    b = res.best_placement
    c_map = [0.5 * (xs[0] + xs[-1]), 0.5 * (ys[0] + ys[-1]), b[2]]
    smap = stiffness_map(
        model,
        make_transform(rot_z(b[3]), c_map),
        half_width=max(0.25, 0.5 * max(xs[-1] - xs[0], ys[-1] - ys[0]) + 0.1),
        n=41,
    )
    with staged_directory(output) as d:
        _write_tables(res, d, summary)
        # each caption names what its figure draws, with units: the second map draws the
        # robot's compliance (µm/N, higher is softer), not a stiffness
        images = {
            "predicted mean robot |δ| [mm] at the ball centre per candidate placement (work "
            "origin over the base x–y plane, mm, at the best height and yaw)": plot_placement_map(
                res, d / "placement_map.png"
            ),
            "robot translational compliance k_xx, k_yy, k_zz [µm/N] (diagonal of the VJM "
            "compliance at the tool tip, work axes; higher is softer) of tool-down poses over the "
            "swept area, work axes centred at "
            f"({c_map[0] * 1e3:.0f}, {c_map[1] * 1e3:.0f}, {c_map[2] * 1e3:.0f}) mm in the base, "
            f"yaw {math.degrees(b[3]):.0f}°": plot_stiffness_map(smap, d / "stiffness_map.png"),
        }
        write_plan_html(res, d / "plan.html", images, summary=summary, top=top)
    _print(res, summary, top, with_tool=not no_tool_compliance)
    state.info(f"wrote {output}/ (placements.csv, plan.json, plan.html, *.png)")


def _problem(
    part: Path | None,
    study: Path | None,
    robot: str,
    stiffness: Path | None,
    tool: str | None,
    with_tool: bool,
    opts: dict[str, Any],
    tip_link: str | None = None,
    baseline: str | None = None,
) -> tuple[Any, Any, np.ndarray | None, str]:
    from roboisf.cell import ForceModel, build_robot, cell_from_study, make_cell
    from roboisf.cli.robot import tool_pose
    from roboisf.frames.pose import XYZ_YAW_MM_DEG, parse_pose
    from roboisf.parts import load_part
    from roboisf.plan import PlanProblem, problem_from_cell
    from roboisf.plan.setup import tool_and_holder_compliance
    from roboisf.robot import load_stiffness

    def _override(m: Any) -> Any:
        if stiffness is not None:
            m = m.with_stiffness(load_stiffness(stiffness, robot=m.name), source=str(stiffness))
        if tool is not None:
            m = m.with_tool(tool_pose(tool))
        return m

    if part is not None:
        # the cell needs a placement; plan scores its own candidates, so a robot without a
        # default one (a URDF) takes --baseline's (make_cell refused it, naming T_base_work)
        T_bw = (
            None if baseline is None else parse_pose(baseline, XYZ_YAW_MM_DEG, field="--baseline")
        )
        if T_bw is None and build_robot(robot, tip_link=tip_link).default_placement is None:
            raise InputError(
                f"robot {robot} has no default placement; give --baseline x,y,z,yaw (mm, deg), "
                "the placement the candidates are compared with",
                field="--baseline",
            )
        cell = make_cell(
            load_part(part), robot=robot, force=ForceModel(), tip_link=tip_link, T_base_work=T_bw
        )
        m = _override(cell.robot)
        prob, _ = problem_from_cell(cell, with_tool=with_tool, model=m, **opts)
        return prob, m, None, f"part {part.name}, force model"
    assert study is not None
    from roboisf.decompose.pipeline import run_tip_wrench
    from roboisf.study.spec import load_study
    from roboisf.study.toolpaths import study_toolpath

    s = load_study(study)
    if s.robot is None:
        raise InputError("the study has no [robot] table", file=s.root / "study.toml")
    c = cell_from_study(s)
    # the study's robot and tool; --stiffness wins over the study's joint stiffness
    m = (
        c.robot
        if stiffness is None
        else build_robot(c.robot_name, T_flange_tip=c.T_flange_tip, tip_link=c.tip_link)
    )
    m = _override(m)
    rob = s.robot_run
    tp = study_toolpath(s, rob, c.part)  # a toolpath CSV or a CAM program
    W = run_tip_wrench(s, rob, tp)
    # the study's tool and holder compliance, as analyze takes them
    k = tool_and_holder_compliance(c) if with_tool else None
    prob = PlanProblem(
        m,
        tp.tip,
        tp.normal,
        tp.lap,
        W,
        tool_compliance=k,
        ball_radius=c.tool.radius,
        symmetry=c.part.symmetry,
        **opts,
    )
    what = "robot, tool and holder" if with_tool else "robot only"
    return prob, m, c.T_base_work, f"study {s.name}, robot-run forces, {what}"


def _baseline(text: str | None, study_T: np.ndarray | None, model: Any) -> np.ndarray:
    from roboisf.cell import PAPER_CELL_PLACEMENT
    from roboisf.frames.pose import XYZ_YAW_MM_DEG, parse_pose

    if text is not None:
        return parse_pose(text, XYZ_YAW_MM_DEG, field="--baseline")
    if study_T is not None:
        return study_T
    if model.name.startswith("irb7600"):
        return PAPER_CELL_PLACEMENT
    if model.default_placement is None:
        raise InputError(
            f"robot {model.name} has no default placement; give --baseline", field="--baseline"
        )
    return model.default_placement


def _on_the_edge(best: Any, xs: Any, ys: Any, zs: Any) -> list[str]:
    """A note per searched axis (of two values or more) whose end the best placement lies on
    (m): a better placement may lie beyond it, outside the grid."""
    out = []
    for name, v, grid in (("x", best[0], xs), ("y", best[1], ys), ("z", best[2], zs)):
        lo, hi = float(min(grid)), float(max(grid))
        if len(grid) < 2 or hi <= lo:
            continue
        tol = 1e-6 * max(1.0, hi - lo)
        end = "low" if abs(v - lo) <= tol else "high" if abs(v - hi) <= tol else None
        if end is not None:
            out.append(
                f"the best placement lies at the {end} end of the searched {name} range "
                f"({name} = {v * 1e3:.0f} mm): a better one may lie beyond it — widen "
                f"--{name}-range (placements out of reach are rejected, never chosen)"
            )
    return out


def _summary(res: Any, robot: str, source: str, scheduler: str) -> dict[str, Any]:
    b, p = res.best, res.best_placement
    out: dict[str, Any] = {
        "robot": robot,
        "input": source,
        "objective": res.objective,
        "candidates": len(res.scores),
        "feasible": int(res.order.size),
        "rejected": res.rejected(),
        "scheduler": scheduler,
        "best placement x,y,z [mm], yaw [deg]": [
            round(p[0] * 1e3, 3),
            round(p[1] * 1e3, 3),
            round(p[2] * 1e3, 3),
            round(math.degrees(p[3]), 3),
        ],
        "best tool rotation per lap [deg] (min..max)": [
            round(math.degrees(float(b.gamma.min())), 3),
            round(math.degrees(float(b.gamma.max())), 3),
        ],
        "best mean robot |δ| [mm]": round(b.mean_robot * 1e3, 5),
        "best max robot |δ| [mm]": round(b.max_robot * 1e3, 5),
        "best mean |δ| (robot + tool) [mm]": round(b.mean_abs * 1e3, 5),
        "best max |δ| (robot + tool) [mm]": round(b.max_abs * 1e3, 5),
        "best mean |δ·n| [mm]": round(b.mean_abs_normal * 1e3, 5),
    }
    b0 = res.best_gamma0
    if b0 is not None:
        out["best placement at γ = 0: mean robot |δ| [mm]"] = (
            round(b0.mean_robot * 1e3, 5) if b0.ok else f"{b0.status}: {b0.reason}"
        )
    if res.baseline is not None:
        T = res.baseline_T
        out["baseline placement x,y,z [mm], yaw [deg]"] = [
            *(round(float(v) * 1e3, 3) for v in T[:3, 3]),
            round(math.degrees(math.atan2(T[1, 0], T[0, 0])), 3),
        ]
        if res.baseline.ok:
            out["baseline mean robot |δ| [mm]"] = round(res.baseline.mean_robot * 1e3, 5)
            out["baseline mean |δ| (robot + tool) [mm]"] = round(res.baseline.mean_abs * 1e3, 5)
            out["mean robot |δ| reduction vs baseline [%]"] = round(
                100 * res.improvement("mean_robot"), 2
            )
            out["mean |δ| reduction vs baseline [%]"] = round(100 * res.improvement("mean_abs"), 2)
        else:
            out["baseline status"] = f"{res.baseline.status}: {res.baseline.reason}"
    return out


def _write_tables(res: Any, d: Path, summary: dict[str, Any]) -> None:
    import numpy as np
    import pandas as pd

    from roboisf.io.atomic import atomic_path, atomic_write

    df = pd.DataFrame(res.table())
    with atomic_path(d / "placements.csv") as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write("# roboisf plan: candidates ranked by predicted deflection\n")
            fh.write("# units: length=mm angle=deg\n")
            df.to_csv(fh, index=False, float_format="%.6f")
    doc = {
        "summary": summary,
        "notes": res.notes,
        "best_gamma_per_lap_deg": np.degrees(res.best.gamma).round(6).tolist(),
        "candidates": res.table(),
    }
    with atomic_write(d / "plan.json") as fh:
        json.dump(doc, fh, indent=1, default=_json_default)


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(type(o).__name__)


def _gamma_text(row: dict[str, Any]) -> str:
    """A candidate's tool rotation for the terminal, deg: ``-45``, or ``-90..0`` when the best
    rotation differs from lap to lap (the CSV has the first, the least and the largest)."""
    lo, hi = round(row["gamma_min_deg"]), round(row["gamma_max_deg"])
    return f"{lo:g}" if lo == hi else f"{lo:g}..{hi:g}"


def _print(res: Any, summary: dict[str, Any], top: int, *, with_tool: bool = True) -> None:
    from roboisf.report.page import fmt

    rows = [r for r in res.table() if r["status"] == "ok"][:top]
    # several tool rotations evaluated: the one chosen (per lap: its range) belongs in the table
    with_gamma = res.tool_rotations.size > 1
    state.info(
        "rank      x       y       z   yaw"
        + ("          γ" if with_gamma else "")
        + "  mean_robot  max_robot  mean|δ|  mean|δ·n|  [mm, deg]"
    )
    for r in rows:
        state.info(
            f"{r['rank']:>4} {r['x_mm']:7.0f} {r['y_mm']:7.0f} {r['z_mm']:7.0f} {r['yaw_deg']:5.0f}"
            + (f" {_gamma_text(r):>10}" if with_gamma else "")
            + f"  {fmt(r['mean_robot_mm'], 4):>10} {fmt(r['max_robot_mm'], 4):>10}"
            f" {fmt(r['mean_abs_mm'], 4):>8} {fmt(r['mean_abs_normal_mm'], 4):>10}"
        )
    rej = res.rejected()
    if rej:
        state.info("rejected: " + ", ".join(f"{v} {k}" for k, v in rej.items()))
    if res.baseline is not None and res.baseline.ok:
        tool = (
            f"; mean |δ| with the tool {res.baseline.mean_abs * 1e3:.4f} → "
            f"{res.best.mean_abs * 1e3:.4f} mm"
            if with_tool
            else ""
        )
        state.info(
            f"baseline {summary['baseline placement x,y,z [mm], yaw [deg]']}: mean robot |δ| "
            f"{res.baseline.mean_robot * 1e3:.4f} mm → best {res.best.mean_robot * 1e3:.4f} mm "
            f"({abs(100 * res.improvement('mean_robot')):.1f} % "
            f"{'lower' if res.improvement('mean_robot') >= 0 else 'higher'}{tool})"
        )
    elif "baseline status" in summary:
        state.warn(f"baseline not feasible: {summary['baseline status']}")
