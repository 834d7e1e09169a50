"""Arrow arrays to numpy without pandas (:mod:`roboisf.io.arrow`): the same values as Arrow's
own conversion, for the buffers' offsets, both float widths, and None where a view is wrong."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from roboisf.io.arrow import float_column, float_values


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_float_values_are_the_arrays_values_at_any_offset(dtype):
    x = np.random.default_rng(1).normal(size=1000).astype(dtype)
    arr = pa.array(x)
    for sl in (arr, arr.slice(0, 10), arr.slice(333), arr.slice(997, 3), arr.slice(5, 0)):
        v = float_values(sl)
        assert v is not None and v.dtype == dtype
        np.testing.assert_array_equal(v, sl.to_numpy(zero_copy_only=False))


def test_nulls_other_types_and_half_floats_are_left_to_the_caller():
    assert float_values(pa.array([1.0, None, 3.0])) is None
    assert float_values(pa.array([1, 2, 3])) is None
    assert float_values(pa.array(["1.0"])) is None
    assert float_values(pa.array(np.ones(3, dtype=np.float16))) is None


def test_a_chunked_column_is_joined_in_order():
    a, b = np.arange(5.0), np.arange(5.0, 12.0)
    col = pa.chunked_array([pa.array(a), pa.array(b).slice(2)])
    np.testing.assert_array_equal(float_column(col), np.concatenate([a, b[2:]]))
    one = pa.chunked_array([pa.array(a)])
    np.testing.assert_array_equal(float_column(one), a)
    assert float_column(pa.chunked_array([pa.array([1.0, None])])) is None
    empty = float_column(pa.chunked_array([], type=pa.float64()))
    assert empty is not None and empty.size == 0
