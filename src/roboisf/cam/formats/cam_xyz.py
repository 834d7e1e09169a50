"""A point list (``x,y,z`` rows, any separator, an optional header): :mod:`roboisf.cam.xyz`.
Recognised by rows of numbers without G, M or N words; never by suffix alone (.csv and .txt say
nothing). Its length unit and feed are the import's (a list states neither)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from roboisf.cam.camformat import CamSpec, code_lines, head_lines
from roboisf.formats import FileFormat, register_format

_NUMERIC_ROW = re.compile(r"^\s*[-+.\d]")


def detect(path: Path) -> bool:
    rows = [ln for ln in code_lines(head_lines(path)) if not ln.startswith(";")]
    if not rows or not all(_NUMERIC_ROW.match(ln) for ln in rows[1:] or rows):
        return False
    return not any(re.search(r"[GMN]\d", ln, re.I) for ln in rows)


def read(path: Path, options: Any, *, units: str | None, feed: float) -> Any:
    from roboisf.cam.xyz import read_xyz_moves

    return read_xyz_moves(path, units=units, feed=feed)


register_format(
    FileFormat(
        name="xyz",
        kind="cnc",
        label="x,y,z point list",
        suffixes=(".xyz", ".txt", ".dat", ".asc", ".csv", ".tsv"),
        reader=read,
        detect=detect,
        rank=30,
        spec=CamSpec(takes_units=True, by_suffix=False),
    )
)
