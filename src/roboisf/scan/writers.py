"""Write point clouds as PLY (for synthetic scans and the virtual cell), atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from roboisf.io.atomic import atomic_write
from roboisf.io.units import to_si

__all__ = ["write_ply"]


def write_ply(
    points: ArrayLike,
    path: str | Path,
    *,
    normals: ArrayLike | None = None,
    unit: str = "mm",
    binary: bool = True,
) -> None:
    """Write ``points`` (N, 3) [m] (and unit ``normals``) as a PLY in ``unit`` (default mm).

    Binary little-endian float32 coordinates (ascii when ``binary=False``); float32 keeps
    0.1 µm resolution for parts below 1 m in mm. A ``comment units <unit>`` line records the
    unit.
    """
    from plyfile import PlyData, PlyElement

    P = np.asarray(points, dtype=float) / to_si(unit, "length")
    names = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if normals is not None:
        names += [("nx", "f4"), ("ny", "f4"), ("nz", "f4")]
    rec = np.empty(P.shape[0], dtype=names)
    rec["x"], rec["y"], rec["z"] = P[:, 0], P[:, 1], P[:, 2]
    if normals is not None:
        N = np.asarray(normals, dtype=float)
        rec["nx"], rec["ny"], rec["nz"] = N[:, 0], N[:, 1], N[:, 2]
    ply = PlyData([PlyElement.describe(rec, "vertex")], text=not binary, comments=[f"units {unit}"])
    with atomic_write(path, "wb") as fh:
        ply.write(fh)
