"""Numeric CSV tables with leading ``# key: value`` metadata lines (the roboisf exchange format),
and logs as instruments write them (:func:`read_log_table`).

Layout of every roboisf table::

    # key: value          ← optional metadata, only before the header
    # another: value
    col_a,col_b,col_c     ← header (column names in any case, any order)
    1.0,2.0,3.0           ← numeric rows; blank lines are skipped

Read with Arrow's CSV reader (a large file with pandas' C parser in blocks: :func:`_fast_body`).
Also accepted, as spreadsheets and instruments write them: a semicolon or tab separator (taken
from the header line), a decimal comma (with a separator other than the comma), a UTF-8
byte-order mark, and lines of free text before the header (the header is the first line naming
a known column).

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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.io.arrow import float_column
from roboisf.io.text import read_text

__all__ = [
    "LogTable",
    "Table",
    "find_log_header",
    "format_rows",
    "read_log_table",
    "read_table",
    "split_name_unit",
]

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


#: pandas' options for rows of numbers only: every cell float64 through the C parser, a blank
#: line or an empty cell a NaN row (which the callers refuse) rather than skipped
_NUMERIC_ROWS: dict[str, Any] = dict(
    header=None, dtype=np.float64, engine="c", skip_blank_lines=False, na_filter=False
)


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
    known = [*required, *optional]
    raw = _head(path, what, known)  # metadata, free text and header; the body is parsed in C
    meta: dict[str, str] = {}
    i = 0
    while i < len(raw):
        s = raw[i].strip()
        if not s:
            i += 1
            continue
        if not s.startswith("#"):
            if i < len(raw) - 1:  # free text before the header (an instrument's preamble)
                i += 1
                continue
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
    sep = _table_sep(raw[i])
    # names in any case, quotes stripped; written as the reader's callers know them
    by_lower = {k.lower(): k for k in known}
    cells = [c.strip().strip('"').strip() for c in raw[i].split(sep)]
    columns = tuple(by_lower.get(c.lower(), c) for c in cells)
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
        extra = [c for c in columns if c not in set(known)]
        if extra:
            raise InputError(
                f"unknown column(s) {', '.join(extra)}; expected {','.join(required)}"
                + (f" and optionally {','.join(optional)}" if optional else ""),
                file=path,
                line=header_line,
                field=extra[0],
            )
    decimal = _table_decimal(path, header_line, sep)
    fast = _fast_body(path, header_line, len(columns), sep, decimal)
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
    counts = np.fromiter((ln.count(sep) + 1 for ln in body), dtype=np.int64, count=len(body))
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
    import pandas as pd  # here only: a valid table of ≤ ARROW_MAX_BYTES needs no pandas

    try:
        # C parser, exact (round-trip) float conversion; the slow path below only runs to name
        # the offending cell when a cell is not a number
        data = pd.read_csv(
            io.StringIO("\n".join(body)), sep=sep, decimal=decimal, **_NUMERIC_ROWS
        ).to_numpy()
    except ValueError:
        data = np.empty((len(body), k))
        for r, row in enumerate(ln.split(sep) for ln in body):
            for c, cell in enumerate(row):
                v = cell.strip().strip('"')  # quoted, a number still (as the C parsers read it)
                try:
                    data[r, c] = float(v.replace(",", ".") if decimal == "," else v)
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


def _table_sep(header: str) -> str:
    """The separator of a table's header: comma, else semicolon, else tab."""
    for sep in (",", ";", "\t"):
        if sep in header:
            return sep
    return ","


def _table_decimal(path: Path, header_line: int, sep: str) -> str:
    """ "," when the separator is not a comma and the first data row has a decimal comma."""
    if sep == ",":
        return "."
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for n, line in enumerate(fh, start=1):
            if n > header_line and line.strip():
                cells = [c.strip() for c in line.split(sep)]
                return "," if any(_DECIMAL_COMMA.match(c) for c in cells) else "."
    return "."


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


def _head(path: Path, what: str, known: Sequence[str] = ()) -> list[str]:
    """The file's lines up to and including the header: the first non-blank, non-comment line
    that names a known column (case-insensitive), within the first 200 lines — lines of free
    text before it are an instrument's preamble; without such a line, the first non-comment
    line (the caller then names what is missing)."""
    out: list[str] = []
    first: int | None = None
    names = {k.lower() for k in known}
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for n, line in enumerate(fh):
                out.append(line.rstrip("\r\n"))
                s = line.strip()
                if not s or s.startswith("#"):
                    continue
                if first is None:
                    first = n
                cells = {c.strip().strip('"').strip().lower() for c in re.split(r"[,;\t]", s)}
                if not names or cells & names:
                    return out
                if n >= 200:
                    break
    except UnicodeDecodeError:
        read_text(path, what=what)  # raises, naming the line and byte offset
        raise  # pragma: no cover - read_text raised above
    return out[: first + 1] if first is not None else out


def _body_lines(path: Path, header_line: int) -> int | None:
    """Physical lines after the header, trailing blank lines not counted (None when more than
    the last 4 kB are blank: the careful reader then counts). Read 1 MB at a time."""
    n = 0
    tail = b""
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            n += chunk.count(b"\n")
            tail = (tail + chunk[-4096:])[-4096:]
    last = tail.split(b"\n")
    lines = n + (0 if tail.endswith(b"\n") or not tail else 1)
    if tail.endswith(b"\n"):
        last = last[:-1]
    blank = 0
    for ln in reversed(last):
        if ln.strip():
            break
        blank += 1
    else:
        return None
    return lines - header_line - blank


def _fast_body(
    path: Path, header_line: int, k: int, sep: str = ",", decimal: str = "."
) -> F64 | None:
    """All rows after the header, or None when anything is off (a blank or comment line inside,
    a wrong cell count, a non-number, NaN/inf): the careful reader then finds the line to name.

    A file of up to :data:`ARROW_MAX_BYTES` (a toolpath, a thickness table) is parsed whole by
    Arrow's CSV reader: correctly rounded floats, the same bits as pandas' C parser on every file
    tested (the paper cone's 35 k-row toolpath; 200 k random 17-digit and 6-decimal values), in
    25–35 ms instead of 51–138, and without importing pandas (~47 MB of the process, which an
    analysis then loads only after its scans' peak). A larger one (a 1 kHz force log) goes
    through pandas' C parser in blocks of 2¹⁷ rows into one array sized by the file's line
    count: the peak is the data and one block (a 159 MB force log: +0.40 GB read whole,
    +0.15 GB in blocks, the same bits), and the parser lets go of the GIL between blocks, so a
    thread beside it (the scans) is not held up. Arrow's streaming reader was tried for those:
    +0.15 GB more at the peak on that log (its freed blocks stayed resident), and no faster."""
    n = _body_lines(path, header_line)
    if n is None or n <= 0:
        return None
    if path.stat().st_size <= ARROW_MAX_BYTES:
        return _arrow_body(path, header_line, n, k, sep, decimal)
    return _blocks(
        path,
        n,
        k,
        skiprows=header_line,
        sep=sep,
        decimal=decimal,
        encoding="utf-8-sig",
        **_NUMERIC_ROWS,
    )


#: Largest table [bytes] :func:`_fast_body` parses with Arrow (whole); above it, pandas in blocks.
ARROW_MAX_BYTES = 32 * 1024 * 1024


def _arrow_body(path: Path, header_line: int, n: int, k: int, sep: str, decimal: str) -> F64 | None:
    """The ``n`` rows of ``k`` numbers after line ``header_line`` through ``pyarrow.csv``, or
    None unless there are exactly ``n`` rows of ``k`` finite numbers."""
    import pyarrow as pa  # on first use: the kernels' build needs this module, not Arrow
    import pyarrow.csv as pacsv

    names = [f"c{j}" for j in range(k)]
    try:
        table = pacsv.read_csv(
            path,
            read_options=pacsv.ReadOptions(skip_rows=header_line, column_names=names),
            parse_options=pacsv.ParseOptions(delimiter=sep, ignore_empty_lines=True),
            convert_options=pacsv.ConvertOptions(
                column_types=dict.fromkeys(names, pa.float64()),
                decimal_point=decimal,
                null_values=[],
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
            ),
        )
    except (pa.ArrowException, OSError, ValueError):
        return None
    if table.num_rows != n:
        return None
    data = np.empty((n, k))
    for j in range(k):
        v = float_column(table.column(j))
        if v is None:
            return None
        data[:, j] = v
    if not np.all(np.isfinite(data)):
        return None
    return data


def _blocks(path: Path, n: int, k: int, **read_csv: Any) -> F64 | None:
    """``n`` rows of ``k`` numbers through ``pandas.read_csv(path, **read_csv)`` in blocks of
    2¹⁷ rows into one (n, k) array; None unless there are exactly ``n`` rows of ``k`` finite
    numbers (or when pandas refuses the text)."""
    import pandas as pd  # large tables and instrument logs only

    data = np.empty((n, k))
    o = 0
    try:
        with pd.read_csv(path, chunksize=1 << 17, **read_csv) as reader:
            for block in reader:
                m = len(block)
                if o + m > n or block.shape[1] != k:
                    return None
                data[o : o + m] = block.to_numpy()
                o += m
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
        return None
    if o != n or not np.all(np.isfinite(data)):
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
    import pyarrow as pa
    import pyarrow.csv as pacsv

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


# -- logs as instruments write them ------------------------------------------------------------
#
# A logger's text export: a free-text block (instrument, date, sample rate, units), a header row
# of channel names (any case, units in brackets allowed: "Fx [N]", "Fz (N)"), optionally a row
# of units under it ("s  N  N  N"), then the numbers; any separator (comma, semicolon, tab,
# whitespace), decimal point or decimal comma, quoted cells, a UTF-8 byte-order mark.

_SEPARATORS: tuple[tuple[str, str], ...] = (
    ("\t", "tab"),
    (";", "semicolon"),
    (",", "comma"),
    (r"\s+", "whitespace"),
)
_UNIT_IN_NAME = re.compile(r"^(.*?)\s*(?:\[([^\]]*)\]|\(([^)]*)\)|/\s*([A-Za-z°µ·.*]+))\s*$")
_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+(?:[eE][+-]?\d+)?$")


def split_name_unit(cell: str) -> tuple[str, str | None]:
    """``"Fx [N]"`` → ``("fx", "N")``; ``"Time (s)"`` → ``("time", "s")``; ``"q1"`` → ``("q1",
    None)``. The name is lower-cased with runs of blanks and ``_`` folded to one space."""
    s = cell.strip().strip('"').strip()
    unit = None
    m = _UNIT_IN_NAME.match(s)
    if m and m.group(1):
        s = m.group(1)
        unit = next(g for g in m.groups()[1:] if g is not None).strip() or None
    name = re.sub(r"[\s_]+", " ", s.strip().lower())
    return name, unit


def _split(line: str, sep: str) -> list[str]:
    cells = re.split(sep, line.strip()) if sep == r"\s+" else line.split(sep)
    return [c.strip().strip('"').strip() for c in cells]


def _is_number(cell: str, decimal: str) -> bool:
    c = cell.replace(decimal, ".") if decimal == "," else cell
    try:
        float(c)
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class LogTable:
    """A logger's text export, parsed (see :func:`read_log_table`).

    Attributes
    ----------
    path : Path
    meta : dict[str, str] — ``# key: value`` lines (keys lower-cased)
    preamble : dict[str, str] — ``key: value`` / ``key<TAB>value`` lines of the free-text block
        before the header (keys lower-cased, stripped)
    columns : tuple[str, ...] — the header cells as written
    names : tuple[str, ...] — the header names, normalised (:func:`split_name_unit`)
    units : dict[str, str] — canonical column → unit declared in the header name or units row
    data : dict[str, (N,) float] — canonical column → values in file units
    lines : (N,) int — 1-based file line of each row
    header_line : int — 1-based line of the header
    separator : str — "comma" | "semicolon" | "tab" | "whitespace"
    decimal : str — "." or ","
    """

    path: Path
    meta: dict[str, str]
    preamble: dict[str, str]
    columns: tuple[str, ...]
    names: tuple[str, ...]
    units: dict[str, str]
    data: dict[str, F64]
    lines: NDArray[np.int64]
    header_line: int
    separator: str
    decimal: str
    col_index: dict[str, int] = field(default_factory=dict)

    def error(self, message: str, row: int | None = None, field: str | None = None) -> InputError:
        """An :class:`InputError` naming this file and the line of data row ``row`` (0-based)."""
        line = int(self.lines[row]) if row is not None else None
        return InputError(message, file=self.path, line=line, field=field)


#: A column matcher: canonical name → a predicate on the normalised header name.
ColumnMatch = dict[str, "re.Pattern[str]"]


def _decode_log(path: Path, what: str) -> str:
    try:
        data = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read {what}: {e.strerror}", file=path) from None
    if not data.removeprefix(b"\xef\xbb\xbf").strip():
        # said as such: an empty file was "no force-log format recognised: expected a header …"
        raise InputError(
            f"{what} is empty (a logger that never wrote, or a copy that failed)", file=path
        )
    if b"\x00" in data[:4096] and not data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputError(
            f"{what} is a binary file; expected a text export (CSV/TXT) or a .parquet log",
            file=path,
        )
    try:
        from roboisf.io.text import decode_utf8

        return decode_utf8(data, file=path, what=what)
    except InputError:
        if data.startswith((b"\xff\xfe", b"\xfe\xff")):
            raise
        # Windows loggers (DynoWare, KUKA WorkVisual) write cp1252: "°", "µ"; every byte decodes
        return data.decode("cp1252", errors="replace")


#: Lines of a log searched for its header.
_HEADER_LINES = 400


def find_log_header(
    lines: Sequence[str],
    match: ColumnMatch,
    required: Sequence[str],
    *,
    max_lines: int = _HEADER_LINES,
) -> tuple[int, str, dict[str, int]] | None:
    """The first line (0-based index) whose cells, split by one of the separators, name every
    ``required`` canonical column; with that separator's name and the column index of each
    matched canonical column. None if no such line within ``max_lines``."""
    for i, line in enumerate(lines[:max_lines]):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        for sep, sep_name in _SEPARATORS:
            cells = _split(s, sep)
            if len(cells) < 2:
                continue
            names = [split_name_unit(c)[0] for c in cells]
            found: dict[str, int] = {}
            for canon, pat in match.items():
                for j, nm in enumerate(names):
                    if j not in found.values() and pat.fullmatch(nm):
                        found[canon] = j
                        break
            if all(r in found for r in required):
                return i, sep_name, found
    return None


def read_log_table(
    path: str | Path,
    match: ColumnMatch,
    required: Sequence[str],
    *,
    what: str = "log",
    expected: str = "",
) -> LogTable:
    """Read a logger's text export: find the header naming every ``required`` column (matched
    by the regular expressions of ``match`` on the normalised names), sniff the separator and
    the decimal mark, and parse the matched columns with pandas' C parser (other columns, such
    as a status word or a date string, are ignored).

    Parameters
    ----------
    path : the file
    match : canonical column → compiled pattern that the normalised header name must fullmatch
    required : canonical columns that must be found
    what : what the file is, for messages ("force log")
    expected : a description of the expected header, for the message when none is found

    Raises
    ------
    InputError
        no header line naming the required columns (the message lists what was expected and
        the first header-like line seen), a row with too few cells, a cell that is not a number,
        NaN or inf — naming file, line and column.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} not found", file=path)
    head = _log_head(path)
    if head is not None:  # a long file: its layout from the head, the body in blocks
        raw, encoding = head
        layout = _log_layout(path, raw, match, required, what, expected, complete=False)
        if layout is not None:
            fast = _log_body_blocks(path, layout, encoding)
            if fast is not None:
                return _log_table(path, layout, *fast)
    # a short file, or anything the fast reader would not take: every line in memory, and the
    # careful pass names the line of a bad cell
    raw = _decode_log(path, what).splitlines()
    layout = _log_layout(path, raw, match, required, what, expected, complete=True)
    assert layout is not None
    body = "\n".join(raw[j] for j in layout.body_idx)
    data = _parse_log_body(path, body, layout.sep, layout.decimal, layout.cols, layout.ncol)
    if data is None or not np.all(np.isfinite(data)):
        # name the short row or the cell that is not a number (a literal nan/inf is kept and
        # reported below)
        data = _locate_bad_cell(
            path, raw, layout.body_idx, layout.sep, layout.decimal, layout.idx, layout.header_cells
        )
    return _log_table(path, layout, data, np.asarray(layout.body_idx, dtype=np.int64) + 1)


#: Bytes of a log read to find its layout (header, units row, separator, decimal mark) before
#: the body is parsed in blocks; a file this short is read whole.
_HEAD_BYTES = 1 << 20


def _log_head(path: Path) -> tuple[list[str], str] | None:
    """The first lines of a long log (up to :data:`_HEAD_BYTES`, whole lines) and the encoding
    pandas should read it with, or None: a short file, UTF-16, or a binary file (the whole-file
    reader then decides, and names what is wrong)."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(_HEAD_BYTES + 1)
    except OSError:
        return None
    if len(data) <= _HEAD_BYTES or b"\x00" in data[:4096]:
        return None
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return None
    data = data[: data.rfind(b"\n") + 1]
    try:
        text = data.decode("utf-8-sig")
        encoding = "utf-8-sig"
    except UnicodeDecodeError:
        text, encoding = data.decode("cp1252", errors="replace"), "cp1252"
    lines = text.splitlines()  # as the whole-file reader splits them
    if len(lines) != text.count("\n"):
        return None  # other line breaks (a lone CR): the rows' line numbers are the reader's
    return lines, encoding


@dataclass(frozen=True)
class _LogLayout:
    """Where a log's header, units and rows are, and how its cells are written."""

    hi: int  # 0-based line of the header
    sep: str
    sep_name: str
    idx: dict[str, int]  # canonical column → cell index
    header_cells: list[str]
    names_units: list[tuple[str, str | None]]
    meta: dict[str, str]
    preamble: dict[str, str]
    units: dict[str, str]
    body_idx: list[int]  # 0-based lines of the data rows (of the lines given)
    decimal: str

    @property
    def cols(self) -> list[int]:
        return sorted(self.idx.values())

    @property
    def ncol(self) -> int:
        return len(self.header_cells)


def _log_layout(
    path: Path,
    raw: list[str],
    match: ColumnMatch,
    required: Sequence[str],
    what: str,
    expected: str,
    *,
    complete: bool,
) -> _LogLayout | None:
    """The layout of a log from its lines ``raw`` (all of them when ``complete``, else its
    head: None when the head does not settle it)."""
    found = find_log_header(raw, match, required, max_lines=_HEADER_LINES)
    if found is None:
        if not complete and len(raw) < _HEADER_LINES:
            return None  # the header may lie past the head
        first = next((x.strip() for x in raw if x.strip() and not x.lstrip().startswith("#")), "")
        raise InputError(
            f"no header line naming the columns {expected or ', '.join(required)} (case and "
            "units in brackets do not matter; separator comma, semicolon, tab or blanks); "
            f"first line seen: {first[:80]!r}",
            file=path,
        )
    hi, sep_name, idx = found
    sep = dict((n, s) for s, n in _SEPARATORS)[sep_name]
    header_cells = _split(raw[hi].strip(), sep)
    names_units = [split_name_unit(c) for c in header_cells]
    meta: dict[str, str] = {}
    preamble: dict[str, str] = {}
    for j in range(hi):
        s = raw[j].strip()
        if not s:
            continue
        if s.startswith("#"):
            body = s.lstrip("#").strip()
            if ":" in body:
                k, _, v = body.partition(":")
                meta[k.strip().lower()] = v.strip()
            continue
        s = s.strip('"')
        for delim in (":", "\t", "=", ";", ","):
            if delim in s:
                k, _, v = s.partition(delim)
                if k.strip():
                    preamble.setdefault(k.strip().lower(), v.strip().strip('"').strip())
                break
    units = {c: u for c, j in idx.items() if (u := names_units[j][1]) is not None}
    # data rows: blank lines skipped; an optional units row right under the header
    body_idx = [j for j in range(hi + 1, len(raw)) if raw[j].strip()]
    if not complete and len(body_idx) < 52:
        return None  # the head does not hold the units row and 50 rows to sniff
    if not body_idx:
        raise InputError(f"{what} has a header but no data rows", file=path, line=hi + 1)
    first_cells = _split(raw[body_idx[0]], sep)
    cols = sorted(idx.values())
    probe = [first_cells[j] for j in cols if j < len(first_cells)]
    if probe and not any(_is_number(c, ".") or _is_number(c, ",") for c in probe):
        for canon, j in idx.items():
            if j < len(first_cells) and first_cells[j]:
                u = first_cells[j].strip("[]() ")
                if canon in units and units[canon] != u:
                    raise InputError(
                        f"column {header_cells[j]!r} declares unit {units[canon]!r} in its name "
                        f"but {u!r} in the units row",
                        file=path,
                        line=body_idx[0] + 1,
                        field=canon,
                    )
                units[canon] = u
        body_idx = body_idx[1:]
        if not body_idx:
            raise InputError(f"{what} has a header but no data rows", file=path, line=hi + 1)
    sample = [_split(raw[j], sep) for j in body_idx[:50]]
    decimal = "."
    if sep != ",":
        cells = [r[j] for r in sample for j in cols if j < len(r)]
        if any(_DECIMAL_COMMA.match(c) for c in cells):
            decimal = ","
    return _LogLayout(
        hi, sep, sep_name, idx, header_cells, names_units, meta, preamble, units, body_idx, decimal
    )


def _log_body_blocks(
    path: Path, layout: _LogLayout, encoding: str
) -> tuple[F64, NDArray[np.int64]] | None:
    """The matched columns of every row from the first data row on, through pandas' C parser
    in blocks of 2¹⁷ rows into one array sized by the file's line count (the whole-file reader
    held the text, its lines and the parse at once: a 2.3 M-row, 160 MB force log peaked at
    2.2 GB), and the rows' 1-based lines; None when the rows are not every line (a blank line
    inside), or anything else is off: the whole-file reader then decides."""
    first = layout.body_idx[0]
    if layout.body_idx != list(range(first, first + len(layout.body_idx))):
        return None  # blank lines among the first rows
    n = _body_lines(path, first)
    if n is None or n <= 0:
        return None
    data = _blocks(
        path,
        n,
        len(layout.cols),
        skiprows=first,
        sep=layout.sep,
        decimal=layout.decimal,
        names=list(range(layout.ncol)),
        usecols=layout.cols,
        quotechar='"',
        skipinitialspace=True,
        index_col=False,
        encoding=encoding,
        **_NUMERIC_ROWS,
    )
    if data is None:
        return None
    return data, np.arange(first + 1, first + 1 + n, dtype=np.int64)


def _log_table(path: Path, layout: _LogLayout, data: F64, lines: NDArray[np.int64]) -> LogTable:
    cols = layout.cols
    out = {canon: data[:, cols.index(j)] for canon, j in layout.idx.items()}
    finite = np.column_stack(list(out.values()))
    ok = np.isfinite(finite)
    if not ok.all():
        r, c = np.argwhere(~ok)[0]
        canon = list(out)[c]
        raise InputError(
            f"{finite[r, c]} is not a finite number", file=path, line=int(lines[r]), field=canon
        )
    return LogTable(
        path,
        layout.meta,
        layout.preamble,
        tuple(layout.header_cells),
        tuple(n for n, _ in layout.names_units),
        layout.units,
        out,
        lines,
        layout.hi + 1,
        layout.sep_name,
        layout.decimal,
        dict(layout.idx),
    )


def _parse_log_body(
    path: Path, body: str, sep: str, decimal: str, cols: list[int], ncol: int
) -> F64 | None:
    """The matched columns through pandas' C parser (python engine for a regex separator), or
    None when anything is off: the careful pass then names the line."""
    import pandas as pd

    try:
        df = pd.read_csv(
            io.StringIO(body),
            sep=sep,
            decimal=decimal,
            header=None,
            names=list(range(ncol)),
            usecols=cols,
            dtype=np.float64,
            engine="python" if sep == r"\s+" else "c",
            quotechar='"',
            skipinitialspace=True,
            na_filter=False,
            index_col=False,
        )
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    arr = df.to_numpy()
    if arr.ndim != 2 or arr.shape[1] != len(cols):
        return None
    return arr


def _locate_bad_cell(
    path: Path,
    raw: list[str],
    body_idx: list[int],
    sep: str,
    decimal: str,
    idx: dict[str, int],
    header_cells: list[str],
) -> F64:
    cols = sorted(idx.values())
    canon_of = {j: c for c, j in idx.items()}
    out = np.empty((len(body_idx), len(cols)))
    for r, j in enumerate(body_idx):
        cells = _split(raw[j], sep)
        if len(cells) <= cols[-1]:
            raise InputError(
                f"expected at least {cols[-1] + 1} cells ({', '.join(header_cells)}), got "
                f"{len(cells)}",
                file=path,
                line=j + 1,
            )
        for k, c in enumerate(cols):
            cell = cells[c].replace(",", ".") if decimal == "," else cells[c]
            try:
                out[r, k] = float(cell)
            except ValueError:
                raise InputError(
                    f"not a number: {cells[c]!r} (decimal mark {decimal!r})",
                    file=path,
                    line=j + 1,
                    field=canon_of[c],
                ) from None
    return out
