"""ISO G-code (RS-274 / ISO 6983) for a 3-axis CNC mill with the tool along z.

Dialect written::

    %
    (roboisf 0.1.0 ISF toolpath: ...)
    (units mm, absolute; programmed point = ball tip, set the tool length to the tip)
    G21 G90 G17 G94
    G00 Z10.000                         ← safe height above the sheet
    G00 X38.671 Y0.000                  ← above the first point
    G01 X38.671 Y0.000 Z-3.862 F750     ← plunge to the first point at the feed
    G01 X38.670 Y0.185 Z-3.862          ← every forming move: X Y Z (tip, mm, 1 µm)
    ...
    G00 Z10.000
    M30
    %

The parser reads this dialect and the common variants: modal G0/G1 (with or without leading
zero), axis words that keep their previous value when omitted, ``( )`` and ``;`` comments, line
numbers ``N…``, ``G20`` (inch), ``F`` in units per minute. It refuses ``G91`` (incremental) and
arcs (``G02/G03``), which a roboisf program never contains.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from roboisf import __version__
from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.io.program import ProgramPath, check_safe_height, tip_mm
from roboisf.toolpath.toolpath import Toolpath

__all__ = ["read_gcode", "write_gcode"]


def _f(v: float) -> str:
    return f"{v:.3f}"


def write_gcode(
    tp: Toolpath,
    path: str | Path,
    *,
    safe_height: float = 10e-3,
    title: str | None = None,
) -> None:
    """Write ``tp`` as ISO G-code (tip coordinates, mm, 1 µm; feed from ``tp.feed`` in mm/min).

    Parameters
    ----------
    tp : the toolpath (work frame = program zero: blank centre, sheet plane)
    path : output file (``.nc``/``.gcode``)
    safe_height : float, m — z of the rapid moves above the sheet plane
    title : text for the leading comment
    """
    check_safe_height(safe_height)
    p = tip_mm(tp)
    feed = tp.feed * 60e3
    head = [
        "%",
        f"(roboisf {__version__} ISF toolpath{': ' + _clean(title) if title else ''})",
        f"({len(tp)} points, {tp.n_laps} laps, ball radius {tp.tool_radius * 1e3:g} mm)",
        "(units mm, absolute; programmed point = ball tip: set the tool length to the tip)",
        "G21 G90 G17 G94",
        f"G00 Z{_f(safe_height * 1e3)}",
        f"G00 X{_f(p[0, 0])} Y{_f(p[0, 1])}",
        f"G01 X{_f(p[0, 0])} Y{_f(p[0, 1])} Z{_f(p[0, 2])} F{feed:.1f}",
    ]
    body = "".join(f"G01 X{x:.3f} Y{y:.3f} Z{z:.3f}\n" for x, y, z in p[1:].tolist())
    tail = [f"G00 Z{_f(safe_height * 1e3)}", "M30", "%"]
    with atomic_write(path) as fh:
        fh.write("\n".join(head) + "\n" + body + "\n".join(tail) + "\n")


def _clean(text: str) -> str:
    return text.replace("(", "[").replace(")", "]").replace("\n", " ")


_WORD = re.compile(r"([A-Z])\s*([-+]?\d*\.?\d+(?:[eE][-+]?\d+)?)")


def read_gcode(path: str | Path) -> ProgramPath:
    """Parse a G-code file: the feed (G01) moves as tip positions [m] and the feed [m/s].

    Rapid (G00) moves are skipped (approach and retract). Raises :class:`InputError` with the line
    for unsupported words (G91, G02/G03), a feed move before any F, or a program with no feed move.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("G-code file not found", file=path)
    scale = 1.0  # mm
    pos = [np.nan, np.nan, np.nan]
    mode = None
    feed = None
    feeds: set[float] = set()
    pts: list[list[float]] = []
    for lineno, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        line = re.sub(r"\(.*?\)", "", raw).split(";", 1)[0].strip().upper()
        if not line or line == "%":
            continue
        words = _WORD.findall(line)
        rest = _WORD.sub("", line).strip()
        if rest:
            raise InputError(f"cannot parse {rest!r}", file=path, line=lineno)
        moved = False
        for letter, num in words:
            v = float(num)
            if letter == "G":
                g = round(v)
                if g in (0, 1):
                    mode = g
                elif g == 20:
                    scale = 25.4
                elif g == 21:
                    scale = 1.0
                elif g == 91:
                    raise InputError(
                        "incremental mode G91 is not supported", file=path, line=lineno
                    )
                elif g in (2, 3):
                    raise InputError("arcs (G02/G03) are not supported", file=path, line=lineno)
            elif letter in "XYZ":
                pos["XYZ".index(letter)] = v * scale
                moved = True
            elif letter == "F":
                feed = v * scale
        if moved and mode == 1:
            if feed is None:
                raise InputError("feed move before any F word", file=path, line=lineno)
            if np.any(np.isnan(pos)):
                raise InputError(
                    "feed move before X, Y and Z are all known", file=path, line=lineno
                )
            pts.append(list(pos))
            feeds.add(feed)
    if not pts:
        raise InputError("no feed (G01) moves found", file=path)
    assert feed is not None
    return ProgramPath(
        tip=np.array(pts) * 1e-3,
        R_work_tool=None,
        feed=min(feeds) * 1e-3 / 60.0,
        meta={"feeds_mm_min": sorted(feeds)},
    )
