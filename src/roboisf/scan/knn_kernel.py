"""Compiled exact mean distance to the k nearest neighbours, for the scan's statistical outlier
filter (:func:`roboisf.scan.statistical_outliers`). Two compiled forms, the same bits: C
(``knn_kernel.c``, built at install, called through :mod:`roboisf.jit.native` — no numba in the
process) when it is built and fresh, else numba (``ROBOISF_NUMBA=0`` switches it off; built at
install: :mod:`roboisf.jit.prebuild`). The kernels keep their names as Python calls them
(:func:`_cell_keys`, :func:`_counting_sort_into`, :func:`_knn_mean`, :func:`_knn_mean_block9`,
:func:`_knn_mean_rows`) and go to C when :func:`_c` has the library, else to their numba forms
(``…_nb``); tests/test_native_knn.py checks the two against each other. Without either the
filter queries scipy's ``cKDTree``, which gives the same neighbours.

Algorithm (exact, the same idea as :mod:`roboisf.parts.mesh_kernel`):

1. a uniform grid of cubic cells of side ``h`` over the points' bounding box, points sorted by
   cell (compressed rows ``start``; z fastest, so a column's cells are one run of rows); ``h``
   is chosen for a few times ``k`` points per occupied cell (a scan is a surface: points per
   cell grow as h²), with at most :data:`MAX_CELLS` cells;
2. the ring search (:func:`_knn_mean`): per point ``p``, cells in Chebyshev rings
   ``R = 0, 1, …`` around its cell; a cell farther than the current (k+1)-th nearest squared
   distance is skipped; the k+1 smallest squared distances (the point itself included, as
   ``cKDTree.query(X, k + 1)``) are kept sorted;
3. after ring ``R`` every point not yet seen lies outside the cube of rings ``0..R``, at least
   the distance from ``p`` to that cube's faces inside the grid away: the search stops when the
   (k+1)-th distance is not larger; beyond ``max_rings`` rings it gives up (NaN). For the
   default k = 8 the block search (:func:`_knn_mean_block9`) does rings 0 and 1 of every point
   at once, query cell by query cell, and leaves NaN what they do not settle;
4. the points left (~1 % of a scan: a sparse halo of scanner points, each alone in its cell,
   their 9th neighbour 2–7 cells away) get the ring search's result with :data:`MAX_RINGS`
   rings from the column search (:func:`_knn_mean_rows`: the k+1 nearest in the same cube, by
   runs of a column's cells, ~R² columns instead of ~R³ cells), in parts in the threads;
5. a point not resolved within :data:`MAX_RINGS` rings (far from the rest: a stray point, a
   sparse line) gets the column search again with as many rings as :data:`FAR_CELLS` allows
   for all such points together (:func:`_far_rings`: 8 rings for the paper cone's ~1,500 per
   scan, 34 for 30 of them); what is still unresolved is finished by scipy's k-d tree over all
   points (built only then: 0.25–0.5 s on the paper cone's 1.7 M points).

The paper cone's scan without its rim (1.26 M wall points, one thread, 2026-11-29): block search
0.36 s; the ~12 k points it leaves 0.042 s and the ~1.5 k strays 0.013 s by columns, against
0.085 s and 0.048 s by the ring search (per stray one call) before.

Squared distances are summed x, y, z as scipy does, so the neighbour distances are the same
numbers; their mean may differ from numpy's pairwise sum in the last bit. The kernels are
serial and release the GIL: :func:`mean_knn_distance` runs them on chunks in several threads.
"""

from __future__ import annotations

import ctypes
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, njit
from roboisf.parts.mesh_kernel import bounds as _bounds
from roboisf.parts.mesh_kernel import gather_rows as _gather
from roboisf.parts.mesh_kernel import scatter_rows

__all__ = ["HAVE_NUMBA", "mean_knn_distance", "mean_knn_distance_held"]

if HAVE_NUMBA:
    compile_notice(__file__)  # numba compiles these on first call: say so once

#: Rings searched before a point is left to the wider search of the strays (:func:`_far_rings`)
#: and then to a k-d tree (the ring search grows as R³ far from the cloud, the column search as
#: R²: a stray point 0.5 m from a scan with 0.4 mm cells would need 10⁹ cells, 10⁶ columns). It
#: fixes which points the k-d tree gets (whose mean of the k distances, numpy's, may differ in
#: the last bit): the column search keeps it, and so the numbers.
MAX_RINGS = 6

#: Largest number of grid cells (int32 row starts, transient: ≤ 64 MB, summed in place from
#: the cell counts).
MAX_CELLS = 16_000_000

F64 = NDArray[np.float64]

_NO_ROWS = np.zeros(0, dtype=np.int64)

_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double
_GRID = [_P, _I, _I, _P, _I, _P, _D, _I, _I, _I]  # X, its strides, start, wide, lo, h, shape

#: The C functions of ``knn_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    "knn_mean": (ctypes.c_int, [*_GRID, _I, _I, _I, _I, _P, _I]),
    "knn_mean_rows": (ctypes.c_int, [*_GRID, _I, _I, _P, _I, _P, _I]),
    "knn_mean_block9": (ctypes.c_int, [*_GRID, _P, _I, _I, _P, _I]),
    "counting_sort_into": (None, [_P, _I, _P, _I, _P, _I]),
    "cell_keys": (_I, [_P, _I, _I, _I, _P, _I, _P, _D, _I, _I, _I, _P, _I, _P, _I]),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


_njit = njit


def _inline() -> Any:
    return njit(inline="always")


@_inline()
def _offer(
    X: F64, j0: int, j1: int, px: float, py: float, pz: float, best: F64, k1: int
) -> None:  # pragma: no cover - compiled
    """Rows ``j0 … j1 − 1`` of ``X`` offered to ``best``, the ``k1`` smallest squared
    distances to ``p`` so far (ascending; x, y, z summed as scipy does).

    A distance below the largest is merged in without a data-dependent branch: from the top,
    ``best[t] = min(best[t], max(best[t − 1], d²))`` shifts the larger ones up by one and puts
    ``d²`` in its place — the array an insertion sort gives, without the mispredicted exit of
    its shifting loop (1.15× on the paper cone's scan)."""
    for j in range(j0, j1):
        dx = X[j, 0] - px
        dy = X[j, 1] - py
        dz = X[j, 2] - pz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < best[k1 - 1]:
            for t in range(k1 - 1, 0, -1):
                best[t] = min(best[t], max(best[t - 1], d2))
            best[0] = min(best[0], d2)


@_inline()
def _unseen_xy(
    px: float, py: float, ci: int, cj: int, r: int, lo: F64, h: float, nx: int, ny: int
) -> float:  # pragma: no cover - compiled
    """How far every point outside the square of columns ``0 … r`` around column ``(ci, cj)``
    is from ``p`` at least: the distance to the square's x and y faces inside the grid (inf: no
    such face)."""
    bound = np.inf
    if ci - r > 0:
        bound = min(bound, px - (lo[0] + (ci - r) * h))
    if ci + r < nx - 1:
        bound = min(bound, lo[0] + (ci + r + 1) * h - px)
    if cj - r > 0:
        bound = min(bound, py - (lo[1] + (cj - r) * h))
    if cj + r < ny - 1:
        bound = min(bound, lo[1] + (cj + r + 1) * h - py)
    return bound


@_inline()
def _unseen(
    px: float,
    py: float,
    pz: float,
    ci: int,
    cj: int,
    ck: int,
    r: int,
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
) -> float:  # pragma: no cover - compiled
    """How far every point outside the cube of rings ``0 … r`` around cell ``(ci, cj, ck)`` is
    from ``p`` at least: the distance to the cube's faces inside the grid (inf: no such face;
    the square's x and y faces, :func:`_unseen_xy`, then z's)."""
    bound = _unseen_xy(px, py, ci, cj, r, lo, h, nx, ny)
    if ck - r > 0:
        bound = min(bound, pz - (lo[2] + (ck - r) * h))
    if ck + r < nz - 1:
        bound = min(bound, lo[2] + (ck + r + 1) * h - pz)
    return bound


@_inline()
def _resolved(best: F64, k1: int, bound: float, out: F64, i: int) -> bool:  # pragma: no cover
    """When the ``k1``-th distance is within ``bound``: ``out[i]`` = the mean of the roots of
    ``best[1:]`` (the point itself is ``best[0]``) and True."""
    if bound == np.inf or best[k1 - 1] <= max(bound, 0.0) ** 2:
        s = 0.0
        for t in range(1, k1):
            s += math.sqrt(best[t])
        out[i] = s / (k1 - 1)
        return True
    return False


@_njit()
def _knn_mean_nb(
    X: F64,
    start: NDArray[np.int32],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    k1: int,
    max_rings: int,
    a: int,
    b: int,
    out: F64,
) -> None:  # pragma: no cover - compiled
    best = np.empty(k1)
    for i in range(a, b):
        px, py, pz = X[i, 0], X[i, 1], X[i, 2]
        ci = min(max(int((px - lo[0]) / h), 0), nx - 1)
        cj = min(max(int((py - lo[1]) / h), 0), ny - 1)
        ck = min(max(int((pz - lo[2]) / h), 0), nz - 1)
        for t in range(k1):
            best[t] = np.inf
        r = 0
        while True:
            if r > max_rings:  # far from the others: left to the caller's k-d tree
                out[i] = np.nan
                break
            # centre out (0, −1, 1, −2, 2, …): the nearest cells first tighten the best early
            for qi in range(2 * r + 1):
                di = (qi + 1) // 2 * (1 if qi % 2 == 0 else -1)
                ii = ci + di
                if ii < 0 or ii >= nx:
                    continue
                # distance from p to the cell's box, by axis; a column of cells whose x, y
                # part alone is farther than the best is skipped whole
                ex = max(lo[0] + ii * h - px, 0.0, px - (lo[0] + (ii + 1) * h))
                if ex * ex > best[k1 - 1]:
                    continue
                for qj in range(2 * r + 1):
                    dj = (qj + 1) // 2 * (1 if qj % 2 == 0 else -1)
                    jj = cj + dj
                    if jj < 0 or jj >= ny:
                        continue
                    ey = max(lo[1] + jj * h - py, 0.0, py - (lo[1] + (jj + 1) * h))
                    exy = ex * ex + ey * ey
                    if exy > best[k1 - 1]:
                        continue
                    # a column inside the ring: only its two end cells are new
                    inner = r > 0 and abs(di) < r and abs(dj) < r
                    for qk in range(2 if inner else 2 * r + 1):
                        if inner:
                            dk = r if qk else -r
                        else:
                            dk = (qk + 1) // 2 * (1 if qk % 2 == 0 else -1)
                        kk = ck + dk
                        if kk < 0 or kk >= nz:
                            continue
                        # skip a cell farther than the best
                        ez = max(lo[2] + kk * h - pz, 0.0, pz - (lo[2] + (kk + 1) * h))
                        if exy + ez * ez > best[k1 - 1]:
                            continue
                        c = (ii * ny + jj) * nz + kk
                        _offer(X, start[c], start[c + 1], px, py, pz, best, k1)
            # every point not seen is outside the cube of rings 0..r (faces inside the grid)
            if _resolved(best, k1, _unseen(px, py, pz, ci, cj, ck, r, lo, h, nx, ny, nz), out, i):
                break
            r += 1


#: The 27 cells of a 3 × 3 × 3 block as offsets, the point's own cell first, then its faces,
#: edges and corners (the nearest cells first tighten the k-th distance early).
_BLOCK = np.array(
    sorted(
        ((a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)),
        key=lambda t: (abs(t[0]) + abs(t[1]) + abs(t[2]), t),
    ),
    dtype=np.int64,
)


@_njit()
def _knn_mean_block9_nb(
    X: F64,
    start: NDArray[Any],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    block: NDArray[np.int64],
    ca: int,
    cb: int,
    out: F64,
) -> None:  # pragma: no cover - compiled
    """:func:`_knn_mean` (``k1 = 9``: the filter's default k = 8, what the analysis runs) of
    the points of cells ``ca … cb − 1``, query cell by query cell.

    The points of the non-empty cells of the 3 × 3 × 3 block around a query cell are copied
    once, for all its points, into a buffer of three coordinate columns (the point's own cell
    first, then faces, edges, corners: :data:`_BLOCK`). Each point then takes its squared
    distances to the whole buffer in one pass without a branch (x, y, z summed as scipy does;
    the compiler vectorises it) and merges them into the nine smallest, held in nine scalars
    (registers) by the branch-free ``b[t] = min(b[t], max(b[t − 1], d²))`` — the array an
    insertion sort gives, value for value. The stop test after the block is the ring search's
    after ring 1; a point it does not settle (its ninth distance beyond the block's faces) is
    left NaN here and finished after every cell by the column search (:func:`_knn_mean_rows`:
    ~11–12 k of the paper cone's 1.26 M; calling the ring search from this loop made the loop
    1.4× slower).
    Same bits as the ring search: the nine smallest of a set that holds every point nearer
    than the block's faces.

    No cell of the block is pruned by its box distance: the ~2× more distances (≈ 120 against
    ≈ 57 a point visited with pruning on the paper cone) cost less in one vectorised pass over
    a buffer in L1 than the per-cell tests and short loops did. One core, the paper cone's
    1.26 M wall points (2026-11-29): this kernel 0.42–0.46 s plus 0.10 s of ring search for the
    ~11–12 k points it leaves (the scan's strays), against 0.57–0.59 s for ``_knn_mean_cells9``
    (pruned, the ring search called inside); :func:`mean_knn_distance` 0.66–0.68 → 0.58–0.59 s.
    (Since the column search, the points it leaves take 0.04 s.) Tried and no faster
    (2026-11-29): testing four distances at once against the ninth before the merge (0.39 s both).
    Any other k runs the ring search (the same neighbours)."""
    k1 = 9
    cap = 4096
    bx = np.empty(cap)
    by = np.empty(cap)
    bz = np.empty(cap)
    d2 = np.empty(cap)
    best = np.empty(k1)
    for c in range(ca, cb):
        a0, a1 = start[c], start[c + 1]
        if a0 == a1:
            continue
        ci = c // (ny * nz)
        cj = (c // nz) % ny
        ck = c % nz
        n = 0
        for q in range(27):
            ii, jj, kk = ci + block[q, 0], cj + block[q, 1], ck + block[q, 2]
            if ii < 0 or ii >= nx or jj < 0 or jj >= ny or kk < 0 or kk >= nz:
                continue
            e = (ii * ny + jj) * nz + kk
            s0, s1 = start[e], start[e + 1]
            if s0 == s1:
                continue
            if n + (s1 - s0) > cap:  # a dense block: the buffer grows (kept for later cells)
                cap = 2 * (n + (s1 - s0))
                gx, gy, gz = np.empty(cap), np.empty(cap), np.empty(cap)
                gx[:n] = bx[:n]
                gy[:n] = by[:n]
                gz[:n] = bz[:n]
                bx, by, bz, d2 = gx, gy, gz, np.empty(cap)
            for j in range(s0, s1):
                bx[n] = X[j, 0]
                by[n] = X[j, 1]
                bz[n] = X[j, 2]
                n += 1
        for i in range(a0, a1):
            px, py, pz = X[i, 0], X[i, 1], X[i, 2]
            for j in range(n):
                dx = bx[j] - px
                dy = by[j] - py
                dz = bz[j] - pz
                d2[j] = dx * dx + dy * dy + dz * dz
            b0 = b1 = b2 = b3 = b4 = b5 = b6 = b7 = b8 = np.inf
            for j in range(n):
                d = d2[j]
                if d < b8:
                    b8 = min(b8, max(b7, d))
                    b7 = min(b7, max(b6, d))
                    b6 = min(b6, max(b5, d))
                    b5 = min(b5, max(b4, d))
                    b4 = min(b4, max(b3, d))
                    b3 = min(b3, max(b2, d))
                    b2 = min(b2, max(b1, d))
                    b1 = min(b1, max(b0, d))
                    b0 = min(b0, d)
            best[0], best[1], best[2], best[3], best[4] = b0, b1, b2, b3, b4
            best[5], best[6], best[7], best[8] = b5, b6, b7, b8
            if not _resolved(
                best, k1, _unseen(px, py, pz, ci, cj, ck, 1, lo, h, nx, ny, nz), out, i
            ):
                out[i] = np.nan  # for the ring search (_knn_mean_rows), after every cell


@_inline()
def _box_gap(x: float, lo: float, i: int, h: float) -> float:  # pragma: no cover - compiled
    """The distance from coordinate ``x`` to the cell ``[lo + i h, lo + (i + 1) h]`` of an axis."""
    return max(lo + i * h - x, 0.0, x - (lo + (i + 1) * h))


@_njit()
def _knn_mean_rows_nb(
    X: F64,
    start: NDArray[Any],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    k1: int,
    max_rings: int,
    rows: NDArray[np.int64],
    out: F64,
) -> None:  # pragma: no cover - compiled
    """:func:`_knn_mean` of the points ``rows`` (those the block search leaves NaN, the strays
    beyond it), the same numbers found by columns instead of cells.

    The ring search with ``max_rings`` resolves a point iff the ``k1`` smallest squared
    distances among the points of the cube of rings ``0 … max_rings`` around its cell have the
    ``k1``-th within the cube's unseen bound (:func:`_unseen`; the nearest of a smaller cube
    within its smaller bound are those of the larger cube within the larger bound), and then
    gives their mean. So this kernel finds the ``k1`` smallest of that cube and makes the same
    test once. It walks the cube's columns (all cells of one x, y) in square rings centre out:
    cells are sorted z fastest, so the cells of a column between two heights are one run of
    rows — two row starts for the whole run where the ring search looks at each cell. A column
    farther in x, y than the ``k1``-th distance so far is skipped, and of the others only the
    cells within that distance in z are offered (the ring search's pruning, by runs). After
    square ring ``r`` every point of the cube not yet seen lies outside the square, at least
    :func:`_unseen_xy` away: when the ``k1``-th distance is not larger, the cube has no nearer
    point and the walk stops. A point ``R`` cells from the nearest others costs ~R² columns
    instead of the ring search's ~R³ cells. Same bits as :func:`_knn_mean_nb`: the same
    smallest squared distances (x, y, z summed as scipy does) and the same mean of their roots.
    """
    best = np.empty(k1)
    for i in rows:
        px, py, pz = X[i, 0], X[i, 1], X[i, 2]
        ci = min(max(int((px - lo[0]) / h), 0), nx - 1)
        cj = min(max(int((py - lo[1]) / h), 0), ny - 1)
        ck = min(max(int((pz - lo[2]) / h), 0), nz - 1)
        zmin, zmax = max(ck - max_rings, 0), min(ck + max_rings, nz - 1)
        ih = 1.0 / h
        zp = (pz - lo[2]) * ih  # z in cells (a run's first guess)
        for t in range(k1):
            best[t] = np.inf
        for r in range(max_rings + 1):
            for qi in range(2 * r + 1):  # the columns of square ring r, centre out
                di = (qi + 1) // 2 * (1 if qi % 2 == 0 else -1)
                ii = ci + di
                if ii < 0 or ii >= nx:
                    continue
                ex = _box_gap(px, lo[0], ii, h)
                if ex * ex > best[k1 - 1]:
                    continue
                edge = abs(di) == r  # a whole row of the ring, else its two ends
                for qj in range(2 * r + 1 if edge else 2):
                    if edge:
                        dj = (qj + 1) // 2 * (1 if qj % 2 == 0 else -1)
                    else:
                        dj = r if qj else -r
                    jj = cj + dj
                    if jj < 0 or jj >= ny:
                        continue
                    ey = _box_gap(py, lo[1], jj, h)
                    exy = ex * ex + ey * ey
                    b = best[k1 - 1]
                    if exy > b:
                        continue
                    # the column's cells within the cube and not farther than the best: one
                    # run of rows (cells are sorted z fastest)
                    k0, k9 = zmin, zmax
                    if b < np.inf:
                        s = math.sqrt(b - exy)
                        t0 = zp - s * ih
                        t9 = zp + s * ih
                        if t0 > zmin:
                            k0 = int(t0) if t0 < zmax else zmax
                        if t9 < zmax:
                            k9 = int(t9) if t9 > zmin else zmin
                        while k0 > zmin:  # one cell more where rounding cut it
                            ez = _box_gap(pz, lo[2], k0 - 1, h)
                            if exy + ez * ez > b:
                                break
                            k0 -= 1
                        while k9 < zmax:
                            ez = _box_gap(pz, lo[2], k9 + 1, h)
                            if exy + ez * ez > b:
                                break
                            k9 += 1
                    c = (ii * ny + jj) * nz
                    _offer(X, start[c + k0], start[c + k9 + 1], px, py, pz, best, k1)
            if r == max_rings:
                break
            # every point of the cube not seen is outside the square of columns 0..r
            bxy = max(_unseen_xy(px, py, ci, cj, r, lo, h, nx, ny), 0.0)
            if bxy == np.inf or best[k1 - 1] <= bxy * bxy:
                break
        if not _resolved(
            best, k1, _unseen(px, py, pz, ci, cj, ck, max_rings, lo, h, nx, ny, nz), out, i
        ):
            out[i] = np.nan  # far from the others: left to the caller's k-d tree


def _counting_sort(key: NDArray[Any], start: NDArray[Any]) -> NDArray[Any]:
    """Stable permutation sorting ``key`` by cell, given the cells' row starts (of the keys'
    integer type: int32 below 2³¹ points). ``start`` itself holds each cell's next row during
    the pass and is restored before this returns: no copy of the grid's size (33 MB beside the
    paper cone's scan, at the filter's and the toolpath statistics' peak). The permutation is
    numpy's (huge pages: :func:`roboisf.parts.mesh_kernel.fresh_rows`), filled by a compiled
    pass."""
    return _counting_sort_into(key, start, np.empty_like(key))


@_njit()
def _counting_sort_into_nb(
    key: NDArray[Any], start: NDArray[Any], order: NDArray[Any]
) -> NDArray[Any]:  # pragma: no cover - compiled
    """:func:`_counting_sort` into ``order`` (the keys' shape and type)."""
    for i in range(key.size):
        c = key[i]
        order[start[c]] = i
        start[c] += 1
    # start[c] is now the end of cell c, the start of cell c + 1: shifted back by one cell
    for c in range(start.size - 2, 0, -1):
        start[c] = start[c - 1]
    start[0] = 0
    return order


# The kernels as Python calls them: the C form when it is built (``_c()``), else numba's.


def _points(X: Any) -> tuple[F64, int, int]:
    """Points (N, ≥ 3) float64 and their row and column strides in elements (a copy only of a
    view whose strides are not whole elements)."""
    if not isinstance(X, np.ndarray) or X.dtype != np.float64 or X.ndim != 2 or X.shape[1] < 3:
        raise TypeError("points: a float64 array (N, 3) expected")
    if X.strides[0] % 8 or X.strides[1] % 8:
        X = np.ascontiguousarray(X)
    return X, X.strides[0] // 8, X.strides[1] // 8


def _vector(out: Any, name: str) -> int:
    """The stride in elements of the float64 vector ``out`` (written by C: never a copy)."""
    if not isinstance(out, np.ndarray) or out.dtype != np.float64 or out.ndim != 1:
        raise TypeError(f"{name}: a float64 vector expected")
    if out.strides[0] % 8:
        raise ValueError(f"{name}: strides of whole elements expected")
    return out.strides[0] // 8


def _wide(*arrays: Any) -> int:
    """1 when the integer arrays (C-contiguous vectors of one type) are int64, 0 for int32."""
    dt = arrays[0].dtype if isinstance(arrays[0], np.ndarray) else None
    for a in arrays:
        if not isinstance(a, np.ndarray) or a.dtype != dt or a.ndim != 1:
            raise TypeError("cell keys, row starts and permutation: one integer type expected")
        if not a.flags.c_contiguous:
            raise ValueError("cell keys, row starts and permutation: contiguous arrays expected")
    if dt not in (np.dtype(np.int32), np.dtype(np.int64)):
        raise TypeError(f"cell keys, row starts and permutation: int32 or int64, not {dt}")
    return int(dt == np.dtype(np.int64))


def _lo(lo: Any) -> F64:
    out = np.ascontiguousarray(lo, dtype=np.float64)
    if out.size < 3:
        raise ValueError("lo: the grid's origin (3,) expected")
    return out


def _check_grid(X: F64, start: NDArray[Any], nx: int, ny: int, nz: int, out: F64) -> None:
    """The grid's shape is the row starts', its rows within the points and the output."""
    if start.size != nx * ny * nz + 1:
        raise ValueError(f"row starts: {nx * ny * nz + 1} expected (grid {nx}×{ny}×{nz})")
    if int(start[-1]) > min(X.shape[0], out.size):
        raise IndexError("row starts beyond the points or the output")


def _check_k1(k1: int) -> None:
    if k1 < 2:
        raise ValueError(f"k + 1 = {k1}: at least one neighbour (k ≥ 1) is needed")


def _knn_mean(
    X: F64,
    start: NDArray[Any],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    k1: int,
    max_rings: int,
    a: int,
    b: int,
    out: F64,
) -> None:
    """The ring search of the points ``a … b − 1`` of ``X`` sorted by cell (:func:`_knn_mean_nb`):
    ``out[i]`` their mean distance to their ``k1 − 1`` nearest, NaN beyond ``max_rings``."""
    lib = _c()
    if lib is None:
        _knn_mean_nb(X, start, lo, h, nx, ny, nz, k1, max_rings, a, b, out)
        return
    X, rs, cs = _points(X)
    os_, wide, lo = _vector(out, "out"), _wide(start), _lo(lo)
    a, b = int(a), int(b)
    if a >= b:
        return
    _check_k1(k1)
    _check_grid(X, start, nx, ny, nz, out)
    if a < 0 or b > min(X.shape[0], out.size):
        raise IndexError(f"points {a}…{b - 1} beyond the points or the output")
    ok = lib.knn_mean(
        X.ctypes.data, rs, cs, start.ctypes.data, wide, lo.ctypes.data, float(h),
        nx, ny, nz, k1, max_rings, a, b, out.ctypes.data, os_,
    )  # fmt: skip
    if not ok:
        raise MemoryError("knn ring search: no memory for its scratch")


def _knn_mean_block9(
    X: F64,
    start: NDArray[Any],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    block: NDArray[np.int64],
    ca: int,
    cb: int,
    out: F64,
) -> None:
    """The block search (k = 8) of the points of cells ``ca … cb − 1``
    (:func:`_knn_mean_block9_nb`); the points it does not settle are left NaN."""
    lib = _c()
    if lib is None:
        _knn_mean_block9_nb(X, start, lo, h, nx, ny, nz, block, ca, cb, out)
        return
    X, rs, cs = _points(X)
    os_, wide, lo = _vector(out, "out"), _wide(start), _lo(lo)
    B = np.ascontiguousarray(block, dtype=np.int64)
    if B.shape != (27, 3):
        raise ValueError("block: the 27 cell offsets (27, 3) expected")
    ca, cb = int(ca), int(cb)
    if ca >= cb:
        return
    _check_grid(X, start, nx, ny, nz, out)
    if ca < 0 or cb > start.size - 1:
        raise IndexError(f"cells {ca}…{cb - 1} beyond the grid")
    ok = lib.knn_mean_block9(
        X.ctypes.data, rs, cs, start.ctypes.data, wide, lo.ctypes.data, float(h),
        nx, ny, nz, B.ctypes.data, ca, cb, out.ctypes.data, os_,
    )  # fmt: skip
    if not ok:
        raise MemoryError("knn block search: no memory for its buffer")


def _knn_mean_rows(
    X: F64,
    start: NDArray[Any],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    k1: int,
    max_rings: int,
    rows: NDArray[np.int64],
    out: F64,
) -> None:
    """The ring search's result for the points ``rows`` only, found by columns
    (:func:`_knn_mean_rows_nb`): ``out[i]`` their mean distance to their ``k1 − 1`` nearest, NaN
    beyond ``max_rings``, the numbers of :func:`_knn_mean`."""
    lib = _c()
    if lib is None:
        _knn_mean_rows_nb(X, start, lo, h, nx, ny, nz, k1, max_rings, rows, out)
        return
    X, rs, cs = _points(X)
    os_, wide, lo = _vector(out, "out"), _wide(start), _lo(lo)
    R = np.ascontiguousarray(rows, dtype=np.int64)
    if R.size == 0:
        return
    _check_k1(k1)
    _check_grid(X, start, nx, ny, nz, out)
    if int(R.min()) < 0 or int(R.max()) >= min(X.shape[0], out.size):
        raise IndexError("rows beyond the points or the output")
    ok = lib.knn_mean_rows(
        X.ctypes.data, rs, cs, start.ctypes.data, wide, lo.ctypes.data, float(h),
        nx, ny, nz, k1, max_rings, R.ctypes.data, R.size, out.ctypes.data, os_,
    )  # fmt: skip
    if not ok:
        raise MemoryError("knn ring search: no memory for its scratch")


def _counting_sort_into(
    key: NDArray[Any], start: NDArray[Any], order: NDArray[Any]
) -> NDArray[Any]:
    """:func:`_counting_sort` into ``order`` (the keys' shape and type;
    :func:`_counting_sort_into_nb`)."""
    lib = _c()
    if lib is None:
        return _counting_sort_into_nb(key, start, order)
    wide = _wide(key, start, order)
    if order.size != key.size or start.size < 1:
        raise ValueError("counting sort: a permutation of the keys' size and row starts expected")
    lib.counting_sort_into(
        key.ctypes.data, key.size, start.ctypes.data, start.size, order.ctypes.data, wide
    )
    return order


def _cell_keys(
    P: F64,
    rows: NDArray[np.int64],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    key: NDArray[Any],
    counts: NDArray[Any],
) -> int:
    """Cell of every point ``P[rows]`` (all of ``P`` when ``rows`` is empty) in ``key``, and
    points per cell added to ``counts``; the number of occupied cells
    (:func:`_cell_keys_nb`)."""
    lib = _c()
    if lib is None:
        return int(_cell_keys_nb(P, rows, lo, h, nx, ny, nz, key, counts))
    P, rs, cs = _points(P)
    R = np.ascontiguousarray(rows, dtype=np.int64)
    wide, lo = _wide(key, counts), _lo(lo)
    n = key.size
    if counts.size < nx * ny * nz:
        raise ValueError(f"counts: {nx * ny * nz} cells expected")
    if R.size:
        if R.size < n or (n and (int(R.min()) < -P.shape[0] or int(R.max()) >= P.shape[0])):
            raise IndexError("rows beyond the points, or fewer than the keys")
    elif n > P.shape[0]:
        raise IndexError("more keys than points")
    occupied = int(
        lib.cell_keys(
            P.ctypes.data, rs, cs, P.shape[0], R.ctypes.data, R.size, lo.ctypes.data, float(h),
            nx, ny, nz, key.ctypes.data, n, counts.ctypes.data, wide,
        )
    )  # fmt: skip
    if occupied < 0:
        raise ValueError("points outside their grid: a non-finite point?")
    return occupied


def _shape(span: F64, h: float, max_cells: int) -> tuple[int, int, int]:
    """Cells per axis for side ``h``, coarsened until there are at most ``max_cells`` (a
    degenerate cloud — a line, a plane — has zero-span axes of one cell)."""
    while True:
        shape = tuple(int(v // h) + 1 for v in span)
        if shape[0] * shape[1] * shape[2] <= max_cells:
            return (shape[0], shape[1], shape[2])
        h *= 1.25


@_njit()
def _cell_keys_nb(
    P: F64,
    rows: NDArray[np.int64],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    key: NDArray[Any],
    counts: NDArray[Any],
) -> int:  # pragma: no cover - compiled
    """Cell of every point ``P[rows]`` (all of ``P`` when ``rows`` is empty) in ``key``, and
    points per cell (``counts``, zeroed by the caller), in one pass; returns the number of
    occupied cells. Cell index per axis: ``min(int((x − lo) / h), n − 1)`` (x ≥ lo)."""
    occupied = 0
    for i in range(key.size):
        r = rows[i] if rows.size else i
        ci = min(int((P[r, 0] - lo[0]) / h), nx - 1)
        cj = min(int((P[r, 1] - lo[1]) / h), ny - 1)
        ck = min(int((P[r, 2] - lo[2]) / h), nz - 1)
        c = (ci * ny + cj) * nz + ck
        key[i] = c
        if counts[c] == 0:
            occupied += 1
        counts[c] += 1
    return occupied


def _grid(
    X: F64, k: int, max_cells: int, rows: NDArray[np.int64] | None = None
) -> tuple[F64, float, tuple[int, int, int], NDArray[Any], NDArray[Any]]:
    """Origin, cell side, shape, the cell key of every point (of ``X[rows]`` if given) and
    the cells' row starts (int32 below 2³¹ points, else int64)."""
    R = _NO_ROWS if rows is None else rows
    n = X.shape[0] if rows is None else rows.size
    lo, hi = _bounds(X, R)
    span = np.maximum(hi - lo, 1e-12)
    h_min = float(np.cbrt(np.prod(span) / max_cells))  # finest grid allowed
    # a scan is a surface: guess its area from the box (the largest face), then correct h with
    # the measured occupancy (points per occupied cell grow as h²)
    target = 2.0 * (k + 1)
    s = np.sort(span)
    h = max(h_min, math.sqrt(target * s[1] * s[2] / n))
    cdt = np.int32 if n < 2**31 else np.int64  # cells ≤ MAX_CELLS < 2³¹: keys fit too
    key = np.empty(n, dtype=cdt)
    for it in range(3):
        shape = _shape(span, h, max_cells)
        h = max(h, float(np.max(span / np.array(shape))))
        # the cells' counts from index 1, summed in place into their row starts below (no
        # second array of the grid's size: 33 MB on the paper cone, beside the scan's peak)
        cells = np.zeros(shape[0] * shape[1] * shape[2] + 1, dtype=cdt)
        occupied = _cell_keys(X, R, lo, h, shape[0], shape[1], shape[2], key, cells[1:])
        per_cell = n / max(occupied, 1)
        h_new = max(h_min, h * math.sqrt(target / per_cell))
        if it == 2 or 0.5 * target <= per_cell <= 2 * target or abs(h_new - h) <= 1e-3 * h:
            break
        h = h_new
    start = np.cumsum(cells, out=cells)  # in place: numpy's accumulate makes no copy
    return lo, h, (shape[0], shape[1], shape[2]), key, start


#: Grid cells the second search's cubes may hold in all, over every point the first left
#: unresolved (:func:`_far_rings`). Chosen for the ring search, which visited them (at 3e7
#: cells its misses cost up to 0.2 s on 1.5 M points with 1000 strays before the k-d tree was
#: built all the same; at 1e7 within the noise); the column search visits ~(2R + 1)² columns
#: of a cube of (2R + 1)³ cells, far less, but the rings it gives fix which points the k-d tree
#: gets — and so the last bit of their means — and are kept. The paper cone's ~1,500 strays per
#: scan get 8 rings and are all resolved (0.013 s), saving the tree's 0.25–0.5 s.
FAR_CELLS = 10_000_000


def _far_rings(n_far: int) -> int:
    """Rings of the second search for ``n_far`` unresolved points: the most for which the
    cubes of (2R + 1)³ cells of them all stay within :data:`FAR_CELLS` (at most 128)."""
    side = (FAR_CELLS / max(n_far, 1)) ** (1.0 / 3.0)
    return int(min(128, max(0, (side - 1.0) // 2.0)))


def _each(f: Callable[[Any], None], items: Sequence[Any], threads: int) -> None:
    """``f(item)`` for every item, in up to ``threads`` threads (the kernels release the GIL)."""
    nw = max(1, min(threads, len(items)))
    if nw == 1:
        for it in items:
            f(it)
    else:
        with ThreadPoolExecutor(max_workers=nw) as pool:
            list(pool.map(f, items))


def _sorted_mean(
    Xs: F64,
    start: NDArray[Any],
    lo: F64,
    h: float,
    shape: tuple[int, int, int],
    k: int,
    workers: int | None,
) -> F64:
    """Mean k-NN distance of the points ``Xs`` sorted by cell (grid ``start``), their order.

    The block search (k = 8) or the ring search over chunks of whole cells in the threads; the
    column search of what they leave, with :data:`MAX_RINGS` rings, then of what that leaves
    with :func:`_far_rings` rings, each in parts in the threads (it used to run serially, one
    call per stray in the second: 0.13 s of the paper cone's 0.55 s on one thread, now 0.055 s);
    the k-d tree for the rest."""
    n = Xs.shape[0]
    nx, ny, nz = shape
    ms = np.empty(n)
    chunk = 65_536
    # chunks of whole cells, ~chunk points each (a cell's points share their block)
    # the cut points in the row starts' own integer type: an int64 needle would make numpy cast
    # the whole grid (8 M cells on the paper cone: a 66 MB copy, 20-160 ms) to search 30 values
    cuts = np.searchsorted(start, np.arange(chunk, n, chunk, dtype=start.dtype), side="right") - 1
    edges = np.unique(np.concatenate(([0], cuts, [start.size - 1])))
    spans = list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))
    threads = workers or os.cpu_count() or 1

    def run(span: tuple[int, int]) -> None:
        if k == 8:  # the default: the nine nearest in registers, query cell by query cell
            _knn_mean_block9(Xs, start, lo, h, nx, ny, nz, _BLOCK, span[0], span[1], ms)
        else:  # any other k: the ring search over the cells' rows (the same neighbours)
            a, b = int(start[span[0]]), int(start[span[1]])
            _knn_mean(Xs, start, lo, h, nx, ny, nz, k + 1, MAX_RINGS, a, b, ms)

    def rows(far: NDArray[np.int64], rings: int) -> NDArray[np.int64]:
        """The ring search's result for the points ``far`` (found by columns), in parts in the
        threads; those it leaves NaN."""

        def part(p: NDArray[np.int64]) -> None:
            _knn_mean_rows(Xs, start, lo, h, nx, ny, nz, k + 1, rings, p, ms)

        _each(part, np.array_split(far, min(-(-far.size // 256), 4 * threads)), threads)
        return far[np.isnan(ms[far])]

    _each(run, spans, threads)
    far = np.flatnonzero(np.isnan(ms))
    if far.size and k == 8:  # not settled by the block: the ring search's result, as for any k
        far = rows(far, MAX_RINGS)
    if far.size:  # points far from every other (stray scanner points): more rings first
        rings = _far_rings(far.size)
        if rings > MAX_RINGS:
            far = rows(far, rings)
    if far.size:  # still unresolved (farther still): a k-d tree over all points finishes them
        from scipy.spatial import cKDTree

        d, _ = cKDTree(Xs).query(Xs[far], k=k + 1, workers=-1)
        ms[far] = d[:, 1:].mean(axis=1)
    return ms


def mean_knn_distance(
    points: F64, k: int, *, workers: int | None = None, rows: NDArray[np.int64] | None = None
) -> F64:
    """(N,) m — mean distance of each point (N, 3) [m] to its ``k`` nearest other points (a
    duplicate counts, at 0), in the caller's order. ``rows``: of the points ``points[rows]``
    only (in the order of ``rows``; no copy of them is made). Needs a compiled form (C, or numba:
    :data:`HAVE_NUMBA`) and more than ``k`` points.

    Memory: the points once more, sorted by cell (the only copy), plus ~4 int64/float64 per
    point and the grid's row starts (≤ 64 MB).
    """
    if rows is None:
        X = np.ascontiguousarray(points, dtype=float)
        R = _NO_ROWS
    else:
        X = np.asarray(points, dtype=float)
        R = np.ascontiguousarray(rows, dtype=np.int64)
    n = X.shape[0] if rows is None else R.size
    lo, h, (nx, ny, nz), key, start = _grid(X, k, MAX_CELLS, None if rows is None else R)
    order = _counting_sort(key, start)
    del key
    # the points sorted by cell, the only copy; freed when _sorted_mean returns
    ms = _sorted_mean(_gather(X, R, order), start, lo, h, (nx, ny, nz), k, workers)
    m = np.empty(n)
    m[order] = ms
    return m


def _row_starts(Xs: F64, lo: F64, h: float, shape: tuple[int, int, int]) -> NDArray[Any]:
    """The grid's row starts (of :func:`_grid`, for its ``lo``, ``h``, ``shape``) counted again
    from the points ``Xs``: the same cells, so the same array."""
    n = Xs.shape[0]
    cdt = np.int32 if n < 2**31 else np.int64
    cells = np.zeros(shape[0] * shape[1] * shape[2] + 1, dtype=cdt)
    _cell_keys(Xs, _NO_ROWS, lo, h, shape[0], shape[1], shape[2], np.empty(n, cdt), cells[1:])
    return np.cumsum(cells, out=cells)


def mean_knn_distance_held(box: list[F64], k: int, *, workers: int | None = None) -> F64:
    """:func:`mean_knn_distance` of the points (N, 3) [m] in ``box``, a one-element list to
    which the caller keeps no other reference: they are taken out while their copy sorted by
    cell exists, and put back (a new array of the same values) before this returns.

    The points are then never held twice beside the grid: the filter's peak over the points is
    max(points, grid) + the means and the permutation instead of points + grid + the same rest,
    on the paper cone's 1.7 M-point scans ~100 MB instead of 133. The same numbers. Its price,
    measured there: the grid's row starts counted again from the sorted copy (17–66 ms; the
    higher figure on fresh pages) and the points scattered back (23–33 ms).
    """
    X = np.ascontiguousarray(box.pop(), dtype=float)
    n = X.shape[0]
    lo, h, shape, key, start = _grid(X, k, MAX_CELLS)
    order = _counting_sort(key, start)
    del key, start  # not beside both copies of the points: counted again below
    Xs = _gather(X, _NO_ROWS, order)
    del X  # the caller's points: freed here
    start = _row_starts(Xs, lo, h, shape)
    ms = _sorted_mean(Xs, start, lo, h, shape, k, workers)
    del start
    box.append(scatter_rows(Xs, order))
    del Xs
    m = np.empty(n)
    m[order] = ms
    return m
