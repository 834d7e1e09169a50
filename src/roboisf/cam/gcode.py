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

Reader (:func:`read_iso_moves` → :class:`~roboisf.cam.cam.CamMoves`, :func:`read_gcode` →
feed moves as a ``ProgramPath``): ISO 6983 / Fanuc / Haas programs as CAM systems post them —
``%`` and ``%2002`` tape marks, ``O`` program numbers, ``N`` sequence numbers, ``( )`` and ``;``
comments, block delete ``/`` (read, warned), numbers like ``Z0.``, ``X-.5``, ``F1e3``, several
words per block in any order; G0/G1, G2/G3 with I/J/K (incremental centre) or R (R < 0: the arc
over 180°) in G17/G18/G19, full circles and helical arcs, linearised to a chord tolerance
(:func:`roboisf.cam.cam.arc_points`); G20/G21, G90/G91, G28/G30 (also ``G28 G91 Z0``), G53,
G54…G59 (values from :class:`~roboisf.cam.cam.ReadOptions` or taken as they are, warned), G93/G94,
F, T, H/D with G43/G44/G49; M codes and path-mode words are listed once as notes. Everything
else — G92, G68, G51, G41/G42, canned cycles, macros, subprograms, A/B/C/U/V/W words (unless
ignored on request, warned) — is an error naming the line. Integers are whole units
(decimal-point input by calculator, as Haas, LinuxCNC, Sinumerik and most Fanuc set-ups).

A small hand-written word tokenizer rather than pygcode (a test dependency here): pygcode does not
attach the ``Z0`` of ``G28 G91 Z0`` to the G28 and rejects Sinumerik's ``X=`` forms; one
interpreter (:class:`Interpreter`) then serves this module and :mod:`roboisf.cam.sinumerik`, whose
words differ but whose motion is ISO's.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roboisf import __version__
from roboisf.cam.cam import (
    FEED,
    RAPID,
    CamMoves,
    MoveList,
    ReadOptions,
    arc_center_from_radius,
    arc_points,
)
from roboisf.cam.program import (
    NUMBER_RE,
    ProgramPath,
    check_safe_height,
    read_program_text,
    tip_mm,
)
from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.path.toolpath import Toolpath

__all__ = [
    "Interpreter",
    "program_number",
    "read_gcode",
    "read_iso_moves",
    "tokenize_iso",
    "write_gcode",
]

F64 = NDArray[np.float64]


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


# -- reader ----------------------------------------------------------------------------------------

#: One address word: letter(s), value, and a Sinumerik per-word distance mode ('IC', 'AC' or None).
Word = tuple[str, float, str | None]

_ISO_WORD = re.compile(r"([A-Z])\s*(" + NUMBER_RE + r")")
_AXES = "XYZ"
_EXTRA_AXES = "ABCUVW"
_PLANES = {17: (2, "XY"), 18: (1, "ZX"), 19: (0, "YZ")}  # normal axis index, name
#: G codes that change nothing on a 3-axis ball-tool path (noted once): path-control modes,
#: cancels of functions this reader refuses, canned-cycle return level.
_ISO_IGNORED = {
    9: "exact stop",
    40: "cutter compensation off",
    49: "tool length compensation off",
    50: "scaling off",
    61: "exact-stop mode",
    64: "continuous-path mode",
    69: "coordinate rotation off",
    80: "canned cycle cancel",
    98: "canned-cycle return level",
    99: "canned-cycle return level",
}
_ISO_REFUSED = {
    10: "G10 writes offsets into the control; give offset values with --work-offset",
    15: "polar coordinates are not supported",
    16: "polar coordinates are not supported",
    41: "cutter radius compensation (G41/G42) offsets the path in the control; post the program "
    "without it (tool centre or tip path)",
    42: "cutter radius compensation (G41/G42) offsets the path in the control; post the program "
    "without it (tool centre or tip path)",
    51: "scaling (G51) is not supported",
    52: "a local coordinate system (G52) is not supported",
    68: "coordinate rotation (G68) is not supported",
    92: "G92 shifts the coordinate system; it is not supported (use work offsets G54…G59)",
    95: "feed per revolution (G95) has no meaning for a forming tool",
}


#: Fanuc/Haas high-speed and look-ahead modes (with their P/Q/E/R parameters): noted, no effect
#: on the programmed path.
_PATH_CONTROL = {
    5.1: "Fanuc AI contour control",
    8.0: "Fanuc look-ahead",
    5.0: "Fanuc high-speed cycle",
    103.0: "Haas block look-ahead",
    187.0: "Haas smoothness",
    61.1: "Fanuc tool-path-error control",
}


@dataclass(frozen=True)
class Dialect:
    """What differs between the G-code families that share this interpreter."""

    name: str
    #: G code → unit scale [m per program unit] for the unit-select codes
    units: dict[float, float]
    #: G code → note, for modal words that change nothing here
    ignored: dict[float, str]
    #: work-offset G codes (``G54`` …) and the one that cancels them (None for ISO)
    offsets: frozenset[float]
    offset_cancel: float | None = None
    #: reference-point return codes (ISO G28/G30)
    home: frozenset[float] = frozenset({28.0, 30.0})


ISO = Dialect(
    name="iso",
    units={20.0: 25.4e-3, 21.0: 1e-3},
    ignored={float(k): v for k, v in _ISO_IGNORED.items()} | {50.1: "mirror off"},
    offsets=frozenset(float(g) for g in range(54, 60)),
)


def tokenize_iso(text: str, *, file: Path, line: int) -> tuple[list[Word], str]:
    """Words of one ISO block and its comment text: ``( )`` and ``;`` comments removed, any case,
    spaces anywhere between words, numbers like ``Z0.``, ``X-.5``, ``F1e3``."""
    if "(" not in text and ")" not in text and ";" not in text:  # the common case, fast
        return _iso_words(text.upper().strip(), file, line), ""
    comments = []
    out = []
    depth_start = None
    for k, ch in enumerate(text):
        if depth_start is not None:
            if ch == ")":
                comments.append(text[depth_start + 1 : k])
                depth_start = None
            continue
        if ch == "(":
            depth_start = k
        elif ch == ";":
            comments.append(text[k + 1 :])
            break
        else:
            out.append(ch)
    if depth_start is not None:
        raise InputError("comment '(' is not closed on this line", file=file, line=line)
    code = "".join(out).upper().strip()
    return _iso_words(code, file, line), " ".join(c.strip() for c in comments)


def _iso_words(code: str, file: Path, line: int) -> list[Word]:
    if code.startswith("/"):
        code = code[1:]
    words: list[Word] = [
        (m[0], program_number(m[1], file, line), None) for m in _ISO_WORD.findall(code)
    ]
    rest = _ISO_WORD.sub("", code).strip()
    if rest:
        raise InputError(_bad_token(code), file=file, line=line)
    return words


#: Fanuc Custom Macro B / LinuxCNC O-word control flow and variables
_MACRO = re.compile(r"#|\[|\b(?:IF|WHILE|GOTO|DO\d*|END\d*|THEN|EQ|NE|GT|LT|GE|LE)\b")


def _bad_token(code: str) -> str:
    """The message for a block with text that is no address word: the first such token as
    written (not what is left once the words are removed), and whether it is a macro."""
    pos = 0
    while pos < len(code):
        m = _ISO_WORD.match(code, pos)
        if m:
            pos = m.end()
        elif code[pos].isspace():
            pos += 1
        else:
            break
    tok = code[pos:].split()[0] if code[pos:].split() else code[pos:]
    if _MACRO.search(code):
        return (
            f"cannot parse {tok!r} at column {pos + 1}: a macro statement (Fanuc Custom Macro B "
            "variables #…, [expressions], IF/WHILE/GOTO) — roboisf reads posted moves only; "
            "post the program without macros (expanded), or export the moves from the CAM system"
        )
    return f"cannot parse {tok!r} at column {pos + 1} (expected address words like X10.5, G01)"


#: Largest magnitude of a number in a program (10 km in mm): beyond it a typo, not a position.
MAX_NUMBER = 1e7


def program_number(text: str, file: Path, line: int) -> float:
    """A number of a program word; InputError naming the line if not finite or absurdly large."""
    v = float(text)
    if not (math.isfinite(v) and abs(v) <= MAX_NUMBER):
        raise InputError(
            f"number {text} out of range (|value| ≤ {MAX_NUMBER:g})", file=file, line=line
        )
    return v


@dataclass
class _State:
    scale: float = 1e-3  # m per program unit (mm until G20)
    absolute: bool = True
    plane: int = 17
    motion: float | None = None
    feed: float | None = None  # program units / min (G94) or 1/min (G93)
    inverse_time: bool = False
    ijk_absolute: bool = False  # G90.1: arc centres I/J/K absolute (default G91.1: incremental)
    offset: str | None = None
    pos: F64 = field(default_factory=lambda: np.full(3, np.nan))


_NO_F = (
    "feed move before any F word (a program posted without feeds: give its feed with "
    "--feed MM/MIN, or put an F word on the first feed move)"
)


class Interpreter:
    """Runs the blocks of a G-code program (ISO or Sinumerik words) into :class:`CamMoves`.

    Positions are kept in the work frame of the work offset active at the first move (or of the
    one active at the control if the program selects none); see
    :class:`roboisf.cam.cam.ReadOptions`.
    """

    def __init__(self, path: Path, dialect: Dialect, options: ReadOptions) -> None:
        self.path = path
        self.d = dialect
        self.opt = options
        self.st = _State()
        self.moves = MoveList(path)
        self.ref_offset: str | None = None
        self.shift = np.zeros(3)  # active offset − reference offset, m
        self.m_codes: list[str] = []
        self.ignored: dict[str, list[int]] = {}
        self.defaulted_feed: list[int] = []  # lines of feed moves that took options.feed
        self.tools: list[int] = []
        self.length_comp: list[int] = []
        self.offsets_used: list[str] = []
        self.units_used: set[str] = set()
        self.moves.meta["dialect"] = dialect.name

    # -- helpers
    def err(self, msg: str, line: int) -> InputError:
        return InputError(msg, file=self.path, line=line)

    def _select_offset(self, name: str, line: int) -> None:
        self.st.offset = name
        if name not in self.offsets_used:
            self.offsets_used.append(name)
        if self.ref_offset is None or not self.moves.points:
            # the reference: the offset active at the first move (a safe-start G500 or G54 that
            # the header changes before moving does not count)
            self.ref_offset = name
            self.shift = np.zeros(3)
            return
        if name == self.ref_offset:
            self.shift = np.zeros(3)
            return
        vals = self.opt.work_offsets
        if name in vals and self.ref_offset in vals:
            self.shift = np.asarray(vals[name], float) - np.asarray(vals[self.ref_offset], float)
        else:
            self.shift = np.zeros(3)
            self.moves.warn_once(
                f"line {line}: work offset {name} selected after {self.ref_offset} but their "
                f"values are not given (--work-offset {name}=X,Y,Z and "
                f"{self.ref_offset}=X,Y,Z): its coordinates are taken as if in {self.ref_offset}"
            )

    def finish(self) -> CamMoves:
        if self.m_codes:
            self.moves.note_once(
                "M codes ignored (spindle, coolant, tool change, stops, end): "
                + " ".join(sorted(set(self.m_codes), key=lambda m: float(m[1:])))
            )
        if self.defaulted_feed and self.opt.feed is not None:
            n = len(self.defaulted_feed)
            self.moves.warnings.append(
                f"{n} feed move(s) before any F word (first on line {self.defaulted_feed[0]}) "
                f"take the feed given, {self.opt.feed * 60e3:g} mm/min"
            )
        for letter, lines in self.ignored.items():
            shown = ", ".join(str(x) for x in lines[:5]) + (" …" if len(lines) > 5 else "")
            self.moves.warnings.append(
                f"{letter} words ignored on {len(lines)} line(s) ({shown}): the path is read as "
                "3-axis XYZ"
            )
        self.moves.meta.update(
            work_offsets=self.offsets_used,
            tools=self.tools,
            length_compensation=self.length_comp,
            units=sorted(self.units_used) or ["mm"],
        )
        return self.moves.result()

    # -- one block
    def block(self, words: list[Word], line: int) -> None:
        st = self.st
        gs = [v for a, v, _ in words if a == "G"]
        other: dict[str, tuple[float, str | None]] = {}
        for a, v, mode in words:
            if a in ("G", "M"):
                continue
            if a in other:
                raise self.err(f"{a} given twice in one block", line)
            other[a] = (v, mode)
        for a, v, _ in words:
            if a == "M":
                code = f"M{v:g}"
                if v in (97.0, 98.0):
                    raise self.err(
                        f"subprogram calls ({code}) are not expanded; post the program "
                        "without subprograms",
                        line,
                    )
                self.m_codes.append(code)
        # G codes of the block
        dwell = home = machine = params = False
        arc_motion = None
        for g in gs:
            gi = round(g)
            if g in (0.0, 1.0, 2.0, 3.0):
                st.motion = g
            elif g == 4.0:
                dwell = True
            elif g in _PLANES:
                st.plane = gi
            elif g in self.d.units:
                st.scale = self.d.units[g]
                self.units_used.add("inch" if st.scale > 1e-3 else "mm")
            elif g == 90.0:
                st.absolute = True
            elif g == 91.0:
                st.absolute = False
            elif g == 93.0:
                st.inverse_time = True
                self.moves.note_once(
                    "G93 inverse-time feed: each feed move lasts 1/F minutes (times from that)"
                )
            elif g == 94.0:
                st.inverse_time = False
            elif g in self.d.home:
                home = True
            elif g == 53.0:
                machine = True
            elif g in self.d.offsets:
                self._select_offset(f"G{g:g}", line)
            elif self.d.offset_cancel is not None and g == self.d.offset_cancel:
                self._select_offset(f"G{g:g}", line)
            elif g in (43.0, 44.0):
                h = other.get("H") or other.get("D")
                self.length_comp.append(round(h[0]) if h else 0)
                if self.moves.points and any(k == FEED for k in self.moves.kinds):
                    raise self.err(
                        "tool length compensation changes in the middle of the forming moves", line
                    )
            elif g in self.d.ignored:
                params |= g == 64.0  # LinuxCNC G64 P… Q… (blending tolerance)
                self.moves.note_once(f"G{g:g} ({self.d.ignored[g]}) ignored: no effect here")
            elif g in (90.1, 91.1):
                st.ijk_absolute = g == 90.1
            elif g in _PATH_CONTROL and self.d is ISO:
                params = True  # its P/Q/E/R words set the control, not the path
                self.moves.note_once(f"G{g:g} ({_PATH_CONTROL[g]}) ignored: no effect here")
            elif g == 154.0 and self.d is ISO:
                p = other.get("P")
                if p is None:
                    raise self.err("G154 needs P (the extended work offset number)", line)
                params = True
                self._select_offset(f"G154P{p[0]:g}", line)
            elif float(gi) == g and gi in _ISO_REFUSED:
                raise self.err(_ISO_REFUSED[gi], line)
            elif 73 <= g <= 89:
                raise self.err(f"canned cycle G{g:g} is not supported (post it as G01 moves)", line)
            else:
                raise self.err(
                    f"unknown G code G{g:g} ({self.d.name} dialect); expected motion G0–G3, "
                    "G17–G19, units, G90/G91, G28, G53–G59, G93/G94 or a path-mode word",
                    line,
                )
        # words other than axes
        for a in list(other):
            v, _ = other[a]
            if a in ("N", "O"):
                if a == "O":
                    self.moves.meta.setdefault("program", f"O{v:g}")
            elif a == "F":
                if not dwell:
                    if not (math.isfinite(v) and v > 0):
                        raise self.err(f"feed F must be > 0, got {v:g}", line)
                    st.feed = v
            elif a == "T":
                self.tools.append(round(v))
            elif a in ("S", "H", "D"):
                pass  # spindle speed, length/radius offset numbers: no effect on the tip path
            elif a in _EXTRA_AXES:
                if a in self.opt.ignore_words:
                    self.ignored.setdefault(a, []).append(line)
                else:
                    raise self.err(
                        f"{a} word: a rotary or extra axis a 3-axis ball-tool path cannot use "
                        f"(pass --ignore-words {a} to ignore it with a warning)",
                        line,
                    )
            elif a in "IJKR" and (st.motion in (2.0, 3.0) or dwell) and not home:
                pass  # arc centre / radius: read by the arc below
            elif a in ("P", "X", "U") and dwell:
                pass  # dwell time: not timed (the unit differs by control; docs/toolpaths.md)
            elif a in ("P", "Q", "E", "R", "L") and params:
                pass  # parameters of a noted high-speed/smoothing mode word
            elif a in ("P", "L", "Q"):
                raise self.err(f"{a} word outside a dwell (G04): not supported", line)
            elif a in _AXES or a in "IJKR":
                if a in "IJKR":
                    raise self.err(f"{a} word outside an arc (G02/G03)", line)
            else:
                raise self.err(f"unknown address {a!r} for a 3-axis program", line)
        if dwell:
            # seconds where the unit is unambiguous: ISO X/U, Sinumerik F (P is ms on Fanuc and
            # s on LinuxCNC: not recorded)
            sec = other.get("F") if self.d is not ISO else (other.get("X") or other.get("U"))
            if sec is not None:
                self.moves.pending_dwell += max(sec[0], 0.0)
            self.moves.note_once("dwells (G04) are not counted in the times")
            return
        axes = {a: other[a] for a in _AXES if a in other}
        if home:
            self._home(axes, line)
            return
        if machine:
            self._machine(axes, line)
            return
        arc_words = any(a in other for a in "IJKR")
        if not axes and not (st.motion in (2.0, 3.0) and arc_words):
            return
        if st.motion is None:
            raise self.err("axis words before any motion code (G00/G01/G02/G03)", line)
        target = self._target(axes, line)
        if st.motion == 0.0:
            self.moves.add(target, RAPID, math.nan, line)
            st.pos = target
            return
        arc_motion = st.motion if st.motion in (2.0, 3.0) else None
        if st.feed is None and (self.opt.feed is None or st.inverse_time):
            raise self.err(_NO_F, line)
        unknown = np.isnan(target) | (np.isnan(st.pos) if arc_motion is not None else False)
        if np.any(unknown):
            missing = "".join(a for a, x in zip(_AXES, unknown, strict=True) if x)
            raise self.err(
                f"feed move with the {missing} position unknown (set X, Y and Z absolutely "
                "before the first feed move, also after G28/G53)",
                line,
            )
        if arc_motion is None:
            pts = target[None, :]
        else:
            pts = self._arc(target, other, arc_motion == 3.0, line)
        if st.inverse_time:
            length = float(
                np.sum(np.linalg.norm(np.diff(np.vstack([st.pos, pts]), axis=0), axis=1))
            )
            if not math.isfinite(length):
                raise self.err("G93 inverse-time move from an unknown position", line)
            if "F" not in other or st.feed is None:
                raise self.err("G93 inverse-time feed needs an F word on every feed move", line)
            feed = length / (60.0 / st.feed) if length > 0 else st.feed * 1e-3 / 60
        elif st.feed is None:
            assert self.opt.feed is not None
            feed = self.opt.feed  # the program has no F yet: the feed given (--feed)
            self.defaulted_feed.append(line)
        else:
            feed = st.feed * st.scale / 60.0
        self.moves.add(pts, FEED, feed, line)
        st.pos = target

    def _value(self, a: str, v: float, mode: str | None, line: int) -> float:
        i = _AXES.index(a)
        x = v * self.st.scale
        absolute = self.st.absolute if mode is None else mode == "AC"
        if absolute:
            return x + self.shift[i]
        if np.isnan(self.st.pos[i]):
            raise self.err(f"incremental {a} move from an unknown position", line)
        return float(self.st.pos[i] + x)

    def _target(self, axes: dict[str, tuple[float, str | None]], line: int) -> F64:
        target = self.st.pos.copy()
        for a, (v, mode) in axes.items():
            target[_AXES.index(a)] = self._value(a, v, mode, line)
        return target

    def _home(self, axes: dict[str, tuple[float, str | None]], line: int) -> None:
        """G28/G30: rapid through the intermediate point (if given) to the reference point, whose
        place in the work frame is unknown: those axes (all without words) become unknown."""
        if axes:
            mid = self.st.pos.copy()  # the intermediate point (unknown from an unknown start)
            for a, (v, mode) in axes.items():
                i = _AXES.index(a)
                absolute = self.st.absolute if mode is None else mode == "AC"
                mid[i] = v * self.st.scale + (self.shift[i] if absolute else self.st.pos[i])
            self.moves.add(mid, RAPID, math.nan, line)
        homed = [a for a in _AXES if a in axes] or list(_AXES)
        pos = self.st.pos.copy() if axes else np.full(3, np.nan)
        for a in homed:
            pos[_AXES.index(a)] = np.nan
        self.moves.add(pos, RAPID, math.nan, line)
        self.st.pos = pos
        self.moves.note_once(
            "reference-point returns (G28/G30) leave the homed axes at an unknown work position; "
            "those rapids are not forming moves"
        )

    def _machine(self, axes: dict[str, tuple[float, str | None]], line: int) -> None:
        """G53: this block in machine coordinates (work = machine − the reference offset)."""
        if self.st.motion not in (0.0, 1.0):
            raise self.err("G53 needs G00 or G01", line)
        ref = self.ref_offset or "G54"
        off = self.opt.work_offsets.get(ref)
        pos = self.st.pos.copy()
        for a, (v, _) in axes.items():
            i = _AXES.index(a)
            pos[i] = v * self.st.scale - off[i] if off is not None else np.nan
        if off is None:
            self.moves.note_once(
                f"G53 machine-coordinate moves: {ref}'s value is not given (--work-offset), so "
                "those axes are at an unknown work position afterwards"
            )
        if self.st.motion == 1.0:
            if np.any(np.isnan(pos)):
                raise self.err(
                    f"G53 G01 feed move with {ref}'s value unknown; give --work-offset {ref}=X,Y,Z",
                    line,
                )
            if self.st.feed is None and self.opt.feed is None:
                raise self.err(_NO_F, line)
            f = self.opt.feed if self.st.feed is None else self.st.feed * self.st.scale / 60.0
            assert f is not None
            self.moves.add(pos, FEED, f, line)
        else:
            self.moves.add(pos, RAPID, math.nan, line)
        self.st.pos = pos

    def _arc(
        self, target: F64, words: dict[str, tuple[float, str | None]], ccw: bool, line: int
    ) -> F64:
        normal_i, plane_name = _PLANES[self.st.plane]
        axis = np.zeros(3)
        axis[normal_i] = 1.0
        start = self.st.pos
        if "R" in words:
            if any(a in words for a in "IJK"):
                raise self.err("arc with both R and I/J/K", line)
            radius = words["R"][0] * self.st.scale
            center = arc_center_from_radius(
                start, target, radius, axis, ccw, file=self.path, line=line
            )
        else:
            center = start.copy()
            given = False
            for i, a in enumerate("IJK"):
                if a not in words:
                    continue
                v, mode = words[a]
                if i == normal_i:
                    if v != 0:
                        raise self.err(
                            f"{a} word in a {plane_name}-plane arc (G{self.st.plane}); it names "
                            "the centre along the arc's axis",
                            line,
                        )
                    continue
                given = True
                if mode == "AC" or (mode is None and self.st.ijk_absolute):
                    center[i] = v * self.st.scale + self.shift[i]
                else:
                    center[i] = start[i] + v * self.st.scale
            if not given:
                raise self.err(
                    f"arc without centre: give I/J/K (in the {plane_name} plane) or R", line
                )
        return arc_points(
            start, target, center, axis, ccw, self.opt.chord_tol, file=self.path, line=line
        )


def iso_blocks(path: Path, text: str) -> Iterator[tuple[int, list[Word]]]:
    """The words of every block of an ISO/Fanuc/Haas program with its line number: ``%`` lines
    (with a ``%NNNN`` number), Fanuc ``:NNNN`` program numbers and blank lines are skipped."""
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("%") or (s.startswith(":") and s[1:].strip().isdigit()):
            continue
        words, _ = tokenize_iso(s, file=path, line=lineno)
        if words:
            yield lineno, words


def read_iso_moves(path: str | Path, options: ReadOptions | None = None) -> CamMoves:
    """The moves of an ISO / Fanuc / Haas G-code program (see the module docstring).

    Arcs are linearised to ``options.chord_tol``. Raises :class:`InputError` naming the line for
    anything not understood.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("G-code file not found", file=path)
    text = read_program_text(path)
    interp = Interpreter(path, ISO, options or ReadOptions())
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if s.startswith("/"):
            interp.moves.warn_once(
                f"line {lineno}: block-delete lines ('/') are read as if the switch is off"
            )
        if s.startswith("%") and s[1:].strip():
            interp.moves.meta.setdefault("program", s)
    for lineno, words in iso_blocks(path, text):
        interp.block(words, lineno)
    return interp.finish()


def read_gcode(path: str | Path, options: ReadOptions | None = None) -> ProgramPath:
    """Parse a G-code file: the feed moves as tip positions [m] and the slowest feed [m/s].

    Rapid (G00) moves are skipped (approach and retract); arcs are linearised
    (:func:`read_iso_moves`). Raises :class:`InputError` with the line for what is not understood,
    a feed move before any F, or a program with no feed move.
    """
    moves = read_iso_moves(path, options)
    feed_moves = moves.kind == FEED
    if not feed_moves.any():
        raise InputError("no feed (G01/G02/G03) moves found", file=Path(path))
    feeds_mm_min = sorted({round(float(f) * 60e3, 9) for f in moves.feed[feed_moves]})
    return ProgramPath(
        tip=moves.point[feed_moves],
        R_work_tool=None,
        feed=float(np.min(moves.feed[feed_moves])),
        meta={
            "feeds_mm_min": feeds_mm_min,
            "work_offsets": moves.meta["work_offsets"],
            "tools": moves.meta["tools"],
            "length_compensation": moves.meta["length_compensation"],
            "notes": moves.notes,
            "warnings": moves.warnings,
        },
    )
