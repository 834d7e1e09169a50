"""The toolpath statistics' C form (src/roboisf/scan/toolpath_kernel.c) against its numba form,
bit for bit: the contacts' neighbourhood statistics (median, trimmed mean, MAD, counts) and the
grid passes they start with (cell keys, counting sort), on a synthetic cone scan, on lattices of
ties, and on the edge cases the kernel has special paths for."""

from __future__ import annotations

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf.parts import Cone
from roboisf.scan import point_deviations, radial_offset, synthetic_scan
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


def test_c_refuses_a_non_finite_foot():
    """A NaN foot has no cell (numba's kernel writes outside its arrays): a ValueError in C
    (knn_kernel's grid pass, which this module's grid goes through; its equality with numba is
    tests/test_native_knn.py's)."""
    from roboisf.scan import knn_kernel

    c_library(knn_kernel)
    feet = np.random.default_rng(0).uniform(0, 1e-2, (100, 3))
    lo, h, (nx, ny, nz) = _grid_args(feet, 1e-3)
    feet[50, 1] = np.nan
    key = np.empty(100, dtype=np.int32)
    counts = np.zeros(nx * ny * nz, dtype=np.int32)
    with pytest.raises(ValueError, match="non-finite"):
        knn_kernel._cell_keys(feet, tk._NO_ROWS, lo, h, nx, ny, nz, key, counts)
