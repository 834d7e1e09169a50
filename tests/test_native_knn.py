"""The outlier filter's k-NN kernels (roboisf.scan.knn_kernel): their C form against their numba
form, bit for bit — the cell keys, the counting sort, the ring search, the block search of the
default k and the column search of the rows it leaves, and the public mean k-NN distance — on the
inputs their callers pass (int32 row starts, int64 above 2³¹ points, the points' layouts) and at
the special paths (strays beyond the rings, a sparse line and a sparse halo beyond the block, a
dense pile that grows the block's buffer, degenerate clouds of one cell per axis, points on cell
faces). The column search against the ring search it replaces for the rows, point by point, and
the whole filter against scipy's k-d tree, bit for bit."""

from __future__ import annotations

import itertools
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from native_forms import c_library, numba_form
from roboisf.jit import HAVE_NUMBA
from roboisf.parts.mesh_kernel import gather_rows
from roboisf.scan import knn_kernel as kk

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed (the oracle)")

KK = "roboisf.scan.knn_kernel"


def _both(f: Callable[[], Any]) -> tuple[Any, Any]:
    """``f()`` with the C form, then with the numba form."""
    c_library(kk)
    got = f()
    with numba_form(KK):
        want = f()
    return got, want


def _wall(n: int, seed: int = 0) -> np.ndarray:
    """A scan of a cone wall (N, 3) [m]: points on z = −r·tan(50°), r 30–40 mm, uniform over the
    area (~0.34 mm apart at 30 k points), 20 µm noise (the paper cone's scans, smaller)."""
    rng = np.random.default_rng(seed)
    r = np.sqrt(rng.uniform(0.03**2, 0.04**2, n))
    t = rng.uniform(0.0, 2 * np.pi, n)
    X = np.column_stack([r * np.cos(t), r * np.sin(t), -r * np.tan(np.radians(50.0))])
    return X + rng.normal(0.0, 20e-6, (n, 3))


def _cloud(seed: int = 0) -> np.ndarray:
    """A wall with what the filter meets besides: a sparse line 36 mm above it (2 mm apart: its
    neighbours beyond the 3 × 3 × 3 block), repeated points (distance 0), strays 5–50 mm off
    (beyond the first rings)."""
    rng = np.random.default_rng(seed)
    X = _wall(30_000, seed)
    x = np.arange(-0.04, 0.04, 2e-3)
    line = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    d = rng.normal(size=(12, 3))
    strays = (
        X[rng.integers(0, len(X), 12)]
        + d / np.linalg.norm(d, axis=1)[:, None] * (rng.uniform(5e-3, 50e-3, 12)[:, None])
    )
    return np.vstack([X, line, X[:40], strays])


def _halo(seed: int = 0) -> np.ndarray:
    """:func:`_cloud` and what the block search leaves on the paper cone's scans: a sparse halo of
    scanner points ~5 mm off the wall (~2 of its cells here, as ~1 mm is on the paper cone), each
    alone in its cell, their 9th neighbour beyond the 3 × 3 × 3 block, most beyond ring 2, a few
    beyond ring 6; some of them in small clusters."""
    rng = np.random.default_rng(100 + seed)
    X = _cloud(seed)
    halo = X[rng.integers(0, 30_000, 400)] + rng.normal(0.0, 5e-3, (400, 3))
    clusters = np.repeat(halo[:40], 3, axis=0) + rng.normal(0.0, 1.2e-3, (120, 3))
    return np.vstack([X, halo, clusters])


def _sorted(X: np.ndarray, k: int = 8, wide: bool = False) -> tuple[Any, ...]:
    """The points sorted by cell and the grid, as mean_knn_distance makes them (its row starts
    int32; int64 — what above 2³¹ points are — when ``wide``)."""
    lo, h, shape, key, start = kk._grid(X, k, kk.MAX_CELLS)
    order = kk._counting_sort(key, start)
    Xs = gather_rows(X, kk._NO_ROWS, order)
    return Xs, start.astype(np.int64) if wide else start, lo, h, shape


# ---- cell keys and the counting sort -------------------------------------------------------


def _layouts(X: np.ndarray) -> dict[str, np.ndarray]:
    """The layouts _cell_keys gets: mean_knn_distance's rows= path takes the caller's points as
    they are (np.asarray): C order, a column slice of a wider table, rows backwards, Fortran."""
    W = np.hstack([X[:, :1], X, X[:, :1]])
    return {"C": X, "column slice": W[:, 1:4], "reversed": X[::-1], "F": np.asfortranarray(X)}


@pytest.mark.parametrize("wide", [False, True])
@pytest.mark.parametrize("layout", ["C", "column slice", "reversed", "F"])
def test_cell_keys_c_equals_numba(layout: str, wide: bool) -> None:
    P = _layouts(_cloud(1))[layout]
    n = P.shape[0]
    rng = np.random.default_rng(2)
    rows = rng.integers(0, n, 9000).astype(np.int64)
    rows[::3] -= n  # negative rows count from the end, as numba's do
    dt = np.int64 if wide else np.int32
    for R in (kk._NO_ROWS, rows, rows[:1]):
        Y = P[R] if R.size else P
        lo = Y.min(axis=0)
        h = 0.7e-3
        shape = kk._shape(Y.max(axis=0) - lo, h, kk.MAX_CELLS)

        def run(R: Any = R, lo: Any = lo, h: float = h, shape: Any = shape) -> tuple[Any, ...]:
            key = np.empty(R.size or P.shape[0], dt)
            counts = np.zeros(int(np.prod(shape)) + 1, dt)  # from index 1, as _grid's
            occupied = kk._cell_keys(P, R, lo, h, *shape, key, counts[1:])
            return key, counts, occupied

        (key, counts, occ), (key_n, counts_n, occ_n) = _both(run)
        assert key.dtype == dt and counts.dtype == dt
        np.testing.assert_array_equal(key, key_n)
        np.testing.assert_array_equal(counts, counts_n)
        assert occ == occ_n == np.count_nonzero(counts)
        # independently: min(int((x − lo) / h), n − 1) per axis
        ijk = np.minimum(((Y - lo) / h).astype(np.int64), np.array(shape) - 1)
        np.testing.assert_array_equal(
            key, (ijk[:, 0] * shape[1] + ijk[:, 1]) * shape[2] + ijk[:, 2]
        )
        assert counts.sum() == len(Y) and counts[0] == 0


def test_cell_keys_of_no_points() -> None:
    P = _wall(10)
    key = np.empty(0, np.int32)
    counts = np.zeros(8, np.int32)
    got, want = _both(lambda: kk._cell_keys(P, kk._NO_ROWS, P.min(0), 1.0, 2, 2, 2, key, counts))
    assert got == want == 0 and not counts.any()


@pytest.mark.parametrize("wide", [False, True])
def test_counting_sort_c_equals_numba(wide: bool) -> None:
    dt = np.int64 if wide else np.int32
    rng = np.random.default_rng(3)
    m = 5000  # cells, some empty, many keys per cell (a scan's grid)
    key = rng.integers(0, m, 60_000).astype(dt)
    start = np.zeros(m + 1, dt)
    np.add.at(start, key.astype(np.int64) + 1, 1)
    start = np.cumsum(start).astype(dt)

    def run() -> tuple[np.ndarray, np.ndarray]:
        s = start.copy()
        return kk._counting_sort(key, s), s

    (order, s), (order_n, s_n) = _both(run)
    assert order.dtype == dt
    np.testing.assert_array_equal(order, order_n)
    np.testing.assert_array_equal(order, np.argsort(key, kind="stable"))  # stable, by cell
    np.testing.assert_array_equal(s, s_n)
    np.testing.assert_array_equal(s, start)  # the row starts restored
    # no keys, a one-cell grid
    for k, st in ((np.zeros(0, dt), np.zeros(4, dt)), (np.zeros(3, dt), np.array([0, 3], dt))):
        got, want = _both(lambda k=k, st=st: kk._counting_sort(k, st.copy()))
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(got, np.arange(k.size))


# ---- the ring search -----------------------------------------------------------------------


@pytest.mark.parametrize("wide", [False, True])
@pytest.mark.parametrize("k", [8, 5, 1, 16])
def test_ring_search_c_equals_numba(k: int, wide: bool) -> None:
    Xs, start, lo, h, shape = _sorted(_cloud(4), k, wide)
    n = len(Xs)

    def run() -> np.ndarray:
        out = np.full(n, -1.0)
        kk._knn_mean(Xs, start, lo, h, *shape, k + 1, kk.MAX_RINGS, 0, n, out)
        return out

    got, want = _both(run)
    np.testing.assert_array_equal(got, want)  # NaN where both leave a point to the k-d tree
    strays = np.isnan(got)
    assert 1 <= strays.sum() <= 20  # strays (and the line's ends) beyond MAX_RINGS
    # the line: a k-th distance beyond 1.5 h, so resolved only in rings ≥ 2 (inner columns)
    assert (got[~strays] > 1.5 * h).sum() >= 20
    assert (got[~strays] == 0).any() == (k == 1)  # a repeated point's nearest is at 0
    # a part of the points: the others untouched
    part = np.full(n, -1.0)
    kk._knn_mean(Xs, start, lo, h, *shape, k + 1, kk.MAX_RINGS, 1000, 5000, part)
    np.testing.assert_array_equal(part[1000:5000], got[1000:5000])
    assert (part[:1000] == -1).all() and (part[5000:] == -1).all()
    # the strays again with the second search's rings (one point a call, as _sorted_mean)
    far = np.flatnonzero(strays)

    def rings() -> np.ndarray:
        out = got.copy()
        for i in far.tolist():
            kk._knn_mean(Xs, start, lo, h, *shape, k + 1, 40, i, i + 1, out)
        return out

    got2, want2 = _both(rings)
    np.testing.assert_array_equal(got2, want2)
    assert np.isfinite(got2[far]).any()  # resolved within the wider rings


def test_ring_and_block_search_strided_points_and_output() -> None:
    """The C form's strides: the points as a column slice of a wider array (a row stride of 5)
    and in Fortran order (a column stride of N), the output every other element of a vector —
    the numbers of the numba form on contiguous arrays."""
    Xs, start, lo, h, shape = _sorted(_cloud(5))
    n = len(Xs)
    with numba_form(KK):
        ring = np.empty(n)
        kk._knn_mean(Xs, start, lo, h, *shape, 9, kk.MAX_RINGS, 0, n, ring)
        block = np.empty(n)
        kk._knn_mean_block9(Xs, start, lo, h, *shape, kk._BLOCK, 0, start.size - 1, block)
    assert np.isnan(block).sum() > np.isnan(ring).sum() > 0
    c_library(kk)
    W = np.zeros((n, 5))
    W[:, 1:4] = Xs
    for P in (W[:, 1:4], np.asfortranarray(Xs)):
        out2 = np.full(2 * n, -1.0)
        kk._knn_mean(P, start, lo, h, *shape, 9, kk.MAX_RINGS, 0, n, out2[::2])
        kk._knn_mean_block9(P, start, lo, h, *shape, kk._BLOCK, 0, start.size - 1, out2[1::2])
        np.testing.assert_array_equal(out2[::2], ring)
        np.testing.assert_array_equal(out2[1::2], block)
        rows = np.full(n, -1.0)
        far = np.flatnonzero(np.isnan(block))
        kk._knn_mean_rows(P, start, lo, h, *shape, 9, kk.MAX_RINGS, far, rows)
        np.testing.assert_array_equal(rows[far], ring[far])


# ---- the block search (k = 8) and the rows it leaves ---------------------------------------


@pytest.mark.parametrize("wide", [False, True])
def test_block_search_c_equals_numba(wide: bool) -> None:
    """The block search over the cells in chunks (as _sorted_mean runs it), then the ring search
    of the rows it left NaN: both forms alike, and alike the ring search of every point. A pile
    of repeated scanner points holds more than the block's first buffer (4096 points)."""
    rng = np.random.default_rng(6)
    X = _cloud(6)
    pile = np.repeat(X[:1], 6000, axis=0) + rng.normal(0.0, 1e-7, (6000, 3))
    Xs, start, lo, h, shape = _sorted(np.vstack([X, pile]), 8, wide)
    n = len(Xs)
    assert np.diff(start).max() > 4096  # one cell alone overflows the first buffer
    cuts = [0, start.size // 3, start.size // 2, start.size - 1]

    def run() -> tuple[np.ndarray, np.ndarray]:
        out = np.full(n, -1.0)
        for a, b in itertools.pairwise(cuts):
            kk._knn_mean_block9(Xs, start, lo, h, *shape, kk._BLOCK, a, b, out)
        left = out.copy()
        kk._knn_mean_rows(
            Xs, start, lo, h, *shape, 9, kk.MAX_RINGS, np.flatnonzero(np.isnan(out)), out
        )
        return left, out

    (left, out), (left_n, out_n) = _both(run)
    np.testing.assert_array_equal(left, left_n)  # NaN: the points the block leaves
    np.testing.assert_array_equal(out, out_n)
    assert not (left == -1).any()  # every point written
    assert np.isnan(left).sum() > np.isnan(out).sum() >= 1  # the line's, then the strays'
    ring = np.empty(n)
    kk._knn_mean(Xs, start, lo, h, *shape, 9, kk.MAX_RINGS, 0, n, ring)
    np.testing.assert_array_equal(out, ring)  # the ring search's bits
    # an empty span of cells, and rows none
    for f in (
        lambda o: kk._knn_mean_block9(Xs, start, lo, h, *shape, kk._BLOCK, 5, 5, o),
        lambda o: kk._knn_mean_rows(Xs, start, lo, h, *shape, 9, 6, kk._NO_ROWS, o),
    ):
        o = np.full(n, -1.0)
        f(o)
        assert (o == -1).all()


# ---- the column search of the rows (_knn_mean_rows) against the ring search ------------------


def _ring_and_rows(
    Xs: np.ndarray, start: Any, lo: Any, h: float, shape: Any, k1: int, rings: int
) -> tuple[np.ndarray, np.ndarray]:
    """Every point by the ring search (_knn_mean) and by the column search (_knn_mean_rows, the
    rows in an order of their own and in parts, as _sorted_mean's threads call it)."""
    n = len(Xs)
    ring = np.full(n, -1.0)
    kk._knn_mean(Xs, start, lo, h, *shape, k1, rings, 0, n, ring)
    rows = np.full(n, -1.0)
    perm = np.random.default_rng(rings).permutation(n)
    for part in np.array_split(perm, 3):
        kk._knn_mean_rows(Xs, start, lo, h, *shape, k1, rings, part, rows)
    return ring, rows


@pytest.mark.parametrize("wide", [False, True])
@pytest.mark.parametrize("k", [8, 3, 16])
def test_column_search_gives_the_ring_search_s_numbers(k: int, wide: bool) -> None:
    """The column search of the rows is the ring search's result for every point and every
    number of rings — the same k + 1 nearest in the same cube, the same stop test, NaN where the
    ring search gives up — in both forms; the cloud has what it meets after the block search:
    a sparse halo resolved at rings 2–7, strays beyond them, a sparse line, repeated points."""
    Xs, start, lo, h, shape = _sorted(_halo(11), k, wide)
    block = np.full(len(Xs), -1.0)
    kk._knn_mean_block9(Xs, start, lo, h, *shape, kk._BLOCK, 0, start.size - 1, block)
    left = np.isnan(block)  # what the block search leaves (for k = 8: its grid)
    nan = {}
    for rings in (0, 1, 2, 4, kk.MAX_RINGS, 40):
        (ring, rows), (ring_n, rows_n) = _both(
            lambda rings=rings: _ring_and_rows(Xs, start, lo, h, shape, k + 1, rings)
        )
        np.testing.assert_array_equal(ring, ring_n)  # the oracle, both forms alike
        np.testing.assert_array_equal(rows, rows_n)
        np.testing.assert_array_equal(rows, ring)
        assert not (rows == -1).any()
        nan[rings] = np.isnan(rows)
    # resolved at every stage: the halo between rings 2 and 6, strays beyond, the rest at 40
    assert (nan[2] & ~nan[kk.MAX_RINGS]).sum() >= 100
    assert (nan[1] & ~nan[2]).sum() >= 20
    assert 5 <= (nan[kk.MAX_RINGS] & ~nan[40]).sum() <= 60
    assert nan[40].sum() <= 3
    assert nan[0].sum() > len(Xs) // 10  # the own cell alone settles few (its faces are near)
    if k == 8:
        assert left.sum() >= 300
        assert (left & nan[2] & ~nan[kk.MAX_RINGS]).sum() >= 100


def test_column_search_on_cell_faces_and_grid_edges() -> None:
    """Points of lattices on the cells' faces (a lattice of the cell side, shifted: its points
    are on faces up to rounding, and a column's run ends where the ring search's per-cell test
    keeps one cell more than the run's first guess — seeds found by search; a finer lattice),
    a grid of few cells per axis (the cube clipped on every side, faces outside the grid), one
    column (no x, y face at all), one cell: the column search is the ring search's numbers, in
    both forms."""
    cases = []
    # seeds found by search: without the run's one cell more below (91, 787) or above (4103,
    # 4670, 5483), the column search misses a neighbour of the ring search (k + 1 = 9 or 5)
    for seed in (91, 787, 4103, 4670, 5483):
        rng = np.random.default_rng(seed)
        h = [0.3e-3, 0.7e-3, 1.1e-3][seed % 3]
        g = np.arange(5 + seed % 4) * h
        lattice = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
        cases.append((lattice[rng.random(len(lattice)) < 0.6] + rng.uniform(-1e-3, 1e-3, 3), h))
    rng = np.random.default_rng(12)
    g = np.arange(0.0, 8e-3, 0.5e-3)
    fine = np.stack(np.meshgrid(g, g, [0.0, 1e-3, 3e-3]), -1).reshape(-1, 3)
    holes = fine[rng.random(len(fine)) > 0.6]  # sparse: beyond the first rings
    column = np.column_stack([np.zeros(40), np.zeros(40), np.arange(40) * 0.7e-3])
    cases += [
        (fine, 1e-3),
        (holes, 1e-3),
        (holes, 0.25e-3),
        (holes, 3e-3),
        (column, 1e-3),
        (rng.uniform(0, 1e-3, (30, 3)), 1e-3),
    ]
    for X, h in cases:
        lo = X.min(axis=0)
        shape = kk._shape(X.max(axis=0) - lo, h, kk.MAX_CELLS)
        key = np.empty(len(X), np.int32)
        start = np.zeros(int(np.prod(shape)) + 1, np.int32)
        kk._cell_keys(X, kk._NO_ROWS, lo, h, *shape, key, start[1:])
        start = np.cumsum(start).astype(np.int32)
        Xs = np.ascontiguousarray(X[kk._counting_sort(key, start)])
        grid = (Xs, start, lo, h, shape)
        nan = 0
        for k1, rings in itertools.product((9, 5), (0, 1, 2, 3, 6)):
            (ring, rows), (ring_n, rows_n) = _both(
                lambda k1=k1, rings=rings, grid=grid: _ring_and_rows(*grid, k1, rings)
            )
            np.testing.assert_array_equal(rows, ring)
            np.testing.assert_array_equal(rows_n, ring_n)
            np.testing.assert_array_equal(rows, rows_n)
            nan += np.isnan(rows).sum()
        assert nan > 0 or shape[0] * shape[1] <= 4  # some points beyond the rings


def test_filter_is_scipy_s_k_d_tree_bit_for_bit() -> None:
    """The whole filter (k = 8: block search, column search of what it leaves, the strays' wider
    search, the k-d tree for what is farther still) against scipy's k-d tree: the same nine
    distances summed in order for every point the compiled searches settle, the tree's own
    mean for those they leave to it — bit for bit. Each stage has points to do."""
    from scipy.spatial import cKDTree

    X = np.vstack([_halo(13), [[0.4, 0.4, 0.2], [0.4, 0.4, 0.2005], [-0.3, 0.1, 0.3]]])
    seen: list[tuple[int, int]] = []
    rows = kk._knn_mean_rows

    def spy(*a: Any) -> None:
        seen.append((int(a[8]), int(a[9].size)))
        rows(*a)

    for form in ("c", "numba"):
        seen.clear()
        kk._knn_mean_rows = spy
        try:
            if form == "c":
                c_library(kk)
                got = kk.mean_knn_distance(X, 8, workers=2)
            else:
                with numba_form(KK):
                    got = kk.mean_knn_distance(X, 8, workers=2)
        finally:
            kk._knn_mean_rows = rows
        assert sum(n for r, n in seen if r == kk.MAX_RINGS) >= 300  # the block's leftovers
        assert 0 < sum(n for r, n in seen if r > kk.MAX_RINGS) < 60  # strays: more rings
        d, _ = cKDTree(X).query(X, k=9)
        s = np.zeros(len(X))
        for t in range(1, 9):
            s += d[:, t]
        want = s / 8
        tree = np.zeros(len(X), bool)
        tree[-3:] = True  # beyond every ring: the k-d tree's mean (numpy's sum of the eight)
        want[tree] = d[tree, 1:].mean(axis=1)
        np.testing.assert_array_equal(got, want)


# ---- the public functions --------------------------------------------------------------------


@pytest.mark.parametrize("k", [8, 5])
def test_mean_knn_distance_c_equals_numba(k: int) -> None:
    """mean_knn_distance and its held form, all points and rows of them, in threads: the same
    bits; strays beyond the second search's rings too (finished by scipy's k-d tree)."""
    X = np.vstack([_cloud(7), [[0.4, 0.4, 0.2], [0.4, 0.4, 0.2005]]])
    rng = np.random.default_rng(8)
    rows = rng.permutation(len(X))[: len(X) // 2].astype(np.int64)

    def run() -> list[np.ndarray]:
        box = [X.copy()]
        held = kk.mean_knn_distance_held(box, k, workers=2)
        np.testing.assert_array_equal(box[0], X)  # the points given back
        return [
            kk.mean_knn_distance(X, k, workers=2),
            kk.mean_knn_distance(X, k, workers=1, rows=rows),
            held,
        ]

    got, want = _both(run)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)
        assert np.isfinite(g).all()
    np.testing.assert_array_equal(got[2], got[0])
    from scipy.spatial import cKDTree

    d, _ = cKDTree(X).query(X, k=k + 1)
    np.testing.assert_allclose(got[0], d[:, 1:].mean(axis=1), rtol=1e-14, atol=0)


@pytest.mark.parametrize(
    "cloud",
    ["one cell", "line", "plane", "k + 1 points", "identical"],
)
def test_mean_knn_distance_degenerate_clouds(cloud: str) -> None:
    """Clouds of one cell along an axis (a zero span: 1e-12), one cell in all (every face of
    the search outside the grid: its bound inf), exactly k + 1 points, all points equal."""
    rng = np.random.default_rng(9)
    x = rng.uniform(0.0, 0.05, 400)
    X = {
        "one cell": rng.uniform(0.0, 1e-4, (30, 3)),
        "line": np.column_stack([x, np.zeros_like(x), np.zeros_like(x)]),
        "plane": np.column_stack([x, rng.uniform(0.0, 0.05, 400), np.zeros_like(x)]),
        "k + 1 points": rng.uniform(0.0, 0.05, (9, 3)),
        "identical": np.tile([0.01, 0.02, 0.03], (20, 1)),
    }[cloud]
    for k in (8, 3):
        got, want = _both(lambda k=k: kk.mean_knn_distance(X, k, workers=1))
        np.testing.assert_array_equal(got, want)
        assert np.isfinite(got).all()
        if cloud == "identical":
            assert (got == 0).all()


# ---- what never reaches C --------------------------------------------------------------------


def test_wrong_arrays_are_refused_before_c() -> None:
    c_library(kk)
    Xs, start, lo, h, shape = _sorted(_wall(2000, 10))
    n = len(Xs)
    out = np.empty(n)
    ring = (lo, h, *shape, 9, kk.MAX_RINGS)
    with pytest.raises(TypeError):
        kk._knn_mean(Xs.astype(np.float32), start, *ring, 0, n, out)
    with pytest.raises(TypeError):
        kk._knn_mean(Xs, start.astype(np.float64), *ring, 0, n, out)
    with pytest.raises(TypeError):
        kk._knn_mean(Xs, start.astype(np.int16), *ring, 0, n, out)
    with pytest.raises(ValueError):
        kk._knn_mean(Xs, np.repeat(start, 2)[::2], *ring, 0, n, out)  # not contiguous
    with pytest.raises(TypeError):
        kk._knn_mean(Xs, start, *ring, 0, n, out.astype(np.float32))
    with pytest.raises(IndexError):
        kk._knn_mean(Xs, start, *ring, 0, n + 1, np.empty(n + 1))
    with pytest.raises(ValueError):  # a grid of another shape
        kk._knn_mean(Xs, start[:-1], *ring, 0, n, out)
    with pytest.raises(ValueError):
        kk._knn_mean(Xs, start, lo, h, *shape, 1, kk.MAX_RINGS, 0, n, out)  # k = 0
    with pytest.raises(IndexError):
        kk._knn_mean_rows(Xs, start, *ring, np.array([n], np.int64), out)
    with pytest.raises(IndexError):
        kk._knn_mean_block9(Xs, start, lo, h, *shape, kk._BLOCK, 0, start.size, out)
    with pytest.raises(ValueError):
        kk._knn_mean_block9(Xs, start, lo, h, *shape, kk._BLOCK[:26], 0, 3, out)
    key = np.zeros(n, np.int32)
    with pytest.raises(TypeError):  # the keys and the counts of one type
        kk._cell_keys(Xs, kk._NO_ROWS, lo, h, *shape, key, np.zeros(start.size, np.int64))
    with pytest.raises(IndexError):
        kk._cell_keys(Xs, np.array([0, n], np.int64), lo, h, *shape, key[:2], start * 0)
    with pytest.raises(TypeError):
        kk._counting_sort_into(key, start, np.empty(n, np.int64))


def test_the_c_form_runs_without_numba_s_knn_kernels() -> None:
    """With the C library built, the filter's calls never make a numba kernel of this module
    (each would import numba and compile or load it): in a fresh process, every path of
    mean_knn_distance — k = 8 with a stray left to the rings and the k-d tree, another k, rows,
    the held form — leaves them all unmade."""
    c_library(kk)
    code = """
import numpy as np
from roboisf.jit.shim import LazyKernel
from roboisf.scan import knn_kernel as kk
X = np.random.default_rng(0).uniform(0, 0.05, (3000, 3))
X = np.vstack([X, [[0.06, 0.06, 0.06], [0.5, 0.5, 0.5]]])
kk.mean_knn_distance(X, 8)
kk.mean_knn_distance(X, 5, rows=np.arange(0, len(X), 2))
kk.mean_knn_distance_held([X.copy()], 8)
made = [k for k, v in vars(kk).items() if k.endswith("_nb") and not isinstance(v, LazyKernel)]
made += [k for k, v in vars(kk).items() if isinstance(v, LazyKernel) and v._dispatcher is not None]
print(made)
"""
    env_root = Path(__file__).resolve().parents[1]
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=env_root, timeout=120
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
