"""Compiled exact closest point on an axisymmetric part's generatrix. Two compiled forms, the
same bits: C (``axisym_kernel.c``, built at install, called through :mod:`roboisf.jit.native` —
no numba in the process) when it is built and fresh, else numba (built at install:
:mod:`roboisf.jit.prebuild`; tests/test_native_axisym.py compares them).

The numpy query of :meth:`~roboisf.parts.AxisymmetricPart.closest_point` builds some twenty
temporaries per point (its primitives' closest points, ``np.where`` merges, the 3-D feet and
normals): on the paper cone's 2 M-point scans it was the analysis's largest single cost after the
outlier filter (three passes — registration, classification, deviations — ~2 CPU-s per
``roboisf analyze``). This kernel is the same algorithm in one pass per point:

1. the meridian coordinates ``r = sqrt(x² + y²)`` and the direction ``(cos φ, sin φ) = (x, y)/r``
   (``(1, 0)`` on the axis, where numpy's ``arctan2(0, 0) = 0`` gives the same);
2. every primitive's closest point in the (r, z) half-plane (a segment: the clamped projection;
   an arc: the radial projection, clamped to its angle range), wall primitives first, a later
   one taken only when nearer by more than 1e-12 m (the numpy query's tie rule: a ball at a
   concave corner touches the wall);
3. the foot, the tool-side normal ``(−sin α cos φ, −sin α sin φ, cos α)`` (a segment's
   ``sin α``, ``cos α`` computed once per query, not per point), the signed distance, wall
   angle, depth, arc length and region code.

Its numbers equal the numpy query's to rounding (``sqrt`` for numpy's ``hypot``, the direction
from ``(x, y)/r`` instead of ``cos(arctan2(y, x))``: an ulp; tests/test_parts.py checks every
field to 1e-12, tests/test_jit.py the dispatch). 44 ns a point on the cone against numpy's 350
(85 against 420 on the VWACF, one arc; one core, chunks of 65 536 points). The
kernel is serial and releases the GIL (numba's ``nogil``; :mod:`ctypes` releases it for a C
call): :func:`roboisf.scan.point_deviations` runs it on threads, chunk by chunk.
"""

from __future__ import annotations

import ctypes
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, njit
from roboisf.parts.axisymmetric import query_buffers

if TYPE_CHECKING:
    from roboisf.parts.generatrix import Generatrix

__all__ = ["build", "closest", "pack"]

if HAVE_NUMBA:
    compile_notice(__file__)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Primitive kinds of the packed generatrix.
SEGMENT, ARC = 0, 1

_P, _I = ctypes.c_void_p, ctypes.c_int64

#: The C functions of ``axisym_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    "closest": (ctypes.c_int, [_P, _I, _I, _I, _P, _P, _P, _P, _I, _P, _I, _P, _P, _P, _P, _P, _P]),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernel serves)."""
    return native.library(__name__, SIGNATURES)


def pack(g: Generatrix, region_codes: dict[str, int]) -> tuple[I64, F64, F64, I64, I64]:
    """The generatrix ``g`` as arrays for :func:`closest`: ``kind`` (P,) (0 segment, 1 arc),
    ``par`` (P, 8) (a segment: r0, z0, r1, z1, its length, wall angle α, −sin α, cos α — its
    tool-side normal in (r, z); an arc: rc, zc, radius, β0, β1), ``s0`` (P,) m (arc length of
    each primitive's start from the top of the wall), ``code`` (P,) region codes and
    ``order`` (P,): the primitives' visiting order, wall first."""
    from roboisf.parts.generatrix import Arc

    n = len(g.primitives)
    kind = np.zeros(n, dtype=np.int64)
    par = np.zeros((n, 8))
    for i, p in enumerate(g.primitives):
        if isinstance(p, Arc):
            kind[i] = ARC
            par[i, :5] = (p.rc, p.zc, p.radius, p.beta0, p.beta1)
        else:
            a = p.wall_angle
            par[i] = (p.r0, p.z0, p.r1, p.z1, p.length, a, -math.sin(a), math.cos(a))
    code = np.array([region_codes[x] for x in g.regions], dtype=np.int64)
    order = np.array(sorted(range(n), key=lambda i: g.regions[i] != "wall"), dtype=np.int64)
    return kind, par, np.asarray(g._s0, dtype=float), code, order


@njit()
def _closest(
    X: F64,
    kind: I64,
    par: F64,
    s0: F64,
    code: I64,
    order: I64,
    foot: F64,
    normal: F64,
    dist: F64,
    alpha: F64,
    s: F64,
    region: I64,
) -> None:  # pragma: no cover - compiled
    for k in range(X.shape[0]):
        x, y, z = X[k, 0], X[k, 1], X[k, 2]
        r = math.sqrt(x * x + y * y)
        if r > 0.0:
            c, sn = x / r, y / r
        else:
            c, sn = 1.0, 0.0
        best = math.inf
        rp = zp = al = ss = nr = 0.0
        nz = 1.0
        idx = 0
        for j in range(order.size):
            i = order[j]
            if kind[i] == 0:
                r0, z0, r1, z1 = par[i, 0], par[i, 1], par[i, 2], par[i, 3]
                dr, dz = r1 - r0, z1 - z0
                u = ((r - r0) * dr + (z - z0) * dz) / (dr * dr + dz * dz)
                u = min(max(u, 0.0), 1.0)
                cr, cz = r0 + u * dr, z0 + u * dz
                d = math.sqrt((cr - r) ** 2 + (cz - z) ** 2)
                if d < best - 1e-12:
                    best, rp, zp, ss, idx = d, cr, cz, u * par[i, 4] + s0[i], i
                    al, nr, nz = par[i, 5], par[i, 6], par[i, 7]
            else:
                rc, zc, rho, b0, b1 = par[i, 0], par[i, 1], par[i, 2], par[i, 3], par[i, 4]
                ur, uz = r - rc, z - zc
                beta = math.atan2(-ur, uz) if ur != 0.0 or uz != 0.0 else b0
                beta = min(max(beta, b0), b1)
                sb, cb = math.sin(beta), math.cos(beta)
                cr, cz = rc - rho * sb, zc + rho * cb
                d = math.sqrt((cr - r) ** 2 + (cz - z) ** 2)
                if d < best - 1e-12:
                    best, rp, zp, ss, idx = d, cr, cz, (beta - b0) * rho + s0[i], i
                    al, nr, nz = beta, -sb, cb
        foot[k, 0], foot[k, 1], foot[k, 2] = rp * c, rp * sn, zp
        normal[k, 0], normal[k, 1], normal[k, 2] = nr * c, nr * sn, nz
        dd = math.sqrt((r - rp) ** 2 + (z - zp) ** 2)
        dist[k] = -dd if (r - rp) * nr + (z - zp) * nz < 0.0 else dd
        alpha[k], s[k], region[k] = al, ss, code[idx]


def closest(X: F64, packed: tuple[I64, F64, F64, I64, I64]) -> tuple[F64, F64, F64, F64, F64, I64]:
    """Closest point of each of ``X`` (N, 3) [m] on the packed generatrix (:func:`pack`):
    foot (N, 3) m, tool-side normal (N, 3), signed distance (N,) m, wall angle (N,) rad, arc
    length (N,) m, region code (N,)."""
    lib = _c()
    # the C form reads X through its strides; numba's gets it C-contiguous, as before
    X = np.asarray(X, dtype=np.float64) if lib is not None else np.ascontiguousarray(X, np.float64)
    n = X.shape[0]
    foot, normal, dist, alpha, s, region = query_buffers(n)
    if lib is None:
        _closest(X, *packed, foot, normal, dist, alpha, s, region)
        return foot, normal, dist, alpha, s, region
    if X.ndim != 2 or X.shape[1] < 3:
        raise ValueError(f"X: (N, 3) points expected, got {X.shape}")
    kind, par, s0, code, order = (
        np.ascontiguousarray(packed[0], dtype=np.int64),
        np.ascontiguousarray(packed[1], dtype=np.float64),
        np.ascontiguousarray(packed[2], dtype=np.float64),
        np.ascontiguousarray(packed[3], dtype=np.int64),
        np.ascontiguousarray(packed[4], dtype=np.int64),
    )
    m = kind.shape[0]
    if par.shape != (m, 8) or s0.shape != (m,) or code.shape != (m,) or order.ndim != 1:
        raise ValueError("packed: the arrays of pack() expected")
    if order.size and (order.min() < -m or order.max() >= m):
        raise IndexError("packed: a primitive index out of range")
    if n and m == 0:
        raise ValueError("packed: a generatrix without primitives")
    rs, cs = (v // X.itemsize for v in X.strides)
    err = lib.closest(
        X.ctypes.data, n, rs, cs, kind.ctypes.data, par.ctypes.data, s0.ctypes.data,
        code.ctypes.data, m, order.ctypes.data, order.size, foot.ctypes.data, normal.ctypes.data,
        dist.ctypes.data, alpha.ctypes.data, s.ctypes.data, region.ctypes.data,
    )  # fmt: skip
    if err:
        raise ZeroDivisionError("float division by zero")
    return foot, normal, dist, alpha, s, region


def build() -> None:
    """Compile (and so cache) the kernel through its caller, on a cone and a VWACF (segments
    and arcs): part of the background builder's group "mesh" (:mod:`roboisf.jit.background`)."""
    from roboisf.parts.axisymmetric import VWACF, Cone

    P = np.random.default_rng(0).uniform(-0.1, 0.1, (64, 3))
    for part in (Cone(), VWACF()):
        part.closest_point(P, backend="numba")
