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


_TABLE_CASES = {
    "plain": "# units: x=mm\nx,y,z\n1.5,2,-3e-4\n0.1,0.2,0.30000000000000004\n",
    "semicolon, decimal comma": "x;y;z\n1,5;2;-0,0003\n0,1;0,2;0,3\n",
    "quoted, CRLF, trailing blank lines": 'x,y,z\r\n"1.5",2,3\r\n4,5,6\r\n\r\n\r\n',
    "tab, BOM": "\ufeffx\ty\tz\n1\t2\t3\n",
}


@pytest.mark.parametrize("case", list(_TABLE_CASES))
def test_a_table_reads_the_same_bits_through_arrow_and_through_pandas(case, tmp_path, monkeypatch):
    """``read_table``'s two fast paths — Arrow whole (small files) and pandas' C parser in
    blocks (large ones) — give the same rows and the same line numbers; a small table is read
    by Arrow alone (pandas' parser made to fail meanwhile)."""
    import pandas as pd

    from roboisf.io import table as T

    p = tmp_path / "t.csv"
    p.write_bytes(_TABLE_CASES[case].encode("utf-8"))

    def no_pandas(*a, **k):
        raise AssertionError("a small valid table must be read by Arrow")

    with monkeypatch.context() as m:  # neither pandas' blocks nor the careful reader's parse
        m.setattr(pd, "read_csv", no_pandas)
        a = T.read_table(p, ("x", "y", "z"))
    monkeypatch.setattr(T, "ARROW_MAX_BYTES", 0)  # every file is "large": pandas in blocks
    b = T.read_table(p, ("x", "y", "z"))
    np.testing.assert_array_equal(a.data.view(np.int64), b.data.view(np.int64))
    np.testing.assert_array_equal(a.lines, b.lines)
    assert a.data.shape == (1 if "tab" in case else 2, 3)


def test_a_bad_row_is_named_whichever_path_read_it(tmp_path, monkeypatch):
    from roboisf.errors import InputError
    from roboisf.io import table as T

    p = tmp_path / "t.csv"
    p.write_text("x,y,z\n1,2,3\n4,oops,6\n7,8,9\n")
    for limit in (T.ARROW_MAX_BYTES, 0):
        monkeypatch.setattr(T, "ARROW_MAX_BYTES", limit)
        with pytest.raises(InputError, match="not a number") as e:
            T.read_table(p, ("x", "y", "z"))
        assert e.value.line == 3 and e.value.field == "y"
