"""Measured wall thickness along the depth (ultrasonic gauge, sectioned part, CT).

File format (CSV)::

    # units: length=mm        ← optional; mm when absent
    depth,thickness
    5.0,0.31
    ...

``depth`` is positive below the sheet plane; rows in any order (sorted on read).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.io.atomic import atomic_write
from roboisf.io.table import format_rows, read_table
from roboisf.io.units import to_si

__all__ = ["ThicknessProfile", "read_thickness_csv", "write_thickness_csv"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ThicknessProfile:
    """depth (N,) m, increasing; thickness (N,) m."""

    depth: F64
    thickness: F64

    def at(self, depth: ArrayLike) -> F64:
        """Linear interpolation at ``depth`` [m]; NaN outside the measured range."""
        d = np.asarray(depth, dtype=float)
        out = np.interp(d, self.depth, self.thickness)
        return np.where((d < self.depth[0]) | (d > self.depth[-1]), np.nan, out)


def read_thickness_csv(path: str | Path) -> ThicknessProfile:
    """Read a thickness profile (see module docstring) into SI."""
    t = read_table(path, ("depth", "thickness"), what="thickness CSV")
    unit = "mm"
    if "units" in t.meta:
        for tok in t.meta["units"].split():
            k, _, v = tok.partition("=")
            if k.strip() == "length":
                unit = v.strip()
    f = to_si(unit, "length", file=path, field="units")
    d, th = t.column("depth") * f, t.column("thickness") * f
    bad = np.flatnonzero((d < 0) | (th <= 0))
    if bad.size:
        raise t.error("depth must be ≥ 0 and thickness > 0", row=int(bad[0]))
    order = np.argsort(d, kind="stable")
    if np.any(np.diff(d[order]) == 0):
        i = int(order[np.flatnonzero(np.diff(d[order]) == 0)[0] + 1])
        raise t.error("depth repeated", row=i, field="depth")
    return ThicknessProfile(d[order], th[order])


def write_thickness_csv(path: str | Path, depth: ArrayLike, thickness: ArrayLike) -> None:
    """Write a thickness profile (m in, mm on file), atomically."""
    data = np.column_stack([np.asarray(depth, float), np.asarray(thickness, float)]) * 1e3
    with atomic_write(path) as fh:
        fh.write("# units: length=mm\ndepth,thickness\n" + format_rows(data, ["%.4f", "%.5f"]))
