"""ISO G-code (RS-274 / ISO 6983) for a 3-axis CNC mill with the tool along z.

Dialect written::

    %
    (roboisf 0.1.0 ISF toolpath: ...)
    (units mm, absolute, work offset G54 = blank centre in the sheet plane, z up)
    (T1 = the ball tool, H1 = its length to the ball TIP: programmed Z is the tool tip)
    G21 G90 G17 G94 G40 G49 G80        ← safe start: mm, absolute, XY plane, no compensations
    G54                                ← work offset (selectable: G54…G59)
    T1 M06                             ← tool call
    G00 G43 H1 Z10.000                 ← tool length compensation on, at the safe height
    G00 X38.671 Y0.000                 ← above the first point
    G01 X38.671 Y0.000 Z-3.862 F750.0  ← plunge to the first point at the feed
    G01 X38.670 Y0.185 Z-3.862         ← every forming move: X Y Z (tip, mm, 1 µm)
    ...
    G00 Z10.000
    G49                                ← length compensation off
    M30
    %

The parser reads this dialect and the common variants: modal G0/G1 (with or without leading
zero), axis words that keep their previous value when omitted, ``( )`` and ``;`` comments, line
numbers ``N…``, ``G20`` (inch), ``F`` in units per minute, work offsets, tool calls and length
compensation (recorded in ``meta``). It refuses ``G91`` (incremental) and arcs (``G02/G03``),
which a roboisf program never contains.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from roboisf import __version__
from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.io.program import ProgramPath, check_safe_height, read_program_text, tip_mm
from roboisf.toolpath.toolpath import Toolpath

__all__ = ["read_gcode", "write_gcode"]


def _f(v: float) -> str:
    return f"{v:.3f}"


#: Work offsets a program may select.
WORK_OFFSETS = ("G54", "G55", "G56", "G57", "G58", "G59")


def write_gcode(
    tp: Toolpath,
    path: str | Path,
    *,
    safe_height: float = 10e-3,
    title: str | None = None,
    work_offset: str = "G54",
    tool_number: int = 1,
    notes: tuple[str, ...] = (),
) -> list[Path]:
    """Write ``tp`` as ISO G-code (tip coordinates, mm, 1 µm; feed from ``tp.feed`` in mm/min).

    Parameters
    ----------
    tp : the toolpath (work frame = program zero: blank centre, sheet plane)
    path : output file (``.nc``/``.gcode``)
    safe_height : float, m — z of the rapid moves above the sheet plane
    title : text for the leading comment
    work_offset : ``G54`` … ``G59`` — the work offset holding the blank centre
    tool_number : T and H number of the ball tool (its length measured to the ball tip)
    notes : extra header comment lines (what the program contains)
    """
    check_safe_height(safe_height)
    if work_offset not in WORK_OFFSETS:
        raise InputError(
            f"unknown work offset {work_offset!r}; expected one of {', '.join(WORK_OFFSETS)}",
            field="work_offset",
        )
    if not (isinstance(tool_number, int) and 1 <= tool_number <= 99):
        raise InputError(f"must be an integer in 1…99, got {tool_number!r}", field="tool_number")
    t = tool_number
    p = tip_mm(tp)
    feed = tp.feed * 60e3
    head = [
        "%",
        f"(roboisf {__version__} ISF toolpath{': ' + _clean(title) if title else ''})",
        f"({len(tp)} points, {tp.n_laps} laps, ball radius {tp.tool_radius * 1e3:g} mm)",
        *(f"({_clean(n)})" for n in notes),
        f"(units mm, absolute, work offset {work_offset} = blank centre in the sheet plane, z up)",
        f"(T{t} = the ball tool, H{t} = its length to the ball TIP: programmed Z is the tool tip)",
        "G21 G90 G17 G94 G40 G49 G80",
        work_offset,
        f"T{t} M06",
        f"G00 G43 H{t} Z{_f(safe_height * 1e3)}",
        f"G00 X{_f(p[0, 0])} Y{_f(p[0, 1])}",
        f"G01 X{_f(p[0, 0])} Y{_f(p[0, 1])} Z{_f(p[0, 2])} F{feed:.1f}",
    ]
    body = "".join(f"G01 X{x:.3f} Y{y:.3f} Z{z:.3f}\n" for x, y, z in p[1:].tolist())
    tail = [f"G00 Z{_f(safe_height * 1e3)}", "G49", "M30", "%"]
    with atomic_write(path) as fh:
        fh.write("\n".join(head) + "\n" + body + "\n".join(tail) + "\n")
    return [Path(path)]


def _clean(text: str) -> str:
    # no parentheses or ';' inside a comment: some readers end the comment there
    return text.replace("(", "[").replace(")", "]").replace(";", ",").replace("\n", " ")


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
    offsets: list[str] = []
    tools: list[int] = []
    length_comp: list[int] = []
    for lineno, raw in enumerate(read_program_text(path).splitlines(), start=1):
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
                elif 54 <= g <= 59 and v == g:
                    offsets.append(f"G{g}")
                elif g == 43:
                    h = [float(n) for ltr, n in words if ltr == "H"]
                    length_comp.append(int(h[0]) if h else 0)
                    if pts:
                        raise InputError(
                            "tool length compensation changes in the middle of the forming moves",
                            file=path,
                            line=lineno,
                        )
            elif letter in "XYZ":
                pos["XYZ".index(letter)] = v * scale
                moved = True
            elif letter == "F":
                feed = v * scale
            elif letter == "T":
                tools.append(int(v))
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
        meta={
            "feeds_mm_min": sorted(feeds),
            "work_offsets": offsets,
            "tools": tools,
            "length_compensation": length_comp,
        },
    )
