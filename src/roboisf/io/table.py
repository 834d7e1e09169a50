"""Numeric CSV tables with leading ``# key: value`` metadata lines (the roboisf exchange format).

Layout of every such file::

    # key: value          ← optional metadata, only before the header
    # another: value
    col_a,col_b,col_c     ← header (column names, case-sensitive, any order)
    1.0,2.0,3.0           ← numeric rows; blank lines are skipped

:func:`read_table` parses it once, vectorised, and reports the first bad row with its **file line
number** (1-based, counting every physical line of the file): rows with a wrong number of
columns, non-numeric cells, NaN/inf. Callers then check meaning (units, monotonicity) and use
:attr:`Table.lines` to name the line of a bad row.
"""

from __future__ import annotations

import io
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pacsv
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.io.text import read_text

__all__ = ["Table", "format_rows", "read_table"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Table:
    """A parsed numeric CSV.

    Attributes
    ----------
    path : Path — the file read
    meta : dict[str, str] — ``# key: value`` lines before the header (keys lower-cased)
    columns : tuple[str, ...] — header names as written
    data : (N, K) float — the rows, in file units
    lines : (N,) int — 1-based file line number of each row
    header_line : int — 1-based line number of the header
    """

    path: Path
    meta: dict[str, str]
    columns: tuple[str, ...]
    data: F64
    lines: NDArray[np.int64]
    header_line: int

    def column(self, name: str) -> F64:
        """The column ``name`` (N,) (must be in :attr:`columns`)."""
        return self.data[:, self.columns.index(name)]

    def has(self, *names: str) -> bool:
        return all(n in self.columns for n in names)

    def error(self, message: str, row: int | None = None, field: str | None = None) -> InputError:
        """An :class:`InputError` naming this file and the line of data row ``row`` (0-based)."""
        line = int(self.lines[row]) if row is not None else None
        return InputError(message, file=self.path, line=line, field=field)


def read_table(
    path: str | Path,
    required: Sequence[str],
    *,
    optional: Iterable[str] = (),
    what: str = "CSV",
    allow_extra: bool = False,
) -> Table:
    """Read a metadata + header + numeric-rows CSV (see module docstring).

    Parameters
    ----------
    path : the file
    required : column names that must be in the header
    optional : column names that may be in the header
    what : what the file is, for messages ("toolpath CSV", "force log")
    allow_extra : accept (and keep) columns outside ``required`` and ``optional``

    Raises
    ------
    InputError
        file missing or empty, header missing columns or with duplicates/unknown names, a row with
        the wrong number of cells, a non-numeric cell, NaN or inf — naming file, line and column.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} not found", file=path)
    raw = _head(path, what)  # metadata and header only; the body is parsed in C below
    meta: dict[str, str] = {}
    i = 0
    while i < len(raw):
        s = raw[i].strip()
        if not s:
            i += 1
            continue
        if not s.startswith("#"):
            break
        comment = s.lstrip("#").strip()
        if ":" in comment:
            key, _, value = comment.partition(":")
            key = key.strip().lower()
            if key in meta and meta[key] != value.strip():
                raise InputError(
                    f"metadata key {key!r} given twice with different values",
                    file=path,
                    line=i + 1,
                    field=key,
                )
            meta[key] = value.strip()
        i += 1
    if i == len(raw):
        raise InputError(
            f"{what} is empty; expected a header {','.join(required)} and data rows", file=path
        )
    header_line = i + 1
    columns = tuple(c.strip() for c in raw[i].split(","))
    dup = {c for c in columns if columns.count(c) > 1}
    if dup:
        raise InputError(
            f"duplicate column(s) {', '.join(sorted(dup))}", file=path, line=header_line
        )
    missing = [c for c in required if c not in columns]
    if missing:
        raise InputError(
            f"missing column(s) {', '.join(missing)}; expected header "
            f"{','.join(required)} (got {','.join(columns)})",
            file=path,
            line=header_line,
            field=missing[0],
        )
    if not allow_extra:
        known = set(required) | set(optional)
        extra = [c for c in columns if c not in known]
        if extra:
            raise InputError(
                f"unknown column(s) {', '.join(extra)}; expected {','.join(required)}"
                + (f" and optionally {','.join(optional)}" if optional else ""),
                file=path,
                line=header_line,
                field=extra[0],
            )
    fast = _fast_body(path, header_line, len(columns))
    if fast is not None:
        n = fast.shape[0]
        lines_fast = np.arange(header_line + 1, header_line + 1 + n, dtype=np.int64)
        return Table(path, meta, columns, fast, lines_fast, header_line)
    # slow path: find and name the offending line
    raw = read_text(path, what=what).splitlines()
    body_idx = [j for j in range(i + 1, len(raw)) if raw[j].strip()]
    if not body_idx:
        raise InputError(f"{what} has a header but no data rows", file=path)
    lines = np.asarray(body_idx, dtype=np.int64) + 1
    body = [raw[j] for j in body_idx]
    k = len(columns)
    counts = np.fromiter((ln.count(",") + 1 for ln in body), dtype=np.int64, count=len(body))
    if np.any(counts != k):
        r = int(np.argmax(counts != k))
        if body[r].lstrip().startswith("#"):
            raise InputError(
                "comment lines are only allowed before the header", file=path, line=int(lines[r])
            )
        raise InputError(
            f"expected {k} columns ({','.join(columns)}), got {counts[r]}",
            file=path,
            line=int(lines[r]),
        )
    try:
        # C parser, exact (round-trip) float conversion; the slow path below only runs to name
        # the offending cell when a cell is not a number
        data = pd.read_csv(
            io.StringIO("\n".join(body)),
            header=None,
            dtype=np.float64,
            engine="c",
            skip_blank_lines=False,
            na_filter=False,
        ).to_numpy()
    except ValueError:
        data = np.empty((len(body), k))
        for r, row in enumerate(ln.split(",") for ln in body):
            for c, cell in enumerate(row):
                try:
                    data[r, c] = float(cell)
                except ValueError:
                    raise InputError(
                        f"not a number: {cell.strip()!r}",
                        file=path,
                        line=int(lines[r]),
                        field=columns[c],
                    ) from None
    finite = np.isfinite(data)
    if not finite.all():
        r, c = np.argwhere(~finite)[0]
        raise InputError(
            f"{data[r, c]} is not a finite number",
            file=path,
            line=int(lines[r]),
            field=columns[c],
        )
    return Table(path, meta, columns, data, lines, header_line)


_FMT = re.compile(r"%\.(\d+)([fge])|%d")


def _round_column(col: F64, fmt: str) -> F64 | NDArray[np.int64]:
    m = _FMT.fullmatch(fmt)
    if m is None:
        raise ValueError(f"unsupported format {fmt!r} (use %d, %.Nf, %.Ng or %.Ne)")
    if fmt == "%d":
        return np.rint(col).astype(np.int64)
    digits, kind = int(m.group(1)), m.group(2)
    if kind == "f":
        return np.round(col, digits)
    # significant digits: %.Ng keeps N, %.Ne keeps N + 1
    sig = digits if kind == "g" else digits + 1
    out = col.copy()
    nz = (col != 0) & np.isfinite(col)
    x = col[nz]
    k = sig - 1 - np.floor(np.log10(np.abs(x)))  # decimals to keep (may be negative)
    # scale by an exact power of ten: 10**k for k ≥ 0 is exact up to 1e22, so divide by it
    # afterwards; for k < 0 divide first by the exact 10**−k and multiply back
    pos = k >= 0
    p = 10.0 ** np.abs(k)
    out_nz = np.where(pos, np.round(x * p) / p, np.round(x / p) * p)
    out[nz] = out_nz
    return out


def _head(path: Path, what: str) -> list[str]:
    """The file's lines up to and including the first non-blank, non-comment line."""
    out: list[str] = []
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for line in fh:
                out.append(line.rstrip("\r\n"))
                s = line.strip()
                if s and not s.startswith("#"):
                    break
    except UnicodeDecodeError:
        read_text(path, what=what)  # raises, naming the line and byte offset
        raise  # pragma: no cover - read_text raised above
    return out


def _fast_body(path: Path, header_line: int, k: int) -> F64 | None:
    """All rows after the header through pandas' C parser, or None when anything is off
    (a blank or comment line, a wrong cell count, a non-number, NaN/inf): the careful reader
    then finds the line to name. Trailing blank lines are fine."""
    try:
        data = pd.read_csv(
            path,
            skiprows=header_line,
            header=None,
            dtype=np.float64,
            engine="c",
            skip_blank_lines=False,
            na_filter=False,
            encoding="utf-8-sig",
        ).to_numpy()
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
        return None
    if data.ndim != 2 or data.shape[1] != k or data.shape[0] == 0:
        return None
    if not np.all(np.isfinite(data)):
        return None
    return data


def format_rows(data: F64, formats: Sequence[str]) -> str:
    """Format an (N, K) array as CSV rows, column j at the precision of ``formats[j]``.

    Each column is rounded to its format's precision (``%.Nf`` decimals, ``%.Ng`` significant
    digits, ``%d`` integers) and written by pyarrow's C CSV writer as the shortest decimal that
    reads back to the rounded value — the digits ``%`` would print, without a Python loop over
    rows (≈ 20× faster on million-row force logs).
    """
    if data.shape[1] != len(formats):
        raise ValueError("one format per column")
    arrays = [
        pa.array(_round_column(np.asarray(data[:, j], dtype=float), f))
        for j, f in enumerate(formats)
    ]
    table = pa.Table.from_arrays(arrays, names=[f"c{j}" for j in range(len(formats))])
    buf = io.BytesIO()
    pacsv.write_csv(table, buf, pacsv.WriteOptions(include_header=False, quoting_style="none"))
    return buf.getvalue().decode()


def finite_float(text: str, *, file: str | Path | None = None, field: str | None = None) -> float:
    """Parse a metadata number (raising InputError naming the field)."""
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"expected a number, got {text!r}", file=file, field=field) from None
    if not math.isfinite(v):
        raise InputError(f"expected a finite number, got {text!r}", file=file, field=field)
    return v
