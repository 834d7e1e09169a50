"""Generatrix of an axisymmetric part: a chain of line segments and circular arcs in (r, z).

The chain runs from the outer rim inwards and downwards (z ≤ 0 below the sheet plane). Every
primitive knows, for a point on it, the **local wall angle** α (angle between the wall and the
sheet plane: 0 on the flange, 90° on a vertical wall) and the **tool-side normal**
``n = (−sin α, cos α)`` in (r, z): it points away from the material, towards the side a forming
tool touches (inwards and upwards on a cone).

Closest-point queries are exact: for a surface of revolution the closest point to X lies in X's
own meridian half-plane, so the 3-D problem is a 2-D one per primitive (projection on a segment;
radial projection on an arc, clamped to its angle range).

:meth:`Generatrix.at_heights` answers the same queries for points whose heights stay fixed while
their radii change (the ball-position bisections of :mod:`roboisf.toolpath.generate`): the same
numbers, bit for bit, in a fraction of the numpy calls.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError

__all__ = ["Arc", "Generatrix", "HeightQuery", "Segment"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Segment:
    """Straight piece from ``(r0, z0)`` to ``(r1, z1)`` [m], traversed rim → bottom."""

    r0: float
    z0: float
    r1: float
    z1: float

    @property
    def length(self) -> float:
        return float(np.hypot(self.r1 - self.r0, self.z1 - self.z0))

    @property
    def wall_angle(self) -> float:
        """α [rad] from the direction ``(−cos α, −sin α)``."""
        return float(np.arctan2(-(self.z1 - self.z0), -(self.r1 - self.r0)))

    def at(self, s: F64) -> tuple[F64, F64, F64]:
        """Point and wall angle at arc length ``s`` ∈ [0, length] from the start."""
        u = s / self.length
        r = self.r0 + u * (self.r1 - self.r0)
        z = self.z0 + u * (self.z1 - self.z0)
        return r, z, np.full_like(r, self.wall_angle)

    def s_at_z(self, z: F64) -> F64:
        return (z - self.z0) / (self.z1 - self.z0) * self.length

    def closest(self, r: F64, z: F64) -> tuple[F64, F64, F64, F64]:
        """Closest point (rp, zp), its wall angle (the segment's one, a 0-d array) and arc
        length, for query points (r, z)."""
        dr, dz = self.r1 - self.r0, self.z1 - self.z0
        L2 = dr * dr + dz * dz
        u = np.clip(((r - self.r0) * dr + (z - self.z0) * dz) / L2, 0.0, 1.0)
        # the wall angle is the segment's own: one value, broadcast by the caller
        return self.r0 + u * dr, self.z0 + u * dz, np.asarray(self.wall_angle), u * self.length


@dataclass(frozen=True)
class Arc:
    """Circular arc, convex towards the tool: ``(r, z) = (rc, zc) + ρ (−sin β, cos β)``.

    β runs from ``beta0`` to ``beta1`` (> beta0) [rad] and *is* the local wall angle, so the
    tool-side normal is the outward radial direction of the arc.
    """

    rc: float
    zc: float
    radius: float
    beta0: float
    beta1: float

    @property
    def length(self) -> float:
        return self.radius * (self.beta1 - self.beta0)

    def at(self, s: F64) -> tuple[F64, F64, F64]:
        beta = self.beta0 + s / self.radius
        return self.rc - self.radius * np.sin(beta), self.zc + self.radius * np.cos(beta), beta

    def s_at_z(self, z: F64) -> F64:
        beta = np.arccos(np.clip((z - self.zc) / self.radius, -1.0, 1.0))
        return (beta - self.beta0) * self.radius

    def closest(self, r: F64, z: F64) -> tuple[F64, F64, F64, F64]:
        ur, uz = r - self.rc, z - self.zc
        beta = np.arctan2(-ur, uz)  # direction (−sin β, cos β) = u/|u|; β = β0 at the centre
        beta = np.where(np.hypot(ur, uz) > 0, beta, self.beta0)
        beta = np.clip(beta, self.beta0, self.beta1)
        rp = self.rc - self.radius * np.sin(beta)
        zp = self.zc + self.radius * np.cos(beta)
        return rp, zp, beta, (beta - self.beta0) * self.radius


Primitive = Segment | Arc


@dataclass(frozen=True)
class Generatrix:
    """A chain of primitives with region labels.

    ``regions[i]`` names primitive *i*: ``"flange"``, ``"wall"`` or ``"bottom"``. Arc length ``s``
    is measured from the start of the first *wall* primitive (negative on the flange).
    """

    primitives: tuple[Primitive, ...]
    regions: tuple[str, ...]
    _s0: F64 = field(init=False, repr=False, compare=False)
    _wall_first: tuple[int, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.primitives) != len(self.regions) or not self.primitives:
            raise InputError("generatrix needs one region label per primitive")
        if "wall" not in self.regions:
            raise InputError("generatrix has no wall")
        lengths = np.array([p.length for p in self.primitives])
        starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        first_wall = self.regions.index("wall")
        object.__setattr__(self, "_s0", starts - starts[first_wall])
        # the closest-point queries' visiting order: wall primitives first (their tie rule)
        order = sorted(range(len(self.primitives)), key=lambda i: self.regions[i] != "wall")
        object.__setattr__(self, "_wall_first", tuple(order))

    # -- wall parameterisation ---------------------------------------------------------------
    @property
    def wall_indices(self) -> list[int]:
        return [i for i, g in enumerate(self.regions) if g == "wall"]

    @property
    def wall_length(self) -> float:
        """Length of the wall along the generatrix [m]."""
        return float(sum(self.primitives[i].length for i in self.wall_indices))

    @property
    def wall_top_z(self) -> float:
        p = self.primitives[self.wall_indices[0]]
        return float(p.at(np.array([0.0]))[1][0])

    @property
    def wall_bottom_z(self) -> float:
        p = self.primitives[self.wall_indices[-1]]
        return float(p.at(np.array([p.length]))[1][0])

    def wall_at_s(self, s: ArrayLike) -> tuple[F64, F64, F64]:
        """(r, z, α) at wall arc length ``s`` ∈ [0, wall_length] [m] (batched)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        r = np.empty_like(s)
        z = np.empty_like(s)
        a = np.empty_like(s)
        done = np.zeros(s.shape, dtype=bool)
        for i in self.wall_indices:
            p = self.primitives[i]
            local = s - self._s0[i]
            sel = ~done & (local <= p.length + 1e-15)
            if i == self.wall_indices[-1]:
                sel = ~done
            if np.any(sel):
                r[sel], z[sel], a[sel] = p.at(np.clip(local[sel], 0.0, p.length))
                done |= sel
        return r, z, a

    def wall_s_at_z(self, z: ArrayLike) -> F64:
        """Wall arc length at height ``z`` [m] (z between the wall's top and bottom)."""
        z = np.atleast_1d(np.asarray(z, dtype=float))
        out = np.full_like(z, np.nan)
        for i in self.wall_indices:
            p = self.primitives[i]
            ztop = float(p.at(np.array([0.0]))[1][0])
            zbot = float(p.at(np.array([p.length]))[1][0])
            sel = np.isnan(out) & (z <= ztop + 1e-15) & (z >= zbot - 1e-15)
            if np.any(sel) and ztop > zbot:
                out[sel] = self._s0[i] + np.clip(p.s_at_z(z[sel]), 0.0, p.length)
        if np.any(np.isnan(out)):
            bad = z[np.isnan(out)][0]
            raise InputError(
                f"z = {bad * 1e3:.4f} mm is outside the wall "
                f"({self.wall_bottom_z * 1e3:.4f} .. {self.wall_top_z * 1e3:.4f} mm)"
            )
        return out

    # -- closest point ---------------------------------------------------------------------
    def closest(self, r: ArrayLike, z: ArrayLike) -> tuple[F64, F64, F64, F64, NDArray[np.int64]]:
        """Exact closest point on the chain for query points in the (r, z) half-plane.

        Returns ``rp, zp, alpha, s, primitive_index`` (each (N,)); ``s`` is the arc length
        from the start of the wall. Ties within 1e-12 m go to a wall primitive (deterministic
        contacts at a concave corner, where a ball touches wall and bottom at once).
        """
        r = np.asarray(r, dtype=float)
        z = np.asarray(z, dtype=float)
        best = np.full(r.shape, np.inf)
        rp = np.zeros_like(r)
        zp = np.zeros_like(r)
        al = np.zeros_like(r)
        ss = np.zeros_like(r)
        idx = np.zeros(r.shape, dtype=np.int64)
        d = np.empty_like(r)
        better = np.empty(r.shape, dtype=bool)
        for i in self._wall_first:
            cr, cz, ca, cs = self.primitives[i].closest(r, z)
            np.hypot(cr - r, cz - z, out=d)
            np.less(d, best - 1e-12, out=better)
            # in place where nearer (the first primitive: everywhere, as best starts at inf)
            np.copyto(best, d, where=better)
            np.copyto(rp, cr, where=better)
            np.copyto(zp, cz, where=better)
            np.copyto(al, ca, where=better)
            cs += self._s0[i]
            np.copyto(ss, cs, where=better)
            np.copyto(idx, i, where=better)
        return rp, zp, al, ss, idx

    def at_heights(self, z: ArrayLike) -> HeightQuery:
        """Closest-point queries for points at the heights ``z`` [m] (flattened, (N,)), whose
        radii a caller changes from query to query: :class:`HeightQuery`."""
        return HeightQuery(self, z)


class HeightQuery:
    """Closest points on a generatrix for points ``(r, z)`` whose heights ``z`` (N,) are fixed
    and radii ``r`` (N,) vary from query to query (a bisection on r at fixed heights).

    :meth:`closest` returns what :meth:`Generatrix.closest` returns for ``(r, z)``, and
    :meth:`signed` the signed distance to it (+ on the tool side), **bit for bit**: every
    element goes through the same floating-point operations in the same order. Only the
    bookkeeping differs: the primitives are stacked — segments in one (S, N) array, arcs in one
    (A, N) — so that a query costs a few dozen numpy calls whatever the number of primitives,
    the parts of the segment projection that depend on z alone (``(z − z0)·Δz``, an arc's
    ``z − zc``) are computed once, and the winning primitive's values are gathered once at the
    end instead of being copied in after every primitive. The winner is chosen as
    :meth:`Generatrix.closest` chooses it: wall primitives first, a later one only when nearer
    by more than 1e-12 m; a point no primitive wins (a NaN distance) gets zeros, as there.
    """

    def __init__(self, g: Generatrix, z: ArrayLike) -> None:
        zf = np.ascontiguousarray(np.asarray(z, dtype=float).reshape(-1))
        n = zf.shape[0]
        self.z, self.n = zf, n
        prims = g.primitives
        segs = [i for i, p in enumerate(prims) if isinstance(p, Segment)]
        arcs = [i for i, p in enumerate(prims) if isinstance(p, Arc)]
        sp = [p for p in prims if isinstance(p, Segment)]
        ap = [p for p in prims if isinstance(p, Arc)]
        order = segs + arcs  # row k of the stacked arrays is primitive order[k]
        row = {i: k for k, i in enumerate(order)}
        n_seg, n_arc = len(segs), len(arcs)
        n_rows = n_seg + n_arc
        self._ns, self._na, self._p = n_seg, n_arc, n_rows
        self._visit = [row[i] for i in g._wall_first]
        # primitive index of each row, the last row (nobody won) → 0 as in Generatrix.closest
        self._prim = np.array([*order, 0], dtype=np.int64)

        def col(values: list[float]) -> F64:
            return np.array(values, dtype=float).reshape(-1, 1)

        dr = [p.r1 - p.r0 for p in sp]
        dz = [p.z1 - p.z0 for p in sp]
        self._r0, self._z0 = col([p.r0 for p in sp]), col([p.z0 for p in sp])
        self._dr, self._dz = col(dr), col(dz)
        self._l2 = col([a * a + b * b for a, b in zip(dr, dz, strict=True)])
        self._len = col([p.length for p in sp])
        self._s0s = col([float(g._s0[i]) for i in segs])
        self._a = (zf - self._z0) * self._dz  # (S, N): the z part of the projection's dot
        self._rc, self._zc = col([p.rc for p in ap]), col([p.zc for p in ap])
        self._rho = col([p.radius for p in ap])
        self._b0, self._b1 = col([p.beta0 for p in ap]), col([p.beta1 for p in ap])
        self._s0a = col([float(g._s0[i]) for i in arcs])
        self._uz = zf - self._zc  # (A, N)
        # stacked candidates (+ one row of zeros: nobody won) and work arrays
        shape = (n_rows + 1, n)
        self._cr, self._cz = np.zeros(shape), np.zeros(shape)
        self._al, self._ss = np.zeros(shape), np.zeros(shape)
        self._nr, self._nz = np.zeros(shape), np.zeros(shape)
        # the tool-side normal (−sin α, cos α) of a segment (α its own) and of nobody (α = 0),
        # by np.sin and np.cos of the array of α as generate's meridian query takes them
        alpha: F64 = np.array([p.wall_angle for p in sp] + [0.0], dtype=float)
        sn, cs = np.sin(alpha), np.cos(alpha)
        seg_and_none = [*range(n_seg), n_rows]
        self._al[seg_and_none] = alpha[:, None]
        self._nr[seg_and_none] = -sn[:, None]
        self._nz[seg_and_none] = cs[:, None]
        self._t = np.empty((n_seg, n))
        self._ur, self._neg, self._h = (np.empty((n_arc, n)) for _ in range(3))
        self._sb = np.empty((n_arc, n))
        self._dx, self._dy, self._d = (np.empty((n_rows, n)) for _ in range(3))
        self._best, self._thr = np.empty(n), np.empty(n)
        self._better = np.empty(n, dtype=bool)
        self._win = np.empty(n, dtype=np.intp)
        self._flat = np.arange(n, dtype=np.intp)

    def _candidates(self, r: F64, full: bool) -> None:
        """Every primitive's closest point (and distance) for radii r, as Segment.closest and
        Arc.closest compute them."""
        S, A = self._ns, self._na
        if S:
            t = self._t
            np.subtract(r, self._r0, out=t)
            t *= self._dr
            t += self._a
            t /= self._l2
            np.clip(t, 0.0, 1.0, out=t)
            cr, cz = self._cr[:S], self._cz[:S]
            np.multiply(t, self._dr, out=cr)
            cr += self._r0
            np.multiply(t, self._dz, out=cz)
            cz += self._z0
            if full:
                ss = self._ss[:S]
                np.multiply(t, self._len, out=ss)
                ss += self._s0s
        if A:
            ur, neg, h, sb = self._ur, self._neg, self._h, self._sb
            beta, nz = self._al[S : S + A], self._nz[S : S + A]
            np.subtract(r, self._rc, out=ur)
            np.negative(ur, out=neg)
            np.arctan2(neg, self._uz, out=beta)
            np.hypot(ur, self._uz, out=h)
            np.copyto(beta, self._b0, where=np.logical_not(h > 0))  # β0 at the centre
            np.clip(beta, self._b0, self._b1, out=beta)
            np.sin(beta, out=sb)
            np.cos(beta, out=nz)
            cr, cz = self._cr[S : S + A], self._cz[S : S + A]
            np.multiply(self._rho, sb, out=cr)
            np.subtract(self._rc, cr, out=cr)
            np.multiply(self._rho, nz, out=cz)
            np.add(self._zc, cz, out=cz)
            np.negative(sb, out=self._nr[S : S + A])
            if full:
                ss = self._ss[S : S + A]
                np.subtract(beta, self._b0, out=ss)
                ss *= self._rho
                ss += self._s0a
        P = self._p
        np.subtract(self._cr[:P], r, out=self._dx)
        np.subtract(self._cz[:P], self.z, out=self._dy)
        np.hypot(self._dx, self._dy, out=self._d)

    def _select(self, r: F64, full: bool) -> NDArray[np.intp]:
        """Flat indices into the stacked arrays of each point's winning primitive."""
        r = np.asarray(r, dtype=float)
        if r.shape != (self.n,):
            raise ValueError(f"r: ({self.n},) radii expected, got {r.shape}")
        self._candidates(r, full)
        best, thr, better, win = self._best, self._thr, self._better, self._win
        best.fill(np.inf)
        win.fill(self._p)
        for k in self._visit:
            np.subtract(best, 1e-12, out=thr)
            np.less(self._d[k], thr, out=better)
            np.copyto(best, self._d[k], where=better)
            np.copyto(win, k, where=better)
        flat: NDArray[np.intp] = win * self.n
        flat += self._flat
        return flat

    def closest(self, r: ArrayLike) -> tuple[F64, F64, F64, F64, NDArray[np.int64]]:
        """``rp, zp, alpha, s, primitive_index`` (N,) of :meth:`Generatrix.closest` for the
        points ``(r, z)``."""
        r = np.asarray(r, dtype=float)
        flat = self._select(r, True)
        return (
            self._cr.take(flat),
            self._cz.take(flat),
            self._al.take(flat),
            self._ss.take(flat),
            self._prim[flat // self.n],
        )

    def signed(self, r: ArrayLike) -> F64:
        """Signed distance (N,) [m] of the points ``(r, z)`` to their closest point
        ``(rp, zp)`` (+ on the tool side of its normal ``(−sin α, cos α)``): ``hypot(r − rp,
        z − zp)``, negative where ``(r − rp, z − zp)·n < 0``."""
        r = np.asarray(r, dtype=float)
        flat = self._select(r, False)
        a = r - self._cr.take(flat)
        b = self.z - self._cz.take(flat)
        dist = np.hypot(a, b)
        side = a * self._nr.take(flat)
        side += b * self._nz.take(flat)
        return np.where(side < 0, -dist, dist)
