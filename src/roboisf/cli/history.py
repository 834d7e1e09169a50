"""``roboisf history …``: the cell's analysed parts in a database — add, list, show, trend.

Examples::

    roboisf history add results/ results2/ --db history.db       # one SQLite file
    roboisf history add results/ --db postgresql://user:pw@host/isf   # a shared server
    roboisf history list --db history.db --robot irb7600-500-2.55
    roboisf history show 3 --db history.db
    roboisf history trend --db history.db --by tool --factor tool -o trend.png
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import typer

from roboisf.cli.console import state
from roboisf.cli.lazy import FullHelpGroup
from roboisf.cli.outputs import FILE_HELP, Overwrite, output_file
from roboisf.errors import InputError

__all__ = ["register"]

history_app = typer.Typer(
    help="The cell's history: analysed parts in a database (add, list, show, trend).",
    no_args_is_help=True,
    cls=FullHelpGroup,
)

DB_HELP = (
    "The history: an SQLite file (created by `add` when new) or postgresql://user:password@"
    "host:port/name (a shared server; pip install 'roboisf[history]')."
)
DbOpt = Annotated[str, typer.Option("--db", help=DB_HELP)]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


def register(app: typer.Typer) -> None:
    app.add_typer(history_app, name="history")


def _open(db: str, *, create: bool) -> Any:
    from roboisf.history.db import Database

    return Database(db, create=create)


def _mm(v: Any, nd: int = 3) -> str:
    return "—" if v is None or not math.isfinite(float(v)) else f"{float(v) * 1e3:.{nd}f}"


@history_app.command("add")
def add_cmd(
    results: Annotated[
        list[Path], typer.Argument(help="`roboisf analyze` results folders to store.")
    ],
    db: DbOpt = "history.db",
    formed: Annotated[
        str | None,
        typer.Option(
            help="When the parts were formed (YYYY-MM-DD or YYYY-MM-DDTHH:MM:SS, UTC); "
            "default: when each analysis was written."
        ),
    ] = None,
) -> None:
    """Store analysed parts in the history: study, part, robot, placement, tool, sheet, the
    per-point terms, both share tables and the diagnosis.

    Each part is written in one transaction: an interrupted add leaves no half-written part.
    A part already in the history (same summary.json and per_point.parquet) is skipped.
    """
    from roboisf.history.store import add_parts, read_results

    records = [read_results(r, formed_at=formed) for r in results]  # all checked before writing
    with _open(db, create=True) as d:
        done = add_parts(d, records)
        for r, rec, (pid, new) in zip(results, records, done, strict=True):
            what = "added as part" if new else "already in the history as part"
            state.info(f"{r}: {rec.meta['study']} {what} {pid}")
        state.info(f"{sum(n for _, n in done)} added to {d.describe()}")


@history_app.command("list")
def list_cmd(
    db: DbOpt = "history.db",
    robot: Annotated[str | None, typer.Option(help="Only this robot.")] = None,
    kind: Annotated[str | None, typer.Option(help="Only this part kind (cone, mesh, …).")] = None,
    as_json: JsonOpt = False,
) -> None:
    """List the parts in the history, oldest formed first, with each factor's R_m (mm, normal
    book) and the VJM check's verdict."""
    from roboisf.history.store import list_parts

    with _open(db, create=False) as d:
        rows = list_parts(d, robot=robot, kind=kind)
    if as_json:
        typer.echo(json.dumps(rows, indent=1))
        return
    head = f"{'id':>4} {'formed (UTC)':20} {'study':18} {'kind':9} {'robot':18} "
    head += "R_m mm: springback  robot   tool  holder  total  VJM"
    typer.echo(head)
    for r in rows:
        typer.echo(
            f"{r['id']:>4} {r['formed_at']:20} {str(r['study'])[:18]:18} {r['part_kind']:9} "
            f"{str(r['robot'])[:18]:18} {_mm(r.get('r_m_springback')):>18} "
            f"{_mm(r.get('r_m_robot_compliance')):>6} {_mm(r.get('r_m_tool')):>6} "
            f"{_mm(r.get('r_m_tool_holder')):>7} {_mm(r.get('r_m_total')):>6}  "
            f"{r['vjm_verdict'] or '—'}"
        )


@history_app.command("show")
def show_cmd(
    part_id: Annotated[int, typer.Argument(help="The part's id (`roboisf history list`).")],
    db: DbOpt = "history.db",
) -> None:
    """Everything the history holds on one part (JSON, SI units: m, rad, m/N)."""
    from roboisf.history.store import show_part

    with _open(db, create=False) as d:
        typer.echo(json.dumps(show_part(d, part_id), indent=1))


@history_app.command("trend")
def trend_cmd(
    db: DbOpt = "history.db",
    by: Annotated[str, typer.Option(help="Group by robot, kind or tool.")] = "robot",
    factor: Annotated[
        str,
        typer.Option(help="The term followed: robot_compliance, springback, tool or tool_holder."),
    ] = "robot_compliance",
    robot: Annotated[str | None, typer.Option(help="Only this robot.")] = None,
    kind: Annotated[str | None, typer.Option(help="Only this part kind.")] = None,
    output: Annotated[
        Path | None,
        typer.Option("--output", "-o", help=f"Also draw the trend as a PNG. {FILE_HELP}"),
    ] = None,
    overwrite: Overwrite = False,
    as_json: JsonOpt = False,
) -> None:
    """A term over time per robot, part kind or tool: its R_m per part and the VJM check's
    measured/modelled ratio, with their slopes per 30 days (is the robot drifting, did a tool
    change move the tool term?)."""
    if output is not None:
        if output.suffix.lower() != ".png":
            raise InputError("expected a .png file", field="--output")
        output_file(output, "history trend", overwrite, [db])
    from roboisf.history.trend import MIN_SPAN_DAYS, trend

    with _open(db, create=False) as d:
        groups = trend(d, by=by, factor=factor, robot=robot, kind=kind)
    if as_json:
        typer.echo(json.dumps([g.as_dict() for g in groups], indent=1))
    else:
        for g in groups:
            slope = "—" if g.slope is None else f"{g.slope * 1e3:+.4f} mm"
            rs = "—" if g.ratio_slope is None else f"{g.ratio_slope:+.4f}"
            why = ""
            if g.slope is None and g.ratio_slope is None and len(g.part_ids) > 1:
                why = f" (the parts span less than {MIN_SPAN_DAYS:g} day: no slope)"
            typer.echo(
                f"{g.key}: {len(g.part_ids)} parts, {factor} R_m slope {slope} per 30 days, "
                f"VJM ratio slope {rs} per 30 days{why}"
            )
            for t, pid, v, r in zip(g.formed_at, g.part_ids, g.values, g.vjm_ratio, strict=True):
                ratio = "—" if r is None else f"{r:.3f}"
                typer.echo(f"  {t}  part {pid:>4}  R_m {_mm(v)} mm  VJM ratio {ratio}")
    if output is not None:
        from roboisf.report.history import save_trend_png

        save_trend_png(groups, factor, output)
        state.info(f"wrote {output}")
