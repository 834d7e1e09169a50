"""Generatrix of an axisymmetric part: a chain of line segments and circular arcs in (r, z).

The chain runs from the outer rim inwards and downwards (z ≤ 0 below the sheet plane). Every
primitive knows, for a point on it, the **local wall angle** α (angle between the wall and the
sheet plane: 0 on the flange, 90° on a vertical wall) and the **tool-side normal**
``n = (−sin α, cos α)`` in (r, z): it points away from the material, towards the side a forming
tool touches (inwards and upwards on a cone).

Closest-point queries are exact: for a surface of revolution the closest point to X lies in X's
own meridian half-plane, so the 3-D problem is a 2-D one per primitive (projection on a segment;
radial projection on an arc, clamped to its angle range).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError

__all__ = ["Arc", "Generatrix", "Segment"]

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

    def __post_init__(self) -> None:
        if len(self.primitives) != len(self.regions) or not self.primitives:
            raise InputError("generatrix needs one region label per primitive")
        if "wall" not in self.regions:
            raise InputError("generatrix has no wall")
        lengths = np.array([p.length for p in self.primitives])
        starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        first_wall = self.regions.index("wall")
        object.__setattr__(self, "_s0", starts - starts[first_wall])

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
        wall_first = sorted(range(len(self.primitives)), key=lambda i: self.regions[i] != "wall")
        d = np.empty_like(r)
        better = np.empty(r.shape, dtype=bool)
        for i in wall_first:
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
