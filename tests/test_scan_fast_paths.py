"""The scan comparison's faster numpy paths give the bits of the ones they replace (issue #31):
the deviation statistics' block sums, the finiteness check."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.scan.readers import check_finite
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


def test_check_finite_names_the_first_bad_point():
    X = np.zeros((10, 3))
    check_finite(X, "a.ply")
    X[7, 2], X[9, 0] = np.nan, -np.inf
    with pytest.raises(
        InputError, match=r"2 point\(s\) have NaN or inf coordinates \(first: point 7\)"
    ):
        check_finite(X, "a.ply")
