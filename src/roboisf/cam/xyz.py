"""A bare point list ``x,y,z[,i,j,k]`` (one tool position per row) as CAM moves.

Read with :func:`pandas.read_csv`. The separator is found from the first data row: ``;`` (then a
decimal comma ``1,5`` is read as 1.5), tab (decimal comma allowed), ``,``, or runs of spaces.
Lines starting with ``#`` or ``//`` are comments; a ``# units: mm|m|in`` comment sets the length
unit (otherwise the ``units`` argument, default mm). An optional header row names the columns:
``x,y,z`` and optionally ``i,j,k`` (any case; other columns are refused so that nothing is
silently dropped). Without a header, 3 columns are ``x,y,z`` and 6 are ``x,y,z,i,j,k``.

Every row is a feed move at ``feed`` (the list has no feeds); rows are numbered by their file
line in every error.
"""

from __future__ import annotations

import io
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from roboisf.cam.cam import FEED, CamMoves
from roboisf.cam.gcode import MAX_NUMBER
from roboisf.errors import InputError
from roboisf.io.text import read_text

__all__ = ["XYZ_UNITS", "read_xyz_moves"]

#: Length units of a point list [m per unit].
XYZ_UNITS = {"mm": 1e-3, "m": 1.0, "in": 25.4e-3, "inch": 25.4e-3}
_DECIMAL_COMMA = re.compile(r"\d,\d")
_LETTER = re.compile(r"[A-DF-Za-df-z_]")  # letters other than the exponent e/E


def _separator(row: str) -> tuple[str, str]:
    """(sep, decimal) for pandas from one data row."""
    if ";" in row:
        return ";", "," if _DECIMAL_COMMA.search(row) else "."
    if "\t" in row:
        return "\t", "," if _DECIMAL_COMMA.search(row) else "."
    if "," in row:
        return ",", "."
    return r"\s+", "."


def read_xyz_moves(
    path: str | Path, *, units: str | None = None, feed: float = 750.0 / 60e3
) -> CamMoves:
    """The rows of a point list as feed moves (see the module docstring).

    Parameters
    ----------
    path : the file
    units : length unit of the file (``mm``, ``m``, ``in``); a ``# units:`` comment wins over the
        default (mm) but must agree with an explicit ``units``
    feed : float, m/s — the feed of every move
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("point list not found", file=path)
    if not (math.isfinite(feed) and feed > 0):
        raise InputError(f"must be > 0 mm/min, got {feed * 60e3:g}", field="feed")
    text = read_text(path, what="point list")
    rows: list[str] = []
    lines: list[int] = []
    file_unit: str | None = None
    header: list[str] | None = None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#") or s.startswith("//"):
            m = re.match(r"^(?:#|//)\s*units?\s*[:=]\s*(?:length\s*=\s*)?(\w+)", s, re.I)
            if m:
                file_unit = m[1].lower()
                if file_unit not in XYZ_UNITS:
                    raise InputError(
                        f"unknown length unit {m[1]!r}; expected one of {', '.join(XYZ_UNITS)}",
                        file=path,
                        line=lineno,
                    )
            continue
        if not rows and header is None and _LETTER.search(s):
            sep, _ = _separator(s)
            header = [h.strip().strip('"').lower() for h in re.split(sep, s)]
            header_line = lineno
            continue
        rows.append(s)
        lines.append(lineno)
    if not rows:
        raise InputError("no data rows (expected x,y,z[,i,j,k] per line)", file=path)
    if units is not None and file_unit is not None and units != file_unit:
        raise InputError(
            f"the file declares units {file_unit!r} but {units!r} was given", file=path
        )
    unit = file_unit or units or "mm"
    if unit not in XYZ_UNITS:
        raise InputError(
            f"unknown length unit {unit!r}; expected one of {', '.join(XYZ_UNITS)}", field="units"
        )
    sep, _ = _separator(rows[0])
    dec = "." if sep == "," else ("," if any(_DECIMAL_COMMA.search(r) for r in rows) else ".")
    names: list[str]
    if header is not None:
        allowed = ["x", "y", "z", "i", "j", "k"]
        bad = [h for h in header if h not in allowed]
        if bad or not {"x", "y", "z"} <= set(header) or len(set(header)) != len(header):
            raise InputError(
                f"header {header!r}: expected the columns x, y, z and optionally i, j, k",
                file=path,
                line=header_line,
            )
        names = header
    else:
        n = len(re.split(sep, rows[0]))
        if n not in (3, 6):
            raise InputError(
                f"{n} values per row; expected x,y,z or x,y,z,i,j,k (or a header naming them)",
                file=path,
                line=lines[0],
            )
        names = ["x", "y", "z", "i", "j", "k"][:n]
    try:
        df = pd.read_csv(
            io.StringIO("\n".join(rows)),
            sep=sep,
            header=None,
            names=names,
            dtype=str,
            na_filter=False,
            engine="python",
            skipinitialspace=True,
        )
    except pd.errors.ParserError as e:
        m = re.search(r"line (\d+)", str(e))
        line = lines[int(m[1]) - 1] if m and int(m[1]) <= len(lines) else None
        raise InputError(
            f"expected {len(names)} values per row ({', '.join(names)})", file=path, line=line
        ) from None
    data = np.empty((len(df), len(names)))
    for j, name in enumerate(names):
        cells = df[name].str.replace(",", ".", regex=False) if dec == "," else df[name]
        col = pd.to_numeric(cells, errors="coerce").to_numpy(dtype=float)
        bad_rows = ~(np.isfinite(col) & (np.abs(col) <= MAX_NUMBER))
        if bad_rows.any():
            r = int(np.argmax(bad_rows))
            raw = df[name].iloc[r]
            missing = not isinstance(raw, str) or not raw.strip()
            what = "missing" if missing else f"{raw!r} is not a finite number ≤ {MAX_NUMBER:g}"
            raise InputError(
                f"{what} (separator {sep!r}, decimal {dec!r})",
                file=path,
                line=lines[r],
                field=name,
            )
        data[:, j] = col
    xyz = data[:, [names.index(a) for a in "xyz"]] * XYZ_UNITS[unit]
    axis = None
    if "i" in names:
        if not {"i", "j", "k"} <= set(names):
            raise InputError("a tool axis needs all of i, j, k", file=path, field="header")
        axis = data[:, [names.index(a) for a in "ijk"]]
        norm = np.linalg.norm(axis, axis=1)
        if np.any(norm < 1e-9):
            r = int(np.argmax(norm < 1e-9))
            raise InputError("zero tool axis i,j,k", file=path, line=lines[r])
        axis = axis / norm[:, None]
    n = len(xyz)
    return CamMoves(
        path=path,
        point=xyz,
        kind=np.full(n, FEED, dtype=np.int64),
        feed=np.full(n, feed),
        line=np.array(lines, dtype=np.int64),
        dwell=np.zeros(n),
        tool_axis=axis,
        notes=[f"point list: every row a feed move at {feed * 60e3:g} mm/min, {unit}"],
        warnings=[],
        meta={"dialect": "xyz", "units": [unit], "separator": sep, "decimal": dec},
    )
