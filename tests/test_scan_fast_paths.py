"""The scan comparison's faster numpy paths give the bits of the ones they replace (issue #31):
the deviation statistics' block sums, the transform of a scan into the work frame, the
finiteness check, the toolpath statistics' small ball first."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames.se3 import transform_points
from roboisf.jit import HAVE_NUMBA
from roboisf.scan import toolpath_kernel
from roboisf.scan.compare import _einsum_order, _to_work
from roboisf.scan.readers import ScanCloud, check_finite, read_scan
from roboisf.scan.summary import block_sums, dn_block_sums


def _reduction(delta: np.ndarray) -> np.ndarray:
    """block_sums as it was: numpy's reductions of the (M, 3) block along its rows."""
    out = np.empty((3, 3))
    out[0] = delta.sum(axis=0)
    np.abs(delta, out=delta)
    out[1] = delta.sum(axis=0)
    out[2] = delta.max(axis=0)
    return out


@pytest.mark.parametrize("m", [1, 2, 3, 7, 1000, 65_536, 12_345])
def test_block_sums_are_the_rows_reduction_bit_for_bit(m):
    rng = np.random.default_rng(m)
    # magnitudes spread over many decades: any other order of the additions shows
    d = rng.normal(size=(m, 3)) * rng.lognormal(0.0, 6.0, (m, 1))
    nrm = rng.normal(size=(m, 3))
    np.testing.assert_array_equal(block_sums(d.copy()), _reduction(d.copy()))
    np.testing.assert_array_equal(
        dn_block_sums(d[:, 1].copy(), nrm), _reduction(d[:, 1, None] * nrm)
    )
    # not C-contiguous: the reduction itself (numpy sums such a block pairwise)
    f = np.asfortranarray(d)
    np.testing.assert_array_equal(block_sums(f.copy(order="F")), _reduction(f.copy(order="F")))
    fn = np.asfortranarray(nrm)
    np.testing.assert_array_equal(dn_block_sums(d[:, 1], fn), _reduction(d[:, 1, None] * fn))


def test_block_sums_of_negative_zeros_are_positive_zeros_as_the_reduction():
    z = -np.zeros((5, 3))
    a, b = block_sums(z.copy()), _reduction(z.copy())
    np.testing.assert_array_equal(np.signbit(a), np.signbit(b))
    np.testing.assert_array_equal(
        np.signbit(dn_block_sums(-np.zeros(5), np.ones((5, 3)))), np.signbit(b)
    )


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("n", [1, 5, 40_000, 70_001])
def test_scan_into_the_work_frame_is_transform_points_bit_for_bit(seed, n):
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 0.05, (n, 3))
    X[: min(n, 3)] = 0.0  # zero rows: the sign of a zero as transform_points'
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = (Q if seed else np.eye(3)), rng.normal(0.0, 1e-3, 3) * (seed > 1)
    ref = transform_points(T, X)
    out = _to_work(T, X, own=False)
    assert out is not X
    np.testing.assert_array_equal(out, ref)
    np.testing.assert_array_equal(np.signbit(out), np.signbit(ref))
    mine = X.copy()
    got = _to_work(T, mine, own=True)
    np.testing.assert_array_equal(got, ref)
    assert (got is mine) == _einsum_order()  # in place where the columns' sums are einsum's


def test_a_numpy_whose_einsum_adds_otherwise_gets_transform_points(monkeypatch):
    from roboisf.scan import compare

    monkeypatch.setattr(compare, "_EINSUM_ORDER", [False])
    X = np.random.default_rng(0).normal(0.0, 0.05, (100, 3))
    T = np.eye(4)
    T[:3, 3] = 1e-3
    mine = X.copy()
    out = _to_work(T, mine, own=True)
    assert out is not mine
    np.testing.assert_array_equal(out, transform_points(T, X))
    np.testing.assert_array_equal(mine, X)


def test_the_reader_s_points_are_overwritten_only_when_nobody_else_holds_them(tmp_path):
    path = tmp_path / "s.xyz"
    np.savetxt(path, np.random.default_rng(0).normal(0.0, 10.0, (50, 3)))
    cloud = read_scan(path)
    pts, own = cloud.take_own_points()
    assert own and pts.shape == (50, 3) and cloud.points.shape == (0, 3)
    with pytest.raises(InputError, match="already taken"):
        cloud.take_own_points()
    cloud = read_scan(path)
    kept = cloud.points  # the caller holds them: not ours to overwrite
    assert not cloud.take_own_points()[1]
    del kept
    cloud = read_scan(path)
    cloud.points = cloud.points * 1.0  # put in by the caller
    assert not cloud.take_own_points()[1]
    assert not ScanCloud(np.ones((4, 3)), None, "x.ply").take_own_points()[1]


def test_check_finite_names_the_first_bad_point():
    X = np.zeros((10, 3))
    check_finite(X, "a.ply")
    X[7, 2], X[9, 0] = np.nan, -np.inf
    with pytest.raises(
        InputError, match=r"2 point\(s\) have NaN or inf coordinates \(first: point 7\)"
    ):
        check_finite(X, "a.ply")


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed")
@pytest.mark.parametrize("lattice", [False, True])
def test_toolpath_statistics_small_ball_first_are_the_whole_ball_s_bits(lattice):
    """The contacts' neighbourhoods searched in the last one's k-th distance first are the
    whole ball's numbers, bit for bit: on a noisy surface, and on a lattice of feet whose
    distances tie at every rank with dn that repeat and hold ±0 (the whole ball's search then
    decides)."""
    rng = np.random.default_rng(7)
    if lattice:
        g = np.arange(-60, 61) * 0.1e-3
        x, y = np.meshgrid(g, g)
        feet = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
        feet = np.vstack([feet, feet + np.array([0.0, 0.0, 0.1e-3])])
        dn = rng.integers(-3, 4, len(feet)) * 1e-5
        dn[rng.random(len(feet)) < 0.05] = -0.0
    else:
        feet = rng.uniform(-6e-3, 6e-3, (150_000, 3))
        feet[:, 2] = 1e-3 * np.sin(300 * feet[:, 0]) + rng.normal(0, 20e-6, len(feet))
        dn = rng.normal(0.0, 1e-4, len(feet))
    t = np.linspace(0.0, 1.0, 3000)
    P = np.column_stack([4e-3 * t * np.cos(40 * t), 4e-3 * t * np.sin(40 * t), np.zeros_like(t)])
    if lattice:
        P[::7, :2] = np.round(P[::7, :2] / 0.1e-3) * 0.1e-3  # on a lattice point: ties
    else:
        P[:, 2] = 1e-3 * np.sin(300 * P[:, 0])
    for k, radius in [(64, 1e-3), (16, 0.5e-3), (7, 0.3e-3)]:
        for trim in (0.2, 0.1):
            a = toolpath_kernel.contact_statistics(feet, dn, P, radius=radius, k=k, trim=trim)
            b = toolpath_kernel.contact_statistics(
                feet, dn, P, radius=radius, k=k, trim=trim, widen=0.0
            )
            assert (a[0] == k).mean() > 0.5
            for u, v in zip(a, b, strict=True):
                np.testing.assert_array_equal(u, v)
                np.testing.assert_array_equal(np.signbit(u), np.signbit(v))
