"""Siemens Sinumerik (840D / 828D) part programs (``.mpf``, ``.spf``): the moves of a 3-axis
ball-tool program.

Read: ``N`` numbers, ``;`` comments, the ``%_N_NAME_MPF`` / ``;$PATH=`` header, ISO words
(``G1 X10 Z-2.5``) and the ``=`` forms ``X=50``, ``Z=-2.5``, ``X=IC(1.5)`` (incremental for this
word), ``X=AC(10)`` (absolute for this word), ``I=AC(…)`` (absolute arc centre), ``CR=`` (arc
radius, as ISO ``R``), ``F=``; ``G70``/``G71``/``G700``/``G710`` (inch/mm); work offsets
``G54``…``G57``, ``G505``…``G599`` and ``G500`` (none); ``G53``/``SUPA`` (machine coordinates in
this block). Path-control and machine-setup words that do not change the programmed path —
``G60``, ``G64``, ``G641``…``G645``, ``G9``, ``SOFT``, ``BRISK``, ``FFWON``/``FFWOF``,
``CYCLE832(…)`` (the high-speed settings), ``MSG(…)``, ``TRAFOOF``, ``D`` and ``T`` —
are ignored with one note each. Frames (``TRANS``, ``ROT``, ``ATRANS`` …), R parameters,
``CIP``/``CT`` arcs, polar coordinates and machining ``CYCLE``s are refused, naming the line.

The motion itself (G0–G3, planes, G90/G91, feeds, arcs to a chord tolerance) is the ISO
interpreter of :mod:`roboisf.cam.gcode`: Sinumerik is ISO G-code with its own word syntax, so only
the tokenizer is Sinumerik's. A hand-written tokenizer, not pygcode: pygcode rejects the ``X=``
forms (``word 'X' value invalid``).
"""

from __future__ import annotations

import re
from pathlib import Path

from roboisf.cam.cam import CamMoves, ReadOptions
from roboisf.cam.gcode import ISO, Dialect, Interpreter, Word, program_number
from roboisf.cam.program import NUMBER_RE, read_program_text
from roboisf.errors import InputError

__all__ = ["SINUMERIK", "read_sinumerik_moves", "tokenize_sinumerik"]

SINUMERIK = Dialect(
    name="sinumerik",
    units={70.0: 25.4e-3, 71.0: 1e-3, 700.0: 25.4e-3, 710.0: 1e-3},
    ignored={
        **{k: v for k, v in ISO.ignored.items() if k in (9.0, 40.0, 64.0)},
        60.0: "exact stop",
        601.0: "exact stop window",
        602.0: "exact stop window",
        603.0: "exact stop window",
        641.0: "continuous path with smoothing",
        642.0: "continuous path with smoothing",
        643.0: "continuous path with smoothing",
        644.0: "continuous path with smoothing",
        645.0: "continuous path with smoothing",
        153.0: "suppress frames (machine coordinates)",
    },
    offsets=frozenset({54.0, 55.0, 56.0, 57.0} | {float(g) for g in range(505, 600)}),
    offset_cancel=500.0,
    home=frozenset(),
)

#: Keywords without effect on the programmed path (noted once each).
_IGNORED_KEYWORDS = {
    "SOFT": "jerk-limited acceleration",
    "BRISK": "step acceleration",
    "FFWON": "feed-forward control",
    "FFWOF": "feed-forward control",
    "COMPON": "compressor",
    "COMPCURV": "compressor",
    "COMPCAD": "compressor",
    "COMPOF": "compressor",
    "TRAFOOF": "transformation off",
    "UPATH": "path-parameter mode",
    "SPATH": "path-parameter mode",
    "DYNNORM": "dynamic response",
    "DYNPOS": "dynamic response",
    "DYNROUGH": "dynamic response",
    "DYNSEMIFIN": "dynamic response",
    "DYNFINISH": "dynamic response",
    "CFC": "feed at the contour",
    "CFTCP": "feed at the tool centre point",
    "CFIN": "feed at the contour",
    "ORIWKS": "orientation reference",
    "ORIAXES": "orientation interpolation",
    "TOFFOF": "tool offset off",
    "STOPRE": "pre-processing stop",
    "RET": "end of subprogram",
    "WHEN": "synchronised action",
}
#: Machining / setting cycles that only change the control's behaviour (noted); others refused.
_SETTING_CYCLES = ("CYCLE832", "CYCLE800_OFF")
_REFUSED_KEYWORDS = {
    "TRANS": "a programmable frame (TRANS/ATRANS/ROT/SCALE/MIRROR) moves the coordinates",
    "ATRANS": "a programmable frame (TRANS/ATRANS/ROT/SCALE/MIRROR) moves the coordinates",
    "ROT": "a programmable frame (TRANS/ATRANS/ROT/SCALE/MIRROR) moves the coordinates",
    "AROT": "a programmable frame (TRANS/ATRANS/ROT/SCALE/MIRROR) moves the coordinates",
    "SCALE": "a programmable frame (TRANS/ATRANS/ROT/SCALE/MIRROR) moves the coordinates",
    "MIRROR": "a programmable frame (TRANS/ATRANS/ROT/SCALE/MIRROR) moves the coordinates",
    "CIP": "circles through an intermediate point (CIP) are not supported; post with G2/G3",
    "CT": "tangential circles (CT) are not supported; post with G2/G3",
    "TRAORI": "5-axis transformation (TRAORI): not a 3-axis path",
    "G41": "cutter radius compensation",
}

_NUM = NUMBER_RE
_TOKEN = re.compile(
    rf"""\s*(?:
      (?P<eqaddr>[A-Z][A-Z0-9_]*)\s*=\s*(?:
          (?P<mode>IC|AC)\s*\(\s*(?P<mval>{_NUM})\s*\)
        | (?P<eqval>{_NUM})
        | (?P<eqother>"[^"]*"|\S+))
    | (?P<call>[A-Z_][A-Z0-9_]*)\s*\((?P<args>[^)]*)\)
    | (?P<iso>[A-Z])\s*(?P<isoval>{_NUM})
    | (?P<kw>[A-Z_][A-Z0-9_]*)
    )""",
    re.VERBOSE,
)
_AXIS_ALIASES = {"CR": "R"}
_EQ_ADDRESSES = set("XYZIJKFRTDSHABCUVWN") | set(_AXIS_ALIASES)


def tokenize_sinumerik(text: str, *, file: Path, line: int, notes: list[str]) -> list[Word]:
    """Words of one Sinumerik block (comment removed); keywords without effect are added to
    ``notes`` (once each); anything else not understood raises naming the line."""
    code = text.split(";", 1)[0].strip().upper()
    words: list[Word] = []
    pos = 0
    while pos < len(code):
        m = _TOKEN.match(code, pos)
        if m is None or m.end() == pos:
            raise InputError(f"cannot parse {code[pos:].strip()!r}", file=file, line=line)
        pos = m.end()
        if m["eqaddr"]:
            addr = _AXIS_ALIASES.get(m["eqaddr"], m["eqaddr"])
            if m["eqother"] is not None:
                if addr in ("T",):  # T="BALL10": a tool by name
                    continue
                raise InputError(
                    f"cannot read {m['eqaddr']}={m['eqother']} (expected a number, IC(…) or AC(…); "
                    "R parameters and expressions are not supported)",
                    file=file,
                    line=line,
                )
            if addr not in _EQ_ADDRESSES:
                raise InputError(
                    f"unknown address {m['eqaddr']!r} (R parameters, variables and polar "
                    "coordinates are not supported)",
                    file=file,
                    line=line,
                )
            if m["mode"]:
                words.append((addr, program_number(m["mval"], file, line), m["mode"]))
            else:
                words.append((addr, program_number(m["eqval"], file, line), None))
        elif m["call"]:
            name = m["call"]
            if name == "MSG" or name in _SETTING_CYCLES:
                _note(notes, f"{name}(…) ignored: no effect on the programmed path")
            elif name.startswith("CYCLE") or name.startswith("POCKET") or name.startswith("SLOT"):
                raise InputError(
                    f"machining cycle {name} is not supported (post the program as G1 moves)",
                    file=file,
                    line=line,
                )
            else:
                raise InputError(f"unknown call {name}(…)", file=file, line=line)
        elif m["iso"]:
            words.append((m["iso"], program_number(m["isoval"], file, line), None))
        else:
            kw = m["kw"]
            if kw in _IGNORED_KEYWORDS:
                _note(notes, f"{kw} ({_IGNORED_KEYWORDS[kw]}) ignored: no effect here")
            elif kw == "SUPA":
                words.append(("G", 53.0, None))
            elif kw in _REFUSED_KEYWORDS:
                raise InputError(
                    f"{kw}: {_REFUSED_KEYWORDS[kw]}; not supported", file=file, line=line
                )
            else:
                raise InputError(f"unknown keyword {kw!r}", file=file, line=line)
    return words


def _note(notes: list[str], text: str) -> None:
    if text not in notes:
        notes.append(text)


def read_sinumerik_moves(path: str | Path, options: ReadOptions | None = None) -> CamMoves:
    """The moves of a Sinumerik part program (see the module docstring); arcs linearised to
    ``options.chord_tol``. Raises :class:`InputError` naming the line."""
    path = Path(path)
    if not path.is_file():
        raise InputError("Sinumerik program not found", file=path)
    interp = Interpreter(path, SINUMERIK, options or ReadOptions())
    for lineno, raw in enumerate(read_program_text(path).splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith(";"):
            continue
        if s.startswith("%"):
            interp.moves.meta.setdefault("program", s)
            continue
        if s.startswith("/"):
            interp.moves.warn_once(
                f"line {lineno}: block-delete lines ('/') are read as if the switch is off"
            )
            s = s[1:]
        words = tokenize_sinumerik(s, file=path, line=lineno, notes=interp.moves.notes)
        if words:
            interp.block(words, lineno)
    return interp.finish()
