"""The registration's and the pyramid's fast paths give the same bits as the plain forms.

``Pyramid.closest_point`` (shared |x|, |y|, the arcs' hypot only beyond the corners' centres,
in-place polygon edges, the nearest patch's data copied once), ``_flange_points`` (the 8 probe
sets in one query), ``_search_rz`` (the candidates in one query), ``_jacobian`` (column-wise
cross product) and ``_normal_equations`` (H and G formed on demand) are checked against the
straightforward forms they replaced, written out here, with ``np.array_equal``: a reordered
sum or a lost tie-break fails. Batching rests on every part's query being per point (a row's
numbers do not depend on the rows around it): checked for the analytic and mesh parts.
"""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from roboisf.frames.rotations import rot_z
from roboisf.frames.se3 import make_transform, transform_points
from roboisf.parts import Cone, Pyramid, tessellate
from roboisf.parts.axisymmetric import REGION_CODES, SurfaceQuery
from roboisf.parts.pyramid import TIE, rounded_rectangle_closest
from roboisf.scan import registration as reg
from roboisf.scan import synthetic_scan

PYRAMIDS = {
    "rounded": Pyramid(0.1, 0.1, math.radians(60), 0.03, corner_radius=0.01),
    "rect_rounded": Pyramid(120e-3, 90e-3, math.radians(55.0), 35e-3, corner_radius=12e-3),
    "sharp_two_angles": Pyramid(
        100e-3, 80e-3, math.radians(60.0), 30e-3, wall_angle_y=math.radians(50), corner_radius=0
    ),
    "no_flange": Pyramid(
        80e-3, 60e-3, math.radians(55.0), 25e-3, corner_radius=8e-3, flange_width=0.0
    ),
    "round_opening": Pyramid(100e-3, 100e-3, math.radians(60.0), 20e-3, corner_radius=50e-3),
}


def _same(a: SurfaceQuery, b: SurfaceQuery) -> None:
    for f in fields(SurfaceQuery):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), f.name


# -- the plain forms ----------------------------------------------------------------------------


def _rr_ref(p, a, b, r):
    x, y = p[:, 0], p[:, 1]
    ax, ay = np.abs(x), np.abs(y)
    qx, qy = ax - (a - r), ay - (b - r)
    corner = (qx > 0.0) & (qy > 0.0)
    nq = np.hypot(qx, qy)
    scale = np.where(corner, r / np.where(nq > 0, nq, 1.0), 0.0)
    xside = qx >= qy
    cx = np.where(corner, (a - r) + qx * scale, np.where(xside, a, ax))
    cy = np.where(corner, (b - r) + qy * scale, np.where(xside, ay, b))
    sd = np.where(corner, nq - r, np.where(xside, qx, qy) - r)
    closest = np.empty_like(p)
    closest[:, 0] = np.copysign(cx, x)
    closest[:, 1] = np.copysign(cy, y)
    return closest, sd


def _polygon_ref(poly, X):
    Y = X - poly.o
    u, v = Y @ poly.e1, Y @ poly.e2
    uv = poly.uv
    k = len(uv)
    inside = np.ones(len(X), dtype=bool)
    best = np.full(len(X), np.inf)
    bu, bv = u.copy(), v.copy()
    for i in range(k):
        a, b = uv[i], uv[(i + 1) % k]
        eu, ev = b[0] - a[0], b[1] - a[1]
        du, dv = u - a[0], v - a[1]
        inside &= eu * dv - ev * du >= 0.0
        t = np.clip((du * eu + dv * ev) / (eu * eu + ev * ev), 0.0, 1.0)
        cu, cv = a[0] + t * eu, a[1] + t * ev
        d2 = (u - cu) ** 2 + (v - cv) ** 2
        better = d2 < best
        best = np.where(better, d2, best)
        bu = np.where(better, cu, bu)
        bv = np.where(better, cv, bv)
    bu = np.where(inside, u, bu)
    bv = np.where(inside, v, bv)
    return poly.o + bu[:, None] * poly.e1 + bv[:, None] * poly.e2


def _pyramid_ref(self, points):
    """The patch-by-patch form: every patch's results copied wherever nearer by more than the
    tie margin (pyramid.TIE)."""
    X = np.atleast_2d(np.asarray(points, dtype=float))
    n = X.shape[0]
    best_d = np.full(n, np.inf)
    best_p = np.zeros((n, 3))
    best_n = np.zeros((n, 3))
    best_a = np.zeros(n)
    best_s = np.zeros(n)
    best_r = np.zeros(n, dtype=np.int64)

    def take(idx, P, N, alpha, s, region):
        Y = X[idx] - P
        d = np.einsum("ij,ij->i", Y, Y)
        better = np.sqrt(d) < np.sqrt(best_d[idx]) - TIE
        j = idx[better]
        best_d[j] = d[better]
        best_p[j] = P[better]
        best_n[j] = N[better] if N.ndim == 2 else N
        best_a[j] = alpha
        best_s[j] = s[better]
        best_r[j] = region

    everyone = np.arange(n)
    up = np.array([0.0, 0.0, 1.0])
    bx, by, br = self.section(self.depth)
    c2, sd = _rr_ref(X[:, :2], bx, by, br)
    P_bot = np.c_[np.where((sd <= 0)[:, None], X[:, :2], c2), np.full(n, -self.depth)]
    slope = self.depth / math.sin(min(self.alpha_x, self.alpha_y))
    s_bot = slope - np.minimum(sd, 0.0)
    bound = np.einsum("ij,ij->i", X - P_bot, X - P_bot)
    if self.flange_width > 0:
        ox, oy, orc = self.top_length / 2, self.top_width / 2, self.corner_radius
        fw = self.flange_width
        ci, sdo = _rr_ref(X[:, :2], ox, oy, orc)
        co, _ = _rr_ref(X[:, :2], ox + fw, oy + fw, orc + fw)
        xy = np.where((sdo < 0)[:, None], ci, np.where((sdo > fw)[:, None], co, X[:, :2]))
        P_fl = np.c_[xy, np.zeros(n)]
        s_fl = -np.clip(sdo, 0.0, fw)
        bound = np.minimum(bound, np.einsum("ij,ij->i", X - P_fl, X - P_fl))
    wall = REGION_CODES["wall"]
    for poly, nrm, alpha in self._wall_polygons:
        h = (X - poly.o) @ nrm
        lim = np.minimum(bound, best_d)
        idx = np.flatnonzero(np.abs(h) <= np.sqrt(lim) * (1 + 1e-9) + 2 * TIE)
        if idx.size:
            P = _polygon_ref(poly, X[idx])
            take(idx, P, nrm, alpha, -P[:, 2] / math.sin(alpha), wall)
    hc = self.corner_depth
    if hc > 0:
        a = self.alpha_x
        rc = self.corner_radius
        r0, r1 = rc, rc - hc / math.tan(a)
        dr, dz = r1 - r0, -hc
        L2 = dr * dr + dz * dz
        for sx in (1.0, -1.0):
            for sy in (1.0, -1.0):
                cx = sx * (self.top_length / 2 - rc)
                cy = sy * (self.top_width / 2 - rc)
                idx = np.flatnonzero(((X[:, 0] - cx) * sx >= 0) & ((X[:, 1] - cy) * sy >= 0))
                if idx.size == 0:
                    continue
                vx, vy, z = X[idx, 0] - cx, X[idx, 1] - cy, X[idx, 2]
                r = np.hypot(vx, vy)
                safe = np.where(r > 0, r, 1.0)
                ux = np.where(r > 0, vx / safe, sx / math.sqrt(2))
                uy = np.where(r > 0, vy / safe, sy / math.sqrt(2))
                t = np.clip(((r - r0) * dr + z * dz) / L2, 0.0, 1.0)
                rp, zp = r0 + t * dr, t * dz
                P = np.c_[cx + rp * ux, cy + rp * uy, zp]
                N = np.c_[-math.sin(a) * ux, -math.sin(a) * uy, np.full(idx.size, math.cos(a))]
                take(idx, P, N, a, -zp / math.sin(a), wall)
    take(everyone, P_bot, up, 0.0, s_bot, REGION_CODES["bottom"])
    if self.flange_width > 0:
        take(everyone, P_fl, up, 0.0, s_fl, REGION_CODES["flange"])
    dist = np.sqrt(best_d)
    side = np.einsum("ij,ij->i", X - best_p, best_n)
    signed = np.where(side < 0, -dist, dist)
    return SurfaceQuery(best_p, best_n, signed, best_a, -best_p[:, 2], best_s, best_r)


def _flange_points_ref(part, q, w):
    cand = np.flatnonzero((q.region == 0) & (w > 0))
    out = np.zeros(w.shape, dtype=bool)
    if cand.size == 0:
        return out
    F = q.point[cand]
    rho = np.hypot(F[:, 0], F[:, 1])
    ok = np.ones(cand.size, dtype=bool)
    for a in np.arange(8) * (math.pi / 4):
        d = np.array([math.cos(a), math.sin(a), 0.0]) * reg.FLANGE_CLEARANCE
        qq = reg._closest(part, F + d)
        on = np.abs(qq.distance) <= 1e-6
        outward = np.hypot(qq.point[:, 0], qq.point[:, 1]) > rho + 1e-9
        ok &= (qq.region == 0) & (on | outward)
    out[cand[ok]] = True
    return out


# -- the checks -----------------------------------------------------------------------------------


def _query_points(part, n, seed):
    """Random points of the bounding box (1 cm beyond), points on the surface and just off it,
    the axis, the corners of the opening."""
    rng = np.random.default_rng(seed)
    lo, hi = part.bounds
    X = lo - 0.01 + rng.random((n, 3)) * (hi - lo + 0.02)
    q = part.closest_point(lo - 0.002 + rng.random((n, 3)) * (hi - lo + 0.004))
    on = q.point + rng.normal(0.0, 1e-4, n)[:, None] * q.normal
    ends = [[0.0, 0.0, 0.0], [0.0, 0.0, -0.01], [0.05, 0.05, 0.0], [0.04, -0.04, -0.01]]
    return np.r_[X, q.point, on, ends]


@pytest.mark.parametrize("name", list(PYRAMIDS))
def test_pyramid_closest_point_is_the_patch_by_patch_form(name):
    p = PYRAMIDS[name]
    X = _query_points(p, 4000, 5)
    numpy = {"backend": "numpy"}  # (the compiled query: tests/test_native_pyramid.py)
    _same(p.closest_point(X, **numpy), _pyramid_ref(p, X))
    # not C-contiguous: each layout's own sums, as the plain form gathers them
    _same(p.closest_point(np.asfortranarray(X), **numpy), _pyramid_ref(p, np.asfortranarray(X)))
    _same(p.closest_point(X[::3], **numpy), _pyramid_ref(p, X[::3]))
    with np.errstate(over="ignore", invalid="ignore"):  # squares overflow: no patch is nearer
        big = np.array([[1e200, 0.0, 0.0], [1e160, 1e160, -1e170], [0.01, 0.0, 1e300]])
        _same(p.closest_point(big, **numpy), _pyramid_ref(p, big))
    for r in (0.0, 0.01, 0.03):
        for a, b in zip(rounded_rectangle_closest(X[:, :2], 0.04, 0.03, r),
                        _rr_ref(X[:, :2], 0.04, 0.03, r), strict=True):  # fmt: skip
            assert np.array_equal(a, b)


@pytest.mark.parametrize("kind", ["pyramid", "cone", "mesh"])
def test_queries_are_per_point_and_batched_probes_match(kind):
    part = {"pyramid": PYRAMIDS["rounded"], "cone": Cone(), "mesh": None}[kind]
    if part is None:
        part = tessellate(Cone(), chordal_error=0.2e-3, edge=6e-3)
    s = synthetic_scan(part, 30_000, noise=25e-6, outlier_fraction=0.01, seed=11)
    X = np.ascontiguousarray(transform_points(make_transform(rot_z(0.02), [3e-4, -2e-4, 1e-4]),
                                              s.points))  # fmt: skip
    # a row's numbers do not depend on its neighbours (chunks and batches rely on it)
    whole = part.closest_point(X)
    pieces = [part.closest_point(P) for P in np.split(X, [1, 999, 12_345])]
    for f in fields(SurfaceQuery):
        cat = np.concatenate([getattr(q, f.name) for q in pieces])
        assert np.array_equal(cat, getattr(whole, f.name), equal_nan=True), f.name
    q = reg._closest(part, X)
    w, _ = reg._huber_weights(q.distance, 5e-3)
    got = reg._flange_points(part, q, w)
    assert got.any() and not got.all()
    assert np.array_equal(got, _flange_points_ref(part, q, w))


def test_rz_search_is_the_one_query_per_candidate_form():
    p = PYRAMIDS["sharp_two_angles"]
    s = synthetic_scan(p, 8000, noise=25e-6, seed=3)
    X = transform_points(make_transform(rot_z(math.radians(40.0)), [2e-4, 1e-4, 0.0]), s.points)
    T0 = np.eye(4)
    got = reg._search_rz(p, X, T0, math.pi, 0.0, 5e-3, 0)
    # the plain form: one query per candidate
    rng = np.random.default_rng(0)
    S = X[rng.choice(X.shape[0], 3000, replace=False)]
    n = 36
    offsets = (np.arange(n) - n // 2) * (math.pi / n)
    base = make_transform(rot_z(0.0 - reg.twist_about_z(T0))) @ T0
    cost = np.empty(n)
    for i, off in enumerate(offsets):
        d = p.signed_distance(transform_points(make_transform(rot_z(float(off))) @ base, S))
        cost[i] = float(np.mean(np.minimum(d * d, 5e-3**2)))
    best = int(np.argmin(cost))
    assert best != n // 2  # the search moved
    assert np.array_equal(got, make_transform(rot_z(float(offsets[best]))) @ base)


def test_jacobian_and_normal_equations_are_the_plain_forms():
    p = PYRAMIDS["rounded"]
    s = synthetic_scan(p, 20_000, noise=25e-6, outlier_fraction=0.02, seed=7)
    P = transform_points(make_transform(rot_z(0.01), [2e-4, 0.0, 3e-4]), s.points)
    P[:50] = p.closest_point(P[:50]).point  # on the surface: the normal's branch
    q = p.closest_point(P)
    J = reg._jacobian(P, q)
    r = q.distance
    off = np.abs(r) > 1e-9
    assert off.any() and not off.all()
    g = np.where(off[:, None], (P - q.point) / np.where(off, r, 1.0)[:, None], q.normal)
    J_ref = np.zeros((P.shape[0], 7))
    J_ref[:, :3] = g
    J_ref[:, 3:6] = np.cross(P, g)
    assert np.array_equal(J, J_ref)
    w, _ = reg._huber_weights(r, 5e-3)
    eq = reg._normal_equations(J, P, r, w)
    L = math.sqrt(float(np.average(np.einsum("ij,ij->i", P, P), weights=w)))
    Js = J / np.array([1.0, 1.0, 1.0, L, L, L, 1.0])
    quad = (w >= 1.0).astype(float)
    assert np.array_equal(eq.A, Js.T @ (Js * w[:, None]))
    assert np.array_equal(eq.b, Js.T @ (w * r))
    assert np.array_equal(eq.quad, quad)
    assert np.array_equal(eq.H, Js.T @ (Js * quad[:, None]))
    assert np.array_equal(eq.G, Js.T @ (Js * ((w * r) ** 2)[:, None]))
    # the Huber scale: 1.4826 MAD of the residuals within max_distance (medians of copies)
    ri = r[np.abs(r) <= 5e-3]
    _, sigma = reg._huber_weights(r, 5e-3)
    assert sigma == max(1.4826 * float(np.median(np.abs(ri - np.median(ri)))), 1e-7)
