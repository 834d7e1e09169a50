"""Arrow arrays to numpy, without pandas.

pyarrow's own ``Array.to_numpy()`` (and ``np.asarray`` of an array) imports pandas on first use
(its pandas shim), ~47 MB of the process and ~0.2 s: reading a study's CSV tables and Parquet
logs would load it under the analysis's peak for nothing. A float column without nulls — what
the readers get from a valid file — is one contiguous buffer: a view of it is the same values.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["float_column", "float_values"]


def float_values(arr: Any) -> NDArray[np.floating[Any]] | None:
    """The values of a float32/float64 ``pyarrow.Array`` without nulls as a read-only numpy view
    of its data buffer (offset and length honoured); None for any other type, a half-float, or
    an array with nulls (the caller's general path then decides)."""
    import pyarrow as pa

    t = arr.type
    if arr.null_count or not pa.types.is_floating(t) or t.bit_width not in (32, 64):
        return None
    dt = np.dtype(np.float64 if t.bit_width == 64 else np.float32)
    n = len(arr)
    if n == 0:
        return np.empty(0, dtype=dt)
    return np.frombuffer(arr.buffers()[1], dtype=dt, count=n, offset=arr.offset * dt.itemsize)


def float_column(col: Any) -> NDArray[np.floating[Any]] | None:
    """:func:`float_values` of a ``pyarrow.ChunkedArray`` (a table's column): its chunks joined
    (one copy; a single chunk is its view), or None as there."""
    parts = [float_values(c) for c in col.chunks]
    if any(p is None for p in parts):
        return None
    if len(parts) == 1:
        return parts[0]
    if not parts:
        return np.empty(0, dtype=np.float64 if col.type.bit_width == 64 else np.float32)
    return np.concatenate(parts)  # type: ignore[arg-type]
