"""Reductions of the per-point table that the figures draw: lap profiles, the unrolled map, the
contour nearest a height, and the headline numbers. Pure pandas/numpy — no plotting here, so both
renderers (plotly for HTML, matplotlib for PNG) draw the very same numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = [
    "Contour",
    "Headline",
    "contour",
    "contour_lap",
    "decimate",
    "force_profile",
    "headline",
    "lap_profile",
    "masked",
    "unrolled_map",
]

#: Percentiles of the spread band drawn around a lap mean.
BAND = (5.0, 95.0)


def masked(per_point: pd.DataFrame, column: str) -> np.ndarray:
    """Column values as float with NaN where the scan it comes from has a hole.

    ``cnc_*`` and ``springback_*`` follow ``cnc_valid``; ``robot_*`` follows ``robot_valid``;
    ``robot_compliance_*`` and ``delta_*`` need both scans. Force, tool, holder and VJM columns
    come from logs and models, not scans, and are never masked.
    """
    values = per_point[column].to_numpy(dtype=float).copy()
    needs: tuple[str, ...] = ()
    if column.startswith(("cnc_d", "springback_")):
        needs = ("cnc_valid",)
    elif column.startswith(("robot_d",)):
        needs = ("robot_valid",)
    elif column.startswith(("robot_compliance_", "delta_")):
        needs = ("cnc_valid", "robot_valid")
    for flag in needs:
        values[~per_point[flag].to_numpy(dtype=bool)] = np.nan
    return values


def lap_profile(per_point: pd.DataFrame, columns: Sequence[str]) -> pd.DataFrame:
    """Per-lap mean and 5–95 % band of ``columns`` against the lap's mean depth.

    Returns
    -------
    DataFrame indexed by lap (ascending), with ``depth`` (mean, mm), ``time`` (mean, s) and for
    each column ``<col>`` (mean), ``<col>_lo`` and ``<col>_hi`` (5th and 95th percentile of the
    lap). Holes (NaN) are ignored; a lap with no valid value gives NaN.
    """
    data = {c: masked(per_point, c) for c in columns}
    frame = pd.DataFrame(data)
    frame["lap"] = per_point["lap"].to_numpy()
    grouped = frame.groupby("lap", sort=True)
    out = pd.DataFrame(index=grouped.size().index)
    geo = per_point[["lap", "depth", "time"]].groupby("lap", sort=True).mean()
    out["depth"] = geo["depth"]
    out["time"] = geo["time"]
    if columns:
        mean = grouped[list(columns)].mean()
        lo = grouped[list(columns)].quantile(BAND[0] / 100.0)
        hi = grouped[list(columns)].quantile(BAND[1] / 100.0)
        for c in columns:
            out[c] = mean[c]
            out[f"{c}_lo"] = lo[c]
            out[f"{c}_hi"] = hi[c]
    return out


def decimate(n: int, max_points: int) -> np.ndarray:
    """Indices of at most ``max_points`` evenly strided samples of ``n`` (first and last kept)."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(np.intp))


def unrolled_map(
    per_point: pd.DataFrame, column: str, n_angle_bins: int = 120
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The part unrolled: mean of ``column`` per (lap, angle bin).

    Returns
    -------
    angle : (B,) float, deg
        Bin centres in [0, 360).
    depth : (L,) float, mm
        Mean depth of each lap, ascending lap order.
    values : (L, B) float
        Bin means, NaN where the bin is empty or every point in it is a hole.
    """
    values = masked(per_point, column)
    laps, lap_idx = np.unique(per_point["lap"].to_numpy(), return_inverse=True)
    angle = np.mod(per_point["angle_deg"].to_numpy(dtype=float), 360.0)
    bins = np.minimum((angle / 360.0 * n_angle_bins).astype(np.intp), n_angle_bins - 1)
    flat = lap_idx * n_angle_bins + bins
    ok = np.isfinite(values)
    size = len(laps) * n_angle_bins
    total = np.bincount(flat[ok], weights=values[ok], minlength=size)
    count = np.bincount(flat[ok], minlength=size)
    with np.errstate(invalid="ignore", divide="ignore"):
        grid = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    depth = np.bincount(lap_idx, weights=per_point["depth"].to_numpy(dtype=float)) / np.bincount(
        lap_idx
    )
    centres = (np.arange(n_angle_bins) + 0.5) * 360.0 / n_angle_bins
    return centres, depth, grid.reshape(len(laps), n_angle_bins)


def contour_lap(per_point: pd.DataFrame, contour_z: float) -> tuple[int, float, str | None]:
    """The lap whose mean contact height is nearest ``contour_z`` (mm) and has valid scan data.

    Returns ``(lap, z, note)``: the lap number, its mean contact z (mm) and a note for the reader
    when the nearest lap had to be skipped because both scans were holes there (else None).
    """
    z = per_point.groupby("lap", sort=True)["contact_z"].mean()
    usable = (
        pd.Series(np.isfinite(masked(per_point, "robot_compliance_dn")), index=per_point.index)
        .groupby(per_point["lap"])
        .any()
    )
    order = np.argsort(np.abs(z.to_numpy() - contour_z), kind="stable")
    first = int(z.index[order[0]])
    for k in order:
        lap = int(z.index[k])
        if usable.loc[lap]:
            note = None
            if lap != first:
                note = (
                    f"lap {first} (z = {z.loc[first]:.2f} mm) has no valid scan data; "
                    f"showing lap {lap} instead"
                )
            return lap, float(z.loc[lap]), note
    return (
        first,
        float(z.loc[first]),
        "no lap has valid scan data; the contour shows the models only",
    )


@dataclass(frozen=True)
class Contour:
    """Robot deflection magnitudes around one lap, sorted by angle and closed (last = first).

    ``angle_deg`` (M+1,) deg; ``experiment``, ``vjm``, ``delta`` (M+1,) mm: resultant
    |δc_exp|, |δc_VJM|, |Δ| (NaN at scan holes for experiment and Δ).
    """

    lap: int
    z: float
    note: str | None
    angle_deg: np.ndarray
    experiment: np.ndarray
    vjm: np.ndarray
    delta: np.ndarray


def contour(per_point: pd.DataFrame, contour_z: float) -> Contour:
    """Resultant robot deflections around the lap chosen by :func:`contour_lap`."""
    lap, z, note = contour_lap(per_point, contour_z)
    sel = per_point["lap"].to_numpy() == lap
    angle = per_point["angle_deg"].to_numpy(dtype=float) % 360.0
    order = np.argsort(angle[sel], kind="stable")

    def closed(values: np.ndarray) -> np.ndarray:
        v = values[sel][order]
        return np.append(v, v[:1])

    def resultant(prefix: str) -> np.ndarray:
        comps = np.stack([masked(per_point, f"{prefix}_{a}") for a in ("dx", "dy", "dz")])
        return closed(np.sqrt(np.sum(comps**2, axis=0)))

    return Contour(
        lap,
        z,
        note,
        closed(angle),
        resultant("robot_compliance"),
        resultant("vjm"),
        resultant("delta"),
    )


def force_profile(per_point: pd.DataFrame) -> pd.DataFrame:
    """:func:`lap_profile` of ``<run>_Fz`` and the in-plane resultant ``<run>_Fxy`` (N)."""
    frame = pd.DataFrame(
        {"lap": per_point["lap"], "depth": per_point["depth"], "time": per_point["time"]}
    )
    for run in ("cnc", "robot"):
        frame[f"{run}_Fz"] = per_point[f"{run}_Fz"]
        frame[f"{run}_Fxy"] = np.hypot(per_point[f"{run}_Fx"], per_point[f"{run}_Fy"])
    return lap_profile(frame, [f"{r}_{c}" for r in ("cnc", "robot") for c in ("Fz", "Fxy")])


@dataclass(frozen=True)
class Headline:
    """The numbers at the top of a report (mm and %)."""

    R_m_total: float
    robot_share_percent: float
    robot_R_m: float
    springback_share_percent: float
    R_m_total_normal: float
    robot_share_percent_normal: float


def headline(contributions: pd.DataFrame, contributions_normal: pd.DataFrame) -> Headline:
    """Headline from two checked contribution tables (indexed by factor)."""
    return Headline(
        R_m_total=float(contributions.loc["total", "R_m"]),
        robot_share_percent=float(contributions.loc["robot_compliance", "share_percent"]),
        robot_R_m=float(contributions.loc["robot_compliance", "R_m"]),
        springback_share_percent=float(contributions.loc["springback", "share_percent"]),
        R_m_total_normal=float(contributions_normal.loc["total", "R_m"]),
        robot_share_percent_normal=float(
            contributions_normal.loc["robot_compliance", "share_percent"]
        ),
    )
