"""Reductions of the per-point table that the figures draw: lap profiles, the unrolled map (by
position along each lap, any part), the top view, the contour nearest a height, and the headline
numbers. Pure pandas/numpy — no plotting here, so both renderers (plotly for HTML, matplotlib for
PNG) draw the very same numbers.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator, Sequence
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
import pandas as pd

from roboisf.scan.summary import lap_arc_length

__all__ = [
    "Contour",
    "ContourPath",
    "Headline",
    "LapMap",
    "LapSpread",
    "TopView",
    "arc_length",
    "contour",
    "contour_along",
    "contour_lap",
    "decimate",
    "force_profile",
    "headline",
    "is_round",
    "lap_map",
    "lap_profile",
    "masked",
    "part_view",
    "reused",
    "thickness_spread",
    "top_view",
    "unrolled_map",
]

#: Part kinds that are surfaces of revolution (continuous symmetry about z).
ROUND_KINDS = frozenset({"cone", "vwacf", "profile"})
#: A part whose every lap keeps its radius (less its linear trend with z: a spiral descends
#: within a lap) within this fraction of the lap's mean radius is drawn as round when the summary
#: does not say. A square's radius varies by 41 %, an ellipse's by its axis ratio.
ROUND_TOLERANCE = 0.02
#: Most cells across the unrolled map (keeps the embedded figure data small).
MAX_MAP_BINS = 360
#: Most points per part drawn in the top view.
MAX_TOP_POINTS = 12_000
#: Most toolpath points drawn in the 3D view of the formed part (one subset for every term).
MAX_3D_POINTS = 8_000
#: The terms of the 3D view: (column, label). ``robot_dn`` is the robot part's measured normal
#: deviation (the total the factors add up to); ``delta_dn`` the residual the robot model leaves,
#: Δ = δc_exp − δc_VJM.
PART_VIEW_TERMS: tuple[tuple[str, str], ...] = (
    ("robot_dn", "total (robot part, measured)"),
    ("springback_dn", "springback"),
    ("tool_dn", "tool"),
    ("tool_holder_dn", "tool holder"),
    ("robot_compliance_dn", "robot compliance"),
    ("delta_dn", "residual Δ = measured − VJM robot"),
)

#: Percentiles of the spread band drawn around a lap mean.
BAND = (5.0, 95.0)


_F = TypeVar("_F", bound=Callable[..., Any])
_REUSE: ContextVar[dict[tuple[Any, ...], tuple[object, Any]] | None] = ContextVar(
    "roboisf_report_reuse", default=None
)


@contextlib.contextmanager
def reused() -> Iterator[None]:
    """Within the block, each reduction of the same table with the same arguments is computed
    once and its result shared (the HTML and the PNG renderers draw the same lap profiles,
    maps and contours). The results are shared objects: callers must not modify them."""
    token = _REUSE.set({})
    try:
        yield
    finally:
        _REUSE.reset(token)


def _reusable(fn: _F) -> _F:
    @functools.wraps(fn)
    def wrapper(per_point: pd.DataFrame, *args: Any, **kwargs: Any) -> Any:
        memo = _REUSE.get()
        if memo is None:
            return fn(per_point, *args, **kwargs)
        key = (
            fn.__name__,
            id(per_point),
            *(tuple(a) if isinstance(a, list) else a for a in args),
            *sorted(kwargs.items()),
        )
        if key not in memo:  # the table is kept alive with its result: its id stays unique
            memo[key] = (per_point, fn(per_point, *args, **kwargs))
        return memo[key][1]

    return wrapper  # type: ignore[return-value]


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


@_reusable
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
    geo = per_point[["lap", "depth", "time"]].groupby("lap", sort=True).mean()
    # the columns gathered first and the frame built once: inserted one at a time, they cost
    # ~10 ms a call (pandas copies its blocks as it grows), most of the report's lap profiles
    out = {"depth": geo["depth"], "time": geo["time"]}
    if columns:
        mean = grouped[list(columns)].mean()
        lo = grouped[list(columns)].quantile(BAND[0] / 100.0)
        hi = grouped[list(columns)].quantile(BAND[1] / 100.0)
        for c in columns:
            out[c] = mean[c]
            out[f"{c}_lo"] = lo[c]
            out[f"{c}_hi"] = hi[c]
    return pd.DataFrame(out, index=grouped.size().index)


#: Least spread of the sine-law thickness within a lap [mm] the thickness figure draws as a
#: band: a part whose laps keep one wall angle (a cone, a VWACF: the angle changes with depth,
#: not around a lap) draws its lap mean alone.
SPREAD_MIN = 1e-3


@dataclass(frozen=True)
class LapSpread:
    """The thinnest and thickest sine-law thickness of each lap, where the walls of one lap
    differ in angle (a pyramid with two wall angles, a freeform part).

    ``depth`` (L,) mm, the lap's mean depth; ``low``, ``high`` (L,) mm, the lap's least and
    greatest ``thickness_predicted``; ``angle_low``, ``angle_high`` deg, the median over the
    laps that spread of their least and greatest wall angle (the walls' angles, not a rim
    lap's).
    """

    depth: np.ndarray
    low: np.ndarray
    high: np.ndarray
    angle_low: float
    angle_high: float

    @property
    def label(self) -> str:
        """The figures' legend entry for the band."""
        return (
            "predicted, thinnest–thickest wall of the lap "
            f"({self.angle_low:.0f}°–{self.angle_high:.0f}° walls)"
        )


@_reusable
def thickness_spread(per_point: pd.DataFrame) -> LapSpread | None:
    """:class:`LapSpread` of ``thickness_predicted``, or None when no lap spreads by more than
    :data:`SPREAD_MIN` (every lap keeps one wall angle). One group-by: cheap."""
    frame = per_point[["lap", "depth", "thickness_predicted", "wall_angle_deg"]]
    g = frame.groupby("lap", sort=True)
    t = g["thickness_predicted"].agg(["min", "max"])
    spread = (t["max"] - t["min"]).to_numpy()
    wide = spread > SPREAD_MIN
    if not wide.any():
        return None
    angle = g["wall_angle_deg"].agg(["min", "max"]).to_numpy()[wide]
    return LapSpread(
        g["depth"].mean().to_numpy(),
        t["min"].to_numpy(),
        t["max"].to_numpy(),
        float(np.median(angle[:, 0])),
        float(np.median(angle[:, 1])),
    )


def decimate(n: int, max_points: int) -> np.ndarray:
    """Indices of at most ``max_points`` evenly strided samples of ``n`` (first and last kept)."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(np.intp))


def unrolled_map(
    per_point: pd.DataFrame, column: str, n_angle_bins: int = 120
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The part unrolled by polar angle: mean of ``column`` per (lap, angle bin).

    Meaningful on round parts only, and a fixed angle grid leaves empty bins on sparse laps; the
    report draws :func:`lap_map` (position along each lap, any part) instead.

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


def contour_lap(
    per_point: pd.DataFrame, contour_z: float | None = None
) -> tuple[int, float, str | None]:
    """The lap the contour figure shows: the lap whose mean contact height is nearest
    ``contour_z`` (mm) among those with valid scan data the analysis used (the ``used`` column
    when present: below the rim band, no scan hole).

    With no ``contour_z``, or one that lies in the rim band the analysis leaves out (above the
    analysed wall: the paper's z = −11 mm under a 20 mm band), the lap nearest the **middle of
    the analysed wall** — halfway between the highest and the lowest analysed point — is shown
    instead: the first lap below the band still carries the rim's transition.

    Returns ``(lap, z, note)``: the lap number, its mean contact z (mm) and, when the lap is not
    the one nearest the requested height, a note for the reader saying which lap was skipped
    and why (else None).
    """
    z = per_point.groupby("lap", sort=True)["contact_z"].mean()
    ok = np.isfinite(masked(per_point, "robot_compliance_dn"))
    rim = "used" in per_point.columns
    if rim:
        ok &= per_point["used"].to_numpy(dtype=bool)
    usable = pd.Series(ok, index=per_point.index).groupby(per_point["lap"]).any()
    zs = z.to_numpy()
    if not usable.any():
        target = float(np.mean(zs)) if contour_z is None else float(contour_z)
        first = int(z.index[np.argmin(np.abs(zs - target))])
        return (
            first,
            float(z.loc[first]),
            "no lap has valid scan data; the contour shows the models only",
        )
    cz = per_point["contact_z"].to_numpy(dtype=float)[ok]
    top, bottom = float(cz.max()), float(cz.min())
    middle = (top + bottom) / 2.0
    wall = f"z {top:.1f} to {bottom:.1f} mm"
    free = np.where(usable.reindex(z.index).to_numpy(dtype=bool), zs, np.nan)

    def nearest(target: float) -> int:
        return int(z.index[np.nanargmin(np.abs(free - target))])

    if contour_z is None:
        lap = nearest(middle)
        note = (
            f"the lap nearest the middle of the analysed wall ({wall}); no contour height was "
            "asked for"
        )
        return lap, float(z.loc[lap]), note
    first = int(z.index[np.argmin(np.abs(zs - contour_z))])
    if usable.loc[first]:
        return first, float(z.loc[first]), None
    if rim and contour_z > top and not per_point.loc[per_point["lap"] == first, "used"].any():
        lap = nearest(middle)
        note = (
            f"the requested z = {contour_z:.2f} mm (lap {first}) lies in the rim band the "
            f"analysis leaves out; showing the lap nearest the middle of the analysed wall "
            f"({wall}) instead"
        )
        return lap, float(z.loc[lap]), note
    lap = nearest(float(contour_z))
    why = (
        "lies in the rim band the analysis leaves out or has no valid scan data"
        if rim
        else "has no valid scan data"
    )
    note = f"lap {first} (z = {z.loc[first]:.2f} mm) {why}; showing lap {lap} instead"
    return lap, float(z.loc[lap]), note


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


@_reusable
def contour(per_point: pd.DataFrame, contour_z: float | None = None) -> Contour:
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


@_reusable
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


def arc_length(per_point: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Position of each point along its lap and the lap's length (mm).

    :func:`roboisf.scan.summary.lap_arc_length` of the contact points: ``s = 0`` at the lap's
    point nearest the +x axis, growing in toolpath order, wrapping at the lap's closed length
    (on a round part ``s = r·φ``). ``per_point`` must be in toolpath order (as
    :func:`~roboisf.report.schema.check_per_point` returns it).

    Returns
    -------
    s, length : (N,) float, mm
    """
    contact = per_point[["contact_x", "contact_y", "contact_z"]].to_numpy(dtype=float)
    return lap_arc_length(contact, per_point["lap"].to_numpy())


def is_round(per_point: pd.DataFrame, symmetry: int | None = None, kind: str | None = None) -> bool:
    """Whether the part is a surface of revolution, i.e. gets the polar contour plot.

    ``symmetry`` (the order of :class:`roboisf.parts.Symmetry`: 0 continuous) decides when given;
    else a ``kind`` of cone, VWACF or profile is round; else the data decides: round when every
    lap of at least 8 points keeps its contact radius, less its linear trend in z, within
    :data:`ROUND_TOLERANCE` of its mean.
    """
    if symmetry is not None:
        return symmetry == 0
    if kind is not None and kind in ROUND_KINDS:
        return True
    r = np.hypot(per_point["contact_x"].to_numpy(float), per_point["contact_y"].to_numpy(float))
    z = per_point["contact_z"].to_numpy(float)
    laps, lap_idx = np.unique(per_point["lap"].to_numpy(), return_inverse=True)
    order = np.argsort(lap_idx, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(lap_idx))])
    for k in range(len(laps)):
        idx = order[bounds[k] : bounds[k + 1]]
        if idx.size < 8 or r[idx].mean() <= 0:
            continue
        # a spiral lap descends as it goes round: take out the radius' linear trend in z
        A = np.column_stack([np.ones(idx.size), z[idx] - z[idx].mean()])
        coef, *_ = np.linalg.lstsq(A, r[idx], rcond=None)
        resid = r[idx] - A @ coef
        if np.ptp(resid) > ROUND_TOLERANCE * r[idx].mean():
            return False
    return True


@dataclass(frozen=True)
class LapMap:
    """A column unrolled by lap and position along the lap.

    Attributes
    ----------
    position : (B,) float
        Cell centres as a fraction of the lap's length, in [0, 1), from the lap's point nearest
        the +x axis, in toolpath order (on a round part: φ/2π).
    depth : (L,) float, mm
        Mean depth of each lap, ascending lap order.
    length : (L,) float, mm
        Closed length of each lap (cell ``b`` of lap ``l`` is ``position[b]·length[l]`` mm along
        it).
    values : (L, B) float
        Mean of the lap's points in the cell; a cell no point falls in takes the value of the
        lap's nearest point (so a lap sparser than the grid leaves no empty cells); NaN where
        that is a scan hole.
    """

    position: np.ndarray
    depth: np.ndarray
    length: np.ndarray
    values: np.ndarray


@_reusable
def lap_map(per_point: pd.DataFrame, column: str, n_bins: int | None = None) -> LapMap:
    """``column`` unrolled by lap × position along the lap — the deviation map of any part.

    The cell count follows the data: by default the median number of points per lap (at most
    :data:`MAX_MAP_BINS`), so a typical lap has about one point per cell and the dense laps are
    averaged; the sparse ones (short laps at the bottom) fill their cells from the nearest point,
    never leaving the empty-bin stripes (moiré) of a fixed grid.
    """
    values = masked(per_point, column)
    s, length = arc_length(per_point)
    laps, lap_idx = np.unique(per_point["lap"].to_numpy(), return_inverse=True)
    counts = np.bincount(lap_idx)
    if n_bins is None:
        n_bins = int(min(MAX_MAP_BINS, max(4, np.median(counts))))
    B = n_bins
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(length > 0, s / np.where(length > 0, length, 1.0), 0.0)
    # cells are [lo, hi): a point on an edge (u·B integral up to the rounding of the chord sums)
    # belongs to the cell above it
    cell = np.minimum((u * B + 1e-9).astype(np.intp), B - 1)
    flat = lap_idx * B + cell
    size = len(laps) * B
    ok = np.isfinite(values)
    total = np.bincount(flat[ok], weights=values[ok], minlength=size)
    n_ok = np.bincount(flat[ok], minlength=size)
    n_any = np.bincount(flat, minlength=size)
    with np.errstate(invalid="ignore", divide="ignore"):
        grid = np.where(n_ok > 0, total / np.maximum(n_ok, 1), np.nan)
    grid = grid.reshape(len(laps), B)
    empty = (n_any == 0).reshape(len(laps), B)
    centres = (np.arange(B) + 0.5) / B
    order = np.lexsort((u, lap_idx))
    bounds = np.concatenate([[0], np.cumsum(counts)])
    for k in np.flatnonzero(empty.any(axis=1)):
        idx = order[bounds[k] : bounds[k + 1]]
        uk, vk = u[idx], values[idx]
        cells = np.flatnonzero(empty[k])
        c = centres[cells]
        j = np.searchsorted(uk, c)
        lo, hi = (j - 1) % len(uk), j % len(uk)
        d_lo = np.mod(c - uk[lo], 1.0)
        d_hi = np.mod(uk[hi] - c, 1.0)
        grid[k, cells] = np.where(d_lo <= d_hi, vk[lo], vk[hi])
    depth = np.bincount(lap_idx, weights=per_point["depth"].to_numpy(dtype=float)) / counts
    lap_len = np.zeros(len(laps))
    lap_len[lap_idx] = length
    return LapMap(centres, depth, lap_len, grid)


@dataclass(frozen=True)
class TopView:
    """Points of the part seen from +z, coloured by a column: ``x``, ``y`` (M,) mm, ``values``
    (M,) — every scan hole left out, at most ``max_points`` (a seeded random subset, in toolpath
    order)."""

    x: np.ndarray
    y: np.ndarray
    values: np.ndarray


@_reusable
def top_view(per_point: pd.DataFrame, column: str, max_points: int = MAX_TOP_POINTS) -> TopView:
    """The top view (x, y) of ``column`` — the points themselves, no binning.

    Beyond ``max_points`` valid points a random subset is drawn (seed 0: the same figure every
    time). An even stride along the path would alias with the laps' own point pattern — laps
    with points at the same angles show spokes, and the stride's phase jumping at a hole shows
    rings that are not in the data.
    """
    values = masked(per_point, column)
    keep = np.flatnonzero(np.isfinite(values))
    if keep.size > max_points:
        rng = np.random.default_rng(0)
        keep = np.sort(rng.choice(keep, size=max_points, replace=False))
    return TopView(
        per_point["contact_x"].to_numpy(dtype=float)[keep],
        per_point["contact_y"].to_numpy(dtype=float)[keep],
        values[keep],
    )


@dataclass(frozen=True)
class ContourPath:
    """Robot deflection magnitudes along one lap, in toolpath order from the lap's point nearest
    the +x axis, closed (last = first, at ``s = length``).

    ``s`` (M+1,) mm along the lap; ``x``, ``y`` (M+1,) mm, the lap's outline; ``experiment``,
    ``vjm``, ``delta`` (M+1,) mm: resultant |δc_exp|, |δc_VJM|, |Δ| (NaN at scan holes for
    experiment and Δ).
    """

    lap: int
    z: float
    note: str | None
    length: float
    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    experiment: np.ndarray
    vjm: np.ndarray
    delta: np.ndarray


@_reusable
def contour_along(per_point: pd.DataFrame, contour_z: float | None = None) -> ContourPath:
    """Resultant robot deflections along the lap chosen by :func:`contour_lap`, by arc length —
    the contour plot of a part that is not round."""
    lap, z, note = contour_lap(per_point, contour_z)
    s_all, length = arc_length(per_point)
    sel = np.flatnonzero(per_point["lap"].to_numpy() == lap)
    order = sel[np.argsort(s_all[sel], kind="stable")]
    L = float(length[order[0]])

    def closed(values: np.ndarray) -> np.ndarray:
        v = values[order]
        return np.append(v, v[:1])

    def resultant(prefix: str) -> np.ndarray:
        comps = np.stack([masked(per_point, f"{prefix}_{a}") for a in ("dx", "dy", "dz")])
        return closed(np.sqrt(np.sum(comps**2, axis=0)))

    s = np.append(s_all[order], L)
    return ContourPath(
        lap,
        z,
        note,
        L,
        s,
        closed(per_point["contact_x"].to_numpy(dtype=float)),
        closed(per_point["contact_y"].to_numpy(dtype=float)),
        resultant("robot_compliance"),
        resultant("vjm"),
        resultant("delta"),
    )


@dataclass(frozen=True)
class PartView:
    """The formed part for the 3D view: whole laps of the toolpath, every ``lap_step``-th one,
    each a polyline in toolpath order, the laps separated by one NaN row (a break in the line).

    ``x, y, z`` (M,) float, mm — contact points in the work frame; ``values`` maps each column of
    :data:`PART_VIEW_TERMS` to (M,) float, mm (NaN at scan holes, see :func:`masked`, and at the
    separators); ``n_total`` the number of toolpath points it was drawn from.
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    values: dict[str, np.ndarray]
    n_total: int
    lap_step: int


@_reusable
def part_view(per_point: pd.DataFrame, max_points: int = MAX_3D_POINTS) -> PartView:
    """Every ``k``-th lap whole, ``k`` the smallest step that keeps at most ``max_points``
    toolpath points, with the normal value of each 3D-view term. Whole laps drawn as lines
    leave no decimation gaps inside a lap (a random subset of points showed them as holes) and
    join the contact points across a corner where the toolpath skips."""
    n = len(per_point)
    lap = per_point["lap"].to_numpy()
    laps = np.unique(lap)
    step = 1
    while step < len(laps) and np.isin(lap, laps[::step]).sum() > max_points:
        step += 1
    keep = np.flatnonzero(np.isin(lap, laps[::step]))
    # one NaN row after each lap kept: the line breaks between laps
    breaks = np.flatnonzero(np.diff(lap[keep]) != 0) + 1
    rows = np.insert(keep.astype(float), breaks, np.nan)
    gap = np.isnan(rows)
    take = np.where(gap, 0, rows).astype(np.intp)

    def pick(values: np.ndarray) -> np.ndarray:
        out = values[take].astype(float)
        out[gap] = np.nan
        return out

    values = {
        col: pick(masked(per_point, col)) for col, _ in PART_VIEW_TERMS if col in per_point.columns
    }
    return PartView(
        pick(per_point["contact_x"].to_numpy(dtype=float)),
        pick(per_point["contact_y"].to_numpy(dtype=float)),
        pick(per_point["contact_z"].to_numpy(dtype=float)),
        values,
        n,
        step,
    )
