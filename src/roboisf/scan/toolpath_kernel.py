"""Compiled neighbourhood statistics of the toolpath contacts, for
:func:`roboisf.scan.toolpath_deviations`. Two compiled forms, the same bits: C
(``toolpath_kernel.c``, built at install, called through :mod:`roboisf.jit.native` — no numba in
the process) when it is built and fresh, else numba (the kernels below, and the grid passes of
:mod:`roboisf.scan.knn_kernel` they share).

Used when a compiled form is there (numba is a dependency; ``ROBOISF_NUMBA=0`` switches it
off); otherwise :func:`~roboisf.scan.toolpath_deviations` queries scipy's ``cKDTree`` (the
reference path, whose results these equal — tested).

Per contact ``P`` the scan points used are the ``k`` nearest feet (closest nominal points) at a
distance ``< radius`` — exactly what ``cKDTree.query(P, k, distance_upper_bound=radius)`` returns:
the squared distance is summed x, y, z and compared with ``radius²`` strictly, as scipy does.
The feet are bucketed once in a uniform grid of cubic cells of side ``radius`` (coarser only
if the grid would exceed :data:`~roboisf.scan.knn_kernel.MAX_CELLS` cells), so every foot
within ``radius`` of ``P`` lies in the ≤ 3 × 3 × 3 cells around it; no tree is built. The
median, the trimmed mean and the MAD of the selected ``dn`` are then computed in the same pass
with the same floating-point operations as the numpy reference (sorted values, a sequential
prefix sum for the trimmed mean), so the numbers are the same bits.

Only an exact tie in distance at the ``k``-th neighbour could select a different point than
the k-d tree (both are then "the k nearest").

A smaller ball first: the contacts come in toolpath order, so the last contact's ``k``-th
neighbour distance, widened by :data:`EST_WIDEN`, is a radius likely to hold ``k`` feet. When
it does, the ``k`` nearest of the ball are among them, and the same set as the whole ball's
quickselect picks unless a foot outside them ties with the ``k``-th distance; that, or a
selected ``dn`` of ±0 (the insertion sort keeps the order of equal values, and the two
quickselects leave them in different orders), or fewer than ``k`` feet in the small ball, and
the contact is searched again in the whole ball as before. The numbers are therefore the same
bits as the whole ball's every time; the small ball has ~85 candidates to select from instead
of ~200 and ~half the cells (the paper cone's contacts 0.31 → 0.225 CPU-s).
"""

from __future__ import annotations

import ctypes
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.jit import HAVE_NUMBA, compile_notice, native, run_chunks
from roboisf.parts.mesh_kernel import bounds as _bounds
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
        [_P, _P, _P, _P, _I, _P, _D, _I, _I, _I, _P, _D, _I, _D, _D, _I, _I, _P, _P, _P, _P],
    ),
}


def _c() -> Any:
    """The C library of this module, or None (the numba kernels serve)."""
    return native.library(__name__, SIGNATURES)


#: Cell side / radius: half the radius, so the cells searched (≤ 5 × 5 × 5 around a contact)
#: hold ~3x the points in the ball instead of ~5x with cells of the radius.
CELL = 0.5

#: The radius searched first, in the last contact's k-th neighbour distances (see the module
#: notes): 1.15 holds the k feet for 94 % of the paper cone's contacts (1.05: 71 %, 1.25:
#: 99 %); its 34 825 contacts took 0.27 s (1.05), 0.225 s (1.1 to 1.25), 0.24 s (1.4), against
#: 0.31 s searching the whole ball every time (one core, CPU).
EST_WIDEN = 1.15


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
def _gather(
    F: F64,
    dn: F64,
    order: NDArray[Any],
    start: NDArray[Any],
    lo: F64,
    h: float,
    ny: int,
    nz: int,
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
    i0, i1, j0, j1, k0, k1, _ = box
    m = 0
    if k0 > k1:
        return 0
    for ii in range(i0, i1 + 1):
        ex = max(lo[0] + ii * h - px, 0.0, px - (lo[0] + (ii + 1) * h))
        for jj in range(j0, j1 + 1):
            ey = max(lo[1] + jj * h - py, 0.0, py - (lo[1] + (jj + 1) * h))
            if ex * ex + ey * ey > prune2:
                continue
            base = (ii * ny + jj) * nz
            t0, t1 = start[base + k0], start[base + k1 + 1]
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
    start: NDArray[Any], ny: int, nz: int, box: tuple[int, int, int, int, int, int, float]
) -> int:  # pragma: no cover - compiled
    """Feet in ``box``'s cells: room for every candidate (no reallocation inside the loop)."""
    i0, i1, j0, j1, k0, k1, _ = box
    need = 0
    if k0 <= k1:
        for ii in range(i0, i1 + 1):
            for jj in range(j0, j1 + 1):
                base = (ii * ny + jj) * nz
                need += start[base + k1 + 1] - start[base + k0]
    return need


@_njit()
def _ball(
    F: F64,
    dn: F64,
    order: NDArray[Any],
    start: NDArray[Any],
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
    need = _need(start, ny, nz, box)
    if need > cd.size:
        cd = np.empty(need)
        cv = np.empty(need)
    rs = box[6]
    m = _gather(F, dn, order, start, lo, h, ny, nz, px, py, pz, box, rad * rad, rs * rs, cd, cv)
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
    vv = np.zeros(k)
    est = 0.0  # a radius likely to hold k feet (the last contact's k-th distance, widened)
    for i in range(a, b):
        px, py, pz = P[i, 0], P[i, 1], P[i, 2]
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
            cnt[i], med[i], trimmed[i], mad[i] = 0, 0.0, 0.0, 0.0
            est = 0.0
            continue
        m = -1
        if 0.0 < est < radius:
            # the feet within est first: when they are k or more, the k nearest are among
            # them — the same set as from the whole ball when no foot outside it ties with
            # the k-th distance (a tie, or a dn of ±0 whose order the sort keeps, takes the
            # whole ball below: the same bits as ever)
            m, cd, cv = _ball(F, dn, order, start, lo, h, nx, ny, nz, px, py, pz, est, cd, cv)
            if m < k:
                m = -1
            else:
                if m > k:
                    _select(cd, cv, m, k)
                vk = _kth(cd, k)
                for t in range(k, m):
                    if cd[t] == vk:
                        m = -1
                        break
                for t in range(k):
                    x = cv[t]
                    if x == 0.0 or x != x:
                        m = -1
                        break
        if m < 0:
            # (columns beyond the widened radius skipped rather than beyond the radius: the
            # same feet kept, in the same order — a skipped column holds none within it)
            m, cd, cv = _ball(F, dn, order, start, lo, h, nx, ny, nz, px, py, pz, radius, cd, cv)
            # the k nearest of them (the k-d tree's set, up to the order of exact ties):
            # moved to the front by a quickselect on the squared distance, their dn alongside
            if m > k:
                _select(cd, cv, m, k)
        c = min(m, k)
        est = 0.0
        if c == k:
            est = math.sqrt(_kth(cd, k)) * widen
        # their dn sorted by value (insertion sort: c ≤ k, a few dozen; np.sort's compiled
        # quicksort would add ~10 s to the first compilation), zero-padded to k as the reference
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

    Memory: ~3 int32 per foot (cell keys, the permutation) and the grid's row starts; the
    feet are not copied. ``widen``: the small ball's radius in the last contact's ``k``-th
    distances (:data:`EST_WIDEN`; 0: the whole ball for every contact) — the same numbers.
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
    key = np.empty(n, dtype=cdt)
    start = np.zeros(nx * ny * nz + 1, dtype=cdt)  # counts from index 1, summed in place
    knn_kernel._cell_keys(F, _NO_ROWS, lo, h, nx, ny, nz, key, start[1:])  # C or numba
    np.cumsum(start, out=start)
    order = knn_kernel._counting_sort(key, start)
    del key
    cnt = np.empty(M, dtype=np.int64)
    med, trimmed, mad = np.empty(M), np.empty(M), np.empty(M)

    if lib is None:

        def rows(a: int, b: int) -> None:
            _contacts(F, d, order, start, lo, h, nx, ny, nz, P, radius, k, trim, widen, a, b,
                      cnt, med, trimmed, mad)  # fmt: skip

    else:
        lo_c = np.ascontiguousarray(lo, dtype=np.float64)
        wide = knn_kernel._wide(order, start)  # one integer type for both, as C reads them

        def rows(a: int, b: int) -> None:
            status = lib.contacts(
                F.ctypes.data, d.ctypes.data, order.ctypes.data, start.ctypes.data, wide,
                lo_c.ctypes.data, h, nx, ny, nz, P.ctypes.data, radius, k, trim, widen, a, b,
                cnt.ctypes.data, med.ctypes.data, trimmed.ctypes.data, mad.ctypes.data,
            )  # fmt: skip
            if status == 1:
                raise MemoryError("contact_statistics: no memory for a contact's candidates")
            if status == 2:
                raise ValueError(f"trim must lie in [0, 1), got {trim}")
            if status != 0:
                raise ValueError(f"contact_statistics: C status {status}")

    run_chunks(rows, M, 4096)  # on every core: the kernel releases the GIL
    return cnt, med, trimmed, mad


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
