"""Placement-study figures and HTML summary (matplotlib Agg; written atomically)."""

from __future__ import annotations

import base64
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from roboisf.io.atomic import atomic_path, atomic_write
from roboisf.plan.sweep import PlanResult
from roboisf.report import page as pg

__all__ = ["plan_section", "plot_placement_map", "write_plan_html"]


def plot_placement_map(result: PlanResult, path: str | Path, *, dpi: int = 120) -> Path:
    """Predicted mean robot |δ| (mm) of each candidate over the x–y plane of the base, at the
    best candidate's height and yaw; infeasible candidates as grey crosses; the best one and the
    baseline marked → PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P = result.placements
    bz, byaw = result.best_placement[2], result.best_placement[3]
    sl = np.isclose(P[:, 2], bz) & np.isclose(P[:, 3], byaw)
    ok = np.array([s.ok for s in result.scores]) & sl
    bad = ~np.array([s.ok for s in result.scores]) & sl
    val = np.array([s.mean_robot * 1e3 for s in result.scores])
    fig, ax = plt.subplots(figsize=(7.2, 5.6), constrained_layout=True)
    if np.any(ok):
        sc = ax.scatter(P[ok, 0] * 1e3, P[ok, 1] * 1e3, c=val[ok], cmap="viridis", s=90, marker="s")
        fig.colorbar(sc, ax=ax, label="mean robot |δ| [mm]")
    if np.any(bad):
        ax.scatter(P[bad, 0] * 1e3, P[bad, 1] * 1e3, c="0.6", marker="x", s=50, label="infeasible")
    b = result.best_placement
    ax.scatter(
        [b[0] * 1e3],
        [b[1] * 1e3],
        facecolors="none",
        edgecolors="#D55E00",
        s=260,
        linewidths=2,
        label="best",
    )
    if result.baseline_T is not None:
        t = result.baseline_T[:3, 3]
        ax.scatter([t[0] * 1e3], [t[1] * 1e3], marker="*", c="k", s=160, label="baseline")
    ax.scatter([0], [0], marker="^", c="k", s=80, label="robot base")
    ax.set_xlabel("x_base [mm]")
    ax.set_ylabel("y_base [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(
        f"placements at z = {bz * 1e3:.0f} mm, yaw = {math.degrees(byaw):.0f}° "
        f"(work origin in the base frame)"
    )
    out = Path(path)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return out


def _img(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<img alt="{pg.esc(alt)}" style="max-width:100%" src="data:image/png;base64,{data}">'


#: Decimals per column of the candidates' table (the rest: :func:`roboisf.report.page.fmt`'s 3):
#: a rank is a whole number, a placement on a grid of millimetres and degrees ("1.000",
#: "1200.000" before).
_DECIMALS = {"rank": 0, "x_mm": 1, "y_mm": 1, "z_mm": 1, "yaw_deg": 1}


def _cell(key: str, value: Any) -> str:
    nd = _DECIMALS.get(key)
    if nd is None or not isinstance(value, int | float) or isinstance(value, bool):
        return pg.fmt(value)
    return pg.fmt(round(float(value), nd) + 0.0, nd)  # + 0.0: no "-0.0"


def _rows_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[tuple[str, str]]) -> str:
    head = "".join(f"<th>{pg.esc(label)}</th>" for _, label in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{_cell(k, r[k])}</td>" for k, _ in columns) + "</tr>" for r in rows
    )
    return f'<table class="data"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def plan_section(
    result: PlanResult, images: Mapping[str, Path], *, top: int = 10, summary: Mapping[str, Any]
) -> str:
    """The placement study as an HTML ``<section>`` (for this page or a larger report)."""
    rows = result.table()[:top]
    cols = [
        ("rank", "rank"),
        ("x_mm", "x [mm]"),
        ("y_mm", "y [mm]"),
        ("z_mm", "z [mm]"),
        ("yaw_deg", "yaw [°]"),
        ("mean_robot_mm", "mean robot |δ| [mm]"),
        ("max_robot_mm", "max robot |δ| [mm]"),
        ("mean_abs_mm", "mean |δ| [mm]"),
        ("max_abs_mm", "max |δ| [mm]"),
        ("mean_abs_normal_mm", "mean |δ·n| [mm]"),
        ("sigma_min", "σ_min"),
        ("gamma_min_deg", "γ min [°]"),
        ("gamma_max_deg", "γ max [°]"),
    ]
    kv = pg.kv_table(list(summary.items()))
    notes = "".join(f"<p>{pg.esc(n)}</p>" for n in result.notes)
    figs = "".join(
        f"<figure>{_img(p, k)}<figcaption>{pg.esc(k)}</figcaption></figure>"
        for k, p in images.items()
    )
    # wide tables scroll inside their box and long values wrap, so nothing spills out of the
    # page's card (13 columns do not fit a narrow window)
    style = (
        "<style>#plan .scroll{max-width:100%;overflow-x:auto}"
        "#plan td,#plan th,#plan dd{overflow-wrap:anywhere}"
        "#plan figure{margin:1em 0;max-width:100%}"
        "</style>"
    )
    return (
        f'<section id="plan">{style}<h2>Placement and tool rotation</h2>'
        '<p class="lead">Predicted deflection |δ| [mm] of the ball centre (VJM robot; robot + '
        "tool where a tool compliance is given) for each candidate placement of the work "
        f"object; best {len(rows)} shown.</p>"
        f'<div class="scroll">{kv}</div>{notes}'
        f'<div class="scroll">{_rows_table(rows, cols)}</div>{figs}</section>'
    )


def write_plan_html(
    result: PlanResult,
    path: str | Path,
    images: Mapping[str, Path],
    *,
    summary: Mapping[str, Any],
    title: str = "roboisf placement plan",
    top: int = 10,
) -> Path:
    """A self-contained HTML page: summary, ranked candidates, stiffness and placement maps."""
    body = plan_section(result, images, top=top, summary=summary)
    out = Path(path)
    with atomic_write(out) as fh:
        fh.write(pg.page(title, body, subtitle="roboisf plan"))
    return out
