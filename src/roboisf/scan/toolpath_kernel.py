"""Compiled neighbourhood statistics of the toolpath contacts, for
:func:`roboisf.scan.toolpath_deviations`. Two compiled forms, the same bits: C
(``toolpath_kernel.c``, built at install, called through :mod:`roboisf.jit.native` — no numba in
the process) when it is built and fresh, else numba (the kernels below, and the counting sort of
:mod:`roboisf.scan.knn_kernel` they share).

Used when a compiled form is there (numba is a dependency; ``ROBOISF_NUMBA=0`` switches it
off); otherwise :func:`~roboisf.scan.toolpath_deviations` queries scipy's ``cKDTree`` (the
reference path, whose results these equal — tested).

Per contact ``P`` the scan points used are the ``k`` nearest feet (closest nominal points) at a
distance ``< radius`` — exactly what ``cKDTree.query(P, k, distance_upper_bound=radius)`` returns:
the squared distance is summed x, y, z and compared with ``radius²`` strictly, as scipy does.
The feet are bucketed once in a uniform grid of cubic cells of side :data:`CELL` · ``radius``
(coarser only if the grid would exceed :data:`~roboisf.scan.knn_kernel.MAX_CELLS` cells), so
every foot within ``radius`` of ``P`` lies in the ≤ 5 × 5 × 5 cells around it; no tree is
built. The grid keeps row starts only from the lowest to the highest occupied cell of each
column of cells (:func:`_grid`: a scanned wall fills a thin shell of its box). The median, the
trimmed mean and the MAD of the selected ``dn`` are then computed in the same pass with the same
floating-point operations as the numpy reference (sorted values, a sequential prefix sum for the
trimmed mean), so the numbers are the same bits.

Only an exact tie in distance at the ``k``-th neighbour could select a different point than
the k-d tree (both are then "the k nearest").

A smaller ball first: the last contact's ``k``-th neighbour distance, widened by
:data:`EST_WIDEN`, is a radius likely to hold ``k`` feet. When it does, the ``k`` nearest of the
ball are among them, and the same set as the whole ball's quickselect picks unless a foot
outside them ties with the ``k``-th distance; that, or a selected ``dn`` of ±0 or NaN (the
insertion sort keeps the order of equal values, and different selections leave them in
different orders), or fewer than ``k`` feet in the small ball, and the contact is searched again
in the whole ball as before. The numbers are therefore the same bits as the whole ball's every
time. In the small ball only the set counts, not its order: its ``k``-th squared distance comes
from a quickselect on the distances alone, branch-free (:func:`_kth_smallest`), and the set is
the feet at no more than it — ``k`` of them, else a tie. Values without NaN and ±0 (the small
ball's always) have one sorted order of their bits, which a vectorised sorting network gives
(:func:`_bitonic`); the insertion sort is kept for the others. The contacts are taken in
Z-order (:func:`_contact_order`): the feet are in that order in memory, and a contact's feet
are still in the cache from the contacts before it. Any order and any small ball give the same
numbers.

The paper cone's 34 825 contacts on 1.67 M feet, ``k`` = 64 (one core, CPU, C): 0.145 s before
these four changes (whole grid, Hoare quickselect with the dn alongside, insertion sort, toolpath
order) and 0.088 s after — grid 14 ms (22-25), contacts ~70 ms; ~190 ms with the whole ball for
every contact (``widen`` 0). numba's form: 0.20 → 0.17 s.
"""

from __future__ import annotations

import ctypes
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, run_chunks
from roboisf.parts.mesh_kernel import bounds as _bounds
from roboisf.parts.mesh_kernel import part1by2
from roboisf.scan import knn_kernel
from roboisf.scan.knn_kernel import MAX_CELLS, _njit, _shape

if HAVE_NUMBA:
    compile_notice(__file__)  # numba compiles these on first call: say so once

__all__ = ["HAVE_NUMBA", "build", "contact_statistics"]

F64 = NDArray[np.float64]

_NO_ROWS = np.zeros(0, dtype=np.int64)

_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double

#: The C functions of ``toolpath_kernel.c`` (:func:`roboisf.jit.native.library`).
SIGNATURES: dict[str, native.Signature] = {
    "contacts": (
        ctypes.c_int,
        [_P, _P, _P, _P, _I, _P, _P, _P, _D, _I, _I, _I, _P, _D, _I, _D, _D, _I, _I] + [_P] * 4,
    ),
    "grid_columns": (ctypes.c_int64, [_P, _I, _P, _D, _I, _I, _I, _P, _P, _I, _P, _P]),
    "grid_keys": (None, [_P, _P, _I, _I, _P, _P, _P]),
    "kth_value": (ctypes.c_double, [_P, _I, _I, _P, _P]),  # (tests)
    "sort_values": (None, [_P, _P, _P, _I, _I]),  # (tests)
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


#: Cell side / radius: half the radius, so the cells searched (≤ 5 × 5 × 5 around a contact)
#: hold ~3x the points in the ball instead of ~5x with cells of the radius.
CELL = 0.5

#: The radius searched first, in the last contact's k-th neighbour distances (see the module
#: notes): 1.15 holds the k feet for 95 % of the paper cone's contacts (1.05: 72 %, 1.25:
#: 99 %); contact_statistics on its 34 825 contacts took 104 ms (1.08), 95 (1.12), 88-93 (1.15
#: to 1.25), against 190 ms searching the whole ball every time (one core, CPU, C).
EST_WIDEN = 1.15


@_njit()
def _grid_columns(
    F: F64,
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    col: NDArray[Any],
    kz: NDArray[Any],
    kmin: NDArray[np.int32],
    kmax: NDArray[np.int32],
) -> int:  # pragma: no cover - compiled
    """The cell (ci, cj, ck) of every foot as :func:`knn_kernel._cell_keys_nb` finds it: its
    column ``ci · ny + cj`` in ``col``, ``ck`` in ``kz``, and each column's lowest and highest
    ``ck`` lowered into ``kmin`` and raised into ``kmax``. 0, or −1 when a foot has no cell
    (not finite)."""
    for i in range(F.shape[0]):
        ci = min(int((F[i, 0] - lo[0]) / h), nx - 1)
        cj = min(int((F[i, 1] - lo[1]) / h), ny - 1)
        ck = min(int((F[i, 2] - lo[2]) / h), nz - 1)
        if ci < 0 or cj < 0 or ck < 0:
            return -1
        c = ci * ny + cj
        col[i] = c
        kz[i] = ck
        if ck < kmin[c]:
            kmin[c] = ck
        if ck > kmax[c]:
            kmax[c] = ck
    return 0


@_njit()
def _grid_keys(
    key: NDArray[Any],
    kz: NDArray[Any],
    kmin: NDArray[np.int32],
    cbase: NDArray[np.int32],
    counts: NDArray[Any],
) -> None:  # pragma: no cover - compiled
    """``key`` (a column on entry) := the compact cell ``cbase[col] + kz − kmin[col]``; the
    feet per cell added to ``counts``."""
    for i in range(key.size):
        c = key[i]
        cell = cbase[c] + kz[i] - kmin[c]
        key[i] = cell
        counts[cell] += 1


@_njit()
def _select(d: F64, v: F64, m: int, k: int) -> None:  # pragma: no cover - compiled
    """Reorder ``d[:m]`` (and ``v`` alongside) so that its ``k`` smallest come first
    (Hoare quickselect, median-of-three pivot; in place, no allocation)."""
    lo, hi = 0, m - 1
    while hi > lo:
        mid = (lo + hi) // 2
        a, b, c = d[lo], d[mid], d[hi]
        piv = max(min(a, b), min(max(a, b), c))
        i, j = lo, hi
        while i <= j:
            while d[i] < piv:
                i += 1
            while d[j] > piv:
                j -= 1
            if i <= j:
                d[i], d[j] = d[j], d[i]
                v[i], v[j] = v[j], v[i]
                i += 1
                j -= 1
        # d[lo..j] ≤ piv ≤ d[i..hi]; the k-th smallest (index k − 1) lies in one part
        if k - 1 <= j:
            hi = j
        elif k - 1 >= i:
            lo = i
        else:
            return


@_njit()
def _kth_smallest(d: F64, n: int, k: int, a: F64, b: F64) -> float:  # pragma: no cover - compiled
    """The ``k``-th smallest of ``d[:n]`` (1 ≤ k ≤ n, no NaN): a quickselect on the values
    alone, median-of-three pivot, each pass a branch-free three-way split of the source into
    ``a`` (below the pivot) and ``b`` (above it) — in place when one of them is the source (the
    write index never passes the read index). ``a``, ``b``: room for ``n``."""
    src = d
    kk = k - 1
    while True:
        x, y, z = src[0], src[n // 2], src[n - 1]
        piv = max(min(x, y), min(max(x, y), z))
        nl = 0
        nr = 0
        for t in range(n):
            v = src[t]
            a[nl] = v
            b[nr] = v
            nl += v < piv
            nr += v > piv
        if kk < nl:
            src = a
            n = nl
        elif kk < n - nr:
            return piv  # the pivot, one of the values: n falls every pass
        else:
            kk -= n - nr
            src = b
            n = nr


@_njit()
def _bitonic(src: F64, dst: F64, x: F64, n: int, n2: int) -> None:  # pragma: no cover - compiled
    """``src[:n]`` sorted ascending into ``dst[:n]`` by a bitonic sorting network on ``x`` (room
    for ``n2``, the power of two ≥ n; padded with +inf): every stage's compare-exchanges a
    branch-free pass over contiguous rows, which C vectorises. For values without NaN and
    without ±0 only: their sorted bits are then unique — those of every sort, the insertion
    sort's too."""
    for t in range(n):
        x[t] = src[t]
    for t in range(n, n2):
        x[t] = np.inf
    p = 1
    while p < n2:
        # blocks of 2p, each half sorted: row t against row 2p − 1 − t (the second reversed)
        for b in range(0, n2, 2 * p):
            for t in range(p):
                u, w = x[b + t], x[b + 2 * p - 1 - t]
                x[b + t] = u if u < w else w
                x[b + 2 * p - 1 - t] = w if u < w else u
        # then half-cleaners: row t against row t + q within blocks of 2q, q = p / 2 … 2
        q = p // 2
        while q > 1:
            for b in range(0, n2, 2 * q):
                for t in range(b, b + q):
                    u, w = x[t], x[t + q]
                    x[t] = u if u < w else w
                    x[t + q] = w if u < w else u
            q //= 2
        if p > 1:  # and q = 1: neighbours
            for t in range(0, n2, 2):
                u, w = x[t], x[t + 1]
                x[t] = u if u < w else w
                x[t + 1] = w if u < w else u
        p *= 2
    for t in range(n):
        dst[t] = x[t]


@_njit()
def _box(
    px: float, py: float, pz: float, rad: float, lo: F64, h: float, nx: int, ny: int, nz: int
) -> tuple[int, int, int, int, int, int, float]:  # pragma: no cover - compiled
    """The cells of the ball of radius ``rad`` about p, widened by a hair (the rounding of
    p ± r drops no cell), and that widened radius."""
    rs = rad + 1e-9 * (rad + abs(px) + abs(py) + abs(pz))
    i0 = max(math.floor((px - rs - lo[0]) / h), 0)
    i1 = min(math.floor((px + rs - lo[0]) / h), nx - 1)
    j0 = max(math.floor((py - rs - lo[1]) / h), 0)
    j1 = min(math.floor((py + rs - lo[1]) / h), ny - 1)
    k0 = max(math.floor((pz - rs - lo[2]) / h), 0)
    k1 = min(math.floor((pz + rs - lo[2]) / h), nz - 1)
    return i0, i1, j0, j1, k0, k1, rs


@_njit()
def _run(
    kmin: NDArray[np.int32],
    cbase: NDArray[np.int32],
    col: int,
    box: tuple[int, int, int, int, int, int, float],
) -> tuple[int, int]:  # pragma: no cover - compiled
    """The rows ``start[r0] … start[r1]`` of ``box``'s cells in column ``col`` (its cells
    ``kmin[col] …`` at the compact rows ``cbase[col] …``); r0 ≥ r1 when it holds none."""
    c0, kl = cbase[col], kmin[col]
    kh = kl + (cbase[col + 1] - c0) - 1
    return c0 + max(box[4], kl) - kl, c0 + min(box[5], kh) - kl + 1


@_njit()
def _gather(
    F: F64,
    dn: F64,
    order: NDArray[Any],
    start: NDArray[Any],
    kmin: NDArray[np.int32],
    cbase: NDArray[np.int32],
    lo: F64,
    h: float,
    ny: int,
    px: float,
    py: float,
    pz: float,
    box: tuple[int, int, int, int, int, int, float],
    keep2: float,
    prune2: float,
    cd: F64,
    cv: F64,
) -> int:  # pragma: no cover - compiled
    """The squared distances to p of the feet in ``box``'s cells whose squared distance is
    below ``keep2``, in ``cd`` (their dn in ``cv``), in the cells' order; returns how many. A
    column of cells whose x, y box is farther than ``prune2`` (squared) is skipped."""
    i0, i1, j0, j1, _, _, _ = box
    m = 0
    for ii in range(i0, i1 + 1):
        ex = max(lo[0] + ii * h - px, 0.0, px - (lo[0] + (ii + 1) * h))
        for jj in range(j0, j1 + 1):
            ey = max(lo[1] + jj * h - py, 0.0, py - (lo[1] + (jj + 1) * h))
            if ex * ex + ey * ey > prune2:
                continue
            r0, r1 = _run(kmin, cbase, ii * ny + jj, box)
            if r0 >= r1:
                continue
            t0, t1 = start[r0], start[r1]
            # branch-free: every candidate is written, kept (m advances) if near enough
            for t in range(t0, t1):
                r = order[t]
                dx = F[r, 0] - px
                dy = F[r, 1] - py
                dz = F[r, 2] - pz
                d2 = dx * dx + dy * dy + dz * dz
                cd[m] = d2
                cv[m] = dn[r]
                m += d2 < keep2
    return m


@_njit()
def _need(
    start: NDArray[Any],
    kmin: NDArray[np.int32],
    cbase: NDArray[np.int32],
    ny: int,
    box: tuple[int, int, int, int, int, int, float],
) -> int:  # pragma: no cover - compiled
    """Feet in ``box``'s cells: room for every candidate (no reallocation inside the loop)."""
    i0, i1, j0, j1, _, _, _ = box
    need = 0
    for ii in range(i0, i1 + 1):
        for jj in range(j0, j1 + 1):
            r0, r1 = _run(kmin, cbase, ii * ny + jj, box)
            if r0 < r1:
                need += start[r1] - start[r0]
    return need


@_njit()
def _ball(
    F: F64,
    dn: F64,
    order: NDArray[Any],
    start: NDArray[Any],
    kmin: NDArray[np.int32],
    cbase: NDArray[np.int32],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    px: float,
    py: float,
    pz: float,
    rad: float,
    cd: F64,
    cv: F64,
) -> tuple[int, F64, F64]:  # pragma: no cover - compiled
    """The feet closer to p than ``rad`` (:func:`_gather` over the ball's cells, columns
    beyond its widened radius skipped): (how many, ``cd``, ``cv``), the two buffers replaced
    by larger ones when the cells hold more feet than they have room for."""
    box = _box(px, py, pz, rad, lo, h, nx, ny, nz)
    if box[4] > box[5]:
        return 0, cd, cv
    need = _need(start, kmin, cbase, ny, box)
    if need > cd.size:
        cd = np.empty(need)
        cv = np.empty(need)
    rs = box[6]
    m = _gather(
        F, dn, order, start, kmin, cbase, lo, h, ny, px, py, pz, box, rad * rad, rs * rs, cd, cv
    )
    return m, cd, cv


@_njit()
def _kth(cd: F64, k: int) -> float:  # pragma: no cover - compiled
    """The largest of ``cd[:k]`` (the k-th squared distance once the k nearest are in front)."""
    vk = cd[0]
    for t in range(1, k):
        vk = max(vk, cd[t])
    return vk


@_njit()
def _contacts(
    F: F64,
    dn: F64,
    order: NDArray[Any],
    start: NDArray[Any],
    kmin: NDArray[np.int32],
    cbase: NDArray[np.int32],
    lo: F64,
    h: float,
    nx: int,
    ny: int,
    nz: int,
    P: F64,
    radius: float,
    k: int,
    trim: float,
    widen: float,
    a: int,
    b: int,
    cnt: NDArray[np.int64],
    med: F64,
    trimmed: F64,
    mad: F64,
) -> None:  # pragma: no cover - compiled
    cd = np.empty(256)
    cv = np.empty(256)
    sa = np.empty(0)  # _kth_smallest's
    sb = np.empty(0)
    vv = np.zeros(k)
    n2 = 1
    while n2 < k:
        n2 *= 2
    xs = np.empty(n2)  # _bitonic's (c ≤ k)
    est = 0.0  # a radius likely to hold k feet (the last contact's k-th distance, widened)
    for i in range(a, b):
        px, py, pz = P[i, 0], P[i, 1], P[i, 2]
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
            cnt[i], med[i], trimmed[i], mad[i] = 0, 0.0, 0.0, 0.0
            est = 0.0
            continue
        m = -1
        kd = 0.0  # the k-th squared distance
        if 0.0 < est < radius:
            # the feet within est first: when they are k or more, the k nearest are among
            # them — the same set as from the whole ball when no foot outside it ties with
            # the k-th distance (a tie, or a dn of ±0 whose order the sort keeps, takes the
            # whole ball below: the same bits as ever). The set alone matters here (no ±0, no
            # NaN: their sorted bits are unique), not its order: the k-th distance kd by a
            # quickselect on the distances alone, then the feet at ≤ kd — k of them unless one
            # ties with the k-th
            m, cd, cv = _ball(
                F, dn, order, start, kmin, cbase, lo, h, nx, ny, nz, px, py, pz, est, cd, cv
            )
            if m < k:
                m = -1
            else:
                if sa.size < m:
                    sa = np.empty(m)
                    sb = np.empty(m)
                kd = _kth_smallest(cd, m, k, sa, sb)
                j = 0
                for t in range(m):
                    cv[j] = cv[t]
                    j += cd[t] <= kd
                if j != k:
                    m = -1  # a tie with the k-th distance
                for t in range(k if m >= 0 else 0):
                    x = cv[t]
                    if x == 0.0 or x != x:
                        m = -1
                        break
        whole = m < 0
        if whole:
            # (columns beyond the widened radius skipped rather than beyond the radius: the
            # same feet kept, in the same order — a skipped column holds none within it)
            m, cd, cv = _ball(
                F, dn, order, start, kmin, cbase, lo, h, nx, ny, nz, px, py, pz, radius, cd, cv
            )
            # the k nearest of them (the k-d tree's set, up to the order of exact ties):
            # moved to the front by a quickselect on the squared distance, their dn alongside
            if m > k:
                _select(cd, cv, m, k)
            if m >= k:
                kd = _kth(cd, k)
        c = min(m, k)
        est = 0.0
        if c == k:
            est = math.sqrt(kd) * widen
        # their dn sorted by value, zero-padded to k as the reference: by a sorting network
        # when no value is NaN or ±0 (the sorted bits are then unique; the small ball's
        # values are not: checked above), else by the insertion sort, which keeps the order
        # of equal values (±0) and meets NaN in its own way, the tested one (np.sort's
        # compiled quicksort would add ~10 s to the first compilation)
        plain = True
        for t in range(c if whole else 0):
            x = cv[t]
            if x != x or x == 0.0:
                plain = False
                break
        if plain:
            c2 = 1
            while c2 < c:
                c2 *= 2
            _bitonic(cv, vv, xs, c, c2)
        else:
            for t in range(c):
                x = cv[t]
                u = t
                while u > 0 and vv[u - 1] > x:
                    vv[u] = vv[u - 1]
                    u -= 1
                vv[u] = x
        for t in range(c, k):
            vv[t] = 0.0
        cc = max(c, 1)
        lo_mid = (cc - 1) // 2
        hi_mid = cc // 2
        md = 0.5 * (vv[lo_mid] + vv[hi_mid])
        # trimmed mean: the reference's prefix sums cs[j] = vv[0] + … + vv[j − 1], in order
        cut = math.floor(cc * trim)
        lo_t, hi_t = cut, cc - cut
        s = 0.0
        cs_lo = 0.0
        cs_hi = 0.0
        for t in range(max(lo_t, hi_t)):
            s = vv[t] if t == 0 else s + vv[t]
            if t + 1 == lo_t:
                cs_lo = s
            if t + 1 == hi_t:
                cs_hi = s
        trimmed[i] = (cs_hi - cs_lo) / max(hi_t - lo_t, 1)
        # MAD: |v − md| of the sorted v falls to the median and rises after it — two sorted
        # runs, merged from the middle outwards up to the rank hi_mid
        if c > 0:
            left = hi_mid
            while left > 0 and vv[left - 1] >= md:
                left -= 1
            right = left  # vv[right:] ≥ md, vv[:right] < md
            lft = right - 1
            a_lo = 0.0
            a_hi = 0.0
            for t in range(hi_mid + 1):
                if lft < 0 or (right < c and vv[right] - md <= md - vv[lft]):
                    e = abs(vv[right] - md)
                    right += 1
                else:
                    e = abs(vv[lft] - md)
                    lft -= 1
                if t == lo_mid:
                    a_lo = e
                if t == hi_mid:
                    a_hi = e
            mad[i] = 0.5 * (a_lo + a_hi)
        else:
            mad[i] = 0.0
        med[i] = md
        cnt[i] = c


def _xyz(a: NDArray[Any], name: str) -> None:
    """Checks an (N, 3) C-contiguous float64 array for C."""
    if a.dtype != np.float64 or a.ndim != 2 or a.shape[1] != 3 or not a.flags.c_contiguous:
        raise TypeError(f"{name}: a C-contiguous (N, 3) float64 array expected")


def contact_statistics(
    feet: F64,
    dn: F64,
    contact: F64,
    *,
    radius: float,
    k: int,
    trim: float,
    widen: float = EST_WIDEN,
) -> tuple[NDArray[np.int64], F64, F64, F64]:
    """Per contact (M, 3) [m]: the number of feet (N, 3) [m] used (the ``k`` nearest at a
    distance ``< radius`` [m]), and the median, the ``trim``-trimmed mean and the MAD [m] of
    their ``dn`` (N,) [m] — (M,) each, 0 where no foot is near. Needs a compiled form (C, or
    numba: :data:`HAVE_NUMBA`) and N ≥ 1.

    Memory: 2 int32 per foot (cell keys, then the permutation in place of the cells' heights)
    and the compact grid's row starts; the feet are not copied — the paper cone's 1.67 M feet
    13.3 MiB at the peak (36.4 with the whole grid's row starts before). ``widen``: the small
    ball's radius in the last contact's ``k``-th distances (:data:`EST_WIDEN`; 0: the whole
    ball for every contact) — the same numbers.
    """
    lib = _c()
    F = np.ascontiguousarray(feet, dtype=float)
    d = np.ascontiguousarray(dn, dtype=float)
    P = np.ascontiguousarray(contact, dtype=float)
    n = F.shape[0]
    lo, hi = _bounds(F, _NO_ROWS)
    span = np.maximum(hi - lo, 1e-12)
    nx, ny, nz = _shape(span, CELL * radius, MAX_CELLS)
    h = max(CELL * radius, float(np.max(span / np.array((nx, ny, nz)))))
    cdt = np.int32 if n < 2**31 else np.int64
    return _statistics(lib, F, d, P, lo, h, (nx, ny, nz), cdt, radius, k, trim, widen)


def _statistics(
    lib: Any,
    F: F64,
    d: F64,
    P: F64,
    lo: F64,
    h: float,
    shape: tuple[int, int, int],
    cdt: Any,
    radius: float,
    k: int,
    trim: float,
    widen: float,
) -> tuple[NDArray[np.int64], F64, F64, F64]:
    """:func:`contact_statistics` once the grid's origin, cell side and shape are chosen, its
    keys of integer type ``cdt`` (int32, or int64 from 2³¹ feet on: tests ask for either)."""
    nx, ny, nz = shape
    n, M = F.shape[0], P.shape[0]
    if lib is not None:  # nothing of another type or size reaches C
        _xyz(F, "feet")
        _xyz(P, "contact")
        if d.dtype != np.float64 or d.ndim != 1 or d.shape[0] < n:
            raise ValueError(f"dn: ({n},) float64 expected, got {d.shape} {d.dtype}")
        if k < 1:
            raise ValueError(f"k must be ≥ 1, got {k}")
        if np.shape(lo) != (3,):
            raise ValueError("lo: (3,) expected")
    order, start, kmin, cbase = _grid(lib, F, lo, h, shape, cdt)
    # the contacts in Z-order (see _contact_order), their results put back in theirs below
    perm = _contact_order(P, lo, float(np.max(np.asarray(shape) * h)))
    P = np.ascontiguousarray(P[perm])
    cnt = np.empty(M, dtype=np.int64)
    med, trimmed, mad = np.empty(M), np.empty(M), np.empty(M)

    if lib is None:

        def rows(a: int, b: int) -> None:
            _contacts(F, d, order, start, kmin, cbase, lo, h, nx, ny, nz, P, radius, k, trim,
                      widen, a, b, cnt, med, trimmed, mad)  # fmt: skip

    else:
        lo_c = np.ascontiguousarray(lo, dtype=np.float64)
        wide = knn_kernel._wide(order, start)  # one integer type for both, as C reads them

        def rows(a: int, b: int) -> None:
            status = lib.contacts(
                F.ctypes.data, d.ctypes.data, order.ctypes.data, start.ctypes.data, wide,
                kmin.ctypes.data, cbase.ctypes.data, lo_c.ctypes.data, h, nx, ny, nz,
                P.ctypes.data, radius, k, trim, widen, a, b, cnt.ctypes.data, med.ctypes.data,
                trimmed.ctypes.data, mad.ctypes.data,
            )  # fmt: skip
            if status == 1:
                raise MemoryError("contact_statistics: no memory for a contact's candidates")
            if status == 2:
                raise ValueError(f"trim must lie in [0, 1), got {trim}")
            if status != 0:
                raise ValueError(f"contact_statistics: C status {status}")

    run_chunks(rows, M, 4096)  # on every core: the kernel releases the GIL
    out = (np.empty_like(cnt), np.empty_like(med), np.empty_like(trimmed), np.empty_like(mad))
    for o, v in zip(out, (cnt, med, trimmed, mad), strict=True):
        o[perm] = v
    return out


def _contact_order(P: F64, lo: F64, span: float, bits: int = 8) -> NDArray[np.int64]:
    """A permutation putting the contacts (M, 3) in Z-order (Morton) of the feet's box (origin
    ``lo``, side ``span``; ``bits`` per axis, contacts outside or not finite on its faces): the
    order of the feet in memory after the analysis' spatial sort, so that a contact's feet are
    mostly still in the cache from the contacts before it — where the toolpath goes round the
    part and comes back to the same feet a ring later. Any order gives the same numbers (each
    contact's are its own; the small ball's radius, from the contact before, only decides how
    fast)."""
    top = float(2**bits - 1)
    q = np.nan_to_num((P - lo) * (top / span), nan=0.0, posinf=top, neginf=0.0)
    np.clip(q, 0.0, top, out=q)
    u = q.astype(np.uint64)
    code = part1by2(u[:, 0]) | (part1by2(u[:, 1]) << np.uint64(1))
    code |= part1by2(u[:, 2]) << np.uint64(2)
    return np.argsort(code, kind="stable")


def _grid(
    lib: Any, F: F64, lo: F64, h: float, shape: tuple[int, int, int], cdt: Any
) -> tuple[NDArray[Any], NDArray[Any], NDArray[np.int32], NDArray[np.int32]]:
    """The feet's grid, column-compact: the permutation ``order`` sorting the feet by cell
    (cells (i, j, k) in that order, k fastest; feet of a cell in their order — the order of
    :func:`knn_kernel._cell_keys` and :func:`knn_kernel._counting_sort` on the whole grid), and
    the cells' row starts ``start`` — only for the cells from the lowest to the highest
    occupied of each column (i, j), those of column ``c`` from ``cbase[c]`` on, its first cell
    ``kmin[c]`` (``cbase``: nx · ny + 1, ``kmin``: nx · ny, int32: the cells are < 2³¹).

    The paper cone's feet (1.67 M; cells of 0.5 mm, 174 × 174 × 205) fill 97 179 such cells of
    the grid's 6.2 M: ~0.5 MB of row starts and columns instead of 25 MB, and 14 instead of
    22-25 ms (one core). ``order`` and ``start`` of type ``cdt`` (int32, or int64 from 2³¹
    feet on)."""
    nx, ny, nz = shape
    n, nc = F.shape[0], nx * ny
    key = np.empty(n, dtype=cdt)  # the column, then the compact cell of each foot
    kz = np.empty(n, dtype=cdt)  # the cell in the column; then the permutation, in place
    kmin = np.full(nc, nz, dtype=np.int32)
    kmax = np.full(nc, -1, dtype=np.int32)
    if lib is None:
        status = _grid_columns(F, lo, h, nx, ny, nz, key, kz, kmin, kmax)
    else:
        wide = knn_kernel._wide(key, kz)
        lo_c = np.ascontiguousarray(lo, dtype=np.float64)
        status = lib.grid_columns(
            F.ctypes.data, n, lo_c.ctypes.data, h, nx, ny, nz, key.ctypes.data, kz.ctypes.data,
            wide, kmin.ctypes.data, kmax.ctypes.data,
        )  # fmt: skip
    if status != 0:
        raise ValueError("feet outside their grid: a non-finite foot?")
    span = np.maximum(kmax - kmin + 1, 0)  # int32: ≤ nz
    del kmax
    cbase = np.zeros(nc + 1, dtype=np.int32)
    np.cumsum(span, out=cbase[1:])
    del span
    start = np.zeros(int(cbase[-1]) + 1, dtype=cdt)  # counts from index 1, summed in place
    if lib is None:
        _grid_keys(key, kz, kmin, cbase, start[1:])
    else:
        lib.grid_keys(
            key.ctypes.data, kz.ctypes.data, n, wide, kmin.ctypes.data, cbase.ctypes.data,
            start[1:].ctypes.data,
        )  # fmt: skip
    np.cumsum(start, out=start)
    order = knn_kernel._counting_sort_into(key, start, kz)  # C or numba
    return order, start, kmin, cbase


def build() -> None:
    """Compile (and so cache) the scan kernels — this module's and
    :mod:`roboisf.scan.knn_kernel`'s — through their callers, on a small synthetic scan: the
    background builder of :mod:`roboisf.jit.background` (group "scan")."""
    from roboisf.scan.deviation import statistical_outliers
    from roboisf.scan.knn_kernel import mean_knn_distance, mean_knn_distance_held

    rng = np.random.default_rng(0)
    X = rng.uniform(-0.05, 0.05, (500, 3))
    statistical_outliers(X)
    statistical_outliers(X, rows=np.arange(0, 500, 2))
    # the default k: its own kernel (k + 1 = 9 in registers); a stray point that the block
    # search leaves to the ring search after it (knn_kernel._knn_mean_rows)
    mean_knn_distance(np.vstack([X, [[0.3, 0.3, 0.3]]]), 8)
    mean_knn_distance_held([X.copy()], 8)  # the grid counted again from the sorted points
    mean_knn_distance(X, 5)  # any other k
    dn = rng.normal(0.0, 1e-4, 500)
    contact_statistics(X, dn, X[:40], radius=0.01, k=16, trim=0.1)
