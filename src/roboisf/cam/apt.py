"""APT / CL data (cutter-location source, ``.apt``, ``.cls``, ``.cl``): the moves of a 3-axis
ball-tool program.

Read statements (one per line, ``$`` at the end continues a statement on the next line, any case,
spaces around ``/`` and ``,``)::

    UNITS/MM | UNITS/INCHES              length unit of everything after (default mm)
    FEDRAT/f[,MMPM|IPM]  FEDRAT/MMPM,f   feed in units per minute (``FEDRAT/f`` alone: the UNITS)
    RAPID                                the next GOTO is a positioning move
    GOTO/x,y,z[,i,j,k]                   a move to x,y,z (with the tool axis i,j,k under MULTAX)
    FROM/x,y,z                           the start position (not a move)
    GOHOME                               back to the home position (unknown in the work frame)
    TLAXIS/i,j,k                         the tool axis of the following moves
    MULTAX[/ON|OFF]                      GOTO records carry the tool axis
    CIRCLE/xc,yc,zc,i,j,k,r[,…]          the next GOTO ends an arc about (xc,yc,zc), counter-
                                         clockwise about the axis (i,j,k); linearised
    CUTTER/d[,…]                         the tool diameter (checked against the importer's)

Statements that do not move the tool (``PARTNO``, ``MACHIN``, ``LOADTL``, ``SPINDL``,
``COOLNT``, ``PPRINT``, ``REMARK``, ``INSERT``, ``INTOL``/``OUTTOL``, ``CYCLE/OFF``, ``FINI`` …)
are ignored with one note each; anything else is an error naming the line. The tool axis must
stay along +z for a 3-axis path: the importer refuses a tilted axis, naming the line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from roboisf.cam.cam import FEED, RAPID, CamMoves, MoveList, ReadOptions, arc_points
from roboisf.cam.gcode import MAX_NUMBER
from roboisf.cam.program import read_program_text
from roboisf.errors import InputError

__all__ = ["read_apt_moves"]

_UNITS = {"MM": 1e-3, "MILLIMETERS": 1e-3, "INCHES": 25.4e-3, "INCH": 25.4e-3, "IN": 25.4e-3}
_IGNORED = (
    "PARTNO",
    "MACHIN",
    "LOADTL",
    "SELCTL",
    "SPINDL",
    "COOLNT",
    "PPRINT",
    "REMARK",
    "INSERT",
    "INTOL",
    "OUTTOL",
    "TOLER",
    "CYCLE",
    "FINI",
    "END",
    "STOP",
    "OPSTOP",
    "TLON",
    "TOOLNO",
    "TPRINT",
    "PAINT",
    "DISPLY",
    "CUTCOM",
    "AUTOPS",
    "PITCH",
    "OPERATION",
    "$$",
)
_STATEMENT = re.compile(r"^\s*([A-Z$][A-Z0-9_$]*)\s*(?:/(.*))?$")


def _statements(text: str) -> list[tuple[int, str]]:
    """(line, statement) with ``$`` continuations joined; ``$$`` comment lines kept as such."""
    out: list[tuple[int, str]] = []
    buf, start = "", 0
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("$$"):
            continue
        if not buf:
            start = lineno
        if s.endswith("$"):
            buf += s[:-1] + " "
            continue
        out.append((start, buf + s))
        buf = ""
    if buf:
        out.append((start, buf))
    return out


def _numbers(args: str, file: Path, line: int, word: str) -> list[float]:
    vals = []
    for item in args.split(","):
        item = item.strip()
        try:
            v = float(item)
        except ValueError:
            raise InputError(f"{word}/: {item!r} is not a number", file=file, line=line) from None
        if not (math.isfinite(v) and abs(v) <= MAX_NUMBER):
            raise InputError(
                f"{word}/: {item!r} out of range (|value| ≤ {MAX_NUMBER:g})", file=file, line=line
            )
        vals.append(v)
    return vals


def read_apt_moves(path: str | Path, options: ReadOptions | None = None) -> CamMoves:
    """The moves of an APT / CL-data file (see the module docstring). Raises
    :class:`InputError` naming the line."""
    path = Path(path)
    if not path.is_file():
        raise InputError("APT/CL file not found", file=path)
    opt = options or ReadOptions()
    moves = MoveList(path)
    moves.meta["dialect"] = "apt"
    scale = 1e-3
    units_seen: list[str] = []
    feed: float | None = None
    rapid_next = False
    multax = False
    axis = np.array([0.0, 0.0, 1.0])
    pos = np.full(3, np.nan)
    circle: tuple[np.ndarray, np.ndarray] | None = None
    for lineno, stmt in _statements(read_program_text(path)):
        m = _STATEMENT.match(stmt.upper())
        if m is None:
            raise InputError(
                f"cannot parse {stmt.strip()!r} (expected WORD or WORD/args)",
                file=path,
                line=lineno,
            )
        word, args = m[1], (m[2] or "").strip()
        if word == "UNITS":
            if args not in _UNITS:
                raise InputError(f"UNITS/{args}: expected MM or INCHES", file=path, line=lineno)
            scale = _UNITS[args]
            units_seen.append("inch" if scale > 1e-3 else "mm")
        elif word == "FEDRAT":
            parts = [p.strip() for p in args.split(",") if p.strip()]
            unit = [p for p in parts if p in ("MMPM", "IPM", "MMPR", "IPR")]
            nums = _numbers(",".join(p for p in parts if p not in unit), path, lineno, word)
            if len(nums) != 1 or not nums[0] > 0:
                raise InputError(
                    f"FEDRAT/{args}: expected one feed > 0 (and MMPM or IPM)",
                    file=path,
                    line=lineno,
                )
            if unit and unit[0] in ("MMPR", "IPR"):
                raise InputError(
                    "feed per revolution (MMPR/IPR) has no meaning for a forming tool",
                    file=path,
                    line=lineno,
                )
            f_scale = {"MMPM": 1e-3, "IPM": 25.4e-3}[unit[0]] if unit else scale
            feed = nums[0] * f_scale / 60.0
        elif word == "RAPID":
            rapid_next = True
        elif word == "MULTAX":
            multax = args in ("", "ON")
        elif word == "TLAXIS":
            v = _numbers(args, path, lineno, word)
            if len(v) < 3 or np.linalg.norm(v[:3]) < 1e-9:
                raise InputError("TLAXIS/: expected a vector i,j,k", file=path, line=lineno)
            axis = np.array(v[:3]) / np.linalg.norm(v[:3])
        elif word in ("GOTO", "FROM"):
            v = _numbers(args, path, lineno, word)
            if len(v) not in (3, 6):
                want = "x,y,z,i,j,k" if multax else "x,y,z (or x,y,z,i,j,k)"
                raise InputError(
                    f"{word}/: expected {want}, got {len(v)} values", file=path, line=lineno
                )
            p = np.array(v[:3]) * scale
            if len(v) == 6:
                a = np.array(v[3:])
                if np.linalg.norm(a) < 1e-9:
                    raise InputError(f"{word}/: zero tool axis", file=path, line=lineno)
                axis = a / np.linalg.norm(a)
            if word == "FROM":
                pos = p
                continue
            if rapid_next:
                moves.add(p, RAPID, math.nan, lineno, axis)
                rapid_next = False
                circle = None
            else:
                if feed is None:
                    raise InputError(
                        "feed move before any FEDRAT (put RAPID before a positioning GOTO)",
                        file=path,
                        line=lineno,
                    )
                if circle is not None:
                    if np.any(np.isnan(pos)):
                        raise InputError("arc from an unknown position", file=path, line=lineno)
                    center, n = circle
                    pts = arc_points(pos, p, center, n, True, opt.chord_tol, file=path, line=lineno)
                    moves.add(pts, FEED, feed, lineno, axis)
                    circle = None
                else:
                    moves.add(p, FEED, feed, lineno, axis)
            pos = p
        elif word == "CIRCLE":
            v = _numbers(args, path, lineno, word)
            if len(v) < 7:
                raise InputError("CIRCLE/: expected xc,yc,zc,i,j,k,r[,…]", file=path, line=lineno)
            n = np.array(v[3:6])
            if np.linalg.norm(n) < 1e-9:
                raise InputError("CIRCLE/: zero axis", file=path, line=lineno)
            circle = (np.array(v[:3]) * scale, n / np.linalg.norm(n))
        elif word == "GOHOME":
            pos = np.full(3, np.nan)
            moves.add(pos, RAPID, math.nan, lineno, axis)
            moves.note_once("GOHOME: the home position is unknown in the work frame")
        elif word == "CUTTER":
            v = _numbers(args.split(",")[0], path, lineno, word)
            moves.meta["cutter_diameter"] = v[0] * scale
        elif word in _IGNORED or word.startswith("$$"):
            moves.note_once(f"{word} statements ignored: no effect on the path")
        else:
            raise InputError(
                f"unknown APT statement {word!r} (expected GOTO, FEDRAT, RAPID, TLAXIS, MULTAX, "
                "UNITS, CIRCLE, FROM, GOHOME or a non-motion statement)",
                file=path,
                line=lineno,
            )
    moves.meta["units"] = sorted(set(units_seen)) or ["mm"]
    return moves.result()
