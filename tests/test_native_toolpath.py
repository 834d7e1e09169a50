"""The toolpath statistics' C form (src/roboisf/scan/toolpath_kernel.c) against its numba form,
bit for bit: the contacts' neighbourhood statistics (median, trimmed mean, MAD, counts) and the
column-compact grid they start with, on a synthetic cone scan, on lattices of ties, and on the
edge cases the kernel has special paths for; the compact grid against knn_kernel's whole grid,
the sorting network and the value quickselect against numpy, the statistics against a numpy
oracle, and the same numbers whatever order the contacts are taken in."""

from __future__ import annotations

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf.parts import Cone
from roboisf.scan import knn_kernel, point_deviations, radial_offset, synthetic_scan
from roboisf.scan import toolpath_kernel as tk
from roboisf.toolpath import step_down

TK = "roboisf.scan.toolpath_kernel"
KNN = "roboisf.scan.knn_kernel"  # its grid passes serve the numba form: numba there too

CONE = Cone()
OFFSET = radial_offset(lambda z, phi: 0.5e-3 + 1e-3 * (-z) + 0.2e-3 * np.cos(3 * phi), CONE)


def _both(feet, dn, P, **kw):
    """contact_statistics by C, and by numba (this module's kernels and knn_kernel's)."""
    c_library(tk)
    got = tk.contact_statistics(feet, dn, P, **kw)
    with numba_form(TK, KNN):
        want = tk.contact_statistics(feet, dn, P, **kw)
    _same(got, want)
    return got


def _same(got, want):
    same_bits(got, want)  # ±0 and NaN signs too


@pytest.fixture(scope="module")
def cone_dev():
    """The feet and normal deviations of a synthetic paper-cone scan (as compare_scan hands
    them to toolpath_deviations), with 1 % outliers."""
    s = synthetic_scan(CONE, 150_000, offset=OFFSET, noise=25e-6, outlier_fraction=0.01, seed=5)
    d = point_deviations(s.points, CONE)
    return np.ascontiguousarray(d.foot), np.ascontiguousarray(d.dn)


@pytest.mark.parametrize(
    ("radius", "k", "trim"), [(1e-3, 16, 0.2), (0.6e-3, 7, 0.1), (4e-3, 360, 0.2), (1e-3, 24, 0.5)]
)
def test_cone_scan_c_equals_numba(cone_dev, radius, k, trim):
    """A step-down toolpath's contacts on the scanned cone (the analysis' case), with contacts
    off the scan (holes) appended: full, partial and empty neighbourhoods, even and odd counts,
    the small ball first (the default widen) and the whole ball only (widen 0); 8 703 contacts:
    three chunks, on threads. Within 1 mm ~22 feet (10-90 %: 16-29), within 4 mm ~360."""
    feet, dn = cone_dev
    tp = step_down(CONE, 5e-3, 1e-3, spacing=2e-3)
    P = np.vstack([tp.contact, tp.contact[::50] + np.array([0.0, 0.0, 0.2])])
    if k > 100:
        P = P[::4]  # (the time of the numba form's insertion sorts)
    a = _both(feet, dn, P, radius=radius, k=k, trim=trim)
    b = _both(feet, dn, P, radius=radius, k=k, trim=trim, widen=0.0)
    _same(a, b)  # the small ball first gives the whole ball's bits (in C as in numba)
    cnt = a[0]
    assert (cnt == k).any() and ((cnt > 0) & (cnt < k)).any() and (cnt == 0).any()
    assert (cnt % 2 == 0).any() and (cnt % 2 == 1).any()
    if k == 360:  # more candidates than the first buffers' 256: they grow
        assert (cnt > 256).any()


@pytest.mark.parametrize("trim", [0.2, 0.1])
def test_lattice_ties_and_signed_zeros(trim):
    """Feet on a lattice (equal distances at every rank) with repeating dn and ±0 among them:
    the small ball's tie and signed-zero checks send contacts to the whole ball, whose
    quickselect then decides (tests/test_scan_fast_paths.py's case)."""
    rng = np.random.default_rng(7)
    g = np.arange(-60, 61) * 0.1e-3
    x, y = np.meshgrid(g, g)
    feet = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    feet = np.vstack([feet, feet + np.array([0.0, 0.0, 0.1e-3])])
    dn = rng.integers(-3, 4, len(feet)) * 1e-5
    dn[rng.random(len(feet)) < 0.05] = -0.0
    t = np.linspace(0.0, 1.0, 3000)
    P = np.column_stack([4e-3 * t * np.cos(40 * t), 4e-3 * t * np.sin(40 * t), np.zeros_like(t)])
    P[::7, :2] = np.round(P[::7, :2] / 0.1e-3) * 0.1e-3  # on a lattice point: ties
    for k, radius in [(64, 1e-3), (16, 0.5e-3), (7, 0.3e-3)]:
        a = _both(feet, dn, P, radius=radius, k=k, trim=trim)
        assert (a[0] == k).mean() > 0.5
        assert (np.signbit(a[1]) & (a[1] == 0)).any()  # a median of −0: the zeros' order counts


def test_nan_dn_and_many_chunks():
    """NaN among the dn (the small ball's check sends those contacts to the whole ball; the
    insertion sort and the MAD meet NaN), and more contacts than one chunk (4096): the chunks
    run on threads, each starting without a small ball."""
    rng = np.random.default_rng(3)
    feet = np.column_stack([rng.uniform(0, 0.03, (60_000, 2)), rng.normal(0, 2e-5, 60_000)])
    dn = rng.normal(0.0, 1e-4, len(feet))
    dn[rng.random(len(feet)) < 0.002] = np.nan
    P = np.column_stack([rng.uniform(0, 0.03, (9000, 2)), np.zeros(9000)])
    P = P[np.lexsort((P[:, 0], np.round(P[:, 1] / 1e-3)))]  # in rows, as a toolpath goes
    a = _both(feet, dn, P, radius=1e-3, k=16, trim=0.2)
    assert np.isnan(a[1]).any() and np.isfinite(a[1]).mean() > 0.5


@pytest.mark.parametrize("trim", [0.0, 0.49, 0.9, 1.0])
def test_trims_c_equals_numba(cone_dev, trim):
    """trim from 0 to 1 (from 0.5 on the trimmed range is empty or reversed)."""
    feet, dn = cone_dev
    tp = step_down(CONE, 5e-3, 1e-3, spacing=4e-3)
    a = _both(feet, dn, tp.contact, radius=1e-3, k=12, trim=trim)
    assert (a[0] == 12).any() and ((a[0] > 0) & (a[0] < 12)).any()


def test_trim_outside_what_numba_can_read_is_refused_by_c(cone_dev):
    """A trim beyond the k values read (numba's kernel reads outside its array there) is a
    ValueError in C, not a read out of bounds."""
    c_library(tk)
    feet, dn = cone_dev
    P = feet[:50]  # on the scan: k feet near
    for trim in (-0.5, 1.5):
        with pytest.raises(ValueError, match="trim"):
            tk.contact_statistics(feet, dn, P, radius=1e-3, k=8, trim=trim)
    with pytest.raises(ValueError, match="k must be"):
        tk.contact_statistics(feet, dn, P, radius=1e-3, k=0, trim=0.2)


def test_small_and_degenerate_clouds():
    """One foot, fewer feet than k, feet on a line with duplicates (zero-span axes: one cell),
    all feet at one place, contacts exactly on feet, a huge radius on a small cloud."""
    rng = np.random.default_rng(1)
    for n, radius, shape in [(1, 1e-3, "box"), (5, 1e-3, "box"), (40, 1e-3, "line"),
                             (30, 1e-3, "point"), (200, 0.05, "box")]:  # fmt: skip
        feet = rng.uniform(-1e-3, 1e-3, (n, 3))
        if shape == "line":
            feet[:, 1:] = 0.0
            feet[20:] = feet[:20]  # duplicates: ties at every distance
        elif shape == "point":
            feet[:] = feet[0]
        dn = rng.normal(0, 1e-4, n)
        P = np.vstack([feet[:3], rng.uniform(-1.5e-3, 1.5e-3, (50, 3))])
        for k in (1, 2, 7, 16):
            a = _both(feet, dn, P, radius=radius, k=k, trim=0.2)
            assert (a[0] > 0).any()
        # dn of −0 (and +0): the prefix sum starts at the first value, not at 0 + it
        z = np.where(rng.random(n) < 0.5, -0.0, 0.0)
        z[0] = -0.0
        neg = False
        for k, trim in [(1, 0.0), (2, 0.0), (7, 0.2)]:
            a = _both(feet, z, P, radius=radius, k=k, trim=trim)
            neg |= bool((np.signbit(a[2]) & (a[0] > 0)).any())
        assert neg  # a trimmed mean of −0 (k = 1: the nearest foot's dn, −0 − 0)


def test_no_contact_one_contact_and_far_or_non_finite_contacts(cone_dev):
    """No contact (empty results), one, and contacts far off the grid — up to coordinates whose
    cells overflow int64 (numba's conversion gives INT64_MIN there: no cell) — or not finite,
    between ordinary ones (their small ball is reset)."""
    feet, dn = cone_dev
    empty = _both(feet, dn, np.zeros((0, 3)), radius=1e-3, k=8, trim=0.2)
    assert all(v.size == 0 for v in empty)
    one = _both(feet, dn, feet[100:101], radius=1e-3, k=8, trim=0.2)
    assert one[0][0] == 8
    odd = np.array(
        [[1e30, 0, 0], [-1e30, 0, 0], [0, 1e300, 0], [0, 0, -1e19], [5.0, 5.0, 5.0],
         [np.nan, 0, 0], [0, np.inf, 0], [0, 0, -np.inf]]
    )  # fmt: skip
    P = np.vstack([feet[:20], odd, feet[20:40], odd[::-1], feet[40:60]])
    a = _both(feet, dn, P, radius=1e-3, k=8, trim=0.2)
    assert (a[0][20:28] == 0).all() and (a[0][:20] == 8).all() and (a[0][28:48] == 8).all()


def test_input_layouts(cone_dev):
    """The feet reversed, in Fortran order, float32: converted to the kernel's layout before
    either form runs."""
    feet, dn = cone_dev
    sub, d = feet[:20_000], dn[:20_000]
    P = sub[::97]
    for f in (sub[::-1], np.asfortranarray(sub), sub.astype(np.float32)):
        _both(f, d, P, radius=1e-3, k=10, trim=0.2)


def _grid_args(feet, radius):
    """The grid of contact_statistics for ``feet`` (its origin, cell side and shape)."""
    lo, hi = tk._bounds(feet, tk._NO_ROWS)
    span = np.maximum(hi - lo, 1e-12)
    shape = tk._shape(span, tk.CELL * radius, tk.MAX_CELLS)
    h = max(tk.CELL * radius, float(np.max(span / np.array(shape))))
    return lo, h, shape


def test_int64_grid_c_equals_numba(cone_dev):
    """The grid of 2³¹ feet or more (int64 keys, row starts and permutation) — asked for
    directly on the scan: the same numbers as the int32 grid, in C and in numba."""
    lib = c_library(tk)
    feet, dn = cone_dev
    tp = step_down(CONE, 5e-3, 1e-3, spacing=3e-3)
    P = tp.contact
    lo, h, shape = _grid_args(feet, 1e-3)
    args = (feet, dn, P, lo, h, shape)
    a64 = tk._statistics(lib, *args, np.int64, 1e-3, 16, 0.2, tk.EST_WIDEN)
    a32 = tk._statistics(lib, *args, np.int32, 1e-3, 16, 0.2, tk.EST_WIDEN)
    with numba_form(TK, KNN):
        b64 = tk._statistics(None, *args, np.int64, 1e-3, 16, 0.2, tk.EST_WIDEN)
    _same(a64, b64)
    _same(a64, a32)
    assert (a64[0] == 16).any()


def test_grid_refuses_a_non_finite_foot():
    """A NaN foot has no cell: a ValueError in both forms (numba's knn_kernel pass wrote outside
    its arrays there)."""
    lib = c_library(tk)
    feet = np.random.default_rng(0).uniform(0, 1e-2, (100, 3))
    lo, h, shape = _grid_args(feet, 1e-3)
    for bad in (np.nan, -np.inf):
        f = feet.copy()
        f[50, 1] = bad
        with pytest.raises(ValueError, match="non-finite"):
            tk._grid(lib, f, lo, h, shape, np.int32)
        with numba_form(TK, KNN), pytest.raises(ValueError, match="non-finite"):
            tk._grid(None, f, lo, h, shape, np.int32)


def _dense_grid(feet, lo, h, shape):
    """knn_kernel's whole grid of the feet (every cell's row start) and its permutation: the
    grid contact_statistics used before the compact one."""
    nx, ny, nz = shape
    key = np.empty(len(feet), dtype=np.int32)
    start = np.zeros(nx * ny * nz + 1, dtype=np.int32)
    knn_kernel._cell_keys(feet, tk._NO_ROWS, lo, h, nx, ny, nz, key, start[1:])
    np.cumsum(start, out=start)
    return knn_kernel._counting_sort(key, start), start


def _two_planes(n=20_000, seed=2):
    """Feet on two horizontal planes 3 mm apart, and a sloped strip between them: columns
    whose occupied cells have empty cells between them (their compact range spans those)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, 0.02, (n, 2))
    z = np.where(rng.random(n) < 0.5, 0.0, 3e-3) + rng.normal(0.0, 2e-5, n)
    strip = rng.random(n) < 0.1
    z[strip] = 0.15 * xy[strip, 0]
    return np.column_stack([xy, z]), rng.normal(0.0, 1e-4, n)


@pytest.mark.parametrize("case", ["cone", "planes"])
def test_compact_grid_is_the_dense_grid(cone_dev, case):
    """The compact grid (C and numba, int32 and int64) holds knn_kernel's whole grid: the same
    permutation, and each column's row starts between its first and last occupied cell, empty
    cells outside them."""
    lib = c_library(tk)
    feet = cone_dev[0] if case == "cone" else _two_planes()[0]
    lo, h, shape = _grid_args(feet, 2e-3)
    nx, ny, nz = shape
    order_d, start_d = _dense_grid(feet, lo, h, shape)
    got = tk._grid(lib, feet, lo, h, shape, np.int32)
    with numba_form(TK, KNN):
        want = tk._grid(None, feet, lo, h, shape, np.int32)
    same_bits(got, want)
    same_bits(tk._grid(lib, feet, lo, h, shape, np.int64), tuple(a.astype(np.int64) if i < 2
              else a for i, a in enumerate(got)))  # fmt: skip
    order, start, kmin, cbase = got
    assert np.array_equal(order, order_d)
    span = np.diff(cbase)
    assert start.size == cbase[-1] + 1 <= start_d.size
    counts_d = np.diff(start_d).reshape(nx * ny, nz)
    counts = np.diff(start)
    gaps = 0
    for c in np.flatnonzero(span):  # the occupied columns: the same counts in their range
        k0 = kmin[c]
        row = counts_d[c]
        assert np.array_equal(counts[cbase[c] : cbase[c + 1]], row[k0 : k0 + span[c]])
        assert row[:k0].sum() == 0 and row[k0 + span[c] :].sum() == 0
        assert row[k0] > 0 and row[k0 + span[c] - 1] > 0
        gaps += int((row[k0 : k0 + span[c]] == 0).sum())
    assert counts_d[span == 0].sum() == 0  # the empty columns
    if case == "planes":
        assert gaps > 0  # columns with empty cells between their occupied ones
    else:
        assert start.size < start_d.size / 10  # a shell: most cells of its box are empty


def _oracle(feet, dn, P, radius, k, trim):
    """The statistics by numpy, one contact at a time: the k nearest feet within the radius
    (brute force), their dn sorted by np.sort, the median, the trimmed mean by the sequential
    prefix sum and the MAD — for data without ties and without ±0 (the same bits then)."""
    M = len(P)
    cnt, med, trimmed, mad = np.zeros(M, np.int64), np.zeros(M), np.zeros(M), np.zeros(M)
    for i, p in enumerate(P):
        d2 = ((feet - p) ** 2).sum(axis=1)
        near = np.flatnonzero(d2 < radius * radius)
        sel = near[np.argsort(d2[near])[:k]]
        c = len(sel)
        vv = np.zeros(k)
        vv[:c] = np.sort(dn[sel])
        cc = max(c, 1)
        lo_mid, hi_mid = (cc - 1) // 2, cc // 2
        md = 0.5 * (vv[lo_mid] + vv[hi_mid])
        cut = int(np.floor(cc * trim))
        cs = np.concatenate([[0.0], np.cumsum(vv)])
        trimmed[i] = (cs[cc - cut] - cs[cut]) / max(cc - 2 * cut, 1)
        a = np.sort(np.abs(vv[:c] - md))
        mad[i] = 0.5 * (a[lo_mid] + a[hi_mid]) if c else 0.0
        cnt[i], med[i] = c, md
    return cnt, med, trimmed, mad


@pytest.mark.parametrize(("k", "trim"), [(64, 0.2), (37, 0.1), (5, 0.2)])
def test_planes_c_equals_numba_and_numpy(k, trim):
    """Contacts over the two planes and the strip (columns with gaps; the balls of 2 mm reach
    both planes): C, numba, the whole ball only, and the numpy oracle agree bit for bit —
    partial, full (k of more) and empty neighbourhoods, k a power of two or not (the sorting
    network's padding)."""
    feet, dn = _two_planes()
    rng = np.random.default_rng(4)
    P = np.column_stack([rng.uniform(-0.002, 0.022, (600, 2)), rng.uniform(0.0, 3e-3, 600)])
    a = _both(feet, dn, P, radius=2e-3, k=k, trim=trim)
    _same(a, _both(feet, dn, P, radius=2e-3, k=k, trim=trim, widen=0.0))
    _same(a, _oracle(feet, dn, P, 2e-3, k, trim))
    cnt = a[0]
    assert (cnt == k).any() and ((cnt > 0) & (cnt < k)).any() and (cnt == 0).any()


def test_sorting_network_and_value_quickselect_against_numpy():
    """The sorting network and the quickselect on values, C and numba: np.sort's values and its
    k-th, for sizes around powers of two, duplicates, ±inf. (A wrong k-th would not show in
    the statistics, only in their time: the tie check sends the contact to the whole ball.)"""
    lib = c_library(tk)
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 4, 5, 7, 8, 9, 16, 31, 33, 64, 65, 100, 128, 200):
        for kind in ("normal", "few", "inf"):
            if kind == "normal":
                x = rng.normal(0.0, 1.0, n)
            elif kind == "few":
                x = rng.integers(1, 4, n) * 0.5  # many duplicates
            else:
                x = rng.normal(0.0, 1.0, n)
                x[rng.random(n) < 0.2] = np.inf
                x[rng.random(n) < 0.1] = -np.inf
            n2 = 1 << (n - 1).bit_length()
            xs = np.sort(x)
            for form in ("c", "numba"):
                out = np.full(n, np.nan)
                xbuf = np.empty(n2)  # (held: C writes it)
                if form == "c":
                    lib.sort_values(x.ctypes.data, out.ctypes.data, xbuf.ctypes.data, n, n2)
                else:
                    tk._bitonic(x.copy(), out, xbuf, n, n2)
                same_bits(out, xs)
            for k in sorted({1, 2, n // 2, n // 2 + 1, n - 1, n} - {0}):
                if k > n:
                    continue
                d = x.copy()
                a, b = np.empty(n), np.empty(n)
                got_c = lib.kth_value(d.ctypes.data, n, k, a.ctypes.data, b.ctypes.data)
                got_nb = tk._kth_smallest(d, n, k, a, b)
                assert got_c == got_nb == xs[k - 1]
                assert np.array_equal(d, x)  # d is not touched


def test_contact_order_does_not_change_the_numbers(cone_dev, monkeypatch):
    """The contacts are taken in Z-order; in their own order, or reversed, the numbers are the
    same (each contact's are its own), in C and in numba."""
    feet, dn = cone_dev
    tp = step_down(CONE, 5e-3, 1e-3, spacing=2e-3)
    P = np.vstack([tp.contact, [[np.nan, 0.0, 0.0], [1e30, 0.0, 0.0]], tp.contact[::7]])
    lo = tk._bounds(feet, tk._NO_ROWS)[0]
    perm = tk._contact_order(P, lo, 0.2)
    assert np.array_equal(np.sort(perm), np.arange(len(P)))
    assert not np.array_equal(perm, np.arange(len(P)))  # a real reordering
    kw = dict(radius=1e-3, k=16, trim=0.2)
    a = _both(feet, dn, P, **kw)
    for other in (
        lambda P, lo, span: np.arange(len(P)),
        lambda P, lo, span: np.arange(len(P))[::-1],
    ):
        monkeypatch.setattr(tk, "_contact_order", other)
        _same(a, _both(feet, dn, P, **kw))
