"""Summaries of deviation vectors: overall, per z-level bin, per angle (round parts) or per arc
length (any part) at a contour.

Resultant mean deviation (paper eq. 6)::

    R_m = sqrt( (mean|δx|)² + (mean|δy|)² + (mean|δz|)² )

i.e. the norm of the per-axis *mean absolute* deviations — the paper's springback figures
(0.72 mm in x and y, 0.49 mm in z) give its resultant 1.132 mm this way. The function is
:func:`resultant_mean_deviation` (one implementation; :mod:`roboisf.decompose` re-exports it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "DeviationStats",
    "by_angle",
    "by_arc_length",
    "by_depth",
    "deviation_stats",
    "lap_arc_length",
    "resultant_mean_deviation",
]

F64 = NDArray[np.float64]


def resultant_mean_deviation(v: F64) -> float:
    """R_m = sqrt(mean|δx|² + mean|δy|² + mean|δz|²) of (N, 3) vectors (eq. 6), same unit."""
    if v.shape[0] == 0:
        raise InputError("no valid toolpath points to average over")
    m = np.mean(np.abs(v), axis=0)
    return float(np.sqrt(np.sum(m**2)))


@dataclass(frozen=True)
class DeviationStats:
    """Statistics of N deviation vectors (SI, m).

    mean, mean_abs, max_abs : (3,) per axis x, y, z; ``max_abs`` is the largest |δ|;
    mean_dn, mean_abs_dn, max_abs_dn : of the signed normal deviation; R_m : eq. 6.
    """

    n: int
    mean: F64
    mean_abs: F64
    max_abs: F64
    mean_dn: float
    mean_abs_dn: float
    max_abs_dn: float
    R_m: float

    def to_dict(self) -> dict[str, object]:
        """JSON-friendly, in mm."""
        out: dict[str, object] = {"n": self.n}
        for name in ("mean", "mean_abs", "max_abs"):
            v = getattr(self, name)
            for j, ax in enumerate("xyz"):
                out[f"{name}_d{ax}_mm"] = float(v[j]) * 1e3
        out["mean_dn_mm"] = self.mean_dn * 1e3
        out["mean_abs_dn_mm"] = self.mean_abs_dn * 1e3
        out["max_abs_dn_mm"] = self.max_abs_dn * 1e3
        out["R_m_mm"] = self.R_m * 1e3
        return out


def deviation_stats(delta: ArrayLike, dn: ArrayLike) -> DeviationStats:
    """Statistics of deviation vectors ``delta`` (N, 3) [m] and normal deviations ``dn`` (N,)."""
    d = np.atleast_2d(np.asarray(delta, dtype=float))
    n_ = np.asarray(dn, dtype=float)
    if d.shape[0] == 0:
        raise InputError("no deviations to summarise (no valid points)")
    _same_length(d, n_)
    # a C-contiguous block is read, not overwritten (block_sums); any other is copied
    return _stats(n_, lambda rows: d[rows] if d.flags.c_contiguous else d[rows].copy())


def _same_length(vectors: F64, dn: F64) -> None:
    if vectors.shape != (dn.shape[0], 3):
        raise InputError(
            f"expected (N, 3) vectors for the N = {dn.shape[0]} normal deviations, "
            f"got {vectors.shape}"
        )


def normal_deviation_stats(dn: ArrayLike, normal: ArrayLike) -> DeviationStats:
    """:func:`deviation_stats` of the deviations ``dn · normal`` — ``dn`` (N,) m along the unit
    normals ``normal`` (N, 3) — without their (N, 3) array: a scan's 1.7 M wall points made it
    and its absolute values, 120 MB on top of the points, the comparison's memory peak."""
    n_ = np.asarray(dn, dtype=float)
    nrm = np.atleast_2d(np.asarray(normal, dtype=float))
    if n_.shape[0] == 0:
        raise InputError("no deviations to summarise (no valid points)")
    _same_length(nrm, n_)
    n = n_.shape[0]
    sums = [dn_block_sums(n_[lo : lo + STATS_BLOCK], nrm[lo : lo + STATS_BLOCK])
            for lo in range(0, n, STATS_BLOCK)]  # fmt: skip
    return stats_from_blocks(n_, np.array(sums).reshape(-1, 3, 3))


#: Rows per block of :func:`_stats` (its temporaries stay in cache and small).
STATS_BLOCK = 65_536


def block_sums(delta: F64) -> F64:
    """(3, 3): the sum, the sum of absolute values and the largest absolute value per axis of
    one block's deviation vectors ``delta`` (M, 3) [m] (may be overwritten by their absolute
    values). The statistics of :func:`deviation_stats` are these, block by block of
    :data:`STATS_BLOCK` rows, combined in order (:func:`stats_from_blocks`): a caller that has
    the blocks one at a time (:func:`roboisf.scan.deviation.foot_deviations`) gets the same
    bits.

    The sums are numpy's ``delta.sum(axis=0)`` of a C-contiguous block: a reduction along the
    strided axis, which adds each column's values one after the other from 0 (no pairwise
    summation) — ~1 ms a block of 65 536 rows, one call of numpy's inner loop per row. A
    column's running sum (``np.cumsum``) adds them in the same order, the same bits (its last
    value plus 0.0: the reduction starts from +0, so a column of −0 sums to +0), in a tenth
    of the time (tests/test_scan_deviation.py checks both against the reduction)."""
    if delta.ndim == 2 and delta.shape[1] == 3 and delta.shape[0] > 0 and delta.flags.c_contiguous:
        return _column_sums([delta[:, j] for j in range(3)], None)
    out = np.empty((3, 3))
    out[0] = delta.sum(axis=0)
    np.abs(delta, out=delta)
    out[1] = delta.sum(axis=0)
    out[2] = delta.max(axis=0)
    return out


def dn_block_sums(dn: F64, normal: F64) -> F64:
    """:func:`block_sums` of the deviation vectors ``dn[:, None] * normal`` (``dn`` (M,) m along
    the unit normals ``normal`` (M, 3)), the same bits, without their (M, 3) array: a column
    of products at a time."""
    if (
        dn.ndim == 1
        and normal.shape == (dn.shape[0], 3)
        and dn.shape[0] > 0
        and normal.flags.c_contiguous
    ):
        # their product would be C-contiguous (as normal): block_sums' running sums apply
        return _column_sums([normal[:, j] for j in range(3)], dn)
    return block_sums(dn[:, None] * normal)


def _column_sums(columns: list[F64], factor: F64 | None) -> F64:
    """:func:`block_sums` column by column: of ``columns`` (three (M,) arrays), each times
    ``factor`` (M,) if given (the same products as the (M, 3) array's)."""
    out = np.empty((3, 3))
    m = columns[0].shape[0]
    col, run = np.empty(m), np.empty(m)
    for j, c in enumerate(columns):
        if factor is not None:
            c = np.multiply(factor, c, out=col)
        out[0, j] = np.cumsum(c, out=run)[-1] + 0.0
        np.abs(c, out=col)
        out[1, j] = np.cumsum(col, out=run)[-1] + 0.0
        out[2, j] = col.max()
    return out


def stats_from_blocks(dn: F64, sums: F64) -> DeviationStats:
    """:class:`DeviationStats` of the normal deviations ``dn`` (N,) m and the :func:`block_sums`
    ``sums`` (B, 3, 3) of their vectors' blocks of :data:`STATS_BLOCK` rows, in row order."""
    n = dn.shape[0]
    total = np.zeros(3)
    total_abs = np.zeros(3)
    max_abs = np.zeros(3)
    for b in sums:
        total += b[0]
        total_abs += b[1]
        np.maximum(max_abs, b[2], out=max_abs)
    abs_dn = np.abs(dn)
    mean_abs = total_abs / n
    return DeviationStats(
        int(n),
        total / n,
        mean_abs,
        max_abs,
        float(dn.mean()),
        float(abs_dn.mean()),
        float(abs_dn.max()),
        float(np.sqrt(np.sum(mean_abs**2))),  # resultant_mean_deviation, its mean|δ| reused
    )


def _stats(dn: F64, delta_rows: Callable[[slice], F64]) -> DeviationStats:
    """The statistics block by block: ``delta_rows(rows)`` gives the rows' (M, 3) vectors (a
    new array: it is overwritten)."""
    n = dn.shape[0]
    sums = [block_sums(delta_rows(slice(lo, lo + STATS_BLOCK))) for lo in range(0, n, STATS_BLOCK)]
    return stats_from_blocks(dn, np.array(sums).reshape(-1, 3, 3))


def _binned(key: NDArray[np.int64], delta: F64, dn: F64) -> pd.DataFrame:
    import pandas as pd  # on first use: reading a study or a scan imports no table library

    df = pd.DataFrame(
        {"bin": key, "dx": delta[:, 0], "dy": delta[:, 1], "dz": delta[:, 2], "dn": dn}
    )
    for c in ("dx", "dy", "dz", "dn"):
        df[f"abs_{c}"] = df[c].abs()
    g = df.groupby("bin", sort=True)
    out = pd.DataFrame({"n": g.size()})
    for c in ("dx", "dy", "dz", "dn"):
        out[f"mean_{c}"] = g[c].mean()
        out[f"mean_abs_{c}"] = g[f"abs_{c}"].mean()
        out[f"max_abs_{c}"] = g[f"abs_{c}"].max()
    out["R_m"] = np.sqrt(
        out["mean_abs_dx"] ** 2 + out["mean_abs_dy"] ** 2 + out["mean_abs_dz"] ** 2
    )
    return out


def by_depth(
    z: ArrayLike, delta: ArrayLike, dn: ArrayLike, *, bin_width: float = 0.5e-3
) -> pd.DataFrame:
    """Statistics per z-level bin (default: the 0.5 mm step-down).

    ``z`` (N,) m is the height of each point's nominal foot (or contact point); bins are
    ``[z_lo, z_hi)`` aligned on multiples of ``bin_width`` below the sheet plane. Returns one
    row per non-empty bin, columns ``z_lo, z_hi, n, mean_dx, mean_abs_dx, max_abs_dx, …, R_m``
    (m).
    """
    if not (bin_width > 0):
        raise InputError("must be > 0 mm", field="bin_width")
    zz = np.asarray(z, dtype=float)
    key = np.floor(zz / bin_width).astype(np.int64)
    out = _binned(key, np.atleast_2d(np.asarray(delta, dtype=float)), np.asarray(dn, dtype=float))
    out.insert(0, "z_hi", (out.index.to_numpy() + 1) * bin_width)
    out.insert(0, "z_lo", out.index.to_numpy() * bin_width)
    return out.sort_index(ascending=False).reset_index(drop=True)


def by_angle(
    angle: ArrayLike,
    z: ArrayLike,
    delta: ArrayLike,
    dn: ArrayLike,
    *,
    z_level: float = -11e-3,
    band: float = 0.25e-3,
    bin_width: float = math.radians(5.0),
) -> pd.DataFrame:
    """Statistics per polar-angle bin at the contour ``z_level`` (paper: −11 mm).

    Uses the points with ``|z − z_level| ≤ band``; bins ``[a_lo, a_hi)`` of ``bin_width`` [rad]
    from 0 to 2π. Columns ``angle_lo, angle_hi`` (rad) then as :func:`by_depth`. Empty if the
    contour has no points (e.g. it lies in the excluded rim band).
    """
    if not (0 < bin_width <= 2 * math.pi):
        raise InputError("must be in (0, 360] deg", field="angle_bin")
    a = np.mod(np.asarray(angle, dtype=float), 2 * math.pi)
    zz = np.asarray(z, dtype=float)
    sel = np.abs(zz - z_level) <= band
    key = np.floor(a[sel] / bin_width).astype(np.int64)
    d = np.atleast_2d(np.asarray(delta, dtype=float))[sel]
    out = _binned(key, d, np.asarray(dn, dtype=float)[sel])
    out.insert(0, "angle_hi", (out.index.to_numpy() + 1) * bin_width)
    out.insert(0, "angle_lo", out.index.to_numpy() * bin_width)
    return out.reset_index(drop=True)


def lap_arc_length(contact: ArrayLike, lap: ArrayLike) -> tuple[F64, F64]:
    """Arc length of each toolpath point along its lap, from the lap's point nearest the +x axis.

    A lap is a run of consecutive points (toolpath order) with the same ``lap`` number. Its
    length is the polyline through its contact points, closed back to its first point. Each
    lap's reference (``s = 0``) is its point of smallest ``|atan2(y, x)|`` — the one nearest the
    ray φ = 0 from the work z axis — so that laps line up however the toolpath starts them; ``s``
    then grows in the toolpath's own direction and wraps at the lap length. On a surface of
    revolution (a lap at constant radius r, counter-clockwise) ``s = r·φ`` up to the chord error
    of the polyline (≈ r θ³/24 per chord of angle θ).

    Parameters
    ----------
    contact : (N, 3) float
        Contact points in toolpath order (any length unit; the result has the same unit).
    lap : (N,) int
        Lap number of each point.

    Returns
    -------
    s : (N,) float
        Arc length from the lap's reference, in ``[0, length)``.
    length : (N,) float
        Closed length of the point's lap (0 for a lap of one point).
    """
    P = np.asarray(contact, dtype=float)
    laps = np.asarray(lap)
    if P.ndim != 2 or P.shape[1] != 3 or laps.shape != (P.shape[0],):
        raise InputError(
            f"expected contact (N, 3) and lap (N,), got {P.shape} and {laps.shape}",
            field="contact",
        )
    n = P.shape[0]
    if n == 0:
        return np.zeros(0), np.zeros(0)
    new = np.ones(n, dtype=bool)
    new[1:] = laps[1:] != laps[:-1]
    run = np.cumsum(new) - 1
    starts = np.flatnonzero(new)
    ends = np.append(starts[1:], n) - 1
    seg = np.zeros(n)
    seg[1:] = np.linalg.norm(np.diff(P, axis=0), axis=1)
    seg[new] = 0.0
    cum = np.cumsum(seg)
    c = cum - cum[starts][run]
    closing = np.linalg.norm(P[ends] - P[starts], axis=1)
    length = c[ends] + closing
    phi = np.abs(np.arctan2(P[:, 1], P[:, 0]))
    order = np.lexsort((np.arange(n), phi, run))
    first = np.ones(n, dtype=bool)
    first[1:] = run[order][1:] != run[order][:-1]
    ref = order[first]
    L = length[run]
    rel = c - c[ref][run]
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(L > 0, np.mod(rel, np.where(L > 0, L, 1.0)), 0.0)
    return s, L


def by_arc_length(
    arc: ArrayLike,
    z: ArrayLike,
    delta: ArrayLike,
    dn: ArrayLike,
    *,
    z_level: float = -11e-3,
    band: float = 0.25e-3,
    bin_width: float = 5e-3,
) -> pd.DataFrame:
    """Statistics per arc-length bin along the contour ``z_level`` — :func:`by_angle` for any part.

    ``arc`` (N,) m is each point's position along its lap (:func:`lap_arc_length`: from the point
    nearest the +x axis, in the toolpath's direction). Uses the points with
    ``|z − z_level| ≤ band``; bins ``[s_lo, s_hi)`` of ``bin_width`` [m] from 0. Columns
    ``s_lo, s_hi`` (m) then as :func:`by_depth`. Empty if the contour has no points.
    """
    if not (math.isfinite(bin_width) and bin_width > 0):
        raise InputError("must be > 0 mm", field="arc_bin")
    s = np.asarray(arc, dtype=float)
    zz = np.asarray(z, dtype=float)
    sel = np.abs(zz - z_level) <= band
    key = np.floor(s[sel] / bin_width).astype(np.int64)
    d = np.atleast_2d(np.asarray(delta, dtype=float))[sel]
    out = _binned(key, d, np.asarray(dn, dtype=float)[sel])
    out.insert(0, "s_hi", (out.index.to_numpy() + 1) * bin_width)
    out.insert(0, "s_lo", out.index.to_numpy() * bin_width)
    return out.reset_index(drop=True)
