"""One palette, one set of labels, one look — shared by the HTML (plotly) and PNG (matplotlib)
figures.

Colours are the Okabe–Ito colour-blind-safe set; every factor keeps its colour in every figure and
table of a report, and the two runs (CNC, robot) keep theirs.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "AXIS_LABELS",
    "FACTOR_COLORS",
    "FACTOR_LABELS",
    "FONT_STACK",
    "RUN_COLORS",
    "RUN_LABELS",
    "SERIES_COLORS",
    "mpl_rc",
    "plotly_layout",
]

FACTOR_COLORS: dict[str, str] = {
    "tool": "#0072B2",  # blue
    "tool_holder": "#56B4E9",  # sky blue
    "springback": "#009E73",  # bluish green
    "robot_compliance": "#D55E00",  # vermilion
    "total": "#3B3B3B",
}
FACTOR_LABELS: dict[str, str] = {
    "tool": "Tool",
    "tool_holder": "Tool holder",
    "springback": "Springback",
    "robot_compliance": "Robot compliance",
    "total": "Total",
}
RUN_COLORS: dict[str, str] = {"cnc": "#5A6B7B", "robot": "#E69F00"}
RUN_LABELS: dict[str, str] = {"cnc": "CNC", "robot": "Robot"}
SERIES_COLORS: dict[str, str] = {
    "experiment": FACTOR_COLORS["robot_compliance"],
    "vjm": "#1B1B1B",
    "delta": "#CC79A7",  # reddish purple
    "truth": "#1B1B1B",
    "predicted": "#0072B2",
    "measured": "#D55E00",
}
AXIS_LABELS: dict[str, str] = {"dx": "δx", "dy": "δy", "dz": "δz", "dn": "δn (normal)"}

#: System fonts only: the report works offline and never fetches a web font.
FONT_STACK = (
    'system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", "Noto Sans", '
    '"Liberation Sans", Arial, sans-serif'
)
_TEXT = "#1F2933"
_GRID = "#E4E7EB"


def plotly_layout(**overrides: Any) -> dict[str, Any]:
    """Base plotly layout (no template: keeps each figure's JSON small)."""
    axis = {
        "showline": True,
        "linecolor": "#9AA5B1",
        "gridcolor": _GRID,
        "zerolinecolor": "#CBD2D9",
        "ticks": "outside",
        "tickcolor": "#9AA5B1",
        "automargin": True,
        "title": {"standoff": 8},
    }
    layout: dict[str, Any] = {
        "template": "none",
        "font": {"family": FONT_STACK, "size": 13, "color": _TEXT},
        "paper_bgcolor": "white",
        "plot_bgcolor": "white",
        "margin": {"l": 64, "r": 24, "t": 48, "b": 56},
        "hovermode": "x unified",
        "legend": {"orientation": "h", "yanchor": "bottom", "y": 1.02, "xanchor": "left", "x": 0},
        "xaxis": dict(axis),
        "yaxis": dict(axis),
        "height": 420,
    }
    layout.update(overrides)
    return layout


def mpl_rc() -> dict[str, Any]:
    """matplotlib rcParams for the static figures (used inside ``plt.rc_context``)."""
    return {
        "font.size": 9,
        "axes.titlesize": 10,
        "axes.labelsize": 9,
        "axes.edgecolor": "#52606D",
        "axes.grid": True,
        "grid.color": _GRID,
        "grid.linewidth": 0.6,
        "axes.spines.top": False,
        "axes.spines.right": False,
        "legend.frameon": False,
        "legend.fontsize": 8,
        "figure.dpi": 100,
        "savefig.dpi": 200,
        "savefig.bbox": "tight",
        "text.color": _TEXT,
        "axes.labelcolor": _TEXT,
        "xtick.color": "#52606D",
        "ytick.color": "#52606D",
    }
