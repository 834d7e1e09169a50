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

Any other part (pyramid, mesh, CAD): :class:`PointField` interpolates ``dn`` in 3-D from the
toolpath's contact points — inverse-distance weights of the ``k`` nearest contacts — and ramps it
linearly in z from the first lap's mean height to 0 at the sheet plane (the clamped rim); points
beyond the last lap (the bottom) take their nearest laps' values. On a wall the nearest contacts
sit on the laps just above and below, spaced by the step-down, so the field is the per-lap
values interpolated across the laps as the axisymmetric one is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from roboisf.errors import InputError
from roboisf.parts.axisymmetric import AxisymmetricPart
from roboisf.path.toolpath import Toolpath

__all__ = ["NormalField", "PointField"]

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
        """dn [m] at wall arc length ``s`` [m] and polar angle ``phi`` [rad]: bilinear in
        (s, φ) on the grid. Computed in place, each quantity once (the floor of the angle
        index, ``1 − fu``, the grid's corners through flat indices): the operations of
        ``v0 · (1 − fs) + v1 · fs`` with ``v = g[i, j0] · (1 − fu) + g[i, j1] · fu``, in that
        order — the same numbers."""
        s = np.asarray(s, dtype=float)
        phi = np.asarray(phi, dtype=float)
        if s.ndim == 0 or phi.ndim == 0:  # scalars as vectors of one (in-place work below)
            shape = np.broadcast_shapes(s.shape, phi.shape)
            return self(np.atleast_1d(s), np.atleast_1d(phi)).reshape(shape)
        A = self.phi.size
        u = np.add(phi, np.pi)  # mod(phi + π, 2π) / 2π · A
        np.mod(u, 2 * np.pi, out=u)
        u /= 2 * np.pi
        u *= A
        fl = np.floor(u)
        j0 = fl.astype(np.int64)
        j0 %= A
        j1 = j0 + 1
        j1 %= A
        fu = np.subtract(u, fl, out=u)  # u − floor(u)
        omfu = np.subtract(1, fu, out=fl)  # 1 − fu
        s_laps = self.s_laps
        i1 = np.searchsorted(s_laps, s, side="right")
        np.clip(i1, 1, s_laps.size - 1, out=i1)
        i0 = i1 - 1
        s0 = np.take(s_laps, i0)
        fs = np.subtract(s, s0)  # (s − s0) / (s1 − s0), clipped to [0, 1]
        fs /= np.subtract(np.take(s_laps, i1), s0, out=s0)
        np.clip(fs, 0.0, 1.0, out=fs)
        g = self.grid.ravel()  # g[i, j] = g.ravel()[i·width + j]
        i0 *= self.grid.shape[1]
        i1 *= self.grid.shape[1]

        def along(row: NDArray[np.int64]) -> F64:  # g[i, j0] · (1 − fu) + g[i, j1] · fu
            v = np.take(g, j0 + row)
            v *= omfu
            w = np.take(g, j1 + row)
            w *= fu
            v += w
            return v

        v0, v1 = along(i0), along(i1)
        v1 *= fs
        v0 *= np.subtract(1, fs, out=fs)
        v0 += v1
        return v0

    def offset(self, part: AxisymmetricPart) -> Callable[[F64, F64], F64]:
        """The field as ``offset(z, phi)`` [m] for nominal points of ``part`` at height z."""
        g = part.generatrix
        z_lo, z_hi = g.wall_bottom_z, g.wall_top_z

        def offset(z: F64, phi: F64) -> F64:
            return self(g.wall_s_at_z(np.clip(z, z_lo, z_hi)), phi)

        return offset


@dataclass(frozen=True, eq=False)
class PointField:
    """``dn`` at any nominal point of any part, from per-toolpath-point values (work frame, m).

    Attributes
    ----------
    contact : (N, 3) float, m — toolpath contact points
    dn : (N,) float, m — normal offset of the formed surface there
    z_first : float, m — mean contact height of the first lap below the sheet plane (< 0):
        above it the field ramps linearly to 0 at z = 0
    k : int — neighbours of the inverse-distance interpolation
    """

    contact: F64
    dn: F64
    z_first: float
    k: int = 8

    @classmethod
    def from_toolpath(cls, toolpath: Toolpath, dn: ArrayLike, k: int = 8) -> PointField:
        """Build the field from per-toolpath-point normal offsets ``dn`` (N,) [m]."""
        dn = np.asarray(dn, dtype=float)
        if dn.shape != (len(toolpath),) or not np.all(np.isfinite(dn)):
            raise InputError(f"dn must be finite with shape ({len(toolpath)},)", field="dn")
        # laps whose ball only rolls over the rim edge touch it at z = 0: the ramp starts at the
        # first lap that touches the wall
        z_lap = np.bincount(toolpath.lap, weights=toolpath.contact[:, 2]) / np.maximum(
            np.bincount(toolpath.lap), 1
        )
        below = z_lap[z_lap < -1e-6]
        if below.size == 0:
            raise InputError(
                "no lap of the toolpath touches the wall below the sheet plane", field="toolpath"
            )
        z_first = float(below.max())
        return cls(np.array(toolpath.contact, dtype=float), dn, z_first, min(k, len(toolpath)))

    @property
    def _tree(self) -> cKDTree:
        tree = self.__dict__.get("_kd")
        if tree is None:
            tree = cKDTree(self.contact)
            object.__setattr__(self, "_kd", tree)
        return tree

    def __call__(self, points: ArrayLike) -> F64:
        """dn [m] (M,) at nominal points (M, 3) [m].

        Many points (a scan's) are queried in the order of a coarse grid over (x, y) and the
        values put back in the points' order: each point's neighbours and distances do not
        depend on the order of the queries, but the tree's nodes are then met in cache
        (~1.5× faster on a 200 k-point scan drawn at random over a pyramid). The weights are
        computed in place: the same operations in the same order, the same numbers."""
        X = np.atleast_2d(np.asarray(points, dtype=float))
        order = _grid_order(X) if X.shape[0] >= _SORTED_QUERIES else None
        dist, idx = self._tree.query(
            X if order is None else X[order], k=list(range(1, self.k + 1))
        )  # (M, k) even for k = 1
        w = np.maximum(dist, 1e-9, out=dist)  # 1 / max(dist, 1e-9)²
        np.square(w, out=w)
        np.divide(1.0, w, out=w)
        wdn = np.take(self.dn, idx)  # w · dn[idx]
        wdn *= w
        v = np.sum(wdn, axis=1)
        v /= np.sum(w, axis=1)
        if order is not None:
            v_sorted, v = v, np.empty_like(v)
            v[order] = v_sorted
        ramp = np.clip(X[:, 2] / self.z_first, 0.0, 1.0)
        v *= ramp
        return v


#: Queries of :meth:`PointField.__call__` from which they are sorted (:func:`_grid_order`).
_SORTED_QUERIES = 4096
#: m — the side of :func:`_grid_order`'s cells (a few toolpath spacings).
_ORDER_CELL = 2e-3


def _grid_order(X: F64) -> NDArray[np.intp]:
    """A permutation of the points ``X`` (M, 3) grouping them by :data:`_ORDER_CELL` squares in
    (x, y), cell rows in x (stable). Only the queries' order: any permutation gives the same
    answers (non-finite coordinates only make a poorer order)."""
    with np.errstate(invalid="ignore", over="ignore"):
        xy = X[:, :2] - np.min(X[:, :2], axis=0)
        xy *= 1.0 / _ORDER_CELL
        cell = xy.astype(np.int64)
    ny = int(np.max(cell[:, 1])) + 1 if cell.size else 1
    key = cell[:, 0] * ny + cell[:, 1]
    return np.argsort(key, kind="stable")
