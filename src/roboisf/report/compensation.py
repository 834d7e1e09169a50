"""The before/after section of a compensation: mean |dn| per lap and the commanded offset per lap.

Input: the per-lap table of :func:`roboisf.compensate.lap_table` (mm) with columns ``lap``,
``command_dn`` (mean commanded normal offset), ``command_norm`` (mean |offset|) and, when known,
``abs_dn_before`` / ``abs_dn_after`` (mean |dn| of the part before and after), plus the
compensation summary (JSON-able dict). Writes ``compensation.html`` (self-contained, plotly
inline) and ``compensation.png`` (matplotlib), both atomically.
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any, cast

import matplotlib as mpl
import pandas as pd
import plotly.graph_objects as go
import plotly.io as pio
from matplotlib.figure import Figure
from plotly.subplots import make_subplots

from roboisf.io.atomic import atomic_write
from roboisf.report.static import save_png
from roboisf.report.style import mpl_rc, plotly_layout

__all__ = ["compensation_figure", "compensation_png", "write_compensation_report"]

_BEFORE, _AFTER, _CMD, _NORM = "#C0392B", "#1F7A4D", "#2F5D8A", "#8E9AAF"


def _after_label(summary: dict[str, Any]) -> str:
    return f"after ({summary.get('after', 'predicted')})"


def compensation_figure(laps: pd.DataFrame, summary: dict[str, Any]) -> go.Figure:
    """Two panels: mean |dn| per lap before/after; the commanded offset per lap."""
    fig = make_subplots(
        rows=1,
        cols=2,
        subplot_titles=("Mean |dn| per lap [mm]", "Commanded offset per lap [mm]"),
    )
    x = laps["lap"]
    if "abs_dn_before" in laps:
        fig.add_trace(
            go.Scatter(x=x, y=laps["abs_dn_before"], name="before", line={"color": _BEFORE}),
            1,
            1,
        )
    if "abs_dn_after" in laps:
        fig.add_trace(
            go.Scatter(
                x=x, y=laps["abs_dn_after"], name=_after_label(summary), line={"color": _AFTER}
            ),
            1,
            1,
        )
    fig.add_trace(
        go.Scatter(x=x, y=laps["command_dn"], name="normal offset n·Δ", line={"color": _CMD}),
        1,
        2,
    )
    fig.add_trace(
        go.Scatter(
            x=x,
            y=laps["command_norm"],
            name="|Δ|",
            line={"color": _NORM, "dash": "dash"},
        ),
        1,
        2,
    )
    fig.update_xaxes(title_text="lap")
    fig.update_layout(**plotly_layout(height=380))
    return fig


def compensation_png(laps: pd.DataFrame, summary: dict[str, Any]) -> Figure:
    """The same two panels as a static figure."""
    with mpl.rc_context(cast(Any, mpl_rc())):
        fig = Figure(figsize=(8.0, 3.0), layout="constrained")
        a1, a2 = fig.subplots(1, 2)
        x = laps["lap"].to_numpy()
        if "abs_dn_before" in laps:
            a1.plot(x, laps["abs_dn_before"].to_numpy(), color=_BEFORE, label="before")
        if "abs_dn_after" in laps:
            a1.plot(x, laps["abs_dn_after"].to_numpy(), color=_AFTER, label=_after_label(summary))
        a1.set_xlabel("lap")
        a1.set_ylabel("mean |dn| [mm]")
        a1.set_title("Deviation per lap")
        if a1.get_legend_handles_labels()[0]:
            a1.legend(loc="best")
        else:
            a1.text(0.5, 0.5, "no measured deviation", ha="center", transform=a1.transAxes)
        a2.plot(x, laps["command_dn"].to_numpy(), color=_CMD, label="normal offset n·Δ")
        a2.plot(x, laps["command_norm"].to_numpy(), color=_NORM, ls="--", label="|Δ|")
        a2.set_xlabel("lap")
        a2.set_ylabel("commanded offset [mm]")
        a2.set_title("Compensation")
        a2.legend(loc="best")
    return fig


def _kv_rows(summary: dict[str, Any]) -> str:
    keys = [
        ("terms", "terms compensated"),
        ("mean_abs_dn_before_mm", "mean |dn| before [mm]"),
        (
            f"mean_abs_dn_after_{str(summary.get('after', 'predicted')).replace(' ', '_')}_mm",
            _after_label(summary),
        ),
        ("max_command_offset_mm", "max commanded offset [mm]"),
        ("max_lap_step_springback_offset_mm", "max lap-to-lap step of the springback offset [mm]"),
        ("max_lap_step_command_dn_mm", "max lap-to-lap step of the commanded offset [mm]"),
        ("complete", "complete"),
    ]
    rows = []
    for k, label in keys:
        if k in summary:
            v = summary[k]
            txt = f"{v:.4f}" if isinstance(v, float) else json.dumps(v)
            rows.append(f"<tr><th>{html.escape(label)}</th><td>{html.escape(txt)}</td></tr>")
    g = summary.get("gouge") or {}
    rows.append(
        f"<tr><th>gouge check</th><td>{'ok' if g.get('ok') else 'GOUGE'} — "
        f"{html.escape(str(g.get('rule', '')))}</td></tr>"
    )
    return "".join(rows)


def write_compensation_report(
    laps: pd.DataFrame, summary: dict[str, Any], out_dir: str | Path, *, png: bool = True
) -> Path:
    """Write ``compensation.html`` (and ``compensation.png``) into ``out_dir``; return the HTML."""
    out = Path(out_dir)
    fig = compensation_figure(laps, summary)
    # a fixed div id (plotly draws a random one otherwise): two runs give the same bytes
    div = pio.to_html(
        fig,
        full_html=False,
        include_plotlyjs=True,
        include_mathjax=False,
        div_id="roboisf-compensation",
    )
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>roboisf compensation</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
        "th{text-align:left;padding-right:1em}</style></head><body>"
        "<h1>Compensation: before / after</h1>"
        f"<table>{_kv_rows(summary)}</table>{div}"
        "<p>Mean |dn| per lap of the part formed with the nominal command (before) and with the "
        "compensated one (after: predicted by the superposition model, or formed on the virtual "
        "cell); commanded offset = compensated − nominal tip, per-lap mean.</p></body></html>"
    )
    with atomic_write(out / "compensation.html") as fh:
        fh.write(page)
    if png:
        save_png(compensation_png(laps, summary), out / "compensation.png")
    return out / "compensation.html"
