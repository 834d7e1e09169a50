"""Compiled exact closest point on a truncated pyramid (:class:`roboisf.parts.Pyramid`). Two
compiled forms, the same bits: C (``pyramid_kernel.c``, built at install, called through
:mod:`roboisf.jit.native` — no numba in the process) when it is built and fresh, else numba
(built at install: :mod:`roboisf.jit.prebuild`; tests/test_native_pyramid.py compares them).

The numpy query of :meth:`~roboisf.parts.Pyramid.closest_point` works patch by patch over the
whole array — four wall polygons (a projection and their edges), four corner cones, the bottom
and the flange (rounded rectangles) — some hundred passes over the points and their
temporaries: 360–730 ns a point, the largest single cost of registering a pyramid's scan and of
slicing its toolpath. This kernel is the same algorithm in one pass per point, in the same
order and with the same tie rule (a later patch is taken only when nearer by more than
:data:`~roboisf.parts.pyramid.TIE`: walls, corners, bottom, flange), a wall skipped when its
plane is already farther than the bottom, the flange or the best patch so far.

Its numbers equal the numpy query's to rounding (a dot product of three in order where numpy's
matrix product sums as BLAS does: an ulp; tests/test_native_pyramid.py checks every field to
1e-12 m, the patch chosen included). The kernel is serial and releases the GIL (numba's ``nogil``;
:mod:`ctypes` releases it for a C call): the registration runs it on threads, chunk by chunk.
"""

from __future__ import annotations

import ctypes
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, njit
from roboisf.parts.axisymmetric import query_buffers
from roboisf.parts.pyramid import TIE

if TYPE_CHECKING:
    from roboisf.parts.pyramid import Pyramid

__all__ = ["MAX_VERTICES", "build", "closest", "pack"]

if HAVE_NUMBA:
    compile_notice(__file__)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Indices of the packed pyramid's scalars (:func:`pack`; the same enum in pyramid_kernel.c).
(DEPTH, BX, BY, BR, SLOPE, FW, OX, OY, ORC, OXF, OYF, ORCF, HC, CA, CA_SIN, CA_MSIN, CA_COS) = (
    range(17)
)
(R0, DR, DZ, L2, CXP, CXM, CYP, CYM, ISQ2, NPRM) = range(17, 27)
#: A wall's row: origin (3), in-plane axes e1, e2 (3 each), tool-side normal (3), wall angle, sine.
WO, WE1, WE2, WN, WA, WSA, NWALL = 0, 3, 6, 9, 12, 13, 14
#: Most vertices of a wall polygon (a wall has at most six: rim, corner-depth and bottom rows).
MAX_VERTICES = 8

_P, _I = ctypes.c_void_p, ctypes.c_int64

#: The C functions of ``pyramid_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    "closest": (None, [_P, _I, _I, _I, _P, _P, _P, _P, _I, _P, _P, _P, _P, _P, _P, _P]),
}

Packed = tuple[F64, F64, F64, I64, I64]


def _c() -> Any:
    """The C library of this module, or None (the numba kernel serves)."""
    return native.library(__name__, SIGNATURES)


def pack(part: Pyramid, region_codes: dict[str, int]) -> Packed:
    """``part`` as arrays for :func:`closest`: the scalars ``prm`` (NPRM,) (the indices above,
    as :meth:`~roboisf.parts.Pyramid.closest_point` computes them), ``walls`` (4, NWALL),
    their polygons' vertices ``uv`` (4, MAX_VERTICES, 2) in the wall's (e1, e2), counter-clockwise
    about its normal, and their counts ``nv`` (4,), and the region codes (flange, wall, bottom)."""
    prm = np.zeros(NPRM)
    bx, by, br = part.section(part.depth)
    prm[DEPTH], prm[BX], prm[BY], prm[BR] = part.depth, bx, by, br
    prm[SLOPE] = part.depth / math.sin(min(part.alpha_x, part.alpha_y))
    fw = part.flange_width
    ox, oy, orc = part.top_length / 2, part.top_width / 2, part.corner_radius
    prm[FW], prm[OX], prm[OY], prm[ORC] = fw, ox, oy, orc
    prm[OXF], prm[OYF], prm[ORCF] = ox + fw, oy + fw, orc + fw
    hc = part.corner_depth
    prm[HC] = hc
    if hc > 0:
        a = part.alpha_x
        rc = part.corner_radius
        r0, r1 = rc, rc - hc / math.tan(a)
        dr, dz = r1 - r0, -hc
        prm[CA], prm[CA_SIN], prm[CA_MSIN], prm[CA_COS] = a, math.sin(a), -math.sin(a), math.cos(a)
        prm[R0], prm[DR], prm[DZ], prm[L2] = r0, dr, dz, dr * dr + dz * dz
        prm[CXP], prm[CXM] = (s * (part.top_length / 2 - rc) for s in (1.0, -1.0))
        prm[CYP], prm[CYM] = (s * (part.top_width / 2 - rc) for s in (1.0, -1.0))
    prm[ISQ2] = 1 / math.sqrt(2)
    polys = part._wall_polygons
    walls = np.zeros((len(polys), NWALL))
    uv = np.zeros((len(polys), MAX_VERTICES, 2))
    nv = np.zeros(len(polys), dtype=np.int64)
    for i, (poly, nrm, alpha) in enumerate(polys):
        k = len(poly.uv)
        if not 2 <= k <= MAX_VERTICES:  # 2: a wall that is a line (corners of half the side)
            raise ValueError(f"a wall polygon of {k} vertices (2 to {MAX_VERTICES} expected)")
        walls[i, WO : WO + 3], walls[i, WE1 : WE1 + 3] = poly.o, poly.e1
        walls[i, WE2 : WE2 + 3], walls[i, WN : WN + 3] = poly.e2, nrm
        walls[i, WA], walls[i, WSA] = alpha, math.sin(alpha)
        uv[i, :k] = poly.uv
        nv[i] = k
    codes = np.array([region_codes[x] for x in ("flange", "wall", "bottom")], dtype=np.int64)
    return prm, walls, uv, nv, codes


@njit()
def _rr_abs(
    ax: float, ay: float, a: float, b: float, r: float
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """``_rounded_rectangle_abs`` of pyramid.py for one point: ``|x|``, ``|y|`` of the closest
    boundary point and the signed distance."""
    qx, qy = ax - (a - r), ay - (b - r)
    if qx >= qy:
        cx, cy, sd = a, ay, qx - r
    else:
        cx, cy, sd = ax, b, qy - r
    if qx > 0.0 and qy > 0.0:
        nq = math.hypot(qx, qy)
        scale = r / nq
        cx, cy, sd = (a - r) + qx * scale, (b - r) + qy * scale, nq - r
    return cx, cy, sd


@njit()
def _closest(
    X: F64,
    prm: F64,
    walls: F64,
    uv: F64,
    nv: I64,
    codes: I64,
    foot: F64,
    normal: F64,
    dist: F64,
    alpha: F64,
    s: F64,
    region: I64,
) -> None:  # pragma: no cover - compiled
    depth, fw = prm[DEPTH], prm[FW]
    for k in range(X.shape[0]):
        x, y, z = X[k, 0], X[k, 1], X[k, 2]
        ax, ay = abs(x), abs(y)
        # the bottom: the section at the depth, its inside or its boundary
        cx, cy, sd = _rr_abs(ax, ay, prm[BX], prm[BY], prm[BR])
        pbx = x if sd <= 0.0 else math.copysign(cx, x)
        pby = y if sd <= 0.0 else math.copysign(cy, y)
        s_bot = prm[SLOPE] - (sd if sd < 0.0 else 0.0)
        ex, ey, ez = x - pbx, y - pby, z - -depth
        d_bot = ex * ex + ey * ey + ez * ez
        bound = d_bot
        # the flange: from the opening's boundary out to its outer edge
        pfx = pfy = s_fl = 0.0
        d_fl = math.inf
        if fw > 0.0:
            cix, ciy, sdo = _rr_abs(ax, ay, prm[OX], prm[OY], prm[ORC])
            pfx = math.copysign(cix, x) if sdo < 0.0 else x
            pfy = math.copysign(ciy, y) if sdo < 0.0 else y
            if sdo > fw:
                cox, coy, _ = _rr_abs(ax, ay, prm[OXF], prm[OYF], prm[ORCF])
                pfx, pfy = math.copysign(cox, x), math.copysign(coy, y)
            c = sdo if sdo > 0.0 else 0.0
            c = c if c < fw else fw
            s_fl = -c
            ex, ey, ez = x - pfx, y - pfy, z - 0.0
            d_fl = ex * ex + ey * ey + ez * ez
            bound = bound if bound < d_fl else d_fl
        bound_r = math.sqrt(bound)
        best = best_r = math.inf
        win = -1
        fx = fy = fz = nx = ny = nz = al = ss = 0.0
        # the walls: the exact closest point of each convex polygon, in its own frame
        for w in range(walls.shape[0]):
            yx, yy, yz = x - walls[w, WO], y - walls[w, WO + 1], z - walls[w, WO + 2]
            h = yx * walls[w, WN] + yy * walls[w, WN + 1] + yz * walls[w, WN + 2]
            # sqrt(min(bound, best)), as numpy's: sqrt is monotone and correctly rounded
            limr = bound_r if bound_r < best_r else best_r
            if not (abs(h) <= limr * (1 + 1e-9) + 2 * TIE):
                continue
            u = yx * walls[w, WE1] + yy * walls[w, WE1 + 1] + yz * walls[w, WE1 + 2]
            v = yx * walls[w, WE2] + yy * walls[w, WE2 + 1] + yz * walls[w, WE2 + 2]
            m = nv[w]
            # inside the polygon (left of every edge): the projection itself; else the nearest
            # of its edges' closest points (the first of equals)
            inside = True
            for i in range(m):
                j = i + 1 if i + 1 < m else 0
                a0, a1 = uv[w, i, 0], uv[w, i, 1]
                eu, ev = uv[w, j, 0] - a0, uv[w, j, 1] - a1
                if not ((v - a1) * eu - (u - a0) * ev >= 0.0):
                    inside = False
                    break
            bu, bv = u, v
            if not inside:
                bd = math.inf
                for i in range(m):
                    j = i + 1 if i + 1 < m else 0
                    a0, a1 = uv[w, i, 0], uv[w, i, 1]
                    eu, ev = uv[w, j, 0] - a0, uv[w, j, 1] - a1
                    du, dv = u - a0, v - a1
                    t = (du * eu + dv * ev) / (eu * eu + ev * ev)
                    t = t if t > 0.0 else 0.0
                    t = t if t < 1.0 else 1.0
                    cu, cv = t * eu + a0, t * ev + a1
                    gu, gv = u - cu, v - cv
                    d2 = gu * gu + gv * gv
                    if d2 < bd:
                        bd, bu, bv = d2, cu, cv
            px = bu * walls[w, WE1] + walls[w, WO] + bv * walls[w, WE2]
            py = bu * walls[w, WE1 + 1] + walls[w, WO + 1] + bv * walls[w, WE2 + 1]
            pz = bu * walls[w, WE1 + 2] + walls[w, WO + 2] + bv * walls[w, WE2 + 2]
            ex, ey, ez = x - px, y - py, z - pz
            d = ex * ex + ey * ey + ez * ez
            if not (d < best):  # (needed for the next, which implies it)
                continue
            dr = math.sqrt(d)
            if dr < best_r - TIE:
                best, best_r, win, fx, fy, fz = d, dr, 1, px, py, pz
                nx, ny, nz = walls[w, WN], walls[w, WN + 1], walls[w, WN + 2]
                al, ss = walls[w, WA], -pz / walls[w, WSA]
        # the corner cones (one wall angle): apex below each corner's centre
        if prm[HC] > 0.0:
            for ix in range(2):
                sx = 1.0 if ix == 0 else -1.0
                ccx = prm[CXP] if ix == 0 else prm[CXM]
                if not ((x - ccx) * sx >= 0.0):
                    continue
                for iy in range(2):
                    sy = 1.0 if iy == 0 else -1.0
                    ccy = prm[CYP] if iy == 0 else prm[CYM]
                    if not ((y - ccy) * sy >= 0.0):
                        continue
                    vx, vy = x - ccx, y - ccy
                    r = math.hypot(vx, vy)
                    ux = vx / r if r > 0.0 else sx * prm[ISQ2]
                    uy = vy / r if r > 0.0 else sy * prm[ISQ2]
                    t = ((r - prm[R0]) * prm[DR] + z * prm[DZ]) / prm[L2]
                    t = t if t > 0.0 else 0.0
                    t = t if t < 1.0 else 1.0
                    rp = prm[R0] + t * prm[DR]
                    px, py, pz = ccx + rp * ux, ccy + rp * uy, t * prm[DZ]
                    ex, ey, ez = x - px, y - py, z - pz
                    d = ex * ex + ey * ey + ez * ez
                    if not (d < best):
                        continue
                    dr = math.sqrt(d)
                    if dr < best_r - TIE:
                        best, best_r, win, fx, fy, fz = d, dr, 1, px, py, pz
                        nx, ny, nz = prm[CA_MSIN] * ux, prm[CA_MSIN] * uy, prm[CA_COS]
                        al, ss = prm[CA], -pz / prm[CA_SIN]
        r_bot = math.sqrt(d_bot)
        if r_bot < best_r - TIE:
            best, best_r, win, fx, fy, fz = d_bot, r_bot, 2, pbx, pby, -depth
            nx, ny, nz, al, ss = 0.0, 0.0, 1.0, 0.0, s_bot
        r_fl = math.sqrt(d_fl)
        if fw > 0.0 and r_fl < best_r - TIE:
            best, best_r, win, fx, fy, fz = d_fl, r_fl, 0, pfx, pfy, 0.0
            nx, ny, nz, al, ss = 0.0, 0.0, 1.0, 0.0, s_fl
        if win < 0:
            fx = fy = fz = nx = ny = nz = al = ss = 0.0
        foot[k, 0], foot[k, 1], foot[k, 2] = fx, fy, fz
        normal[k, 0], normal[k, 1], normal[k, 2] = nx, ny, nz
        dd = best_r
        ex, ey, ez = x - fx, y - fy, z - fz
        dist[k] = -dd if ex * nx + ey * ny + ez * nz < 0.0 else dd
        alpha[k], s[k] = al, ss
        region[k] = 0 if win < 0 else codes[win]


def closest(X: F64, packed: Packed) -> tuple[F64, F64, F64, F64, F64, I64]:
    """Closest point of each of ``X`` (N, 3) [m, finite] on the packed pyramid (:func:`pack`):
    foot (N, 3) m, tool-side normal (N, 3), signed distance (N,) m, wall angle (N,) rad, the
    distance ``s`` along the wall (N,) m (as :class:`~roboisf.parts.SurfaceQuery`), region code
    (N,)."""
    lib = _c()
    # the C form reads X through its strides; numba's gets it C-contiguous
    X = np.asarray(X, dtype=np.float64) if lib is not None else np.ascontiguousarray(X, np.float64)
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(f"X: (N, 3) points expected, got {X.shape}")
    prm, walls, uv = (np.ascontiguousarray(a, dtype=np.float64) for a in packed[:3])
    nv, codes = (np.ascontiguousarray(a, dtype=np.int64) for a in packed[3:])
    nw = walls.shape[0]
    if (
        prm.shape != (NPRM,)
        or walls.shape != (nw, NWALL)
        or uv.shape != (nw, MAX_VERTICES, 2)
        or nv.shape != (nw,)
        or codes.shape != (3,)
    ):
        raise ValueError("packed: the arrays of pack() expected")
    if nw and (nv.min() < 2 or nv.max() > MAX_VERTICES):
        raise ValueError(f"packed: a wall polygon needs 2 to {MAX_VERTICES} vertices")
    n = X.shape[0]
    foot, normal, dist, alpha, s, region = query_buffers(n)
    if lib is None:
        _closest(X, prm, walls, uv, nv, codes, foot, normal, dist, alpha, s, region)
        return foot, normal, dist, alpha, s, region
    rs, cs = (v // X.itemsize for v in X.strides)
    lib.closest(
        X.ctypes.data, n, rs, cs, prm.ctypes.data, walls.ctypes.data, uv.ctypes.data,
        nv.ctypes.data, nw, codes.ctypes.data, foot.ctypes.data, normal.ctypes.data,
        dist.ctypes.data, alpha.ctypes.data, s.ctypes.data, region.ctypes.data,
    )  # fmt: skip
    return foot, normal, dist, alpha, s, region


def build() -> None:
    """Compile (and so cache) the kernel through its caller, on a pyramid with rounded corners
    and one with sharp corners and two wall angles: part of the background builder's group
    "mesh" (:mod:`roboisf.jit.background`)."""
    from roboisf.parts.pyramid import Pyramid

    P = np.random.default_rng(0).uniform(-0.1, 0.1, (64, 3))
    for part in (Pyramid(), Pyramid(wall_angle_y=math.radians(50.0), corner_radius=0.0)):
        part.closest_point(P, backend="numba")
