"""Interactive figures (plotly) of the HTML report. One function per figure, each taking the checked
per-point table (and what else it needs) and returning a :class:`roboisf.report.plotfig.Figure`
(plotly's JSON without its figure objects: ``.to_go()`` gives the validated plotly figure).

Every x-axis that can be is the depth below the sheet (mm), so the figures read together; lap
means are drawn as lines with a 5–95 % band showing the spread around the lap.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from roboisf.report import aggregate as agg
from roboisf.report import plotfig as pf
from roboisf.report.schema import FACTORS, RUNS
from roboisf.report.style import (
    AXIS_LABELS,
    FACTOR_COLORS,
    FACTOR_LABELS,
    RUN_COLORS,
    RUN_LABELS,
    SERIES_COLORS,
    plotly_layout,
)

__all__ = [
    "contributions_figure",
    "deviation_depth_figure",
    "deviation_map_figure",
    "deviation_top_figure",
    "factors_depth_figure",
    "forces_figure",
    "part_figure",
    "thickness_figure",
    "vjm_contour_figure",
    "vjm_path_figure",
    "vjm_polar_figure",
]


def rgba(color: str, alpha: float) -> str:
    """``#RRGGBB`` → ``rgba(r,g,b,alpha)``."""
    c = color.lstrip("#")
    r, g, b = (int(c[i : i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r},{g},{b},{alpha})"


def _f(values: Any) -> np.ndarray:
    """Float32 keeps the embedded JSON small; report precision is well under 1e-7 relative."""
    return np.asarray(values, dtype=np.float32)


def _line_with_band(
    fig: pf.Figure,
    prof: pd.DataFrame,
    col: str,
    *,
    name: str,
    color: str,
    row: int | None = None,
    col_: int | None = None,
    showlegend: bool = True,
    dash: str | None = None,
    band: bool = True,
) -> None:
    kw: dict[str, Any] = {} if row is None else {"row": row, "col": col_}
    x = _f(prof["depth"])
    group = name
    if band:
        for edge, fill in (("hi", None), ("lo", "tonexty")):
            fig.add_trace(
                pf.trace(
                    "scatter",
                    x=x,
                    y=_f(prof[f"{col}_{edge}"]),
                    mode="lines",
                    line={"width": 0},
                    fill=fill,
                    fillcolor=rgba(color, 0.18) if fill else None,
                    hoverinfo="skip",
                    showlegend=False,
                    legendgroup=group,
                ),
                **kw,
            )
    fig.add_trace(
        pf.trace(
            "scatter",
            x=x,
            y=_f(prof[col]),
            mode="lines",
            name=name,
            legendgroup=group,
            showlegend=showlegend,
            line={"color": color, "width": 2, "dash": dash},
            hovertemplate="%{y:.4f}",
        ),
        **kw,
    )


def _style_axes(fig: pf.Figure, layout: dict[str, Any]) -> None:
    fig.update_xaxes(**{k: v for k, v in layout["xaxis"].items() if k != "title"})
    fig.update_yaxes(**{k: v for k, v in layout["yaxis"].items() if k != "title"})


def _subplots(
    rows: int, cols: int, titles: list[str], height: int, hspace: float = 0.09, **kw: Any
) -> pf.Figure:
    """Subplots in the report style, legend above the subplot titles, x titles on the bottom row."""
    top, bottom = 96, 56
    fig = pf.subplots(
        rows,
        cols,
        titles,
        horizontal_spacing=hspace,
        vertical_spacing=min(0.34, 80.0 / (height - top - bottom)) if rows > 1 else 0.0,
        **kw,
    )
    layout = plotly_layout(height=height)
    layout["margin"] = {"l": 64, "r": 24, "t": top, "b": bottom}
    layout["legend"] = {**layout["legend"], "y": 1.0 + 34.0 / (height - top - bottom)}
    fig.update_layout({k: v for k, v in layout.items() if k not in ("xaxis", "yaxis")})
    _style_axes(fig, layout)
    fig.update_annotations(font={"size": 13})
    return fig


def _xtitle_bottom(fig: pf.Figure, rows: int, cols: int, text: str) -> None:
    for c in range(1, cols + 1):
        fig.update_xaxes(title_text=text, row=rows, col=c)


def forces_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Axial force Fz and in-plane resultant √(Fx²+Fy²) vs depth, CNC vs robot (lap means, N)."""
    prof = agg.force_profile(per_point)
    fig = _subplots(
        1, 2, ["Axial force F<sub>z</sub>", "In-plane force √(F<sub>x</sub>²+F<sub>y</sub>²)"], 400
    )
    for j, comp in enumerate(("Fz", "Fxy"), start=1):
        for run in RUNS:
            _line_with_band(
                fig,
                prof,
                f"{run}_{comp}",
                name=RUN_LABELS[run],
                color=RUN_COLORS[run],
                row=1,
                col_=j,
                showlegend=j == 1,
            )
        fig.update_xaxes(title_text="depth (mm)", row=1, col=j)
        fig.update_yaxes(title_text="force (N)", row=1, col=j)
    return fig


def deviation_depth_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Measured deviation per axis vs depth, CNC vs robot part (lap mean and 5–95 % band, mm)."""
    cols = [f"{r}_{a}" for r in RUNS for a in ("dx", "dy", "dz", "dn")]
    prof = agg.lap_profile(per_point, cols)
    axes = ("dx", "dy", "dz", "dn")
    fig = _subplots(2, 2, [AXIS_LABELS[a] for a in axes], 660, shared_xaxes=True)
    for k, a in enumerate(axes):
        row, col = divmod(k, 2)
        for run in RUNS:
            _line_with_band(
                fig,
                prof,
                f"{run}_{a}",
                name=f"{RUN_LABELS[run]} part",
                color=RUN_COLORS[run],
                row=row + 1,
                col_=col + 1,
                showlegend=k == 0,
            )
        fig.update_yaxes(title_text="deviation (mm)", row=row + 1, col=col + 1)
    _xtitle_bottom(fig, 2, 2, "depth (mm)")
    return fig


def _vmax(*arrays: np.ndarray) -> float:
    """Symmetric colour limit: the 99th percentile of |value| over the finite values."""
    finite = np.concatenate([a[np.isfinite(a)] for a in arrays])
    return float(np.percentile(np.abs(finite), 99)) if finite.size else 1.0


def deviation_map_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Normal deviation of the CNC and robot parts unrolled: position along each lap × depth.

    Any part: x is the fraction of the lap's length from its point nearest the +x axis, in
    toolpath order (on a round part φ/360°); the hover gives the arc length in mm.
    """
    maps = {run: agg.lap_map(per_point, f"{run}_dn") for run in RUNS}
    vmax = _vmax(*(m.values for m in maps.values()))
    fig = _subplots(1, 2, [f"{RUN_LABELS[r]} part" for r in RUNS], 520, shared_yaxes=True)
    for j, run in enumerate(RUNS, start=1):
        m = maps[run]
        arc = np.outer(m.length, m.position)
        fig.add_trace(
            pf.trace(
                "heatmap",
                x=_f(100.0 * m.position),
                y=_f(m.depth),
                z=_f(m.values),
                customdata=_f(arc),
                zmin=-vmax,
                zmax=vmax,
                zmid=0.0,
                colorscale=pf.colorscale("RdBu_r"),
                showscale=j == 2,
                coloraxis=None,
                colorbar={"title": {"text": "δn (mm)", "side": "right"}, "thickness": 14},
                hovertemplate=(
                    "%{x:.1f} % of the lap (%{customdata:.1f} mm)<br>depth %{y:.1f} mm<br>"
                    "δn %{z:.3f} mm<extra></extra>"
                ),
                hoverongaps=False,
            ),
            row=1,
            col=j,
        )
        fig.update_xaxes(
            title_text="position along the lap (% of its length, from +x)",
            range=[0, 100],
            dtick=25,
            row=1,
            col=j,
        )
    fig.update_yaxes(title_text="depth (mm)", autorange="reversed", row=1, col=1)
    fig.update_yaxes(autorange="reversed", row=1, col=2)
    fig.update_layout(hovermode="closest", plot_bgcolor="#F5F7FA")
    return fig


def deviation_top_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Normal deviation of the CNC and robot parts seen from above: the toolpath points (x, y),
    at most 12 000 per part, coloured by δn (mm); scan holes are left blank."""
    views = {run: agg.top_view(per_point, f"{run}_dn") for run in RUNS}
    vmax = _vmax(*(v.values for v in views.values()))
    fig = _subplots(1, 2, [f"{RUN_LABELS[r]} part" for r in RUNS], 520)
    for j, run in enumerate(RUNS, start=1):
        v = views[run]
        fig.add_trace(
            pf.trace(
                "scatter",
                x=_f(v.x),
                y=_f(v.y),
                mode="markers",
                marker={
                    "color": _f(v.values),
                    "colorscale": pf.colorscale("RdBu_r"),
                    "cmin": -vmax,
                    "cmax": vmax,
                    "cmid": 0.0,
                    "size": 3,
                    "showscale": j == 2,
                    "colorbar": {"title": {"text": "δn (mm)", "side": "right"}, "thickness": 14},
                },
                showlegend=False,
                hovertemplate="x %{x:.1f} mm, y %{y:.1f} mm<br>δn %{marker.color:.3f} mm"
                "<extra></extra>",
            ),
            row=1,
            col=j,
        )
        axis = "" if j == 1 else str(j)
        fig.update_xaxes(title_text="x (mm)", row=1, col=j)
        fig.update_yaxes(scaleanchor=f"x{axis}", scaleratio=1, row=1, col=j)
    fig.update_yaxes(title_text="y (mm)", row=1, col=1)
    fig.update_layout(hovermode="closest", plot_bgcolor="#F5F7FA")
    return fig


def factors_depth_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Each contribution's normal component vs depth (lap mean, band), truth dashed when known."""
    cols = [f"{f}_dn" for f in FACTORS]
    truth = [f"truth_{f}_dn" for f in FACTORS if f"truth_{f}_dn" in per_point.columns]
    prof = agg.lap_profile(per_point, cols + truth)
    fig = _subplots(2, 2, [FACTOR_LABELS[f] for f in FACTORS], 660, shared_xaxes=True)
    for k, f in enumerate(FACTORS):
        row, col = divmod(k, 2)
        _line_with_band(
            fig,
            prof,
            f"{f}_dn",
            name=f"{FACTOR_LABELS[f]} (recovered)",
            color=FACTOR_COLORS[f],
            row=row + 1,
            col_=col + 1,
        )
        if f"truth_{f}_dn" in truth:
            _line_with_band(
                fig,
                prof,
                f"truth_{f}_dn",
                name="ground truth",
                color=SERIES_COLORS["truth"],
                row=row + 1,
                col_=col + 1,
                dash="dash",
                band=False,
                showlegend=k == 0,
            )
        fig.update_yaxes(title_text="δn (mm)", row=row + 1, col=col + 1)
    _xtitle_bottom(fig, 2, 2, "depth (mm)")
    return fig


def vjm_path_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Robot compliance error along the path, per work axis: experiment δc_exp vs VJM prediction
    and their difference Δ (lap means vs depth; bands: the variation around each lap)."""
    axes = ("dx", "dy", "dz")
    cols = [f"{p}_{a}" for p in ("robot_compliance", "vjm", "delta") for a in axes]
    prof = agg.lap_profile(per_point, cols)
    fig = _subplots(
        3, 1, ["δc<sub>x</sub>", "δc<sub>y</sub>", "δc<sub>z</sub>"], 760, shared_xaxes=True
    )
    for k, a in enumerate(axes, start=1):
        for prefix, name, color, dash, band in (
            (
                "robot_compliance",
                "experiment δc<sub>exp</sub>",
                SERIES_COLORS["experiment"],
                None,
                True,
            ),
            ("vjm", "VJM prediction δc<sub>VJM</sub>", SERIES_COLORS["vjm"], "dash", True),
            (
                "delta",
                "Δ = δc<sub>exp</sub> − δc<sub>VJM</sub>",
                SERIES_COLORS["delta"],
                None,
                False,
            ),
        ):
            _line_with_band(
                fig,
                prof,
                f"{prefix}_{a}",
                name=name,
                color=color,
                row=k,
                col_=1,
                showlegend=k == 1,
                dash=dash,
                band=band,
            )
        fig.update_yaxes(title_text="mm", row=k, col=1)
    fig.update_xaxes(title_text="depth (mm)", row=3, col=1)
    return fig


def contour_caption(
    lap: int, z: float, note: str | None, contour_z: float | None, length: float | None = None
) -> str:
    """Which contour the figure shows and why (:func:`roboisf.report.aggregate.contour_lap`);
    ``length`` (mm) of the lap when given."""
    long = "" if length is None else f", {length:.1f} mm long"
    text = f"Contour at z = {z:.2f} mm (lap {lap}{long})"
    if note is None:
        return f"{text}, the lap nearest the requested z = {contour_z:.2f} mm."
    return f"{text}: {note}."


def vjm_polar_figure(
    per_point: pd.DataFrame, contour_z: float | None = None
) -> tuple[pf.Figure, str]:
    """Resultant robot deflection |δc| around the contour nearest ``contour_z`` (mm; None: the
    middle of the analysed wall, :func:`roboisf.report.aggregate.contour_lap`): experiment vs
    VJM.

    Returns the figure and its caption (which lap, its height, and any substitution).
    """
    c = agg.contour(per_point, contour_z)
    fig = pf.Figure(layout=plotly_layout(height=480, hovermode="closest"))
    series = (
        (
            "experiment |δc<sub>exp</sub>|",
            c.experiment,
            SERIES_COLORS["experiment"],
            2.2,
        ),
        ("VJM |δc<sub>VJM</sub>|", c.vjm, SERIES_COLORS["vjm"], 1.8),
        (
            "|Δ| = |δc<sub>exp</sub> − δc<sub>VJM</sub>|",
            c.delta,
            SERIES_COLORS["delta"],
            1.6,
        ),
    )
    for name, r, color, width in series:
        fig.add_trace(
            pf.trace(
                "scatterpolar",
                r=_f(r),
                theta=_f(c.angle_deg),
                mode="lines",
                name=name,
                line={"color": color, "width": width},
                hovertemplate="%{theta:.0f}°: %{r:.3f} mm<extra></extra>",
            )
        )
    fig.update_layout(
        polar={
            "bgcolor": "white",
            "radialaxis": {
                "gridcolor": "#E4E7EB",
                "angle": 90,
                "tickangle": 90,
                "ticksuffix": " mm",
            },
            "angularaxis": {"direction": "counterclockwise", "rotation": 0, "gridcolor": "#E4E7EB"},
        },
        margin={"l": 40, "r": 40, "t": 60, "b": 40},
    )
    return fig, contour_caption(c.lap, c.z, c.note, contour_z)


def vjm_contour_figure(
    per_point: pd.DataFrame, contour_z: float | None = None
) -> tuple[pf.Figure, str]:
    """Resultant robot deflection along the contour nearest ``contour_z`` on a part that is not
    round: the lap's outline seen from above coloured by |δc_exp| (left) and |δc_exp|, |δc_VJM|,
    |Δ| against the arc length along the lap (right), in mm.

    Returns the figure and its caption (which lap, its height, its length, any substitution).
    """
    c = agg.contour_along(per_point, contour_z)
    fig = _subplots(1, 2, ["Outline, colour |δc<sub>exp</sub>|", "Along the lap"], 480, hspace=0.2)
    fig.add_trace(
        pf.trace(
            "scatter",
            x=_f(c.x),
            y=_f(c.y),
            mode="lines+markers",
            line={"color": "#CBD2D9", "width": 1},
            marker={
                "color": _f(c.experiment),
                "colorscale": pf.colorscale("Viridis"),
                "size": 6,
                "showscale": True,
                "colorbar": {
                    "title": {"text": "mm", "side": "right"},
                    "thickness": 12,
                    "x": 0.41,
                    "xanchor": "left",
                },
            },
            showlegend=False,
            customdata=_f(c.s),
            hovertemplate="s %{customdata:.1f} mm<br>|δc<sub>exp</sub>| %{marker.color:.3f} mm"
            "<extra></extra>",
        ),
        row=1,
        col=1,
    )
    fig.update_xaxes(title_text="x (mm)", row=1, col=1)
    fig.update_yaxes(title_text="y (mm)", scaleanchor="x", scaleratio=1, row=1, col=1)
    for name, r, color, width in (
        ("experiment |δc<sub>exp</sub>|", c.experiment, SERIES_COLORS["experiment"], 2.2),
        ("VJM |δc<sub>VJM</sub>|", c.vjm, SERIES_COLORS["vjm"], 1.8),
        ("|Δ| = |δc<sub>exp</sub> − δc<sub>VJM</sub>|", c.delta, SERIES_COLORS["delta"], 1.6),
    ):
        fig.add_trace(
            pf.trace(
                "scatter",
                x=_f(c.s),
                y=_f(r),
                mode="lines",
                name=name,
                line={"color": color, "width": width},
                hovertemplate="s %{x:.1f} mm: %{y:.3f} mm",
            ),
            row=1,
            col=2,
        )
    fig.update_xaxes(
        title_text="arc length along the lap from +x (mm)", range=[0, c.length], row=1, col=2
    )
    fig.update_yaxes(title_text="|δc| (mm)", rangemode="tozero", row=1, col=2)
    fig.update_layout(hovermode="closest")
    return fig, contour_caption(c.lap, c.z, c.note, contour_z, c.length)


def contributions_figure(
    contributions: pd.DataFrame, contributions_normal: pd.DataFrame
) -> pf.Figure:
    """Share (%) and R_m (mm) of each factor, both ways: per-axis vectors and normal projection."""
    fig = _subplots(1, 2, ["Share of the resultant mean deviation (%)", "R<sub>m</sub> (mm)"], 420)
    labels = [FACTOR_LABELS[f] for f in FACTORS]
    colors = [FACTOR_COLORS[f] for f in FACTORS]
    versions = (
        ("per-axis vectors (paper)", contributions, ""),
        ("normal projection (scan)", contributions_normal, "/"),
    )
    for j, col in enumerate(("share_percent", "R_m"), start=1):
        for name, table, pattern in versions:
            values = table.loc[list(FACTORS), col].to_numpy(dtype=float)
            fig.add_trace(
                pf.trace(
                    "bar",
                    x=labels,
                    y=values,
                    name=name,
                    legendgroup=name,
                    showlegend=j == 1,
                    marker={
                        "color": colors if not pattern else [rgba(c, 0.45) for c in colors],
                        "line": {"color": colors, "width": 1.5},
                        "pattern": {"shape": pattern, "fgcolor": "#FFFFFF" if pattern else None},
                    },
                    text=[f"{v:.1f}" if col == "share_percent" else f"{v:.3f}" for v in values],
                    textposition="outside",
                    cliponaxis=False,
                    hovertemplate="%{x}: %{y:.4g}<extra>" + name + "</extra>",
                ),
                row=1,
                col=j,
            )
    fig.update_layout(barmode="group", hovermode="closest", bargap=0.25)
    fig.update_yaxes(title_text="share (%)", row=1, col=1)
    fig.update_yaxes(title_text="R<sub>m</sub> (mm)", row=1, col=2)
    return fig


def thickness_figure(per_point: pd.DataFrame) -> pf.Figure:
    """Wall thickness vs depth: sine law t₀·cos α, and the measured thickness when given (mm)."""
    cols = ["thickness_predicted"]
    has_measured = "thickness_measured" in per_point.columns
    if has_measured:
        cols.append("thickness_measured")
    prof = agg.lap_profile(per_point, cols)
    spread = agg.thickness_spread(per_point)
    fig = pf.Figure(layout=plotly_layout(height=380))
    if spread is not None:  # walls of different angle in one lap: their range, not a mean
        x = _f(spread.depth)
        name = spread.label
        for y, fill, which in (
            (spread.high, None, "thickest"),
            (spread.low, "tonexty", "thinnest"),
        ):
            fig.add_trace(
                pf.trace(
                    "scatter",
                    x=x,
                    y=_f(y),
                    mode="lines",
                    line={"width": 0, "color": SERIES_COLORS["predicted"]},
                    fill=fill,
                    fillcolor=rgba(SERIES_COLORS["predicted"], 0.18) if fill else None,
                    name=name,
                    legendgroup="spread",
                    showlegend=fill is not None,
                    hovertemplate=f"{which} wall %{{y:.3f}} mm<extra></extra>",
                )
            )
    _line_with_band(
        fig,
        prof,
        "thickness_predicted",
        name="predicted (sine law)" if spread is None else "predicted (sine law), lap mean",
        color=SERIES_COLORS["predicted"],
        band=False,
        dash="dash",
    )
    if has_measured:
        _line_with_band(
            fig, prof, "thickness_measured", name="measured", color=SERIES_COLORS["measured"]
        )
    fig.update_xaxes(title_text="depth (mm)")
    fig.update_yaxes(title_text="wall thickness (mm)", rangemode="tozero")
    return fig


#: The flattest side of the 3D view's box, relative to its longest (a 12 mm deep, 120 mm wide
#: cone keeps a visible depth).
MIN_ASPECT = 0.15


def _aspect(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> dict[str, float]:
    """``scene.aspectratio`` of coordinates (mm): the ranges over the longest, at least
    :data:`MIN_ASPECT`."""
    spans = [
        float(np.nanmax(a) - np.nanmin(a)) if np.any(np.isfinite(a)) else 0.0 for a in (x, y, z)
    ]
    top = max(spans) or 1.0
    return {k: round(max(v / top, MIN_ASPECT), 4) for k, v in zip("xyz", spans, strict=True)}


def part_figure(per_point: pd.DataFrame) -> pf.Figure:
    """The formed part in 3D: whole laps of the toolpath (contact points in the work frame, mm)
    drawn as lines coloured by the normal value of one term at a time — total, springback, tool,
    holder, robot compliance, residual Δ — with buttons to switch; at most
    :data:`~roboisf.report.aggregate.MAX_3D_POINTS` points. Each term has its own symmetric
    colour scale (its 99th percentile of |δn|), blue below the nominal, red above; a scan hole
    breaks the line."""
    view = agg.part_view(per_point)
    terms = [(c, label) for c, label in agg.PART_VIEW_TERMS if c in view.values]
    fig = pf.Figure()
    for k, (col, label) in enumerate(terms):
        v = view.values[col]
        hole = ~np.isfinite(v)
        vmax = _vmax(v) or 1.0

        def cut(a: np.ndarray, hole: np.ndarray = hole) -> np.ndarray:
            return _f(np.where(hole, np.nan, a))

        fig.add_trace(
            pf.trace(
                "scatter3d",
                x=cut(view.x),
                y=cut(view.y),
                z=cut(view.z),
                mode="lines",
                name=label,
                visible=k == 0,
                connectgaps=False,
                line={
                    "color": _f(np.where(hole, 0.0, v)),
                    "colorscale": pf.colorscale("RdBu_r"),
                    "cmin": -vmax,
                    "cmax": vmax,
                    "width": 5,
                    "showscale": True,
                    "colorbar": {"title": {"text": "δn (mm)", "side": "right"}, "thickness": 14},
                },
                hovertemplate="x %{x:.1f}, y %{y:.1f}, z %{z:.1f} mm<br>"
                + label
                + " δn %{line.color:.3f} mm<extra></extra>",
            )
        )
    buttons = [
        {
            "label": label,
            "method": "update",
            "args": [{"visible": [j == k for j in range(len(terms))]}],
        }
        for k, (_, label) in enumerate(terms)
    ]
    fig.update_layout(
        plotly_layout(
            height=620,
            hovermode="closest",
            showlegend=False,
            margin={"l": 0, "r": 0, "t": 56, "b": 0},
            scene={
                # the data's proportions with the longest side 1: plotly's "data" mode scales
                # the box to unit volume, so a flat or long part (a 160 × 80 × 25 mm pyramid,
                # a 12 mm deep cone) grew past the fixed camera and was cut off
                "aspectmode": "manual",
                "aspectratio": _aspect(view.x, view.y, view.z),
                "xaxis": {"title": {"text": "x (mm)"}},
                "yaxis": {"title": {"text": "y (mm)"}},
                "zaxis": {"title": {"text": "z (mm)"}},
                "camera": {"eye": {"x": 1.05, "y": -1.05, "z": 0.75}},
            },
            updatemenus=[
                {
                    "type": "buttons",
                    "direction": "right",
                    "buttons": buttons,
                    "active": 0,
                    "x": 0,
                    "xanchor": "left",
                    "y": 1.0,
                    "yanchor": "bottom",
                    "pad": {"t": 0, "b": 8},
                    "showactive": True,
                    "font": {"size": 12},
                }
            ],
        )
    )
    return fig
