"""ISO / Fanuc / Haas G-code (``%``, ``O…``, ``N…``, ``G``/``M`` words, ``X…``):
:mod:`roboisf.cam.gcode`. Recognised by such a word at a line's start."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from roboisf.cam.camformat import CamSpec, code_lines, head_lines
from roboisf.formats import FileFormat, register_format

_HINT = re.compile(r"^\s*(%|O\d|N\d|[GM]\d|[XYZF][-+.\d])", re.I)


def detect(path: Path) -> bool:
    return any(_HINT.match(ln) for ln in code_lines(head_lines(path)))


def read(path: Path, options: Any, *, units: str | None, feed: float) -> Any:
    from roboisf.cam.gcode import read_iso_moves

    return read_iso_moves(path, options)


register_format(
    FileFormat(
        name="iso",
        kind="cnc",
        label="ISO G-code",
        suffixes=(".nc", ".gcode", ".ngc", ".tap", ".cnc", ".iso", ".g", ".eia", ".min", ".ptp"),
        reader=read,
        detect=detect,
        rank=40,
        spec=CamSpec(),
    )
)
