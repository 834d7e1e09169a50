"""Summaries of deviation vectors: overall, per z-level bin, per angle at a contour.

Resultant mean deviation (paper eq. 6)::

    R_m = sqrt( (mean|δx|)² + (mean|δy|)² + (mean|δz|)² )

i.e. the norm of the per-axis *mean absolute* deviations — the paper's springback figures
(0.72 mm in x and y, 0.49 mm in z) give its resultant 1.132 mm this way. The function is
:func:`roboisf.decompose.resultant_mean_deviation` (one implementation), re-exported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from roboisf.decompose.core import resultant_mean_deviation
from roboisf.errors import InputError

__all__ = [
    "DeviationStats",
    "by_angle",
    "by_depth",
    "deviation_stats",
    "resultant_mean_deviation",
]

F64 = NDArray[np.float64]


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
    a = np.abs(d)
    return DeviationStats(
        int(d.shape[0]),
        d.mean(axis=0),
        a.mean(axis=0),
        a.max(axis=0),
        float(n_.mean()),
        float(np.abs(n_).mean()),
        float(np.abs(n_).max()),
        resultant_mean_deviation(d),
    )


def _binned(key: NDArray[np.int64], delta: F64, dn: F64) -> pd.DataFrame:
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
