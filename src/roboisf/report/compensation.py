"""The before/after section of a compensation: mean |dn| per lap and the commanded offset per lap.

Input: the per-lap table of :func:`roboisf.compensate.lap_table` (mm) with columns ``lap``,
``command_dn`` (mean commanded normal offset), ``command_norm`` (mean |offset|) and, when known,
``abs_dn_before`` / ``abs_dn_after`` (mean |dn| of the part before and after), plus the
compensation summary (JSON-able dict). Writes ``compensation.html`` (self-contained, plotly
inline) and ``compensation.png`` (matplotlib), both atomically.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import pandas as pd
import plotly.graph_objects as go
import plotly.io as pio
from plotly.subplots import make_subplots

from roboisf.io.atomic import atomic_write
from roboisf.report.page import esc, fmt, kv_table, page
from roboisf.report.style import mpl_rc, plotly_layout

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["compensation_figure", "compensation_png", "write_compensation_report"]

_BEFORE, _AFTER, _CMD, _NORM = "#C0392B", "#1F7A4D", "#2F5D8A", "#8E9AAF"


def _after_label(summary: dict[str, Any]) -> str:
    return f"after ({summary.get('after', 'predicted')})"


#: Top margin of the before/after figure [px]: the panels' titles and plotly's tool bar above
#: them, one over the other.
COMPENSATION_TOP = 72


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
    # the legend under the panels: above them it covered the first panel's title; the top
    # margin holds plotly's tool bar above the panels' titles (at 40 px it sat on the right one)
    fig.update_layout(
        **plotly_layout(
            height=440,
            margin={"l": 64, "r": 24, "t": COMPENSATION_TOP, "b": 96},
            legend={"orientation": "h", "yanchor": "top", "y": -0.22, "xanchor": "left", "x": 0},
        )
    )
    fig.update_yaxes(title_text="mm")
    return fig


def compensation_png(laps: pd.DataFrame, summary: dict[str, Any]) -> Figure:
    """The same two panels as a static figure (matplotlib, imported here: only ``--png`` asks
    for it)."""
    import matplotlib as mpl
    from matplotlib.figure import Figure

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


def _terms(summary: dict[str, Any]) -> str:
    """What was compensated, in words."""
    terms = summary.get("terms") or {}
    done = []
    if terms.get("compliance"):
        done.append(
            "the robot's, tool's and holder's deflection under the forming force (pre-deflection)"
        )
    if terms.get("springback"):
        sb = summary.get("springback") or {}
        gain = sb.get("gain")
        done.append(
            "the springback (displacement adjustment from the measured deviation"
            + (f", gain λ = {gain:g}" if isinstance(gain, int | float) else "")
            + ")"
        )
    return " and ".join(done) if done else "nothing (both terms switched off)"


def _stiffness(summary: dict[str, Any]) -> str | None:
    """Which joint stiffness the pre-deflection used (file name only), or None if not said."""
    src = summary.get("stiffness")
    if not src:
        return None
    name = Path(str(src)).name
    if name == "study.toml":
        return "the study's own robot model (study.toml)"
    if name == "identified_stiffness.toml":
        return f"{name}: identified from the forming run by roboisf analyze"
    return f"{name} (given with --stiffness)"


def _start(laps: pd.DataFrame, summary: dict[str, Any]) -> str | None:
    """Why the before/after curves start at their first lap (the rim band), or None."""
    cols = [c for c in ("abs_dn_before", "abs_dn_after") if c in laps]
    if not cols:
        return None
    has = laps[cols].notna().any(axis=1).to_numpy()
    if not has.any():
        return None
    first = int(laps["lap"].to_numpy()[has.argmax()])
    if first == int(laps["lap"].min()):
        return None
    rim = summary.get("rim_band_mm")
    where = (
        f"the first lap below the rim band (the top {float(rim):g} mm of depth, which the "
        "analysis leaves out)"
        if isinstance(rim, int | float)
        else "the first lap with measured deviation"
    )
    blend = summary.get("rim_blend_mm")
    ramp = (
        f"; the springback offset ramps in over the last {float(blend):g} mm of the rim band, "
        "the pre-deflection applies everywhere"
        if isinstance(blend, int | float) and blend > 0
        else ""
    )
    return f"The before/after curves start at lap {first}: {where}{ramp}."


def _number(value: Any) -> float | None:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if ok and math.isfinite(value) else None


def _gouge(g: dict[str, Any]) -> tuple[str, str]:
    """The gouge card's value and note: the verdict *with its margin* — how close the loaded ball
    comes to the gouge limit — and where that limit is (the rule's tolerance: a gouge is the
    ball centre deeper than intended by more than ``tol``), plus the over-bend against its
    limit. ``ok`` alone said nothing of a 0.010 mm margin."""
    verdict = "ok" if g.get("ok") else "GOUGE"
    margin, tol = _number(g.get("min_margin_mm")), _number(g.get("tol_mm"))
    if margin is None:  # an older compensation.json: the rule as it was
        return verdict, esc(g.get("rule", ""))
    value = f"{verdict}<small> · margin {margin:.3f} mm</small>"
    notes = []
    if tol is not None:
        past = tol - margin  # how far the loaded ball centre goes past the intended depth
        where = (
            "at the intended depth"
            if abs(past) < 5e-4
            else f"{abs(past):.3f} mm {'deeper' if past > 0 else 'shallower'} than intended"
        )
        notes.append(
            f"closest point: the loaded ball centre {where}; a gouge is more than {tol:.3f} mm "
            "deeper than intended (margin below 0)"
        )
    else:
        notes.append("smallest margin to the gouge limit (a gouge: margin below 0)")
    bend, limit = _number(g.get("max_intended_overbend_mm")), _number(g.get("max_overbend_mm"))
    if bend is not None and limit is not None:
        notes.append(f"intended over-bend up to {bend:.3f} mm of the {limit:.3f} mm allowed")
    bad = g.get("gouge_indices")
    if not g.get("ok") and isinstance(bad, list) and bad:
        notes.append(f"{len(bad)} points gouge")
    return value, esc("; ".join(notes))


def _card(label: str, value: str, note: str = "", cls: str = "") -> str:
    return (
        f'<div class="card{cls}"><div class="label">{label}</div><div class="value">{value}</div>'
        f'<div class="note">{note}</div></div>'
    )


def _body(laps: pd.DataFrame, summary: dict[str, Any], div: str) -> str:
    after = str(summary.get("after", "predicted"))
    key = f"mean_abs_dn_after_{after.replace(' ', '_')}_mm"
    g = summary.get("gouge") or {}
    cards = []
    if "mean_abs_dn_before_mm" in summary:
        cards.append(
            _card(
                "Mean |dn| before",
                f"{fmt(summary['mean_abs_dn_before_mm'], 3)}<small>mm</small>",
                "the part formed with the nominal command"
                + (
                    f", over its {summary['n_points_before']} scanned toolpath points (the "
                    "analysis's tables: those on both scans)"
                    if summary.get("n_points_before") is not None
                    else ""
                ),
            )
        )
    if key in summary:
        cards.append(
            _card(
                f"Mean |dn| after ({esc(after)})",
                f"{fmt(summary[key], 3)}<small>mm</small>",
                "predicted by superposition of the deflection model"
                if after == "predicted"
                else "formed again with the compensated command",
                " accent",
            )
        )
    if "max_command_offset_mm" in summary:
        cards.append(
            _card(
                "Largest commanded offset",
                f"{fmt(summary['max_command_offset_mm'], 3)}<small>mm</small>",
                f"mean {fmt(summary.get('mean_command_offset_mm'), 3)} mm",
            )
        )
    value, note = _gouge(g)
    cards.append(_card("Gouge check", value, note, "" if g.get("ok") else " warn"))
    lines = [f"<p><b>Compensated:</b> {esc(_terms(summary))}.</p>"]
    stiff = _stiffness(summary)
    if stiff:
        lines.append(f"<p><b>Joint stiffness of the pre-deflection:</b> {esc(stiff)}.</p>")
    elif (summary.get("terms") or {}).get("compliance"):
        lines.append("<p><b>Joint stiffness of the pre-deflection:</b> the cell's robot model.</p>")
    start = _start(laps, summary)
    how = (
        "predicted by superposition of the deflection model"
        if after == "predicted"
        else "formed again on the virtual cell"
        if after == "virtual cell"
        else after
    )
    caption = (
        "Left: mean |dn| per lap of the part formed with the nominal command (before) and with "
        f"the compensated one (after: {how}). Right: commanded offset = compensated − nominal "
        "tip, per-lap mean, its normal part n·Δ and its length |Δ|."
        + (f" {start}" if start else "")
    )
    history = summary.get("mean_abs_dn_per_iteration_mm")
    details = [
        ("study", summary.get("study")),
        ("virtual cell", summary.get("cell")),
        (
            "mean |dn| per iteration",
            " → ".join(f"{fmt(v, 3)}" for v in history) + " mm"
            if isinstance(history, list) and history
            else None,
        ),
        ("robot", summary.get("robot")),
        ("complete", "yes" if summary.get("complete") else "no (partial, see per_point.csv)"),
        ("toolpath points", summary.get("n_points")),
        (
            "rim band",
            None if summary.get("rim_band_mm") is None else f"{summary['rim_band_mm']:g} mm",
        ),
        (
            "largest lap-to-lap step",
            "springback offset "
            f"{fmt(summary.get('max_lap_step_springback_offset_mm'), 3)} mm, commanded offset "
            f"{fmt(summary.get('max_lap_step_command_dn_mm'), 3)} mm",
        ),
        ("G-code", summary.get("gcode")),
        ("gouge rule", g.get("rule")),
    ]
    return (
        f'<div class="cards">{"".join(cards)}</div>'
        + "".join(lines)
        + '<section id="curves"><h2>Before / after, lap by lap</h2>'
        f'<figure><div class="plot">{div}</div><figcaption>{esc(caption)}</figcaption></figure>'
        "</section>"
        '<section id="details"><h2>Details</h2>'
        f"{kv_table(details)}</section>"
    )


def write_compensation_report(
    laps: pd.DataFrame, summary: dict[str, Any], out_dir: str | Path, *, png: bool = False
) -> Path:
    """Write ``compensation.html`` (the study report's look: cards, sections, self-contained)
    and ``compensation.png`` into ``out_dir``; return the HTML.

    Says what was compensated, with which joint stiffness (``summary["stiffness"]``, file name
    only) and why the before/after curves start where they do (``rim_band_mm``)."""
    out = Path(out_dir)
    fig = compensation_figure(laps, summary)
    # a fixed div id (plotly draws a random one otherwise): two runs give the same bytes
    div = pio.to_html(
        fig,
        full_html=False,
        include_plotlyjs=True,
        include_mathjax=False,
        div_id="roboisf-compensation",
        config={"displaylogo": False, "responsive": True},
        default_height="420px",
        default_width="100%",
    )
    name = summary.get("study") or summary.get("cell")
    title = "roboisf compensation" + (f" — {name}" if name else "")
    sub = summary.get("robot") or ("virtual cell" if summary.get("cell") else "")
    document = page(title, _body(laps, summary, div), subtitle=esc(sub))
    with atomic_write(out / "compensation.html") as fh:
        fh.write(document)
    if png:
        from roboisf.report.static import save_png

        save_png(compensation_png(laps, summary), out / "compensation.png")
    return out / "compensation.html"
