"""The formed surface of the virtual cell: the nominal moved along its normal.

A scan sees only the normal component of what moved the wall, so the formed wall is the nominal
displaced by ``dn(s, φ)`` — the normal component of (tool-tip displacement + springback) at the
toolpath point that formed it — interpolated between toolpath points:

* along each lap, periodic linear interpolation in the polar angle φ onto a regular angle grid;
* between laps, linear in the wall arc length s;
* from the rim (s = 0, dn = 0: the clamped sheet does not move) to the first lap, linear;
* beyond the last lap (the flat bottom), the last lap's value.

:meth:`NormalField.offset` gives it as a function of (z, φ), the form the scan simulator takes:
on an axisymmetric part z fixes the point on the wall, the flange (z = 0) shares the rim's 0.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.parts.axisymmetric import AxisymmetricPart
from roboisf.toolpath.toolpath import Toolpath

__all__ = ["NormalField"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class NormalField:
    """``dn(s, φ)`` on a regular (lap, angle) grid. ``s_laps`` (L,) m, ``grid`` (L, A) m."""

    s_laps: F64
    phi: F64
    grid: F64

    @classmethod
    def from_toolpath(
        cls, part: AxisymmetricPart, toolpath: Toolpath, dn: ArrayLike, n_angles: int = 720
    ) -> NormalField:
        """Build the field from per-toolpath-point normal offsets ``dn`` (N,) [m]."""
        dn = np.asarray(dn, dtype=float)
        if dn.shape != (len(toolpath),) or not np.all(np.isfinite(dn)):
            raise InputError(f"dn must be finite with shape ({len(toolpath)},)", field="dn")
        s_pts = part.closest_point(toolpath.contact).s
        phi_pts = toolpath.angle
        phi = np.linspace(-np.pi, np.pi, n_angles, endpoint=False)
        rows, s_laps = [], []
        for k in range(toolpath.n_laps):
            sel = toolpath.lap == k
            order = np.argsort(phi_pts[sel])
            rows.append(np.interp(phi, phi_pts[sel][order], dn[sel][order], period=2 * np.pi))
            s_laps.append(float(np.mean(s_pts[sel])))
        s_arr = np.array([0.0, *s_laps])
        grid = np.vstack([np.zeros(n_angles), np.array(rows)])
        keep = np.concatenate([[True], np.diff(s_arr) > 1e-12])  # drop laps at the same s
        return cls(s_arr[keep], phi, grid[keep])

    def __call__(self, s: ArrayLike, phi: ArrayLike) -> F64:
        """dn [m] at wall arc length ``s`` [m] and polar angle ``phi`` [rad]."""
        s = np.asarray(s, dtype=float)
        phi = np.asarray(phi, dtype=float)
        A = self.phi.size
        u = np.mod(phi + np.pi, 2 * np.pi) / (2 * np.pi) * A
        j0 = np.floor(u).astype(np.int64) % A
        j1 = (j0 + 1) % A
        fu = u - np.floor(u)
        i1 = np.clip(np.searchsorted(self.s_laps, s, side="right"), 1, self.s_laps.size - 1)
        i0 = i1 - 1
        fs = np.clip((s - self.s_laps[i0]) / (self.s_laps[i1] - self.s_laps[i0]), 0.0, 1.0)
        g = self.grid
        v0 = g[i0, j0] * (1 - fu) + g[i0, j1] * fu
        v1 = g[i1, j0] * (1 - fu) + g[i1, j1] * fu
        return np.asarray(v0 * (1 - fs) + v1 * fs, dtype=float)

    def offset(self, part: AxisymmetricPart) -> Callable[[F64, F64], F64]:
        """The field as ``offset(z, phi)`` [m] for nominal points of ``part`` at height z."""
        g = part.generatrix
        z_lo, z_hi = g.wall_bottom_z, g.wall_top_z

        def offset(z: F64, phi: F64) -> F64:
            return self(g.wall_s_at_z(np.clip(z, z_lo, z_hi)), phi)

        return offset
