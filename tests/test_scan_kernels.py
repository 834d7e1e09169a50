"""The scan comparison's compiled kernels give the numbers of their reference paths (scipy's
k-d tree and numpy): per-toolpath-point neighbourhood statistics and the outlier k-NN."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.jit import background as jit_background
from roboisf.jit import native
from roboisf.parts import Cone
from roboisf.parts.mesh_kernel import gather_rows
from roboisf.scan import (
    PointDeviations,
    knn_kernel,
    point_deviations,
    radial_offset,
    synthetic_scan,
    toolpath_deviations,
    toolpath_kernel,
)
from roboisf.toolpath import step_down

needs_numba = pytest.mark.skipif(not toolpath_kernel.HAVE_NUMBA, reason="numba not installed")

CONE = Cone()
OFFSET = radial_offset(lambda z, phi: 0.5e-3 + 1e-3 * (-z) + 0.2e-3 * np.cos(3 * phi), CONE)


def _both(monkeypatch, dev, P, N, **kw):
    """The toolpath deviations by the compiled kernel and by the k-d tree reference."""
    a = toolpath_deviations(dev, P, N, **kw)
    with monkeypatch.context() as m:
        m.setitem(jit_background._decided, "scan", False)  # a cold kernel cache
        m.setattr(native, "_suspended", 1)  # and no C form: the numpy path
        b = toolpath_deviations(dev, P, N, **kw)
    return a, b


def _equal(a, b):
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.n_points, b.n_points)
    np.testing.assert_array_equal(a.dn, b.dn)  # the same bits
    np.testing.assert_array_equal(a.spread, b.spread)


@pytest.fixture(scope="module")
def scan_dev():
    s = synthetic_scan(CONE, 150_000, offset=OFFSET, noise=25e-6, outlier_fraction=0.01, seed=5)
    return point_deviations(s.points, CONE)


@needs_numba
@pytest.mark.parametrize("estimator", ["median", "trimmed"])
@pytest.mark.parametrize(("radius", "max_points"), [(1e-3, 16), (0.6e-3, 7), (2e-3, 300)])
def test_toolpath_kernel_equals_the_tree(monkeypatch, scan_dev, estimator, radius, max_points):
    """Holes, partial neighbourhoods (fewer than max_points within the radius), full ones
    (the k nearest of more: 16 of ~20, 7 of ~8), even and odd counts, both estimators."""
    tp = step_down(CONE, 5e-3, 1e-3, spacing=2e-3)
    kw = dict(radius=radius, max_points=max_points, estimator=estimator)
    a, b = _both(monkeypatch, scan_dev, tp.contact, tp.normal, **kw)
    _equal(a, b)
    n = a.n_points
    assert ((n > 0) & (n < max_points)).any()
    if max_points <= 16:  # ~20 points within 1 mm on this scan: the k nearest of more
        assert (n == max_points).any()
    assert (n % 2 == 0).any() and (n % 2 == 1).any()
    assert a.valid.sum() > 0.5 * len(n)
    # off the scan (a hole): no neighbour, dn = spread = 0, exactly as the tree
    far = tp.contact + np.array([0.0, 0.0, 0.2])
    a, b = _both(monkeypatch, scan_dev, np.vstack([tp.contact, far]), np.vstack([tp.normal] * 2))
    _equal(a, b)
    assert (a.n_points[len(far) :] == 0).all()


@needs_numba
def test_toolpath_kernel_small_cases(monkeypatch):
    """One foot, few feet (k capped by their number), duplicates at equal distances, a contact
    exactly on a foot, feet on a line (degenerate grid box), a huge radius on a small cloud."""
    rng = np.random.default_rng(1)
    for n, radius in [(1, 1e-3), (5, 1e-3), (40, 1e-3), (200, 0.05)]:
        foot = rng.uniform(-1e-3, 1e-3, (n, 3))
        if n == 40:
            foot[:, 1:] = 0.0  # a line
            foot[20:] = foot[:20]  # duplicates
        dn = rng.normal(0, 1e-4, n)
        dev = PointDeviations(foot, foot, np.tile([0.0, 0.0, 1.0], (n, 1)), dn, np.ones(n, int))
        P = np.vstack([foot[:3], rng.uniform(-1.5e-3, 1.5e-3, (50, 3))])
        N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
        for est in ("median", "trimmed"):
            a, b = _both(monkeypatch, dev, P, N, radius=radius, min_points=1, estimator=est)
            _equal(a, b)


@needs_numba
def test_toolpath_kernel_refuses_like_the_tree(scan_dev):
    with pytest.raises(InputError, match="no toolpath point") as ei:
        toolpath_deviations(scan_dev, [[0.0, 0.0, 0.5]], [[0.0, 0.0, 1.0]], source="path.csv")
    assert "path.csv" in str(ei.value)


def test_kernels_are_the_optional_numba_ones():
    assert toolpath_kernel.HAVE_NUMBA == knn_kernel.HAVE_NUMBA


@needs_numba
def test_outlier_knn_by_query_cell_equals_the_ring_search():
    """The cell-by-cell k-NN of the default k (one neighbour-cell list per query cell, the nine
    nearest in registers) gives the ring search's bits for every point: a dense scan patch, a
    sparse line (points resolved only in rings beyond the 3 × 3 × 3 block), duplicates and
    strays (left to the k-d tree: NaN in both)."""
    rng = np.random.default_rng(7)
    patch = np.column_stack([rng.uniform(0, 0.02, (60_000, 2)), rng.normal(0, 2e-5, 60_000)])
    x = np.arange(0, 0.02, 0.5e-3)
    line = np.column_stack([x, np.full(x.size, 0.025), np.zeros(x.size)])
    stray = np.array([[0.01, 0.01, 0.01], [0.0, 0.02, -0.01]])
    X = np.vstack([patch, line, patch[:50], stray])
    k = 8
    lo, h, shape, key, start = knn_kernel._grid(X, k, knn_kernel.MAX_CELLS)
    order = knn_kernel._counting_sort(key, start)
    Xs = gather_rows(X, knn_kernel._NO_ROWS, order)
    n = len(X)
    ring, cells = np.empty(n), np.empty(n)
    args = (Xs, start, lo, h, *shape, k + 1, knn_kernel.MAX_RINGS)
    knn_kernel._knn_mean(*args, 0, n, ring)
    knn_kernel._knn_mean_block9(
        Xs, start, lo, h, *shape, knn_kernel._BLOCK, 0, start.size - 1, cells
    )
    unsettled = np.flatnonzero(np.isnan(cells))  # beyond the block: the ring search after it
    assert unsettled.size > np.isnan(ring).sum()  # the line's points are among them
    knn_kernel._knn_mean_rows(*args, unsettled, cells)
    np.testing.assert_array_equal(cells, ring)  # NaN where both leave it to the tree
    assert 2 <= np.isnan(ring).sum() <= 20  # the strays and the line's ends
    # on the line (0.5 mm spacing, ~0.4 mm cells) the neighbours lie beyond the block
    assert (ring[np.isfinite(ring)] > 2 * h).sum() > 20


@needs_numba
def test_outlier_knn_block_buffer_grows_for_a_dense_cell():
    """A block holding more points than the block kernel's first buffer (4096: a pile of
    repeated scanner points in one cell) grows the buffer and still gives the ring search's
    bits — the pile, its neighbours and the points beyond."""
    rng = np.random.default_rng(11)
    patch = np.column_stack([rng.uniform(0, 0.01, (20_000, 2)), rng.normal(0, 2e-5, 20_000)])
    pile = np.repeat(patch[:1], 6000, axis=0) + rng.normal(0, 1e-7, (6000, 3))
    X = np.vstack([patch, pile])
    lo, h, shape, key, start = knn_kernel._grid(X, 8, knn_kernel.MAX_CELLS)
    order = knn_kernel._counting_sort(key, start)
    Xs = gather_rows(X, knn_kernel._NO_ROWS, order)
    assert np.diff(start).max() > 4096  # one cell alone overflows the first buffer
    n = len(X)
    ring, block = np.empty(n), np.empty(n)
    args = (Xs, start, lo, h, *shape, 9, knn_kernel.MAX_RINGS)
    knn_kernel._knn_mean(*args, 0, n, ring)
    knn_kernel._knn_mean_block9(
        Xs, start, lo, h, *shape, knn_kernel._BLOCK, 0, start.size - 1, block
    )
    # the points of the cells around the pile: the first of them to be searched grew its
    # buffer past 4096 with points in it already; the block itself settles them (none is left
    # to the ring search after it)
    nx, ny, nz = shape
    ci, cj, ck = np.unravel_index(int(np.argmax(np.diff(start))), shape)
    near = [
        (ci + a) * ny * nz + (cj + b) * nz + (ck + c)
        for a, b, c in knn_kernel._BLOCK[1:]
        if 0 <= ci + a < nx and 0 <= cj + b < ny and 0 <= ck + c < nz
    ]
    rows = np.concatenate([np.arange(start[e], start[e + 1]) for e in near])
    assert rows.size > 20 and np.isfinite(block[rows]).all()
    knn_kernel._knn_mean_rows(*args, np.flatnonzero(np.isnan(block)), block)
    np.testing.assert_array_equal(block, ring)


@pytest.mark.parametrize("kind", ["cone", "vwacf", "pyramid"])
def test_registration_closest_points_in_threads_equal_one_call(kind, monkeypatch):
    """The registration's chunked, threaded closest-point query gives one call's rows, bit for
    bit, on the analytic parts (their queries are elementwise)."""
    from dataclasses import fields

    from roboisf.parts import VWACF, Pyramid
    from roboisf.scan import registration
    from roboisf.scan.registration import _CHUNK, _closest

    monkeypatch.setattr(registration.os, "cpu_count", lambda: 4)  # threads on any machine
    part = {"cone": CONE, "vwacf": VWACF(), "pyramid": Pyramid()}[kind]
    lo, hi = (np.asarray(b) for b in part.bounds)
    n = 2 * _CHUNK + 1001
    P = np.random.default_rng(4).uniform(lo - 2e-3, hi + 2e-3, (n, 3))
    a, b = _closest(part, P), part.closest_point(P)
    assert type(a) is type(b)
    for f in fields(b):
        np.testing.assert_array_equal(getattr(a, f.name), getattr(b, f.name))
