"""Static figures (matplotlib, Agg, no pyplot global state) — the report's figures for papers.

They draw the same reductions (:mod:`roboisf.report.aggregate`) with the same palette
(:mod:`roboisf.report.style`) as the interactive ones.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import matplotlib as mpl
import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patheffects import withStroke
from matplotlib.ticker import MaxNLocator

from roboisf.io.atomic import atomic_path
from roboisf.report import aggregate as agg
from roboisf.report.schema import FACTORS, RUNS
from roboisf.report.style import (
    AXIS_LABELS,
    FACTOR_COLORS,
    FACTOR_LABELS,
    RUN_COLORS,
    RUN_LABELS,
    SERIES_COLORS,
    mpl_rc,
)

__all__ = [
    "contributions_png",
    "deviation_depth_png",
    "deviation_map_png",
    "deviation_top_png",
    "factors_depth_png",
    "forces_png",
    "save_png",
    "thickness_png",
    "vjm_contour_png",
    "vjm_path_png",
    "vjm_polar_png",
]


#: PNG resolution [dots per inch].
DPI = 200
#: zlib level of the PNG files: 1 is 2–3× faster to encode than PIL's default 6 for 10–25 %
#: larger files (the figures are mostly flat colour).
PNG_COMPRESS_LEVEL = 1


def save_png(fig: Figure, path: Path) -> Path:
    """Write ``fig`` atomically as PNG (:data:`DPI`, white background).

    The figures have a fixed layout (margins set in inches when they are built, no layout
    engine, no tight bounding box), so matplotlib draws each figure once: constrained layout
    would add a second, measuring draw.
    """
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(
            tmp,
            format="png",
            dpi=DPI,
            facecolor="white",
            bbox_inches=None,
            pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL},
        )
    return path


def _style() -> Any:
    """``rc_context`` with the report rcParams (cast: matplotlib stubs want literal keys)."""
    return mpl.rc_context(cast(Any, mpl_rc()))


def _figure(
    width: float,
    height: float,
    *,
    left: float = 0.8,
    right: float = 0.15,
    bottom: float = 0.45,
    top: float = 0.3,
    wspace: float | None = None,
    hspace: float | None = None,
) -> Figure:
    """A figure of ``width`` × ``height`` inches with fixed margins (inches; ``wspace`` and
    ``hspace`` are fractions of the mean axes width and height, as in ``subplots_adjust``)."""
    fig = Figure(figsize=(width, height))
    fig.set_layout_engine("none")  # whatever the rcParams say: no layout engine, one draw
    fig.subplots_adjust(
        left=left / width,
        right=1.0 - right / width,
        bottom=bottom / height,
        top=1.0 - top / height,
        wspace=wspace,
        hspace=hspace,
    )
    return fig


def _line_band(
    ax: Axes, prof: pd.DataFrame, col: str, color: str, label: str, band: bool = True, **kw: object
) -> None:
    x = prof["depth"].to_numpy()
    if band:
        ax.fill_between(
            x, prof[f"{col}_lo"], prof[f"{col}_hi"], color=color, alpha=0.18, linewidth=0
        )
    ax.plot(x, prof[col].to_numpy(), color=color, label=label, linewidth=1.4, **kw)  # type: ignore[arg-type]


def forces_png(per_point: pd.DataFrame) -> Figure:
    prof = agg.force_profile(per_point)
    with _style():
        fig = _figure(7.0, 2.8, wspace=0.3)
        axes = fig.subplots(1, 2)
        for ax, comp, title in zip(
            axes,
            ("Fz", "Fxy"),
            ("Axial force $F_z$", "In-plane force $\\sqrt{F_x^2+F_y^2}$"),
            strict=True,
        ):
            for run in RUNS:
                _line_band(ax, prof, f"{run}_{comp}", RUN_COLORS[run], RUN_LABELS[run])
            ax.set(title=title, xlabel="depth (mm)", ylabel="force (N)")
        axes[0].legend()
    return fig


def deviation_depth_png(per_point: pd.DataFrame) -> Figure:
    axes_ = ("dx", "dy", "dz", "dn")
    prof = agg.lap_profile(per_point, [f"{r}_{a}" for r in RUNS for a in axes_])
    with _style():
        fig = _figure(7.0, 5.0, wspace=0.3, hspace=0.25)
        axes = fig.subplots(2, 2, sharex=True)
        for ax, a in zip(axes.flat, axes_, strict=True):
            for run in RUNS:
                _line_band(ax, prof, f"{run}_{a}", RUN_COLORS[run], f"{RUN_LABELS[run]} part")
            ax.axhline(0, color="#9AA5B1", linewidth=0.6)
            ax.set(title=AXIS_LABELS[a], ylabel="deviation (mm)")
        for ax in axes[1]:
            ax.set_xlabel("depth (mm)")
        axes[0, 0].legend()
    return fig


def _vmax(*arrays: np.ndarray) -> float:
    finite = np.concatenate([a[np.isfinite(a)] for a in arrays])
    return float(np.percentile(np.abs(finite), 99)) if finite.size else 1.0


def deviation_map_png(per_point: pd.DataFrame) -> Figure:
    maps = {run: agg.lap_map(per_point, f"{run}_dn") for run in RUNS}
    vmax = _vmax(*(m.values for m in maps.values()))
    with _style():
        # wspace: the left map's "100" stood 2 pt from the right one's "0" and read "1000"
        fig = _figure(7.0, 3.6, right=0.05, wspace=0.16)
        axes = fig.subplots(1, 2, sharey=True)
        mesh = None
        for ax, run in zip(axes, RUNS, strict=True):
            m = maps[run]
            mesh = ax.pcolormesh(
                100.0 * m.position,
                m.depth,
                np.ma.masked_invalid(m.values),
                cmap="RdBu_r",
                vmin=-vmax,
                vmax=vmax,
                shading="nearest",
                rasterized=True,
            )
            ax.set(
                title=f"{RUN_LABELS[run]} part",
                xlabel="position along the lap (% from +x)",
                xlim=(0, 100),
            )
            ax.set_xticks(np.arange(0, 101, 25))
            ax.set_facecolor("#F5F7FA")
            ax.grid(False)
        axes[0].set_ylabel("depth (mm)")
        axes[0].invert_yaxis()
        assert mesh is not None
        fig.colorbar(mesh, ax=axes, label="normal deviation δn (mm)", shrink=0.9)
    return fig


def deviation_top_png(per_point: pd.DataFrame) -> Figure:
    views = {run: agg.top_view(per_point, f"{run}_dn") for run in RUNS}
    vmax = _vmax(*(v.values for v in views.values()))
    with _style():
        fig = _figure(7.0, 3.6, right=0.05, wspace=0.08)
        axes = fig.subplots(1, 2, sharex=True, sharey=True)
        sc = None
        for ax, run in zip(axes, RUNS, strict=True):
            v = views[run]
            sc = ax.scatter(
                v.x,
                v.y,
                c=v.values,
                s=1.5,
                cmap="RdBu_r",
                vmin=-vmax,
                vmax=vmax,
                linewidths=0,
                rasterized=True,
            )
            ax.set(title=f"{RUN_LABELS[run]} part", xlabel="x (mm)", aspect="equal")
            ax.set_facecolor("#F5F7FA")
            ax.grid(False)
        axes[0].set_ylabel("y (mm)")
        assert sc is not None
        fig.colorbar(sc, ax=axes, label="normal deviation δn (mm)", shrink=0.7)
    return fig


def factors_depth_png(per_point: pd.DataFrame) -> Figure:
    truth = [f"truth_{f}_dn" for f in FACTORS if f"truth_{f}_dn" in per_point.columns]
    prof = agg.lap_profile(per_point, [f"{f}_dn" for f in FACTORS] + truth)
    with _style():
        fig = _figure(7.0, 5.0, wspace=0.3, hspace=0.25)
        axes = fig.subplots(2, 2, sharex=True)
        for ax, f in zip(axes.flat, FACTORS, strict=True):
            _line_band(ax, prof, f"{f}_dn", FACTOR_COLORS[f], "recovered")
            if f"truth_{f}_dn" in truth:
                _line_band(
                    ax,
                    prof,
                    f"truth_{f}_dn",
                    SERIES_COLORS["truth"],
                    "ground truth",
                    band=False,
                    linestyle="--",
                )
            ax.set(title=FACTOR_LABELS[f], ylabel="δn (mm)")
            ax.legend()
        for ax in axes[1]:
            ax.set_xlabel("depth (mm)")
    return fig


def vjm_path_png(per_point: pd.DataFrame) -> Figure:
    axes_ = ("dx", "dy", "dz")
    prof = agg.lap_profile(
        per_point, [f"{p}_{a}" for p in ("robot_compliance", "vjm", "delta") for a in axes_]
    )
    with _style():
        fig = _figure(7.0, 5.6, top=0.1, hspace=0.12)
        axes = fig.subplots(3, 1, sharex=True)
        for ax, a in zip(axes, axes_, strict=True):
            _line_band(
                ax,
                prof,
                f"robot_compliance_{a}",
                SERIES_COLORS["experiment"],
                "experiment $\\delta c_{exp}$",
            )
            _line_band(
                ax, prof, f"vjm_{a}", SERIES_COLORS["vjm"], "VJM $\\delta c_{VJM}$", linestyle="--"
            )
            _line_band(ax, prof, f"delta_{a}", SERIES_COLORS["delta"], "$\\Delta$", band=False)
            ax.set_ylabel(f"$\\delta c_{a[1]}$ (mm)")
        axes[0].legend(ncols=3)
        axes[-1].set_xlabel("depth (mm)")
    return fig


def vjm_polar_png(per_point: pd.DataFrame, contour_z: float | None = None) -> Figure:
    c = agg.contour(per_point, contour_z)
    th = np.radians(c.angle_deg)
    with _style():
        fig = _figure(4.6, 4.4, left=0.45, right=0.45, bottom=0.9, top=0.5)
        ax = fig.add_subplot(projection="polar")
        ax.plot(
            th,
            c.experiment,
            color=SERIES_COLORS["experiment"],
            label="experiment $|\\delta c_{exp}|$",
        )
        ax.plot(th, c.vjm, color=SERIES_COLORS["vjm"], label="VJM $|\\delta c_{VJM}|$")
        ax.plot(th, c.delta, color=SERIES_COLORS["delta"], label="$|\\Delta|$")
        # at most 4 rings: at 0.1 mm steps the radial labels ran into each other along their ray
        ax.yaxis.set_major_locator(MaxNLocator(nbins=4))
        # the radial labels above the curves, with a white halo where a curve crosses them
        ax.yaxis.set_zorder(2.5)
        for label in ax.get_yticklabels():
            label.set_path_effects([withStroke(linewidth=3, foreground="white")])
        ax.set_title(f"Robot deflection at z = {c.z:.1f} mm (lap {c.lap}), mm")
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, -0.28), ncols=3)
    return fig


def vjm_contour_png(per_point: pd.DataFrame, contour_z: float | None = None) -> Figure:
    c = agg.contour_along(per_point, contour_z)
    with _style():
        fig = _figure(7.0, 3.2, top=0.75, wspace=0.45)
        ax0, ax1 = fig.subplots(1, 2, width_ratios=(1, 1.5))
        ax0.plot(c.x, c.y, color="#CBD2D9", linewidth=0.8)
        sc = ax0.scatter(c.x, c.y, c=c.experiment, s=8, cmap="viridis", linewidths=0)
        ax0.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal")
        fig.colorbar(sc, ax=ax0, label="$|\\delta c_{exp}|$ (mm)", shrink=0.8)
        ax1.plot(c.s, c.experiment, color=SERIES_COLORS["experiment"], label="$|\\delta c_{exp}|$")
        ax1.plot(c.s, c.vjm, color=SERIES_COLORS["vjm"], label="$|\\delta c_{VJM}|$")
        ax1.plot(c.s, c.delta, color=SERIES_COLORS["delta"], label="$|\\Delta|$")
        ax1.set(
            xlabel="arc length along the lap from +x (mm)",
            ylabel="$|\\delta c|$ (mm)",
            xlim=(0, c.length),
            ylim=(0, None),
        )
        ax1.legend(ncols=3, fontsize=7, loc="lower center", bbox_to_anchor=(0.5, 1.0))
        fig.suptitle(f"Robot deflection along the lap at z = {c.z:.1f} mm (lap {c.lap})")
    return fig


def contributions_png(contributions: pd.DataFrame, contributions_normal: pd.DataFrame) -> Figure:
    x = np.arange(len(FACTORS))
    colors = [FACTOR_COLORS[f] for f in FACTORS]
    with _style():
        fig = _figure(7.0, 3.2, right=0.35, bottom=0.85, top=0.45, wspace=0.3)
        axes = fig.subplots(1, 2)
        for ax, col, ylabel in zip(
            axes, ("share_percent", "R_m"), ("share of $R_m$ (%)", "$R_m$ (mm)"), strict=True
        ):
            for k, (table, hatch, label) in enumerate(
                (
                    (contributions, None, "per-axis vectors (paper)"),
                    (contributions_normal, "///", "normal projection (scan)"),
                )
            ):
                values = table.loc[list(FACTORS), col].to_numpy(dtype=float)
                bars = ax.bar(
                    x + (k - 0.5) * 0.38,
                    values,
                    width=0.36,
                    color=colors if hatch is None else "white",
                    edgecolor=colors,
                    hatch=hatch,
                    linewidth=1.2,
                    label=label,
                )
                # upright labels of neighbouring bars ran into each other ("1.1341.132")
                ax.bar_label(
                    bars,
                    fmt="%.1f" if col == "share_percent" else "%.3f",
                    fontsize=7,
                    padding=2,
                    rotation=90,
                )
            # turned 30° and ending at their bar: centred at 15° "Springback" stood within a
            # word space of "Tool holder" and "Robot compliance"
            ax.set_xticks(
                x,
                [FACTOR_LABELS[f] for f in FACTORS],
                rotation=30,
                ha="right",
                rotation_mode="anchor",
            )
            ax.set_ylabel(ylabel)
            ax.grid(axis="x", visible=False)
            ax.margins(y=0.3)
        fig.legend(*axes[0].get_legend_handles_labels(), loc="upper center", ncols=2)
    return fig


def thickness_png(per_point: pd.DataFrame) -> Figure:
    cols = ["thickness_predicted"] + (
        ["thickness_measured"] if "thickness_measured" in per_point.columns else []
    )
    prof = agg.lap_profile(per_point, cols)
    spread = agg.thickness_spread(per_point)
    with _style():
        fig = _figure(5.0, 3.0)
        ax = fig.subplots()
        if spread is not None:  # walls of different angle in one lap: their range, not a mean
            ax.fill_between(
                spread.depth,
                spread.low,
                spread.high,
                color=SERIES_COLORS["predicted"],
                alpha=0.18,
                linewidth=0,
                label=spread.label,
            )
        _line_band(
            ax,
            prof,
            "thickness_predicted",
            SERIES_COLORS["predicted"],
            "predicted (sine law)" if spread is None else "predicted (sine law), lap mean",
            band=False,
            linestyle="--",
        )
        if len(cols) > 1:
            _line_band(ax, prof, "thickness_measured", SERIES_COLORS["measured"], "measured")
        ax.set(xlabel="depth (mm)", ylabel="wall thickness (mm)", ylim=(0, None))
        ax.legend()
    return fig
