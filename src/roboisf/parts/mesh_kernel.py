"""Compiled exact closest-triangle query for :class:`~roboisf.parts.MeshPart`, and the compiled
passes over a scan's points (bounds, Morton order, row gather and scatter).

Two compiled forms, the same bits: C (``mesh_kernel.c``, built at install, called through
:mod:`roboisf.jit.native` — no numba in the process) when it is built and fresh, else numba
(built at install: :mod:`roboisf.jit.prebuild`; tests/test_native_mesh.py compares them). When
neither serves (``ROBOISF_NUMBA=0`` and no C form) ``MeshPart`` falls back to its pure numpy
k-d-tree query, which gives the same answers, ~3× slower.

Algorithm (exact):

1. a uniform grid of cubic cells of side ``h`` (:data:`CELL_EDGES` mean triangle edges) over
   the mesh's bounding box; every triangle is listed in each cell its axis-aligned bounding
   box overlaps (compressed rows: ``start``, ``items``). The closest point of a triangle to any
   query lies in the triangle, hence in its box, hence in a cell that lists the triangle;
2. a triangle of a visited cell is skipped when a lower bound of its distance exceeds the best
   so far: with ``h`` the distance to the triangle's plane and ``q`` the in-plane distance to
   its centroid, every point of the triangle is at least ``sqrt(h² + max(0, q − ρ)²)`` away
   (ρ: its bounding radius around the centroid). The others are evaluated exactly (Ericson
   §5.1.5, the same formula as :func:`~roboisf.parts.mesh.point_triangle_distance2`);
3. seeding: the points come in spatial order (:func:`~roboisf.parts.mesh.spatial_order`), so
   the previous point's closest triangle is a close upper bound ``r`` for this point's
   distance. Every nearer triangle has its closest point in the ball of radius ``r``, hence in
   a cell meeting the ball's box: those cells are all that is searched (when ``r ≤ 2h``);
4. otherwise (the first point, or a seed farther than ``2h``), the cells are visited in
   Chebyshev rings ``R = 0, 1, …`` around the cell of ``p`` (clamped into the grid), a cell
   farther from ``p`` than the best distance so far skipped. After ring ``R`` every triangle
   not yet seen has its closest point in a cell outside the cube of rings ``0..R``: at least
   the distance from ``p`` to (grid box − cube) away (exact distance to the ≤ 6 slabs). The
   search stops when the best distance is smaller;
5. a point still unresolved after :data:`MAX_RINGS` rings is far from the surface (the ring
   search would grow as R³): it finishes with a depth-first walk of a bounding-volume
   hierarchy (Morton-ordered leaves of 8 triangles, nearer child first, a node skipped when
   its box is farther than the best so far), starting from the best found in the grid.

The answer is canonical: the triangle with the smallest computed distance, the lowest index
among equal ones (every pruning test keeps a relative 1e-12 rounding margin, so no triangle at
the minimum is skipped). It therefore does not depend on the seed, the cell size, the order or
the chunking of the queries: a brute force over all triangles with ``argmin`` gives the same
face, bit for bit (tests/test_mesh_closest.py).

The kernel is serial and releases the GIL (numba's ``nogil``; :mod:`ctypes` releases it for a
C call): :meth:`MeshPart.closest_faces` and :func:`roboisf.scan.point_deviations` run it on
several threads. (A ``parallel=True`` kernel called from several Python threads would need a
thread-safe numba threading layer.)
"""

from __future__ import annotations

import ctypes
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, njit

__all__ = [
    "HAVE_NUMBA",
    "bounds",
    "build",
    "build_grid",
    "closest_grid",
    "fresh_rows",
    "gather_rows",
    "morton_order",
    "scatter_rows",
]

if HAVE_NUMBA:
    compile_notice(__file__)  # numba compiles these on first call: say so once

#: Digit width of the Morton codes' radix sort (6 passes for 48-bit codes). 8 bits: a pass's
#: 256 output runs stay in the first-level cache; 12 bits (4 passes of 4096 runs) took 91-98 ms
#: against 67-73 ms for the 2 M points of a paper cone scan (the codes included, one core; 7
#: bits 76 ms, 9 bits 80 ms, 16 bits 90-96 ms). Any width gives the same stable order.
RADIX_BITS = 8

#: Grid cell side in mean triangle edges.
CELL_EDGES = 3.0

#: Largest number of grid cells (bounds the grid's memory to ~130 MB of int64 row starts).
MAX_CELLS = 16_000_000


_njit = njit

_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: The C functions of ``mesh_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    "bounds": (None, [_P, _I, _I, _I, _P, _I, _P, _P]),
    "gather_rows": (None, [_P, _I, _I, _I, _P, _I, _P, _I, _I, _I, _P]),
    "scatter_rows": (None, [_P, _I, _I, _P, _I, _I, _I, _P, _I]),
    "morton_order": (_I, [_P, _I, _I, _I, _P, _D, _I, _P, _P, _I, _P, _P]),
    "fill_grid_count": (_I, [_P, _P, _I, _P, _D, _P, _P, _P]),
    "fill_grid_items": (None, [_P, _I, _P, _P, _P]),
    "closest_grid": (
        ctypes.c_int,
        [
            *(_P, _I, _I, _I, _P, _D, _P, _P, _P, _P, _P, _P, _P, _P, _P, _P, _I),
            *(_P, _P, _P, _I, _I, _I, _D, _I, _P, _I, _P, _I, _P, _I, _I),
        ],
    ),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


def _strides(a: NDArray[Any]) -> tuple[int, ...]:
    """``a``'s strides in elements (views of whole elements: always exact)."""
    return tuple(s // a.itemsize for s in a.strides)


def _typed(a: Any, dtype: Any, name: str, ndim: int, cols: int | None = None) -> NDArray[Any]:
    """``a`` checked for the C form: a numpy array of exactly ``dtype``, ``ndim`` dimensions
    (``cols`` columns at least); no copy."""
    if not isinstance(a, np.ndarray) or a.dtype != dtype or a.ndim != ndim:
        got = f"{a.dtype} {a.ndim}-d" if isinstance(a, np.ndarray) else type(a).__name__
        raise TypeError(f"{name}: {np.dtype(dtype)} {ndim}-d array expected, got {got}")
    if cols is not None and a.shape[1] < cols:
        raise ValueError(f"{name}: at least {cols} columns expected, got {a.shape}")
    return a


def _dense(a: Any, dtype: Any, name: str, shape: tuple[int | None, ...]) -> NDArray[Any]:
    """``a`` as a C-contiguous array of exactly ``dtype`` and ``shape`` (None: any length) for
    the C form: a mesh's or grid's own array (contiguous already: no copy), else a copy."""
    a = np.ascontiguousarray(_typed(a, dtype, name, len(shape)))
    if any(w is not None and w != g for w, g in zip(shape, a.shape, strict=True)):
        raise ValueError(f"{name}: shape {shape} expected, got {a.shape}")
    return a


def _index(a: Any, name: str) -> tuple[NDArray[Any], int]:
    """An index array (1-D, any integer type) for the C form: int32 or int64 as it is (strided
    or not), another integer type as int64 (the same values); and its element size."""
    if not isinstance(a, np.ndarray) or a.ndim != 1 or a.dtype.kind not in "iu":
        raise TypeError(f"{name}: a 1-d integer array expected")
    if a.dtype != np.int32 and a.dtype != np.int64:
        a = a.astype(np.int64)
    return a, a.itemsize


@_njit()
def _fill_grid(
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    origin: NDArray[np.float64],
    h: float,
    dims: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int32]]:
    n_tri = lo.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    rng = np.empty((n_tri, 6), dtype=np.int64)
    count = np.zeros(nx * ny * nz + 1, dtype=np.int64)
    for t in range(n_tri):
        for ax in range(3):
            n = dims[ax]
            i0 = math.floor((lo[t, ax] - origin[ax]) / h)
            i1 = math.floor((hi[t, ax] - origin[ax]) / h)
            rng[t, 2 * ax] = min(max(i0, 0), n - 1)
            rng[t, 2 * ax + 1] = min(max(i1, 0), n - 1)
        for i in range(rng[t, 0], rng[t, 1] + 1):
            for j in range(rng[t, 2], rng[t, 3] + 1):
                for k in range(rng[t, 4], rng[t, 5] + 1):
                    count[(i * ny + j) * nz + k + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    items = np.empty(start[-1], dtype=np.int32)
    for t in range(n_tri):
        for i in range(rng[t, 0], rng[t, 1] + 1):
            for j in range(rng[t, 2], rng[t, 3] + 1):
                for k in range(rng[t, 4], rng[t, 5] + 1):
                    c = (i * ny + j) * nz + k
                    items[fill[c]] = t
                    fill[c] += 1
    return start, items


def build_grid(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64], order: Any
) -> Any:
    """Index ``(origin (3,), h, dims (3,), start, items, bvh)`` of triangles ``a, b, c`` (F, 3):
    the grid and the far-point BVH (:func:`build_bvh`, ``order`` a Morton order of the
    triangles' centroids).

    The cell side is 3× the mean triangle edge (a few dozen triangles per occupied cell; 2.5–4×
    are within 15 % of each other on the benchmark),
    enlarged if the grid would exceed :data:`MAX_CELLS` cells.
    """
    lo = np.minimum(np.minimum(a, b), c)
    hi = np.maximum(np.maximum(a, b), c)
    g_lo, g_hi = lo.min(axis=0), hi.max(axis=0)
    span = np.maximum(g_hi - g_lo, 1e-12)
    edge = float(np.mean(np.linalg.norm(b - a, axis=1) + np.linalg.norm(c - b, axis=1))) / 2
    h = max(CELL_EDGES * edge, float(span.max()) * 1e-6)
    while np.prod(np.floor(span / h) + 1) > MAX_CELLS:
        h *= 1.25
    dims = (np.floor(span / h) + 1).astype(np.int64)
    start, items = _grid_rows(lo, hi, g_lo.astype(np.float64), h, dims)
    return g_lo.astype(np.float64), float(h), dims, start, items, build_bvh(a, b, c, order)


def _grid_rows(
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    origin: NDArray[np.float64],
    h: float,
    dims: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int32]]:
    """The grid's compressed rows ``(start, items)`` of the triangles' boxes ``lo, hi`` (F, 3)
    (:func:`_fill_grid`; in C in two passes, the counts then the items)."""
    lib = _c()
    if lib is None:
        return _fill_grid(lo, hi, origin, h, dims)
    lo = _dense(lo, np.float64, "lo", (None, 3))
    hi = _dense(hi, np.float64, "hi", (lo.shape[0], 3))
    origin = _dense(origin, np.float64, "origin", (3,))
    dims = _dense(dims, np.int64, "dims", (3,))
    if not h > 0.0:
        raise ZeroDivisionError("float division by zero")
    n_tri = lo.shape[0]
    rng = np.empty((n_tri, 6), dtype=np.int64)
    start = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
    d = dims.ctypes.data
    total = lib.fill_grid_count(
        lo.ctypes.data, hi.ctypes.data, n_tri, origin.ctypes.data, float(h), d,
        rng.ctypes.data, start.ctypes.data,
    )  # fmt: skip
    items = np.empty(total, dtype=np.int32)
    lib.fill_grid_items(rng.ctypes.data, n_tri, d, start.ctypes.data, items.ctypes.data)
    return start, items


#: Triangles per leaf of the far-point BVH.
LEAF = 8
#: Rings searched in the grid before a point switches to the BVH (far from the surface).
MAX_RINGS = 3


def build_bvh(
    a: NDArray[np.float64], b: NDArray[np.float64], c: NDArray[np.float64], order: Any
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int32], int]:
    """Implicit bounding-volume hierarchy for points far from the surface.

    Triangles in ``order`` (a Morton order of their centroids), :data:`LEAF` per leaf, leaves
    padded to a power of two ``P``; a complete binary tree in heap layout (children of node
    ``i`` are ``2i + 1, 2i + 2``, leaves are nodes ``P − 1 … 2P − 2``). Returns node box corners
    ``lo, hi (2P − 1, 3)``, leaf slots ``tri (P·LEAF,)`` (−1 = padding) and ``P``.
    """
    F = order.size
    P = 1 << max(0, math.ceil(math.log2(max(1, math.ceil(F / LEAF)))))
    tri = np.full(P * LEAF, -1, dtype=np.int32)
    tri[:F] = order
    blo = np.full((P * LEAF, 3), np.inf)
    bhi = np.full((P * LEAF, 3), -np.inf)
    blo[:F] = np.minimum(np.minimum(a, b), c)[order]
    bhi[:F] = np.maximum(np.maximum(a, b), c)[order]
    nlo = np.empty((2 * P - 1, 3))
    nhi = np.empty((2 * P - 1, 3))
    nlo[P - 1 :] = blo.reshape(P, LEAF, 3).min(axis=1)
    nhi[P - 1 :] = bhi.reshape(P, LEAF, 3).max(axis=1)
    first, n = P - 1, P
    while n > 1:  # one level up: union of the two children
        up = first - n // 2
        nlo[up:first] = np.minimum(nlo[first : first + n : 2], nlo[first + 1 : first + n : 2])
        nhi[up:first] = np.maximum(nhi[first : first + n : 2], nhi[first + 1 : first + n : 2])
        first, n = up, n // 2
    return nlo, nhi, tri, P


@_njit()
def _node_d2(px: float, py: float, pz: float, lo: Any, hi: Any, i: int) -> float:
    s = 0.0
    for ax, q in ((0, px), (1, py), (2, pz)):
        if q < lo[i, ax]:
            s += (lo[i, ax] - q) ** 2
        elif q > hi[i, ax]:
            s += (q - hi[i, ax]) ** 2
    return s


@_njit()
def _box_d2(p: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]) -> float:
    s = 0.0
    for ax in range(3):
        if p[ax] < lo[ax]:
            s += (lo[ax] - p[ax]) ** 2
        elif p[ax] > hi[ax]:
            s += (p[ax] - hi[ax]) ** 2
    return s


@_njit()
def _tri_d2(
    px: float,
    py: float,
    pz: float,
    t: int,
    a: NDArray[np.float64],
    ab: NDArray[np.float64],
    ac: NDArray[np.float64],
    abab: NDArray[np.float64],
    abac: NDArray[np.float64],
    acac: NDArray[np.float64],
) -> tuple[float, float, float]:
    """Scalar twin of ``point_triangle_distance2`` (same regions, same order, same formula)."""
    apx, apy, apz = px - a[t, 0], py - a[t, 1], pz - a[t, 2]
    d1 = ab[t, 0] * apx + ab[t, 1] * apy + ab[t, 2] * apz
    d2 = ac[t, 0] * apx + ac[t, 1] * apy + ac[t, 2] * apz
    s_abab, s_abac, s_acac = abab[t], abac[t], acac[t]
    d3 = d1 - s_abab
    d4 = d2 - s_abac
    d5 = d1 - s_abac
    d6 = d2 - s_acac
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    # an edge's region only for an edge of non-zero length, the face only for a non-zero
    # area: a triangle with two equal vertices (a mesh file's duplicate vertex) divided 0 by 0
    if d1 <= 0 and d2 <= 0:
        v, w = 0.0, 0.0
    elif d3 >= 0 and d4 <= d3:
        v, w = 1.0, 0.0
    elif vc <= 0 and d1 >= 0 and d3 <= 0 and d1 - d3 > 0:
        v, w = d1 / (d1 - d3), 0.0
    elif d6 >= 0 and d5 <= d6:
        v, w = 0.0, 1.0
    elif vb <= 0 and d2 >= 0 and d6 <= 0 and d2 - d6 > 0:
        v, w = 0.0, d2 / (d2 - d6)
    elif va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0 and (d4 - d3) + (d5 - d6) > 0:
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        v, w = 1.0 - t_bc, t_bc
    elif va + vb + vc != 0:
        den = va + vb + vc
        v, w = vb / den, vc / den
    else:  # no area and no edge region (rounding): vertex a, an upper bound of the distance
        v, w = 0.0, 0.0
    r = (
        (apx * apx + apy * apy + apz * apz)
        - 2.0 * (v * d1 + w * d2)
        + v * v * s_abab
        + 2.0 * v * w * s_abac
        + w * w * s_acac
    )
    return max(r, 0.0), v, w


@_njit()
def _scan(
    ids: NDArray[np.int32],
    s: int,
    e: int,
    px: float,
    py: float,
    pz: float,
    tri: Any,
    bnd: NDArray[np.float64],
    tol2: float,
    best2: float,
    bf: int,
    bv: float,
    bw: float,
) -> tuple[float, int, float, float]:
    """Update the best ``(d², face, v, w)`` with triangles ``ids[s:e]`` (a −1 ends the list).

    A triangle is skipped when a lower bound of its distance exceeds the best by more than the
    rounding margin (so that every triangle at the final minimum is evaluated: ties go to the
    lowest index, whatever the order of the search): first its bounding sphere, then, with
    ``h`` the distance from ``p`` to the triangle's plane and ``q`` the in-plane distance to
    its centroid, every point of the triangle is at least ``sqrt(h² + max(0, q − ρ)²)`` away
    (it lies in its plane within ρ of the centroid; for a zero-area triangle the normal is 0
    and this is the bounding sphere).
    The others are evaluated exactly; exact ties go to the lower index.
    """
    a, ab, ac, abab, abac, acac = tri
    # bounding-sphere test first (no square root per triangle): |p − c| − ρ > sb skips
    sb = math.sqrt(best2 * (1.0 + 1e-12) + tol2) * (1.0 + 1e-9)
    for q in range(s, e):
        t = ids[q]
        if t < 0:
            break
        dx = px - bnd[t, 0]
        dy = py - bnd[t, 1]
        dz = pz - bnd[t, 2]
        r2 = dx * dx + dy * dy + dz * dz
        if r2 > (sb + bnd[t, 3]) ** 2:
            continue
        hn = dx * bnd[t, 4] + dy * bnd[t, 5] + dz * bnd[t, 6]
        h2 = hn * hn
        lim = best2 + 1e-12 * (best2 + r2 + bnd[t, 7]) + tol2
        if h2 > lim:
            continue
        g = math.sqrt(max(r2 - h2, 0.0)) - bnd[t, 3]
        if g > 0.0 and h2 + g * g > lim:
            continue
        d2, v, w = _tri_d2(px, py, pz, t, a, ab, ac, abab, abac, acac)
        if d2 < best2 or (d2 == best2 and t < bf):
            best2, bf, bv, bw = d2, t, v, w
            sb = math.sqrt(best2 * (1.0 + 1e-12) + tol2) * (1.0 + 1e-9)
    return best2, bf, bv, bw


@_njit()
def _closest_grid(
    X: NDArray[np.float64],
    origin: NDArray[np.float64],
    h: float,
    dims: NDArray[np.int64],
    start: NDArray[np.int64],
    items: NDArray[np.int32],
    a: NDArray[np.float64],
    ab: NDArray[np.float64],
    ac: NDArray[np.float64],
    abab: NDArray[np.float64],
    abac: NDArray[np.float64],
    acac: NDArray[np.float64],
    bnd: NDArray[np.float64],
    nlo: NDArray[np.float64],
    nhi: NDArray[np.float64],
    leaf_tri: NDArray[np.int32],
    n_leaves: int,
    tol2: float,
    seed: bool,
    face: NDArray[np.int64],
    dist2: NDArray[np.float64],
    closest: NDArray[np.float64],
) -> None:
    """Exact closest triangle of each row of ``X`` (N, 3) [m]: fills ``face`` (N,), ``dist2``
    (N,) [m²] and ``closest`` (N, 3) [m] in place (see the module doc for the algorithm).

    ``bnd`` (F, 8): per triangle centroid (3) [m], bounding radius ρ [m], unit normal (3),
    ρ² [m²]; ``tol2`` [m²] the absolute rounding margin of the pruning tests. ``seed``: start
    each point from the previous point's closest triangle (the same answers; faster on points
    in spatial order).
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    tri = (a, ab, ac, abab, abac, acac)
    g_hi = np.empty(3)
    for ax in range(3):
        g_hi[ax] = origin[ax] + dims[ax] * h
    stack = np.empty(256, dtype=np.int64)
    sd = np.empty(256)
    cell = np.empty(3, dtype=np.int64)
    blo = np.empty(3)
    bhi = np.empty(3)
    p = np.empty(3)
    lo_i = np.empty(3, dtype=np.int64)
    hi_i = np.empty(3, dtype=np.int64)
    for n in range(X.shape[0]):
        px, py, pz = X[n, 0], X[n, 1], X[n, 2]
        p[0], p[1], p[2] = px, py, pz
        best2 = np.inf
        bf, bv, bw = -1, 0.0, 0.0
        done = False
        if seed and n > 0:
            # the previous point's triangle bounds this point's distance; every triangle
            # nearer than that has its closest point in a cell meeting the ball's box
            bf = face[n - 1]
            best2, bv, bw = _tri_d2(px, py, pz, bf, a, ab, ac, abab, abac, acac)
            r = math.sqrt(best2 + tol2) * (1.0 + 1e-9)
            if r <= 2.0 * h:
                for ax in range(3):
                    i0 = math.floor((p[ax] - r - origin[ax]) / h)
                    i1 = math.floor((p[ax] + r - origin[ax]) / h)
                    lo_i[ax] = min(max(i0, 0), dims[ax] - 1)
                    hi_i[ax] = min(max(i1, 0), dims[ax] - 1)
                for i in range(lo_i[0], hi_i[0] + 1):
                    for j in range(lo_i[1], hi_i[1] + 1):
                        for k in range(lo_i[2], hi_i[2] + 1):
                            c = (i * ny + j) * nz + k
                            s, e = start[c], start[c + 1]
                            if s == e:
                                continue
                            blo[0] = origin[0] + i * h
                            blo[1] = origin[1] + j * h
                            blo[2] = origin[2] + k * h
                            bhi[0], bhi[1], bhi[2] = blo[0] + h, blo[1] + h, blo[2] + h
                            if _box_d2(p, blo, bhi) > best2 * (1.0 + 1e-12) + tol2:
                                continue
                            best2, bf, bv, bw = _scan(
                                items, s, e, px, py, pz, tri, bnd, tol2, best2, bf, bv, bw
                            )
                done = True
        if not done:
            for ax in range(3):
                ci = math.floor((p[ax] - origin[ax]) / h) if math.isfinite(p[ax]) else 0
                cell[ax] = min(max(ci, 0), dims[ax] - 1)
            cx, cy, cz = cell[0], cell[1], cell[2]
            R = 0
            while True:
                i0, i1 = max(cx - R, 0), min(cx + R, nx - 1)
                j0, j1 = max(cy - R, 0), min(cy + R, ny - 1)
                k0, k1 = max(cz - R, 0), min(cz + R, nz - 1)
                for i in range(i0, i1 + 1):
                    for j in range(j0, j1 + 1):
                        if abs(i - cx) == R or abs(j - cy) == R:  # a side of the shell
                            ka, kb, ks = k0, k1 + 1, 1
                        else:  # inside the shell's x-y extent: only its two z faces
                            ka, kb, ks = cz - R, cz + R + 1, 2 * R
                        for k in range(ka, kb, ks):
                            if k < 0 or k >= nz:
                                continue
                            c = (i * ny + j) * nz + k
                            s, e = start[c], start[c + 1]
                            if s == e:
                                continue
                            blo[0], blo[1], blo[2] = (
                                origin[0] + i * h,
                                origin[1] + j * h,
                                origin[2] + k * h,
                            )
                            bhi[0], bhi[1], bhi[2] = blo[0] + h, blo[1] + h, blo[2] + h
                            if _box_d2(p, blo, bhi) > best2 * (1.0 + 1e-12) + tol2:
                                continue
                            best2, bf, bv, bw = _scan(
                                items, s, e, px, py, pz, tri, bnd, tol2, best2, bf, bv, bw
                            )
                # lower bound for every triangle outside the cube of rings 0..R: distance to
                # the part of the grid box outside the cube (≤ 6 slabs; empty ones skipped)
                lb2 = np.inf
                lo_c = (cx - R, cy - R, cz - R)
                hi_c = (cx + R, cy + R, cz + R)
                for ax in range(3):
                    for side in range(2):
                        if side == 0 and lo_c[ax] <= 0:
                            continue
                        if side == 1 and hi_c[ax] >= dims[ax] - 1:
                            continue
                        for bx in range(3):
                            blo[bx], bhi[bx] = origin[bx], g_hi[bx]
                        if side == 0:
                            bhi[ax] = origin[ax] + lo_c[ax] * h
                        else:
                            blo[ax] = origin[ax] + (hi_c[ax] + 1) * h
                        lb2 = min(lb2, _box_d2(p, blo, bhi))
                if lb2 == np.inf or best2 * (1.0 + 1e-12) + tol2 < lb2:
                    break
                R += 1
                if R > MAX_RINGS:  # far from the surface: finish with the BVH (exact as well)
                    stack[0], sd[0], top = 0, _node_d2(px, py, pz, nlo, nhi, 0), 1
                    while top > 0:
                        top -= 1
                        node = stack[top]
                        lim = best2 * (1.0 + 1e-12) + tol2
                        if sd[top] > lim:
                            continue
                        if node >= n_leaves - 1:  # a leaf
                            s = (node - (n_leaves - 1)) * LEAF
                            best2, bf, bv, bw = _scan(
                                leaf_tri, s, s + LEAF, px, py, pz, tri, bnd, tol2,
                                best2, bf, bv, bw,
                            )  # fmt: skip
                            continue
                        left = 2 * node + 1
                        dl = _node_d2(px, py, pz, nlo, nhi, left)
                        dr = _node_d2(px, py, pz, nlo, nhi, left + 1)
                        near, far, dn, df = left, left + 1, dl, dr
                        if dr < dl:
                            near, far, dn, df = left + 1, left, dr, dl
                        if df <= lim:  # pushed first: popped after the nearer child
                            stack[top], sd[top], top = far, df, top + 1
                        if dn <= lim:
                            stack[top], sd[top], top = near, dn, top + 1
                    break
        face[n] = bf
        dist2[n] = best2
        for ax in range(3):
            closest[n, ax] = a[bf, ax] + bv * ab[bf, ax] + bw * ac[bf, ax]


def closest_grid(
    X: NDArray[np.float64],
    origin: NDArray[np.float64],
    h: float,
    dims: NDArray[np.int64],
    start: NDArray[np.int64],
    items: NDArray[np.int32],
    a: NDArray[np.float64],
    ab: NDArray[np.float64],
    ac: NDArray[np.float64],
    abab: NDArray[np.float64],
    abac: NDArray[np.float64],
    acac: NDArray[np.float64],
    bnd: NDArray[np.float64],
    nlo: NDArray[np.float64],
    nhi: NDArray[np.float64],
    leaf_tri: NDArray[np.int32],
    n_leaves: int,
    tol2: float,
    seed: bool,
    face: NDArray[np.int64],
    dist2: NDArray[np.float64],
    closest: NDArray[np.float64],
) -> None:
    """Exact closest triangle of each row of ``X`` (N, 3) [m]: fills ``face`` (N,), ``dist2``
    (N,) [m²] and ``closest`` (N, 3) [m] in place (see the module doc for the algorithm).

    ``bnd`` (F, 8): per triangle centroid (3) [m], bounding radius ρ [m], unit normal (3),
    ρ² [m²]; ``tol2`` [m²] the absolute rounding margin of the pruning tests. ``seed``: start
    each point from the previous point's closest triangle (the same answers; faster on points
    in spatial order). ``origin, h, dims, start, items`` the grid and ``nlo, nhi, leaf_tri,
    n_leaves`` the BVH of :func:`build_grid`. C when built (:func:`_c`), else numba
    (:func:`_closest_grid`); both raise ZeroDivisionError where a degenerate input divides by
    zero.
    """
    lib = _c()
    if lib is None:
        _closest_grid(
            X, origin, h, dims, start, items, a, ab, ac, abab, abac, acac, bnd, nlo, nhi,
            leaf_tri, n_leaves, tol2, seed, face, dist2, closest,
        )  # fmt: skip
        return
    X = _typed(X, np.float64, "X", 2, 3)
    n = X.shape[0]
    face = _typed(face, np.int64, "face", 1)
    dist2 = _typed(dist2, np.float64, "dist2", 1)
    closest = _typed(closest, np.float64, "closest", 2, 3)
    if face.shape[0] < n or dist2.shape[0] < n or closest.shape[0] < n:
        raise ValueError("face, dist2, closest: a row for each point expected")
    if n == 0:
        return
    a = _dense(a, np.float64, "a", (None, 3))
    F = a.shape[0]
    if F == 0:
        raise ValueError("closest_grid: a mesh without triangles")
    ab = _dense(ab, np.float64, "ab", (F, 3))
    ac = _dense(ac, np.float64, "ac", (F, 3))
    abab = _dense(abab, np.float64, "abab", (F,))
    abac = _dense(abac, np.float64, "abac", (F,))
    acac = _dense(acac, np.float64, "acac", (F,))
    bnd = _dense(bnd, np.float64, "bnd", (F, 8))
    origin = _dense(origin, np.float64, "origin", (3,))
    dims = _dense(dims, np.int64, "dims", (3,))
    start = _dense(start, np.int64, "start", (int(np.prod(dims)) + 1,))
    items = _dense(items, np.int32, "items", (None,))
    n_leaves = int(n_leaves)
    nlo = _dense(nlo, np.float64, "nlo", (2 * n_leaves - 1, 3))
    nhi = _dense(nhi, np.float64, "nhi", (2 * n_leaves - 1, 3))
    leaf_tri = _dense(leaf_tri, np.int32, "leaf_tri", (n_leaves * LEAF,))
    xs0, xs1 = _strides(X)
    (fs,) = _strides(face)
    (ds,) = _strides(dist2)
    cs0, cs1 = _strides(closest)
    err = lib.closest_grid(
        X.ctypes.data, n, xs0, xs1, origin.ctypes.data, float(h), dims.ctypes.data,
        start.ctypes.data, items.ctypes.data, a.ctypes.data, ab.ctypes.data, ac.ctypes.data,
        abab.ctypes.data, abac.ctypes.data, acac.ctypes.data, bnd.ctypes.data, F,
        nlo.ctypes.data, nhi.ctypes.data, leaf_tri.ctypes.data, n_leaves, LEAF, MAX_RINGS,
        float(tol2), 1 if seed else 0, face.ctypes.data, fs, dist2.ctypes.data, ds,
        closest.ctypes.data, cs0, cs1,
    )  # fmt: skip
    if err:
        raise ZeroDivisionError("float division by zero")


def gather_rows(
    P: NDArray[np.float64], rows: NDArray[np.int64], order: NDArray[Any]
) -> NDArray[np.float64]:
    """``P[rows[order]]`` (``P[order]`` when ``rows`` is empty) of points (N, 3) as a new
    C-contiguous array, without the ``rows[order]`` index temporary, for ``order`` of any integer
    type (``np.take`` first copies int32 indices to int64: 16 MB and ~30 ms on 2 M points).

    The output is numpy's (:func:`fresh_rows`), filled by a compiled pass (C when built, else
    numba: :func:`_gather_rows_into`)."""
    out = fresh_rows(order.size)
    lib = _c()
    if lib is None:
        return _gather_rows_into(P, rows, order, out)
    P = _typed(P, np.float64, "P", 2, 3)
    rows = np.ascontiguousarray(_typed(rows, np.int64, "rows", 1))
    o, osz = _index(order, "order")
    ps0, ps1 = _strides(P)
    (os_,) = _strides(o)
    lib.gather_rows(
        P.ctypes.data, P.shape[0], ps0, ps1, rows.ctypes.data, rows.size, o.ctypes.data, osz,
        os_, o.size, out.ctypes.data,
    )  # fmt: skip
    return out


def fresh_rows(n: int) -> NDArray[np.float64]:
    """An uninitialised (n, 3) float64 array from numpy, for a compiled pass to fill: numpy asks
    Linux for transparent huge pages on large arrays (``madvise``), numba's own allocations
    (``np.empty`` inside a compiled function) get 4 KiB pages — one page fault per 4 KiB
    written, ~12 k faults for 2 M points against ~0.5 k (2026-11-29: the paper cone's
    ``analyze`` faulted ~180 k times, ~1 s of its CPU in the operating system)."""
    return np.empty((n, 3))


@_njit()
def _gather_rows_into(
    P: NDArray[np.float64], rows: NDArray[np.int64], order: NDArray[Any], out: NDArray[np.float64]
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """:func:`gather_rows` into ``out`` (N, 3)."""
    for i in range(order.size):
        r = rows[order[i]] if rows.size else order[i]
        out[i, 0] = P[r, 0]
        out[i, 1] = P[r, 1]
        out[i, 2] = P[r, 2]
    return out


def scatter_rows(Xs: NDArray[np.float64], order: NDArray[Any]) -> NDArray[np.float64]:
    """The points (N, 3) put back where ``order`` took them from: ``out[order[i]] = Xs[i]``,
    the inverse of :func:`gather_rows` (numpy's ``out[order] = Xs`` of rows: ~3x slower); the
    output numpy's (:func:`fresh_rows`); C when built, else numba (:func:`_scatter_rows_into`)."""
    out = fresh_rows(Xs.shape[0])
    lib = _c()
    if lib is None:
        return _scatter_rows_into(Xs, order, out)
    Xs = _typed(Xs, np.float64, "Xs", 2, 3)
    o, osz = _index(order, "order")
    if o.size > Xs.shape[0]:
        raise ValueError(f"order: at most {Xs.shape[0]} rows, got {o.size}")
    xs0, xs1 = _strides(Xs)
    (os_,) = _strides(o)
    lib.scatter_rows(
        Xs.ctypes.data, xs0, xs1, o.ctypes.data, osz, os_, o.size, out.ctypes.data, out.shape[0]
    )
    return out


@_njit()
def _scatter_rows_into(
    Xs: NDArray[np.float64], order: NDArray[Any], out: NDArray[np.float64]
) -> NDArray[np.float64]:  # pragma: no cover - compiled
    """:func:`scatter_rows` into ``out`` (N, 3)."""
    for i in range(order.size):
        r = order[i]
        out[r, 0] = Xs[i, 0]
        out[r, 1] = Xs[i, 1]
        out[r, 2] = Xs[i, 2]
    return out


def bounds(X: NDArray[np.float64], rows: NDArray[np.int64]) -> tuple[Any, Any]:
    """Per-axis minimum and maximum of ``X[rows]`` (all of ``X`` (N ≥ 1, 3) when ``rows`` is
    empty) in one pass (``X.min(axis=0)`` reduces along a strided axis: ~10x slower): two
    arrays (3,). C when built, else numba (:func:`_bounds_nb`)."""
    lib = _c()
    if lib is None:
        return _bounds_nb(X, rows)
    X = _typed(X, np.float64, "X", 2, 3)
    rows = np.ascontiguousarray(_typed(rows, np.int64, "rows", 1))
    if X.shape[0] == 0:
        raise ValueError("bounds: no points")
    lo, hi = np.empty(3), np.empty(3)
    rs, cs = _strides(X)
    lib.bounds(
        X.ctypes.data, X.shape[0], rs, cs, rows.ctypes.data, rows.size, lo.ctypes.data,
        hi.ctypes.data,
    )  # fmt: skip
    return lo, hi


@_njit()
def _bounds_nb(
    X: NDArray[np.float64], rows: NDArray[np.int64]
) -> tuple[Any, Any]:  # pragma: no cover - compiled
    """:func:`bounds`, numba's form."""
    n = rows.size if rows.size else X.shape[0]
    r0 = rows[0] if rows.size else 0
    lo = X[r0].copy()
    hi = X[r0].copy()
    for i in range(1, n):
        r = rows[i] if rows.size else i
        for a in range(3):
            v = X[r, a]
            if v < lo[a]:
                lo[a] = v
            elif v > hi[a]:
                hi[a] = v
    return lo, hi


def part1by2(v: Any) -> Any:
    """Spread the low 21 bits of ``v`` (uint64, an array or, compiled, a scalar) to every third
    bit: one axis of a Morton code."""
    v = v & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    return (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)


#: :func:`part1by2` compiled for the scalar loop of :func:`morton_order`.
_spread3 = _njit()(part1by2)


def morton_order(
    X: NDArray[np.float64],
    lo: NDArray[np.float64],
    scale: float,
    bits: int,
    order: NDArray[Any],
    tmp_o: NDArray[Any],
    code: NDArray[np.uint64],
    tmp_c: NDArray[np.uint64],
) -> NDArray[Any]:
    """Stable permutation sorting the points (N, 3) by Morton code: ``order`` or ``tmp_o``,
    whichever holds it (:func:`_morton_order`, numba's form, documents the arguments). C when
    built: ``order``, ``tmp_o`` C-contiguous, both int32 or both int64, ``code``, ``tmp_c``
    C-contiguous uint64, all N long, and ``3 bits ≤ 64``."""
    lib = _c()
    if lib is None:
        return _morton_order(X, lo, scale, bits, order, tmp_o, code, tmp_c)
    X = _typed(X, np.float64, "X", 2, 3)
    n = X.shape[0]
    lo = _dense(lo, np.float64, "lo", (3,))
    if order.dtype not in (np.int32, np.int64) or tmp_o.dtype != order.dtype:
        raise TypeError("order, tmp_o: both int32 or both int64 expected")
    for name, v in (("order", order), ("tmp_o", tmp_o), ("code", code), ("tmp_c", tmp_c)):
        if v.ndim != 1 or v.shape[0] != n or not v.flags.c_contiguous:
            raise ValueError(f"{name}: a C-contiguous array of the {n} points expected")
    _typed(code, np.uint64, "code", 1)
    _typed(tmp_c, np.uint64, "tmp_c", 1)
    if not 0 <= 3 * int(bits) <= 64:
        raise ValueError(f"bits: 0 to 21 expected, got {bits}")
    rs, cs = _strides(X)
    which = lib.morton_order(
        X.ctypes.data, n, rs, cs, lo.ctypes.data, float(scale), int(bits), order.ctypes.data,
        tmp_o.ctypes.data, order.itemsize, code.ctypes.data, tmp_c.ctypes.data,
    )  # fmt: skip
    return tmp_o if which else order


@_njit()
def _morton_order(
    X: NDArray[np.float64],
    lo: NDArray[np.float64],
    scale: float,
    bits: int,
    order: NDArray[Any],
    tmp_o: NDArray[Any],
    code: NDArray[np.uint64],
    tmp_c: NDArray[np.uint64],
) -> NDArray[Any]:  # pragma: no cover - compiled
    """Stable permutation sorting the points (N, 3) by Morton code, in one fused pass.

    ``order`` (N,) holds ``0 … N−1`` on entry and ``tmp_o`` (N,) is scratch, of one integer
    type (int32 below 2³¹ points: 16 MB less beside a 2 M-point scan than int64 indices); the
    result is one of the two. ``code``, ``tmp_c`` (N,) uint64: scratch for the codes, from the
    caller (numpy's pages: :func:`fresh_rows`).

    The code of a point is that of :func:`roboisf.parts.mesh.spatial_order` (the same float
    operations: ``uint64((x − lo) · scale)`` per axis, interleaved x, y, z from the lowest
    bit); the codes are sorted by a least-significant-digit radix sort (:data:`RADIX_BITS`-bit
    digits, a pass skipped when all codes share its digit), so points with equal codes keep
    their input order.
    """
    n = X.shape[0]
    for i in range(n):
        q0 = np.uint64((X[i, 0] - lo[0]) * scale)
        q1 = np.uint64((X[i, 1] - lo[1]) * scale)
        q2 = np.uint64((X[i, 2] - lo[2]) * scale)
        code[i] = _spread3(q0) | (_spread3(q1) << np.uint64(1)) | (_spread3(q2) << np.uint64(2))
    nbits = 3 * bits
    mask = np.uint64((1 << RADIX_BITS) - 1)
    nb = 1 << RADIX_BITS
    count = np.empty(nb + 1, dtype=np.int64)
    shift = 0
    while shift < nbits:
        s = np.uint64(shift)
        count[:] = 0
        for i in range(n):
            count[np.int64((code[i] >> s) & mask) + 1] += 1
        if count.max() < n:  # else every code has this digit: the pass would not move anything
            for e in range(1, nb + 1):
                count[e] += count[e - 1]
            for i in range(n):
                d = np.int64((code[i] >> s) & mask)
                j = count[d]
                count[d] = j + 1
                tmp_c[j] = code[i]
                tmp_o[j] = order[i]
            code, tmp_c = tmp_c, code
            order, tmp_o = tmp_o, order
        shift += RADIX_BITS
    return order


def build() -> None:
    """Compile (and so cache) these kernels through their callers, on a small mesh, and the
    axisymmetric parts' and the pyramid's (:mod:`roboisf.parts.axisym_kernel`,
    :mod:`roboisf.parts.pyramid_kernel`): the background builder of
    :mod:`roboisf.jit.background` (group "mesh")."""
    from roboisf.parts.mesh import MeshPart, in_spatial_order

    g = np.linspace(-0.05, 0.05, 4)
    x, y = np.meshgrid(g, g)
    V = np.column_stack([x.ravel(), y.ravel(), -0.1 * (x.ravel() ** 2 + y.ravel() ** 2)])
    i = np.arange(3)[:, None] * 4 + np.arange(3)[None, :]
    a = i.ravel()
    F = np.concatenate([np.column_stack([a, a + 1, a + 5]), np.column_stack([a, a + 5, a + 4])])
    P = np.random.default_rng(0).uniform(-0.05, 0.05, (64, 3))
    MeshPart(V, F, backend="numba").closest_point(P)
    in_spatial_order(P)  # the sort and the int32 gather (also the k-NN grid's)
    scatter_rows(P, np.arange(P.shape[0], dtype=np.int32))  # the k-NN filter's points put back
    bounds(P, np.arange(8, dtype=np.int64))
    from roboisf.parts import axisym_kernel, pyramid_kernel  # the analytic parts': same group

    axisym_kernel.build()
    pyramid_kernel.build()
