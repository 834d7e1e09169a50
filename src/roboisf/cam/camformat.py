"""What a CAM program format registers besides its reader: how a file is recognised.

A CAM format (ISO G-code, Sinumerik, APT/CL, a point list) is a :class:`roboisf.formats.FileFormat`
of kind ``cnc`` whose ``spec`` is a :class:`CamSpec`; its ``reader`` is
``read(path, options: ReadOptions, *, units, feed) -> CamMoves`` and its ``detect(path)`` looks at
the program's head (:func:`head_lines`, :func:`code_lines`). The CAM import
(:func:`roboisf.toolpath.importer.detect_toolpath_format`) tries the registered detectors in rank
order, then the suffixes of the formats that allow it. Imports nothing heavy.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from roboisf.errors import InputError

__all__ = ["HEAD_LINES", "CamSpec", "code_lines", "head_lines"]

#: How many lines of a file the detectors look at.
HEAD_LINES = 40


@dataclass(frozen=True)
class CamSpec:
    """A CAM format's import options: ``takes_units`` — the reader takes a length unit (a point
    list; a program declares its own: G20/G21, INCH/METRIC, UNITS/); ``by_suffix`` — its
    suffixes decide when no detector recognises the content (False for a point list, whose
    suffixes — .csv, .txt — say nothing)."""

    takes_units: bool = False
    by_suffix: bool = True


def head_lines(path: Path, n: int = HEAD_LINES) -> list[str]:
    """The first ``n`` non-blank lines of ``path``, stripped; ``InputError`` if unreadable."""
    try:
        with path.open("r", encoding="utf-8-sig", errors="replace") as fh:
            head = [fh.readline() for _ in range(n)]
    except OSError as e:
        raise InputError(f"cannot read the file ({e.strerror})", file=path) from None
    return [ln.strip() for ln in head if ln.strip()]


def code_lines(head: list[str]) -> list[str]:
    """``head`` without comment lines (``(…)``, ``#``, ``//``) and parenthesised comments."""
    return [re.sub(r"\([^)]*\)", "", ln) for ln in head if not ln.startswith(("(", "#", "//"))]
