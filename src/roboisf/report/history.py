"""Figures and the page of the history and of a predicted part (matplotlib, the report's style).

- :func:`save_trend_png` — a term's R_m per part over time, one line per group, and the VJM
  check's measured/modelled ratio below it (``roboisf history trend -o``);
- :func:`prediction_png` / :func:`write_prediction_report` — the predicted normal error of a part
  not yet formed, per term, top view, with the springback interval's width and the learner's
  leave-one-part-out validation (``roboisf predict``: ``prediction.png``, ``report.html``).
"""

from __future__ import annotations

import base64
import html
import io
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from roboisf.io.atomic import atomic_write
from roboisf.report.static import _figure, _style, _vmax, save_png
from roboisf.report.style import FACTOR_COLORS, FACTOR_LABELS, FONT_STACK

__all__ = ["prediction_png", "save_trend_png", "trend_png", "write_prediction_report"]

_PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#3B3B3B")


def _when(stamp: str) -> datetime:
    return datetime.fromisoformat(stamp.rstrip("Z"))


def trend_png(groups: list[Any], factor: str) -> Figure:
    """``groups`` are :class:`roboisf.history.trend.TrendGroup`; R_m in mm over time."""
    with _style():
        fig = _figure(7.0, 4.6, left=0.8, bottom=0.9, hspace=0.25)
        ax, ax2 = fig.subplots(2, 1, sharex=True)
        for i, g in enumerate(groups):
            color = _PALETTE[i % len(_PALETTE)]
            t = [_when(s) for s in g.formed_at]
            v = [np.nan if x is None else x * 1e3 for x in g.values]
            r = [np.nan if x is None else x for x in g.vjm_ratio]
            ax.plot(t, v, "o-", color=color, label=g.key, markersize=3, linewidth=1.2)
            ax2.plot(t, r, "o-", color=color, markersize=3, linewidth=1.2)
        ax.set(ylabel=f"{FACTOR_LABELS.get(factor, factor)} R_m (mm)")
        ax2.axhline(1.0, color="#52606D", linewidth=0.8, linestyle="--")
        ax2.set(ylabel="VJM ratio (measured / model)", xlabel="formed (UTC)")
        ax.legend(loc="best")
        for label in ax2.get_xticklabels():
            label.set_rotation(20)
            label.set_horizontalalignment("right")
    return fig


def save_trend_png(groups: list[Any], factor: str, path: Path) -> Path:
    """Write :func:`trend_png` atomically."""
    return save_png(trend_png(groups, factor), path)


_TERMS = ("springback", "robot_compliance", "tool", "tool_holder")


def prediction_png(per_point: pd.DataFrame) -> Figure:
    """Top views (x, y in mm) of each predicted term's normal deviation and of the total, and
    the springback against depth with its interval and the rim band
    (``roboisf.learn.predict.Prediction.per_point`` with ``below_rim_band``)."""
    cols = [f"{t}_dn" for t in _TERMS] + ["total_dn"]
    vmax = _vmax(*(per_point[c].to_numpy() for c in cols))
    x, y = per_point["contact_x"].to_numpy(), per_point["contact_y"].to_numpy()
    with _style():
        fig = _figure(9.5, 6.0, left=0.6, right=1.0, bottom=0.5, top=0.35)
        gs = fig.add_gridspec(2, 3, wspace=0.3, hspace=0.35)
        sc = None
        for i, c in enumerate(cols):
            ax = fig.add_subplot(gs[i // 3, i % 3])
            name = c.removesuffix("_dn")
            sc = ax.scatter(
                x,
                y,
                c=per_point[c],
                s=2,
                cmap="RdBu_r",
                vmin=-vmax,
                vmax=vmax,
                linewidths=0,
                rasterized=True,
            )
            ax.set_title(FACTOR_LABELS.get(name, name), color=FACTOR_COLORS.get(name, "#1F2933"))
            ax.set(aspect="equal", xlabel="x (mm)" if i >= 3 else "", ylabel="y (mm)")
            ax.grid(False)
        assert sc is not None
        cax = fig.add_axes((1 - 0.8 / 9.5, 0.5 / 6.0, 0.12 / 9.5, 1 - 0.85 / 6.0))
        fig.colorbar(sc, cax=cax, label="predicted δn (mm)")
        ax = fig.add_subplot(gs[1, 2])
        d = per_point["depth"].to_numpy()
        laps = per_point.groupby("lap").agg(
            depth=("depth", "mean"),
            lo=("springback_dn_low", "min"),
            hi=("springback_dn_high", "max"),
        )
        color = FACTOR_COLORS["springback"]
        ax.fill_between(laps["depth"], laps["lo"], laps["hi"], color=color, alpha=0.18, linewidth=0)
        ax.plot(d, per_point["springback_dn"], ".", color=color, markersize=1.5)
        if "below_rim_band" in per_point:
            band = d[~per_point["below_rim_band"].to_numpy(dtype=bool)]
            if band.size:
                ax.axvspan(0, band.max(), color="#E4E7EB", zorder=0, label="rim band")
                ax.legend(loc="lower right")
        ax.set(title="Springback ± interval", xlabel="depth (mm)", ylabel="δn (mm)")
    return fig


def _table(rows: list[list[str]], head: list[str]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def write_prediction_report(
    folder: Path, per_point: pd.DataFrame, summary: dict[str, Any], *, png: bool = False
) -> None:
    """Write ``prediction.png`` (with ``png``) and ``report.html`` (the figure inlined) into
    ``folder`` (a staging folder: the files are written directly)."""
    fig = prediction_png(per_point)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, facecolor="white")
    if png:
        save_png(fig, folder / "prediction.png")
    terms = summary["terms_normal"]
    rows = [
        [FACTOR_LABELS.get(t, t), f"{v['rms_mm']:.3f}", f"{v['mean_abs_mm']:.3f}"]
        for t, v in terms.items()
    ]
    model = summary["springback_model"]
    val = [
        [
            str(v["part_id"]),
            str(v["part_kind"]),
            str(v["n_points"]),
            f"{v['rms_springback_mm']:.3f}",
            f"{v['rms_error_mm']:.3f}",
            f"{100 * v['relative_error']:.0f} %",
            f"{100 * v['coverage']:.0f} %",
        ]
        for v in model["validation"]
    ]
    extra = summary.get("extrapolated_features") or {}
    warn = (
        "<p class='warn'>Outside the history's range below the rim band (share of points): "
        + html.escape(", ".join(f"{k} {100 * s:.0f} %" for k, s in extra.items()))
        + " — the model extrapolates there.</p>"
        if extra
        else ""
    )
    n_rim, rim_mm = summary.get("rim_band_points"), summary.get("rim_band_mm")
    if n_rim and rim_mm is not None:
        warn += (
            f"<p>The rim band (the first {rim_mm:g} mm of depth, {n_rim} of "
            f"{summary['n_points']} points, shaded in the plot) is predicted by extrapolation: "
            "the history's analyses measure springback below it.</p>"
        )
    img = base64.b64encode(buf.getvalue()).decode()
    page = f"""<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>roboisf predict — {html.escape(str(summary.get("part", "")))}</title>
<style>body{{font-family:{FONT_STACK};color:#1F2933;max-width:1000px;margin:2em auto;
padding:0 1em}} table{{border-collapse:collapse;margin:1em 0}} td,th{{border-bottom:1px solid
#E4E7EB;padding:3px 10px;text-align:right}} th{{background:#F5F7FA}} .warn{{color:#D55E00}}
img{{max-width:100%}}</style></head><body>
<h1>Predicted error of a part not yet formed</h1>
<p>{html.escape(str(summary.get("part", "")))} on {html.escape(str(summary.get("robot", "")))};
{summary["n_points"]} toolpath points. Normal deviations δn (mm, positive towards the tool side)
at the ball centre. Springback learned from the history ({model["n_parts"]} parts,
{model["n_points"]} points); tool and holder from their compliance; robot by the VJM with
{html.escape(summary["joint_stiffness_from"])}.</p>
{warn}
<h2>Terms</h2>{_table(rows, ["term", "RMS δn (mm)", "mean |δn| (mm)"])}
<p>Springback interval: ± {model["interval_half_width_mm"]:.3f} mm at a nominal
{100 * model["coverage"]:.0f} % coverage (split-conformal on the leave-one-part-out residuals).
</p>
<img alt="predicted error map" src="data:image/png;base64,{img}">
<h2>Springback model: each history part predicted by the others</h2>
{_table(val, ["part", "kind", "points", "RMS springback", "RMS error", "error/RMS", "in interval"])}
<p>{html.escape(model["method"])}; features: {html.escape(", ".join(model["features"]))}.</p>
</body></html>
"""
    with atomic_write(folder / "report.html") as f:
        f.write(page)
