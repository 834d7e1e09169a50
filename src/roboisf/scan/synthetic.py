"""Synthetic scans with a known answer: points on a perturbed nominal, noise, outliers, holes.

Used by the tests (ground-truth recovery) and by the virtual cell (scanner model). The truth is
a **normal offset field** ``offset(z, phi) → dn`` [m] on the nominal surface (+ = towards the
tool side, the sign of :attr:`roboisf.parts.SurfaceQuery.distance`): a scanner sees only the
normal component of a surface deviation, so that is what a scan can encode. On a part that is
not a surface of revolution (pyramid, freeform) give it as ``offset_at(points) → dn`` of the
nominal points instead.

Sampling: an axisymmetric part analytically (area-weighted on its generatrix), a mesh on its
triangles; any other part (a :class:`~roboisf.parts.Pyramid`, a CAD part …) through its
:meth:`~roboisf.parts.Part.closest_point` only: a height-field tessellation (the surface met by
vertical lines on a grid over ``part.bounds``, found by a safeguarded Newton iteration on the
signed distance — ISF parts are seen whole from above), points drawn by area on its triangles,
then moved onto the exact surface by :meth:`~roboisf.parts.Part.closest_point` (normal and
region from there).
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames.se3 import transform_points
from roboisf.parts.axisymmetric import REGION_CODES, AxisymmetricPart
from roboisf.parts.base import Part
from roboisf.parts.generatrix import Arc, Primitive, Segment
from roboisf.parts.mesh import MeshPart

__all__ = [
    "OffsetField",
    "PointOffset",
    "SyntheticScan",
    "height_field_mesh",
    "radial_offset",
    "surface_heights",
    "synthetic_scan",
]

F64 = NDArray[np.float64]

#: ``offset(z, phi)`` [m, rad] of the *nominal* point → normal offset [m], (N,) → (N,).
OffsetField = Callable[[F64, F64], F64]
#: ``offset_at(points)`` (N, 3) m nominal points → (N,) m normal offset (any part).
PointOffset = Callable[[F64], F64]


@dataclass(frozen=True)
class SyntheticScan:
    """A synthetic scan and its ground truth.

    Attributes
    ----------
    points : (N, 3) float, m — the scan, in the scanner frame (``T_scan_work`` applied)
    nominal : (N, 3) float, m — the nominal point each scan point was generated from (work)
    normal : (N, 3) float — tool-side unit normal there
    offset : (N,) float, m — true normal offset of the surface there (no noise, no outlier)
    region : (N,) int — 0 flange, 1 wall, 2 bottom
    is_outlier : (N,) bool
    T_scan_work : (4, 4) — pose of the work frame in the scanner frame
    """

    points: F64
    nominal: F64
    normal: F64
    offset: F64
    region: NDArray[np.int64]
    is_outlier: NDArray[np.bool_]
    T_scan_work: F64


def radial_offset(dr: Callable[[F64, F64], F64], part: AxisymmetricPart) -> OffsetField:
    """Turn a radial displacement field ``dr(z, phi)`` [m] (+ outwards) of an axisymmetric
    part's wall into the normal offset a scanner sees: ``dn = −dr · sin α`` (the tool-side
    normal points inwards by ``sin α``)."""

    def f(z: F64, phi: F64) -> F64:
        _, alpha = part.wall_at_z(np.clip(z, part.generatrix.wall_bottom_z, 0.0))
        return -dr(z, phi) * np.sin(alpha)

    return f


def _radius_at(p: Primitive, s: F64) -> F64:
    """``p.at(s)[0]`` — the radius at arc length ``s`` — without the heights and angles: a
    segment's ``r0 + (s / length)·(r1 − r0)``, an arc's ``rc − ρ·sin(β0 + s / ρ)`` (the same
    operations, in a single new array), any other primitive's through :meth:`at`. ``s`` is
    kept."""
    if isinstance(p, Segment):
        u = s / p.length
        u *= p.r1 - p.r0
        u += p.r0
        return u
    if isinstance(p, Arc):
        b = s / p.radius
        b += p.beta0
        np.sin(b, out=b)
        b *= p.radius
        return np.subtract(p.rc, b, out=b)
    return p.at(s)[0]


def _sample_axisymmetric(
    part: AxisymmetricPart, n: int, regions: Sequence[str], rng: np.random.Generator
) -> tuple[F64, F64, NDArray[np.int64]]:
    """``n`` points by area on ``part``'s primitives of ``regions``, their normals and region
    codes. The arrays of a million-point scan are computed in place where the numbers allow
    (fresh memory costs as much as the arithmetic on a virtual machine): the random stream and
    every value are those of the plain expressions in the comments. Each primitive's radii,
    heights, angles and polar angles go into whole-scan vectors (contiguous scatters, several
    times faster than scattering rows of three) and the points and normals are made from those
    in one pass (elementwise: the same numbers as per primitive)."""
    g = part.generatrix
    prims = [(i, p) for i, p in enumerate(g.primitives) if g.regions[i] in regions]
    if not prims:
        raise InputError(f"part has none of the regions {list(regions)}", field="regions")
    # area of each primitive: ∫ 2π r ds (r linear on a segment; midpoint rule exact enough)
    areas = []
    for _, p in prims:
        s = np.linspace(0.0, p.length, 201)
        r = p.at(s)[0]
        areas.append(float(np.trapezoid(r, s)))
    w = np.asarray(areas) / np.sum(areas)
    which = rng.choice(len(prims), size=n, p=w)
    R, Z, A, PHI = (np.empty(n) for _ in range(4))
    reg = np.empty(n, dtype=np.int64)
    for k, (i, p) in enumerate(prims):
        sel = np.flatnonzero(which == k)
        m = sel.size
        if m == 0:
            continue
        r_max = float(np.max(p.at(np.linspace(0.0, p.length, 201))[0]))
        accepted: list[F64] = []
        got = 0
        while got < m:  # rejection sampling of s with density ∝ r(s)
            s = rng.random(2 * (m - got) + 16)
            s *= p.length  # rng.random(…) * p.length
            r = _radius_at(p, s)
            u = rng.random(s.size)
            u *= r_max
            accepted.append(s[u <= r])  # s[rng.random(s.size) * r_max <= r]
            got += accepted[-1].size
        s = (accepted[0] if len(accepted) == 1 else np.concatenate(accepted))[:m]
        r, z, a = p.at(s)
        phi = rng.random(m)
        phi *= 2  # rng.random(m) * 2 * np.pi
        phi *= np.pi
        R[sel], Z[sel], A[sel], PHI[sel] = r, z, a, phi
        reg[sel] = REGION_CODES[g.regions[i]]
    c = np.cos(PHI)
    sn = np.sin(PHI, out=PHI)
    pts = np.empty((n, 3))
    np.multiply(R, c, out=pts[:, 0])  # np.stack([r * c, r * sn, z], axis=1)
    np.multiply(R, sn, out=pts[:, 1])
    pts[:, 2] = Z
    nrm = np.empty((n, 3))
    ca = np.cos(A)
    sa = np.sin(A, out=A)
    np.negative(sa, out=sa)  # [-sin(a) * c, -sin(a) * sn, cos(a)]
    np.multiply(sa, c, out=nrm[:, 0])
    np.multiply(sa, sn, out=nrm[:, 1])
    nrm[:, 2] = ca
    return pts, nrm, reg


def height_field_mesh(
    part: Part, spacing: float = 0.5e-3, *, tolerance: float = 1e-7
) -> tuple[F64, NDArray[np.int64]]:
    """Triangulate ``part``'s surface as a height field z(x, y) on a square grid (m).

    Every grid vertex over ``part.bounds`` is placed where the vertical line through it crosses
    the surface (:func:`surface_heights`: |signed distance| ≤ ``tolerance`` / 2); vertices where
    the line misses the surface (beyond a rounded flange's corners) are dropped with their
    triangles. Holds for any part whose surface is met once by every vertical line (every ISF
    part formed from above with wall angles < 90°).

    Returns
    -------
    vertices : (V, 3) float, m — on the surface within ``tolerance``
    faces : (F, 3) int — two triangles per grid cell
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise InputError(f"must be > 0 m, got {spacing}", field="spacing")
    lo, hi = (np.asarray(b, dtype=float) for b in part.bounds)
    inset = 1e-6
    nx = max(2, math.ceil((hi[0] - lo[0]) / spacing) + 1)
    ny = max(2, math.ceil((hi[1] - lo[1]) / spacing) + 1)
    x = np.linspace(lo[0] + inset, hi[0] - inset, nx)
    y = np.linspace(lo[1] + inset, hi[1] - inset, ny)
    X, Y = (a.ravel() for a in np.meshgrid(x, y, indexing="xy"))
    Z, sd = surface_heights(part, X, Y, lo[2] - 1e-3, hi[2] + 1e-3, tolerance)
    V = np.column_stack([X, Y, Z])
    on = np.abs(sd) <= 10 * tolerance
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="xy")
    a = (j * nx + i).ravel()
    b, c, d = a + 1, a + nx, a + nx + 1
    F = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    F = F[np.all(on[F], axis=1)]
    return V, F.astype(np.int64)


#: Newton steps :func:`surface_heights` tries per line before it only bisects.
_NEWTON_STEPS = 12


def surface_heights(
    part: Part, X: F64, Y: F64, z_below: float, z_above: float, tolerance: float = 1e-7
) -> tuple[F64, F64]:
    """Where the vertical lines through (``X``, ``Y``) (N,) m cross ``part``'s surface between
    ``z_below`` and ``z_above`` [m] (below and above it): heights (N,) m and the signed
    distance (N,) m there.

    A safeguarded Newton iteration on the signed distance along each line, f(z) = d(x, y, z),
    whose derivative is the closest point's normal's z: ``z − d / n_z``, taken when it falls
    inside the line's bracket [below, above] (which every evaluation narrows), else the
    bracket's midpoint — on a plane one step lands on the surface, where bisection alone took
    ⌈log₂(range / tolerance)⌉ (21 for a 100 mm part at 0.1 µm) evaluations of every line. A line
    stops once |d| ≤ ``tolerance`` / 2 or its bracket is ``tolerance`` wide (after
    :data:`_NEWTON_STEPS` Newton steps it only bisects, so every line stops); its height is the
    last point evaluated. A line that misses the surface (d of one sign all along) ends at a
    bracket end with |d| > ``tolerance``."""
    n = X.size
    z_lo = np.full(n, float(z_below))
    z_hi = np.full(n, float(z_above))
    z = 0.5 * (z_lo + z_hi)
    d_out = np.full(n, np.inf)
    rows = np.arange(n)
    step = 0
    while rows.size:
        zr = z[rows]
        q = part.closest_point(np.column_stack([X[rows], Y[rows], zr]))
        d, nz = q.distance, q.normal[:, 2]
        d_out[rows] = d
        above = d > 0
        lo = np.where(above, z_lo[rows], zr)
        hi = np.where(above, zr, z_hi[rows])
        z_lo[rows], z_hi[rows] = lo, hi
        go = (np.abs(d) > 0.5 * tolerance) & (hi - lo > tolerance)
        rows, d, nz, zr, lo, hi = rows[go], d[go], nz[go], zr[go], lo[go], hi[go]
        mid = 0.5 * (lo + hi)
        if step < _NEWTON_STEPS:
            with np.errstate(divide="ignore", invalid="ignore"):
                zn = zr - d / nz
            z[rows] = np.where((zn > lo) & (zn < hi), zn, mid)  # NaN, inf: outside
        else:
            z[rows] = mid
        step += 1
    return z, d_out


def _tessellation(part: Part) -> tuple[F64, NDArray[np.int64]]:
    """:func:`height_field_mesh` of ``part`` at the sampling's spacing (its bounds' larger side
    / 400, ≥ 0.25 mm), read-only."""
    lo, hi = part.bounds
    V, F = height_field_mesh(part, max(0.25e-3, float(np.max(hi[:2] - lo[:2])) / 400))
    V.setflags(write=False)
    F.setflags(write=False)
    return V, F


#: :func:`_tessellation` of the last two (hashable) parts, ~12 MB each: the CNC and robot scans
#: of one study sample the same nominal surface.
_cached_tessellation = functools.lru_cache(maxsize=2)(_tessellation)


#: (a, b − a, c − a, p): each triangle's first corner and edges (F, 3) and its share of the
#: area (F,) — what :func:`roboisf.scan.readers.sample_faces` computes from the mesh each call.
_FaceSampler = tuple[F64, F64, F64, F64]

#: :func:`_face_sampler` of the cached tessellations (:data:`_cached_tessellation`), by the
#: identity of their read-only arrays (held here, so the identity is not reused): the last two.
_samplers: dict[tuple[int, int], tuple[F64, NDArray[np.int64], _FaceSampler]] = {}
_samplers_lock = threading.Lock()


def _face_sampler(V: F64, F: NDArray[np.int64], cache: bool = False) -> _FaceSampler:
    """The mesh's :data:`_FaceSampler`, as :func:`~roboisf.scan.readers.sample_faces` makes it
    (the same operations); kept for the last two meshes when ``cache`` (the arrays of
    :data:`_cached_tessellation`, which nothing writes)."""
    key = (id(V), id(F))
    with _samplers_lock:
        hit = _samplers.get(key) if cache else None
    if hit is not None and hit[0] is V and hit[1] is F:
        return hit[2]
    a = V[F[:, 0]]
    ab, ac = V[F[:, 1]], V[F[:, 2]]
    ab -= a  # b − a
    ac -= a  # c − a
    area = np.linalg.norm(np.cross(ab, ac), axis=1)
    if not np.any(area > 0):
        raise InputError("mesh has no triangle with a non-zero area")
    out = (a, ab, ac, area / area.sum())
    if cache:
        with _samplers_lock:
            while len(_samplers) >= 2:
                del _samplers[next(iter(_samplers))]
            _samplers[key] = (V, F, out)
    return out


def _sample_faces(sampler: _FaceSampler, n: int, seed: int) -> F64:
    """``n`` points uniformly distributed over the triangles' area: the points of
    :func:`roboisf.scan.readers.sample_faces` (the same random stream and operations:
    ``a[f] + u·(b − a)[f] + v·(c − a)[f]``, in place), without the face normals."""
    a, ab, ac, p = sampler
    rng = np.random.default_rng(seed)
    f = rng.choice(p.shape[0], size=n, p=p)
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = np.take(ab, f, axis=0)
    pts *= u[:, None]
    pts += np.take(a, f, axis=0)
    t = np.take(ac, f, axis=0)
    t *= v[:, None]
    pts += t
    return pts


def _sample_any(part: Part, n: int, seed: int) -> tuple[F64, F64, NDArray[np.int64]]:
    if isinstance(part, MeshPart):
        sampler = _face_sampler(part.vertices, part.faces)
    else:
        try:
            hash(part)
        except TypeError:  # a part that cannot be hashed: not cached
            sampler = _face_sampler(*_tessellation(part))
        else:  # a study's two scans: one tessellation, its triangles' areas once
            sampler = _face_sampler(*_cached_tessellation(cast(Hashable, part)), cache=True)
    nom = _sample_faces(sampler, n, seed)
    q = part.closest_point(nom)
    return q.point, q.normal, np.asarray(q.region, dtype=np.int64)


def _per_point(values: ArrayLike, n: int) -> F64:
    """An offset field's values as (n,) float: ``values · ones(n)`` (a constant broadcast), an
    (n,) float array of its own as it is (× 1 changes no number)."""
    v = np.asarray(values, dtype=float)
    return v if v.shape == (n,) and v.flags.owndata else v * np.ones(n)


def _outside_holes(nom: F64, holes: Sequence[tuple[ArrayLike, float]]) -> NDArray[np.bool_] | None:
    """Which points ``nom`` (N, 3) lie outside every hole: ``|p − centre| > radius``
    (``np.linalg.norm`` over the rows), or None when all do.

    The norm is computed only for the points within the hole's square in (x, y) (a few per cent
    of a scan): a point whose |Δx| or |Δy| exceeds ``reach = radius·(1 + 1e-9)`` has a rounded
    norm of at least ``|Δ|·(1 − 2⁻⁵²)`` (each rounding is monotone; ``reach`` ≥ 1e-150 keeps
    Δ² clear of underflow), so it is outside — the same answer as the norm of every point.
    With a non-finite point or centre, or another radius (a NaN norm is not outside), every
    point's norm is computed."""
    keep: NDArray[np.bool_] | None = None
    finite = bool(holes) and bool(np.all(np.isfinite(nom)))
    for centre, radius in holes:
        c = np.asarray(centre, dtype=float)
        reach = radius * (1 + 1e-9)
        if finite and 1e-150 <= reach < math.inf and c.shape == (3,) and np.all(np.isfinite(c)):
            near = np.abs(np.subtract(nom[:, 0], c[0])) <= reach
            near &= np.abs(np.subtract(nom[:, 1], c[1])) <= reach
            rows = np.flatnonzero(near)
        else:
            rows = np.arange(nom.shape[0])
        if rows.size == 0:
            continue
        inside = rows[~(np.linalg.norm(nom[rows] - c, axis=1) > radius)]
        if inside.size:
            if keep is None:
                keep = np.ones(nom.shape[0], dtype=bool)
            keep[inside] = False
    return keep


def synthetic_scan(
    part: Part,
    n_points: int,
    *,
    offset: OffsetField | float | None = None,
    offset_at: PointOffset | None = None,
    noise: float = 25e-6,
    outlier_fraction: float = 0.0,
    outlier_distance: tuple[float, float] = (0.3e-3, 3e-3),
    holes: Sequence[tuple[ArrayLike, float]] = (),
    regions: Sequence[str] = ("flange", "wall", "bottom"),
    T_scan_work: ArrayLike | None = None,
    seed: int = 0,
) -> SyntheticScan:
    """Sample a scan of ``part``'s nominal surface, perturbed by a known normal offset.

    Parameters
    ----------
    part : the nominal (any part kind; see the module doc for how each is sampled)
    n_points : int — points drawn uniformly by area (before holes are cut)
    offset : ``offset(z, phi)`` → (N,) m normal offset of the formed surface at the nominal
        point (z, polar angle phi), or a constant [m], or None (0)
    offset_at : ``offset_at(points)`` → (N,) m normal offset at the nominal points (N, 3) m —
        instead of ``offset``, for any part
    noise : float, m — standard deviation of Gaussian noise along the normal (scanner: 25 µm)
    outlier_fraction : fraction of points displaced along the normal by a random distance in
        ``±outlier_distance`` [m] (stray reflections)
    holes : ``(centre (3,) m, radius m)`` pairs: no points within ``radius`` of ``centre``
    regions : which regions of an axisymmetric part to scan (any other part is scanned whole)
    T_scan_work : (4, 4), optional — pose of the work frame in the scanner frame; the returned
        points are ``T_scan_work · p_work`` (default identity)
    seed : random seed
    """
    if n_points < 1:
        raise InputError("must be ≥ 1", field="n_points")
    if not (0.0 <= outlier_fraction < 1.0):
        raise InputError("must be in [0, 1)", field="outlier_fraction")
    if offset is not None and offset_at is not None:
        raise InputError("give offset or offset_at, not both", field="offset_at")
    rng = np.random.default_rng(seed)
    if isinstance(part, AxisymmetricPart):
        nom, nrm, reg = _sample_axisymmetric(part, n_points, tuple(regions), rng)
    else:
        nom, nrm, reg = _sample_any(part, n_points, seed)
    keep = _outside_holes(nom, holes)
    if keep is not None:  # nom[keep], nrm[keep], reg[keep]: the rows found once
        rows = np.flatnonzero(keep)
        nom, nrm = np.take(nom, rows, axis=0), np.take(nrm, rows, axis=0)
        reg = np.take(reg, rows)
    n = nom.shape[0]
    if offset_at is not None:
        dn = _per_point(offset_at(nom), n)
    elif offset is None:
        dn = np.zeros(n)
    elif callable(offset):
        dn = _per_point(offset(nom[:, 2], np.arctan2(nom[:, 1], nom[:, 0])), n)
    else:
        dn = np.full(n, float(offset))
    meas = dn + rng.normal(0.0, noise, n) if noise > 0 else dn.copy()
    is_out: NDArray[np.bool_] = np.asarray(rng.random(n) < outlier_fraction)
    k = int(is_out.sum())
    lo, hi = outlier_distance
    meas[is_out] += rng.choice([-1.0, 1.0], k) * rng.uniform(lo, hi, k)
    pts = nom + meas[:, None] * nrm
    T = np.eye(4) if T_scan_work is None else np.asarray(T_scan_work, dtype=float)
    return SyntheticScan(transform_points(T, pts), nom, nrm, dn, reg, is_out, T)
