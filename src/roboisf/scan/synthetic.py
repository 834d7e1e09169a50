"""Synthetic scans with a known answer: points on a perturbed nominal, noise, outliers, holes.

Used by the tests (ground-truth recovery) and by the virtual cell (scanner model). The truth is
a **normal offset field** ``offset(z, phi) → dn`` [m] on the nominal surface (+ = towards the
tool side, the sign of :attr:`roboisf.parts.SurfaceQuery.distance`): a scanner sees only the
normal component of a surface deviation, so that is what a scan can encode.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames.se3 import transform_points
from roboisf.parts.axisymmetric import REGION_CODES, AxisymmetricPart
from roboisf.parts.mesh import MeshPart

__all__ = ["OffsetField", "SyntheticScan", "radial_offset", "synthetic_scan"]

F64 = NDArray[np.float64]

#: ``offset(z, phi)`` [m, rad] of the *nominal* point → normal offset [m], (N,) → (N,).
OffsetField = Callable[[F64, F64], F64]


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


def _sample_axisymmetric(
    part: AxisymmetricPart, n: int, regions: Sequence[str], rng: np.random.Generator
) -> tuple[F64, F64, NDArray[np.int64]]:
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
    pts = np.empty((n, 3))
    nrm = np.empty((n, 3))
    reg = np.empty(n, dtype=np.int64)
    for k, (i, p) in enumerate(prims):
        sel = np.flatnonzero(which == k)
        m = sel.size
        if m == 0:
            continue
        r_max = float(np.max(p.at(np.linspace(0.0, p.length, 201))[0]))
        s_acc = np.empty(0)
        while s_acc.size < m:  # rejection sampling of s with density ∝ r(s)
            s = rng.random(2 * (m - s_acc.size) + 16) * p.length
            r = p.at(s)[0]
            s_acc = np.concatenate([s_acc, s[rng.random(s.size) * r_max <= r]])
        s = s_acc[:m]
        r, z, a = p.at(s)
        phi = rng.random(m) * 2 * np.pi
        c, sn = np.cos(phi), np.sin(phi)
        pts[sel] = np.stack([r * c, r * sn, z], axis=1)
        nrm[sel] = np.stack([-np.sin(a) * c, -np.sin(a) * sn, np.cos(a)], axis=1)
        reg[sel] = REGION_CODES[g.regions[i]]
    return pts, nrm, reg


def synthetic_scan(
    part: AxisymmetricPart | MeshPart,
    n_points: int,
    *,
    offset: OffsetField | float | None = None,
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
    part : the nominal (analytic axisymmetric part, or a mesh)
    n_points : int — points drawn uniformly by area (before holes are cut)
    offset : ``offset(z, phi)`` → (N,) m normal offset of the formed surface at the nominal
        point (z, polar angle phi), or a constant [m], or None (0)
    noise : float, m — standard deviation of Gaussian noise along the normal (scanner: 25 µm)
    outlier_fraction : fraction of points displaced along the normal by a random distance in
        ``±outlier_distance`` [m] (stray reflections)
    holes : ``(centre (3,) m, radius m)`` pairs: no points within ``radius`` of ``centre``
    regions : which regions of an axisymmetric part to scan (a mesh is scanned whole)
    T_scan_work : (4, 4), optional — pose of the work frame in the scanner frame; the returned
        points are ``T_scan_work · p_work`` (default identity)
    seed : random seed
    """
    if n_points < 1:
        raise InputError("must be ≥ 1", field="n_points")
    if not (0.0 <= outlier_fraction < 1.0):
        raise InputError("must be in [0, 1)", field="outlier_fraction")
    rng = np.random.default_rng(seed)
    if isinstance(part, MeshPart):
        from roboisf.scan.readers import sample_faces

        nom, nrm = sample_faces(part.vertices, part.faces, n_points, seed)
        q = part.closest_point(nom)
        nrm, reg = q.normal, q.region
    else:
        nom, nrm, reg = _sample_axisymmetric(part, n_points, tuple(regions), rng)
    keep = np.ones(nom.shape[0], dtype=bool)
    for centre, radius in holes:
        keep &= np.linalg.norm(nom - np.asarray(centre, dtype=float), axis=1) > radius
    nom, nrm, reg = nom[keep], nrm[keep], reg[keep]
    n = nom.shape[0]
    phi = np.arctan2(nom[:, 1], nom[:, 0])
    if offset is None:
        dn = np.zeros(n)
    elif callable(offset):
        dn = np.asarray(offset(nom[:, 2], phi), dtype=float) * np.ones(n)
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
