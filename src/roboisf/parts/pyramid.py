"""Truncated pyramid: the most common ISF benchmark part, with exact surface queries.

Geometry (work frame, m; the opening centred on the z axis, its sides along x and y):

* the **opening** at the sheet plane (z = 0) is a rectangle ``top_length × top_width`` (x × y)
  with its four corners rounded by ``corner_radius`` about vertical axes (0: sharp corners);
* the walls normal to ±x ("x-walls") have wall angle ``wall_angle``, those normal to ±y
  (``y-walls``) ``wall_angle_y`` (default: the same);
* **the corner radius shrinks with the wall** (a CAD "extrude with draft" of the rounded
  opening): at depth h every horizontal section is the opening shrunk inwards by ``h / tan α``,
  so its corner radius is ``max(r_c − h / tan α, 0)``. With one wall angle the corner patches are
  right circular cones of vertical axis and the *same* wall angle as the planar walls, tangent
  to them: the wall angle, and with it the sine-law thickness, is uniform all round the part.
  (A corner radius kept constant along the depth would make the corners oblique cylinders,
  shallower than the walls by ``tan α_c = tan α / √2`` on the diagonal.) Below the depth
  ``r_c · tan α`` where the radius reaches 0 the corners are sharp edges (two walls meeting);
* a flat **bottom** at z = −depth (the opening shrunk by ``depth / tan α``) and a flat
  **flange** of ``flange_width`` around the opening at z = 0, like the axisymmetric parts.

Rounded corners need one wall angle (with two, the rounded corner would be an oblique cone, not
a surface of this simple family); sharp corners (``corner_radius = 0``) accept two.

Closest points are exact: the surface is split into closed patches — four planar wall polygons,
four quarter-cone corner patches, the bottom and the flange (planar regions bounded by rounded
rectangles) — the exact closest point on each is computed in closed form (projection into a
convex polygon or onto its edges; projection in the cone's meridian half-plane onto its
generatrix segment; projection onto a rounded rectangle's boundary), and the nearest wins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.parts.axisymmetric import (
    PAPER_SHEET_THICKNESS,
    REGION_CODES,
    SurfaceQuery,
    _compiled,
)
from roboisf.parts.base import Symmetry

__all__ = ["Pyramid", "rounded_rectangle_closest"]

F64 = NDArray[np.float64]

#: The closest-point tie rule [m]: a patch later in the order (walls, corners, bottom, flange) is
#: taken only when nearer than the best so far by more than this. A point whose foot is an edge
#: two patches share (above the rim: the wall's top edge and the flange's inner one) is at the
#: same distance from both up to rounding; without a margin the rounding chose between them,
#: and differently in the compiled query (:mod:`roboisf.parts.pyramid_kernel`).
TIE = 1e-12


def rounded_rectangle_closest(p: F64, a: float, b: float, r: float) -> tuple[F64, F64]:
    """Closest boundary point and signed distance of 2-D points to a rounded rectangle.

    Parameters
    ----------
    p : (N, 2) float, m — query points
    a, b : float, m — half sizes along x and y (centred on the origin)
    r : float, m — corner radius, 0 ≤ r ≤ min(a, b)

    Returns
    -------
    closest : (N, 2) float, m — closest point of the boundary
    sd : (N,) float, m — signed distance, negative inside (exact inside and outside)
    """
    x, y = p[:, 0], p[:, 1]
    cx, cy, sd = _rounded_rectangle_abs(np.abs(x), np.abs(y), a, b, r)
    closest = np.empty_like(p)
    closest[:, 0] = np.copysign(cx, x)
    closest[:, 1] = np.copysign(cy, y)
    return closest, sd


def _rounded_rectangle_abs(ax: F64, ay: F64, a: float, b: float, r: float) -> tuple[F64, F64, F64]:
    """:func:`rounded_rectangle_closest` from ``|x|``, ``|y|`` (N,): the closest point's
    ``|x|``, ``|y|`` and the signed distance. The arcs' square root only where it is used (the
    points beyond a corner's centre): the same numbers, a fraction of the work."""
    qx, qy = ax - (a - r), ay - (b - r)
    xside = qx >= qy
    # on the x-side (a, |y|) or on the y-side (|x|, b) …
    cx = np.where(xside, a, ax)
    cy = np.where(xside, ay, b)
    sd = np.where(xside, qx, qy)
    sd -= r
    # … or on the arc, beyond the corner's centre (there hypot(qx, qy) ≥ max(qx, qy) > 0)
    k = np.flatnonzero((qx > 0.0) & (qy > 0.0))
    if k.size:
        qxk, qyk = qx[k], qy[k]
        nq = np.hypot(qxk, qyk)
        scale = r / nq
        cx[k] = (a - r) + qxk * scale
        cy[k] = (b - r) + qyk * scale
        sd[k] = nq - r
    return cx, cy, sd


def _minus(X: F64, o: F64) -> F64:
    """``X − o`` (X (N, 3), o (3,)), a column at a time when X is C-contiguous: the same
    numbers and layout, without numpy's broadcast over a 3-long inner loop (3× slower)."""
    if not X.flags.c_contiguous:
        return X - o
    Y = np.empty(X.shape)
    for c in range(3):
        np.subtract(X[:, c], o[c], out=Y[:, c])
    return Y


@dataclass(frozen=True)
class _PlanarPolygon:
    """A closed convex planar polygon, in its own frame: origin ``o``, in-plane axes ``e1, e2``,
    normal ``n`` (3,) and the vertices ``uv`` (k, 2) in (e1, e2), counter-clockwise about n."""

    o: F64
    e1: F64
    e2: F64
    n: F64
    uv: F64

    @classmethod
    def from_vertices(cls, V: F64, n: F64) -> _PlanarPolygon:
        keep = np.linalg.norm(V - np.roll(V, 1, axis=0), axis=1) > 0
        V = V[keep]
        e1 = V[1] - V[0]
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        uv = np.c_[(V - V[0]) @ e1, (V - V[0]) @ e2]
        area = 0.5 * np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1])
        if area < 0:
            uv = uv[::-1]
        return cls(V[0], e1, e2, n, uv)

    def closest(self, X: F64) -> F64:
        """Exact closest points (N, 3) of the polygon (interior and edges) to X (N, 3)."""
        Y = _minus(X, self.o)
        u, v = Y @ self.e1, Y @ self.e2
        uv = self.uv
        k = len(uv)
        m = len(X)
        inside = np.ones(m, dtype=bool)
        best = np.full(m, np.inf)
        bu, bv = u.copy(), v.copy()
        # the edges' work in place, in these buffers (the same operations as written out)
        du, dv, t, cu, cv, d2, w = (np.empty(m) for _ in range(7))
        better = np.empty(m, dtype=bool)
        for i in range(k):
            a, b = uv[i], uv[(i + 1) % k]
            eu, ev = b[0] - a[0], b[1] - a[1]
            np.subtract(u, a[0], out=du)
            np.subtract(v, a[1], out=dv)
            # inside &= eu·dv − ev·du ≥ 0
            np.multiply(dv, eu, out=t)
            np.multiply(du, ev, out=w)
            np.subtract(t, w, out=t)
            inside &= np.greater_equal(t, 0.0, out=better)
            # t = clip((du·eu + dv·ev) / (eu² + ev²), 0, 1)
            np.multiply(du, eu, out=t)
            np.multiply(dv, ev, out=w)
            np.add(t, w, out=t)
            np.divide(t, eu * eu + ev * ev, out=t)
            np.clip(t, 0.0, 1.0, out=t)
            # the foot (cu, cv) = a + t·e and its squared distance (u − cu)² + (v − cv)²
            np.multiply(t, eu, out=cu)
            np.add(cu, a[0], out=cu)
            np.multiply(t, ev, out=cv)
            np.add(cv, a[1], out=cv)
            np.subtract(u, cu, out=d2)
            np.square(d2, out=d2)
            np.subtract(v, cv, out=w)
            np.square(w, out=w)
            np.add(d2, w, out=d2)
            np.less(d2, best, out=better)
            np.fmin(best, d2, out=best)  # = where(better, d2, best): best is never NaN
            bu = np.where(better, cu, bu)
            bv = np.where(better, cv, bv)
        bu = np.where(inside, u, bu)
        bv = np.where(inside, v, bv)
        P = np.empty((m, 3))
        for c in range(3):  # o + bu·e1 + bv·e2, a column at a time
            np.multiply(bu, self.e1[c], out=t)
            np.add(t, self.o[c], out=t)
            np.multiply(bv, self.e2[c], out=w)
            np.add(t, w, out=P[:, c])
        return P


@dataclass(frozen=True)
class Pyramid:
    """Square or rectangular truncated pyramid (see the module docstring for the geometry).

    Parameters
    ----------
    top_length : float, m — opening along x at the sheet plane
    top_width : float, m — opening along y (= top_length for a square pyramid)
    wall_angle : float, rad — wall angle of the x-walls (and of the y-walls unless
        ``wall_angle_y`` is given), in (0, 90°)
    depth : float, m — depth of the flat bottom below the sheet plane
    wall_angle_y : float or None, rad — wall angle of the y-walls (default: ``wall_angle``)
    corner_radius : float, m — vertical-axis rounding of the opening's corners (shrinks with the
        wall), 0 ≤ r_c ≤ min(top_length, top_width)/2; > 0 needs one wall angle
    sheet_thickness, flange_width : float, m
    """

    kind: ClassVar[str] = "pyramid"
    top_length: float = 150e-3
    top_width: float = 150e-3
    wall_angle: float = math.radians(60.0)
    depth: float = 50e-3
    wall_angle_y: float | None = None
    corner_radius: float = 10e-3
    sheet_thickness: float = field(default=PAPER_SHEET_THICKNESS, kw_only=True)
    flange_width: float = field(default=10e-3, kw_only=True)

    def __post_init__(self) -> None:
        for name in ("top_length", "top_width", "depth", "sheet_thickness"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"must be > 0 mm, got {v * 1e3:g}", field=name)
        for name in ("corner_radius", "flange_width"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"must be ≥ 0 mm, got {v * 1e3:g}", field=name)
        for name in ("wall_angle", "wall_angle_y"):
            v = getattr(self, name)
            if v is not None and not (0 < v < math.pi / 2):
                raise InputError(f"must be in (0, 90) deg, got {math.degrees(v):g}", field=name)
        if self.corner_radius > min(self.top_length, self.top_width) / 2 + 1e-15:
            raise InputError(
                "must be ≤ half the smaller top side "
                f"({min(self.top_length, self.top_width) * 500:g} mm), "
                f"got {self.corner_radius * 1e3:g}",
                field="corner_radius",
            )
        if self.corner_radius > 0 and not math.isclose(self.alpha_x, self.alpha_y, abs_tol=1e-12):
            raise InputError(
                "rounded corners need one wall angle for all four walls (the corner is then a "
                "cone of that angle); give wall_angle_y = wall_angle or corner_radius = 0",
                field="corner_radius",
            )
        for name, half, alpha in (
            ("top_length", self.top_length / 2, self.alpha_x),
            ("top_width", self.top_width / 2, self.alpha_y),
        ):
            inset = self.depth / math.tan(alpha)
            if half - inset <= 0:
                raise InputError(
                    f"walls of {math.degrees(alpha):g}° from a {2 * half * 1e3:g} mm opening meet "
                    f"at {half * math.tan(alpha) * 1e3:.3f} mm depth; depth "
                    f"{self.depth * 1e3:g} mm is too deep (or the {name} too small)",
                    field="depth",
                )

    # -- dimensions ------------------------------------------------------------------------------
    @property
    def alpha_x(self) -> float:
        """Wall angle of the x-walls (normal to ±x) [rad]."""
        return self.wall_angle

    @property
    def alpha_y(self) -> float:
        """Wall angle of the y-walls (normal to ±y) [rad]."""
        return self.wall_angle if self.wall_angle_y is None else self.wall_angle_y

    @property
    def corner_depth(self) -> float:
        """Depth [m] down to which the corners are rounded (then sharp edges)."""
        if self.corner_radius == 0:
            return 0.0
        return min(self.depth, self.corner_radius * math.tan(self.alpha_x))

    def section(self, h: float) -> tuple[float, float, float]:
        """Half sizes (x, y) and corner radius [m] of the horizontal section at depth h [m]."""
        ix, iy = h / math.tan(self.alpha_x), h / math.tan(self.alpha_y)
        rc = max(self.corner_radius - ix, 0.0) if self.corner_radius > 0 else 0.0
        return self.top_length / 2 - ix, self.top_width / 2 - iy, rc

    @property
    def bounds(self) -> tuple[F64, F64]:
        """Lower and upper corners (3,) [m] of the surface (flange included)."""
        hx = self.top_length / 2 + self.flange_width
        hy = self.top_width / 2 + self.flange_width
        return np.array([-hx, -hy, -self.depth]), np.array([hx, hy, 0.0])

    @property
    def symmetry(self) -> Symmetry:
        """Order 4 for a square opening with one wall angle, else 2."""
        square = math.isclose(self.top_length, self.top_width, rel_tol=0, abs_tol=1e-12)
        same = math.isclose(self.alpha_x, self.alpha_y, abs_tol=1e-12)
        return Symmetry(4 if square and same else 2)

    def thickness(self, wall_angle: ArrayLike) -> F64:
        """Sine-law thickness [m] for wall angles [rad]."""
        return self.sheet_thickness * np.cos(np.asarray(wall_angle, dtype=float))

    def to_dict(self) -> dict[str, object]:
        d: dict[str, object] = {
            "kind": "pyramid",
            "top_length": self.top_length * 1e3,
            "top_width": self.top_width * 1e3,
            "wall_angle": math.degrees(self.wall_angle),
            "depth": self.depth * 1e3,
            "corner_radius": self.corner_radius * 1e3,
            "sheet_thickness": self.sheet_thickness * 1e3,
            "flange_width": self.flange_width * 1e3,
        }
        if self.wall_angle_y is not None:
            d["wall_angle_y"] = math.degrees(self.wall_angle_y)
        return d

    # -- patches ---------------------------------------------------------------------------------
    @cached_property
    def _packed(self) -> tuple[F64, F64, F64, NDArray[np.int64], NDArray[np.int64]]:
        """The patches as the compiled query's arrays (:func:`.pyramid_kernel.pack`)."""
        from roboisf.parts import pyramid_kernel

        return pyramid_kernel.pack(self, REGION_CODES)

    @cached_property
    def _wall_polygons(self) -> list[tuple[_PlanarPolygon, F64, float]]:
        return [(_PlanarPolygon.from_vertices(V, n), n, a) for V, n, a in self._walls()]

    def _walls(self) -> list[tuple[F64, F64, float]]:
        """The four planar wall polygons: (vertices (k, 3), tool-side normal (3,), wall angle)."""
        d, hc = self.depth, self.corner_depth
        hs = sorted({0.0, hc, d})
        out = []
        for axis in (0, 1):
            alpha = self.alpha_x if axis == 0 else self.alpha_y
            rows = []
            for h in hs:
                sx, sy, rc = self.section(h)
                n_half, t_half = (sx, sy - rc) if axis == 0 else (sy, sx - rc)
                rows.append((n_half, t_half, -h))
            # polygon in (normal coordinate, along-wall coordinate, z), rim first
            loop = [(nn, -t, z) for nn, t, z in rows] + [(nn, t, z) for nn, t, z in rows[::-1]]
            for sign in (1.0, -1.0):
                V = np.array(
                    [
                        (sign * nn, sign * t, z) if axis == 0 else (-sign * t, sign * nn, z)
                        for nn, t, z in loop
                    ]
                )
                nrm = np.zeros(3)
                nrm[axis] = -sign * math.sin(alpha)
                nrm[2] = math.cos(alpha)
                out.append((V, nrm, alpha))
        return out

    def closest_point(self, points: ArrayLike, *, backend: str = "auto") -> SurfaceQuery:
        """Exact closest point on the nominal surface for each of ``points`` (N, 3) [m].

        ``normal`` is the tool-side normal of the patch the closest point lies on (on an edge
        shared by two patches, the one listed first: walls, corners, bottom, flange); ``s`` is
        the distance down the wall's slope from the rim (on the flange: minus the distance
        outwards from the opening; on the bottom: the wall's slope length plus the distance
        inwards from the bottom edge); ``region`` 0 flange, 1 wall or corner, 2 bottom.

        ``backend``: ``"auto"`` (the compiled kernel of :mod:`roboisf.parts.pyramid_kernel` —
        its C form when built, else numba's once cached: :func:`roboisf.jit.ready` — else
        numpy), ``"numba"`` (compiled) or ``"numpy"``; the same numbers to rounding (1e-12 m).
        """
        X = np.atleast_2d(np.asarray(points, dtype=float))
        if X.ndim != 2 or X.shape[1] != 3:
            raise InputError(f"points must have shape (N, 3), got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise InputError("points contain NaN or inf coordinates")
        if _compiled(backend):
            from roboisf.parts import pyramid_kernel

            foot, normal, signed, angle, s, region = pyramid_kernel.closest(X, self._packed)
            return SurfaceQuery(foot, normal, signed, angle, -foot[:, 2], s, region)
        n = X.shape[0]
        x, y = X[:, 0], X[:, 1]
        ax, ay = np.abs(x), np.abs(y)
        # bottom and flange first (cheap): their distance bounds which walls can be nearer
        bx, by, br = self.section(self.depth)
        cx, cy, sd = _rounded_rectangle_abs(ax, ay, bx, by, br)
        inner = sd <= 0
        P_bot = np.empty((n, 3))
        P_bot[:, 0] = np.where(inner, x, np.copysign(cx, x))
        P_bot[:, 1] = np.where(inner, y, np.copysign(cy, y))
        P_bot[:, 2] = -self.depth
        slope = self.depth / math.sin(min(self.alpha_x, self.alpha_y))
        s_bot = slope - np.minimum(sd, 0.0)
        Y = X - P_bot
        d_bot = np.einsum("ij,ij->i", Y, Y)
        bound = d_bot
        # a patch's squared distances are those of its points gathered (C order): those of X
        # itself unless X is not C-contiguous (then gathered as such, like the walls' points)
        Xg = X if X.flags.c_contiguous else X[np.arange(n)]
        if Xg is not X:
            Y = Xg - P_bot
            d_bot = np.einsum("ij,ij->i", Y, Y)
        fw = self.flange_width
        if fw > 0:
            ox, oy, orc = self.top_length / 2, self.top_width / 2, self.corner_radius
            cix, ciy, sdo = _rounded_rectangle_abs(ax, ay, ox, oy, orc)
            opening = sdo < 0
            P_fl = np.zeros((n, 3))
            P_fl[:, 0] = np.where(opening, np.copysign(cix, x), x)
            P_fl[:, 1] = np.where(opening, np.copysign(ciy, y), y)
            # beyond the flange's outer edge (few points): its boundary
            far = np.flatnonzero(sdo > fw)
            if far.size:
                cox, coy, _ = _rounded_rectangle_abs(ax[far], ay[far], ox + fw, oy + fw, orc + fw)
                P_fl[far, 0] = np.copysign(cox, x[far])
                P_fl[far, 1] = np.copysign(coy, y[far])
            s_fl = -np.clip(sdo, 0.0, fw)
            Y = X - P_fl
            d_fl = np.einsum("ij,ij->i", Y, Y)
            bound = np.minimum(bound, d_fl)
            if Xg is not X:
                Y = Xg - P_fl
                d_fl = np.einsum("ij,ij->i", Y, Y)
        # the patches in priority order (ties keep the first): walls, corners, bottom, flange.
        # Each patch's squared distances are compared with the best so far; the nearest
        # patch's number is kept (``win``) and its point, normal, … copied once at the end.
        best_d = np.full(n, np.inf)
        win = np.full(n, -1, dtype=np.int8)
        found: list[
            tuple[int, NDArray[np.int64], F64, F64 | None, float, tuple[F64, F64] | None]
        ] = []

        def take(idx: NDArray[np.int64], Xi: F64, P: F64) -> None:
            """Patch ``len(found)``'s points ``P`` for the points ``idx`` (at ``Xi``): where
            nearer than the best so far by more than :data:`TIE`, it is the nearest."""
            Y = Xi - P
            d = np.einsum("ij,ij->i", Y, Y)
            better = np.sqrt(d) < np.sqrt(best_d[idx]) - TIE
            j = idx[better]
            best_d[j] = d[better]
            win[j] = len(found)

        wall = REGION_CODES["wall"]
        for poly, nrm, alpha in self._wall_polygons:
            h = _minus(X, poly.o) @ nrm
            # a wall whose plane is farther than the bottom, the flange or the best patch so
            # far (by more than twice the tie margin) cannot win: skipped
            lim = np.minimum(bound, best_d)
            idx = np.flatnonzero(np.abs(h) <= np.sqrt(lim) * (1 + 1e-9) + 2 * TIE)
            if idx.size:
                Xi = np.take(X, idx, axis=0)  # = X[idx], faster
                P = poly.closest(Xi)
                take(idx, Xi, P)
                found.append((len(found), idx, P, nrm, alpha, None))
        # corner cones (one wall angle): apex below the corner centre, generatrix in (r, z)
        hc = self.corner_depth
        if hc > 0:
            a = self.alpha_x
            rc = self.corner_radius
            r0, r1 = rc, rc - hc / math.tan(a)
            dr, dz = r1 - r0, -hc
            L2 = dr * dr + dz * dz
            cxs = {s: s * (self.top_length / 2 - rc) for s in (1.0, -1.0)}
            cys = {s: s * (self.top_width / 2 - rc) for s in (1.0, -1.0)}
            gx = {s: (x - cxs[s]) * s >= 0 for s in (1.0, -1.0)}
            gy = {s: (y - cys[s]) * s >= 0 for s in (1.0, -1.0)}
            for sx in (1.0, -1.0):
                for sy in (1.0, -1.0):
                    ccx, ccy = cxs[sx], cys[sy]
                    idx = np.flatnonzero(gx[sx] & gy[sy])
                    if idx.size == 0:
                        continue
                    Xi = np.take(X, idx, axis=0)
                    vx, vy, z = Xi[:, 0] - ccx, Xi[:, 1] - ccy, Xi[:, 2]
                    r = np.hypot(vx, vy)
                    pos = r > 0
                    safe = np.where(pos, r, 1.0)
                    ux = np.where(pos, vx / safe, sx / math.sqrt(2))
                    uy = np.where(pos, vy / safe, sy / math.sqrt(2))
                    t = np.clip(((r - r0) * dr + z * dz) / L2, 0.0, 1.0)
                    rp = r0 + t * dr
                    P = np.empty((idx.size, 3))
                    P[:, 0] = ccx + rp * ux
                    P[:, 1] = ccy + rp * uy
                    np.multiply(t, dz, out=P[:, 2])
                    take(idx, Xi, P)
                    found.append((len(found), idx, P, None, a, (ux, uy)))
        BOTTOM, FLANGE = len(found), len(found) + 1
        last = [(BOTTOM, d_bot)] + ([(FLANGE, d_fl)] if fw > 0 else [])
        for code, d_patch in last:
            better = np.sqrt(d_patch) < np.sqrt(best_d) - TIE
            win = np.where(better, np.int8(code), win)
            best_d = np.where(better, d_patch, best_d)
        # the nearest patch's point, normal, wall angle, s and region
        on_fl = win == FLANGE
        best_p = P_bot
        best_s = s_bot
        best_r = np.full(n, REGION_CODES["bottom"], dtype=np.int64)
        if fw > 0:
            for c in (0, 1):
                best_p[:, c] = np.where(on_fl, P_fl[:, c], P_bot[:, c])
            best_p[:, 2] = np.where(on_fl, 0.0, -self.depth)
            best_s = np.where(on_fl, s_fl, s_bot)
            best_r[on_fl] = REGION_CODES["flange"]
        best_n = np.zeros((n, 3))
        best_n[:, 2] = 1.0
        best_a = np.zeros(n)
        for k, idx, Pw, nw, aw, uw in found:
            sel = np.flatnonzero(win[idx] == k)
            if sel.size == 0:
                continue
            j = idx[sel]
            Pk = np.take(Pw, sel, axis=0)
            best_p[j] = Pk
            if nw is not None:  # a planar wall's normal
                best_n[j] = nw
            elif uw is not None:  # a corner cone's normal, of its meridian plane's direction u
                Nk = np.empty((sel.size, 3))
                Nk[:, 0] = -math.sin(aw) * uw[0][sel]
                Nk[:, 1] = -math.sin(aw) * uw[1][sel]
                Nk[:, 2] = math.cos(aw)
                best_n[j] = Nk
            best_a[j] = aw
            best_s[j] = -Pk[:, 2] / math.sin(aw)
            best_r[j] = wall
        none = win < 0  # no patch at a finite distance (a point at overflowing coordinates)
        if none.any():
            for arr in (best_p, best_n, best_a, best_s, best_r):
                arr[none] = 0
        dist = np.sqrt(best_d)
        side = np.einsum("ij,ij->i", X - best_p, best_n)
        signed = np.where(side < 0, -dist, dist)
        return SurfaceQuery(best_p, best_n, signed, best_a, -best_p[:, 2], best_s, best_r)

    def signed_distance(self, points: ArrayLike) -> F64:
        """Signed distance [m] of ``points`` (N, 3) to the nominal surface (+ on the tool side)."""
        return self.closest_point(points).distance
