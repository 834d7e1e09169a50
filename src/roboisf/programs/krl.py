"""KUKA KRL program (``.src`` + ``.dat``) for a forming toolpath.

Layout written (``cone.src``; the ``.dat`` next to it holds the frames)::

    &ACCESS RVP
    &REL 1
    DEF cone( )                   ; DEF and DEFDAT name = the file stem
      ;FOLD INI
        GLOBAL INTERRUPT DECL 3 WHEN $STOPMESS==TRUE DO IR_STOPM ( )
        INTERRUPT ON 3
        BAS(#INITMOV,0)
      ;ENDFOLD (INI)
      $H_POS = XHOME
      PTP XHOME                   ; HOME at the start …
      $TOOL = TOOL_ISF            ; DECL FRAME TOOL_ISF={X 306,Y 0,Z 0,A 0,B 90,C 0} in the .dat
      $BASE = BASE_ISF            ; DECL FRAME BASE_ISF = T_base_work (mm, deg)
      $LOAD.M = LOAD_M
      $LOAD.CM = LOAD_CM
      $VEL.CP = 0.0125            ; m/s
      $APO.CDIS = 0.3             ; mm, with C_DIS
      PTP {X 38.671,Y 0,Z 6.138,A 0,B 0,C 180,S 2,T 35}   ; approach: S and T of the IK branch
      form_1( )
      ...
      LIN {X ...,Z <last + safe>,...}                     ; retract
      PTP XHOME                   ; … and at the end
    END

    DEF form_1( )
      LIN {X 38.671,Y 0,Z -3.862,A 0,B 0,C 180} C_DIS
      ...
    END

* Names: the ``DEF`` and ``DEFDAT`` name is the file stem, which must be a KRL name — a letter,
  then letters, digits or ``_``, at most 24 characters (the KRL limit for names, KUKA System
  Software 8 "Operating and Programming Instructions for System Integrators", section on names).
  Any other stem is refused with the name to use; nothing is cut silently.
* Positions: the toolpath tip in $BASE (= the work frame), mm at 1 µm.
* Orientation: ``R = Rz(A) Ry(B) Rx(C)`` (degrees) of the tool frame, whose z axis runs along the
  tool (see :mod:`roboisf.cam.program`); tool pointing down is ``A, B, C = 0, 0, 180``, a rotation
  γ about the tool axis gives ``A = −γ`` (``Rx(180°) Rz(γ) = Rz(−γ) Rx(180°)``).
* ``S``/``T`` of the first PTP from the joint angles of the IK branch
  (:func:`~roboisf.robot.armconfig.kuka_status_turn`); LIN moves keep the status of their start
  (KSS), so the forming moves carry none. Without joint angles the PTP has none either (header
  note).
* ``$TOOL``: TCP at the ball tip, ``X = L`` along the flange's x axis (KUKA's flange x points out
  of the flange) and ``B = 90°`` so that the tool z axis lies on the flange x axis.
* ``XHOME`` is the HOME position of the controller's ``$config.dat``.
* Forming moves are split into local subroutines of at most ``max_moves`` LINs.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from roboisf import __version__
from roboisf.cam.program import (
    NUMBER_RE,
    ProgramPath,
    RobotTool,
    fmt_num,
    prepare_program,
    program_identifier,
    read_program_text,
)
from roboisf.errors import InputError
from roboisf.frames.rotations import abc_to_matrix, matrix_to_abc
from roboisf.io.atomic import atomic_write
from roboisf.path.toolpath import Toolpath
from roboisf.robot.armconfig import ArmConfig, kuka_status_turn

__all__ = ["KRL_NAME", "frame_to_krl", "krl_name", "read_krl", "write_krl"]


def _abc_deg(R: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        # B = ±90° (gimbal lock): scipy warns and returns one valid (A, C) pair; fine for KRL.
        warnings.simplefilter("ignore", UserWarning)
        return np.degrees(matrix_to_abc(R))


def frame_to_krl(p_mm: ArrayLike, abc_deg: ArrayLike, nd_angle: int = 6) -> str:
    """``{X x,Y y,Z z,A a,B b,C c}`` (mm at 1 µm, degrees at 1e-6°)."""
    p = np.asarray(p_mm, dtype=float).tolist()  # Python floats format several times faster
    a = np.asarray(abc_deg, dtype=float).tolist()
    return (
        f"{{X {fmt_num(p[0])},Y {fmt_num(p[1])},Z {fmt_num(p[2])},"
        f"A {fmt_num(a[0], nd_angle)},B {fmt_num(a[1], nd_angle)},C {fmt_num(a[2], nd_angle)}}}"
    )


#: KRL names: a letter, then letters, digits or _, at most 24 characters (KSS 8).
KRL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,23}")


def krl_name(path: Path) -> str:
    """The DEF/DEFDAT name of ``path``: its stem, refused unless it is a valid KRL name."""
    stem = path.stem
    if not KRL_NAME.fullmatch(stem):
        raise InputError(
            f"the file name {stem!r} is not a KRL program name (DEF and DEFDAT must equal the file "
            "name: a letter, then letters, digits or _, at most 24 characters); rename it, e.g. "
            f"{program_identifier(stem, 24)}.src",
            file=path,
        )
    return stem


def write_krl(
    tp: Toolpath,
    path: str | Path,
    *,
    T_base_work: ArrayLike | None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    R_work_tool: ArrayLike | None = None,
    config: ArmConfig | None = None,
    cdis: float = 0.3e-3,
    safe_height: float = 10e-3,
    max_moves: int = 2000,
) -> list[Path]:
    """Write ``tp`` as KUKA KRL: ``path`` (``.src``) and the ``.dat`` beside it; return both.

    Parameters
    ----------
    tp : the toolpath (work frame)
    path : output ``.src`` whose stem is a KRL name; the data list goes to the ``.dat``
    T_base_work : (4, 4) float, m — the work frame in the robot base/world ($BASE; required,
        the identity means the robot base)
    tool : tool data (length, mass, cog); default :class:`RobotTool`
    tool_rotation : float or (N,) float, rad — rotation about the tool axis per point
    R_work_tool : (N, 3, 3), optional — full orientations (override ``tool_rotation``)
    config : ArmConfig, optional — joint angles of every point for S and T of the first PTP
    cdis : float, m — approximation distance ($APO.CDIS, with ``C_DIS``); 0 → exact stops
    safe_height : float, m — approach/retract height above the first/last point
    max_moves : int — LINs per subroutine
    """
    path = Path(path)
    if path.suffix.lower() != ".src":
        raise InputError("a KRL program must be written to a .src file", file=path)
    prog = krl_name(path)
    if not (np.isfinite(cdis) and cdis >= 0):
        raise InputError(f"must be ≥ 0 mm, got {cdis * 1e3:g}", field="cdis")
    inputs = prepare_program(
        tp,
        T_base_work=T_base_work,
        tool=tool,
        tool_rotation=tool_rotation,
        R_work_tool=R_work_tool,
        safe_height=safe_height,
        max_moves=max_moves,
    )
    tool, T, p, chunks = inputs.tool, inputs.T_base_work, inputs.tip_mm, inputs.chunks
    abc = _abc_deg(inputs.R_work_tool)
    base = frame_to_krl(T[:3, 3] * 1e3, _abc_deg(T[:3, :3]))
    tool_frame = frame_to_krl([tool.length * 1e3, 0, 0], [0, 90, 0])
    cog = tool.cog_xyz * 1e3  # flange frame: ABB-style z along the axis → KUKA x along the axis
    cm = frame_to_krl([cog[2], cog[1], -cog[0]], [0, 0, 0])
    approx = " C_DIS" if cdis > 0 else ""
    subs = [f"form_{k + 1}" for k in range(len(chunks))]
    up = np.array([0.0, 0.0, inputs.safe_height_mm])
    first = frame_to_krl(p[0] + up, abc[0])
    if config is not None:
        if len(config) != len(tp):
            raise InputError(
                f"expected joint angles for the {len(tp)} points, got {len(config)}",
                field="config",
            )
        st = kuka_status_turn(config)[0]
        first = f"{first[:-1]},S {int(st[0])},T {int(st[1])}}}"
        st_note = "S and T of the first PTP from the joint angles of the IK branch"
    else:
        st_note = "no robot model given: the first PTP has no S and T (the controller picks)"
    src = [
        "&ACCESS RVP\n&REL 1\n",
        f"DEF {prog}( )\n",
        f"  ; roboisf {__version__}: ISF toolpath, {len(tp)} points, {tp.n_laps} laps, ball radius "
        f"{fmt_num(tp.tool_radius * 1e3)} mm\n",
        "  ; positions: ball tip in $BASE (mm); A,B,C: R = Rz(A) Ry(B) Rx(C) of the tool frame "
        "(z along the tool)\n",
        f"  ; {st_note}\n",
        "  ;FOLD INI\n",
        "    GLOBAL INTERRUPT DECL 3 WHEN $STOPMESS==TRUE DO IR_STOPM ( )\n",
        "    INTERRUPT ON 3\n",
        "    BAS(#INITMOV,0)\n",
        "  ;ENDFOLD (INI)\n",
        "  $H_POS = XHOME\n",
        "  PTP XHOME\n",
        "  $TOOL = TOOL_ISF\n",
        "  $BASE = BASE_ISF\n",
        "  $LOAD.M = LOAD_M\n",
        "  $LOAD.CM = LOAD_CM\n",
        f"  $VEL.CP = {tp.feed:.6f}\n",
        f"  $APO.CDIS = {fmt_num(cdis * 1e3)}\n",
        f"  PTP {first}\n",
    ]
    src += [f"  {s}( )\n" for s in subs]
    src += [f"  LIN {frame_to_krl(p[-1] + up, abc[-1])}\n", "  PTP XHOME\n", "END\n"]
    for s, sl in zip(subs, chunks, strict=True):
        src.append(f"\nDEF {s}( )\n")
        src.extend(
            f"  LIN {frame_to_krl(pp, aa)}{approx}\n" for pp, aa in zip(p[sl], abc[sl], strict=True)
        )
        src.append("END\n")
    dat = [
        "&ACCESS RVP\n&REL 1\n",
        f"DEFDAT {prog}\n",
        f"  DECL FRAME TOOL_ISF={tool_frame}\n",
        f"  DECL FRAME BASE_ISF={base}\n",
        f"  DECL REAL LOAD_M={fmt_num(tool.mass)}\n",
        f"  DECL FRAME LOAD_CM={cm}\n",
        "ENDDAT\n",
    ]
    dat_path = path.with_suffix(".dat")
    with atomic_write(dat_path) as fh:
        fh.write("".join(dat))
    with atomic_write(path) as fh:
        fh.write("".join(src))
    return [path, dat_path]


_NUM = NUMBER_RE
_FRAME = re.compile(
    rf"\{{\s*X\s+({_NUM})\s*,\s*Y\s+({_NUM})\s*,\s*Z\s+({_NUM})\s*,\s*A\s+({_NUM})\s*,"
    rf"\s*B\s+({_NUM})\s*,\s*C\s+({_NUM})\s*\}}"
)


def _frame(m: re.Match[str]) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([float(x) for x in m.groups()])
    return v[:3], v[3:]


_ST = re.compile(r",\s*S\s+(\d+)\s*,\s*T\s+(\d+)\s*\}")


def _status_turn(ptps: list[str]) -> tuple[int, int] | None:
    """S and T of the first Cartesian PTP of the main program (None if it has none)."""
    for t in ptps:
        if t.startswith("{"):
            m = _ST.search(t)
            return (int(m.group(1)), int(m.group(2))) if m else None
    return None


def read_krl(path: str | Path) -> ProgramPath:
    """Parse a KRL ``.src`` (and its ``.dat`` if present) written by :func:`write_krl`.

    Returns the ``LIN`` moves of the subroutines called from the main DEF, in call order, with
    orientations, ``$VEL.CP`` as the feed, ``BASE_ISF`` as ``T_base_work`` and the tool length.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("KRL .src not found", file=path)
    lines = read_program_text(path).splitlines()
    defs: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    calls: list[str] = []
    main = None
    current = None
    feed = None
    ptps: list[str] = []
    main_name = ""
    for lineno, raw in enumerate(lines, start=1):
        s = raw.split(";", 1)[0].strip()
        if not s:
            continue
        m = re.match(r"^(?:GLOBAL\s+)?DEF\s+(\w+)\s*\(", s, re.IGNORECASE)
        if m:
            current = m.group(1).lower()
            defs[current] = []
            main = main or current
            main_name = main_name or m.group(1)
            continue
        if re.match(r"^END$", s, re.IGNORECASE):
            current = None
            continue
        if current is None:
            continue
        if current == main:
            c = re.match(r"^(\w+)\s*\(\s*\)$", s)
            if c:
                calls.append(c.group(1).lower())
            v = re.match(rf"^\$VEL\.CP\s*=\s*({_NUM})$", s, re.IGNORECASE)
            if v:
                feed = float(v.group(1))
            ptp = re.match(r"^PTP\s+(.*)$", s, re.IGNORECASE)
            if ptp:
                ptps.append(ptp.group(1).strip())
            continue
        if re.match(r"^LIN\b", s, re.IGNORECASE):
            f = _FRAME.search(s)
            if not f:
                raise InputError(
                    "cannot parse this LIN (expected {X,Y,Z,A,B,C})", file=path, line=lineno
                )
            defs[current].append(_frame(f))
    rows = [row for c in calls if c in defs for row in defs[c]]
    if not rows:
        raise InputError("no forming LIN moves found in the subroutines", file=path)
    if feed is None:
        raise InputError("no $VEL.CP in the main program", file=path)
    p = np.array([r[0] for r in rows])
    abc = np.array([r[1] for r in rows])
    T = None
    tool = None
    defdat = None
    dat = path.with_suffix(".dat")
    if dat.is_file():
        text = read_program_text(dat)
        dd = re.search(r"^\s*DEFDAT\s+(\w+)", text, re.MULTILINE | re.IGNORECASE)
        defdat = dd.group(1) if dd else None
        b = re.search(r"BASE_ISF\s*=\s*(\{[^}]*\})", text)
        if b and (fb := _FRAME.search(b.group(1))):
            pb, ab = _frame(fb)
            T = np.eye(4)
            T[:3, :3] = abc_to_matrix(np.radians(ab))
            T[:3, 3] = pb * 1e-3
        t = re.search(r"TOOL_ISF\s*=\s*(\{[^}]*\})", text)
        mass = re.search(rf"LOAD_M\s*=\s*({_NUM})", text)
        if t and (ft := _FRAME.search(t.group(1))):
            pt, _ = _frame(ft)
            tool = RobotTool(length=pt[0] * 1e-3, mass=float(mass.group(1)) if mass else 2.0)
    return ProgramPath(
        tip=p * 1e-3,
        R_work_tool=abc_to_matrix(np.radians(abc)),
        feed=feed,
        T_base_work=T,
        tool=tool,
        meta={
            "abc_deg": abc,
            "routines": calls,
            "def": main_name,
            "defdat": defdat,
            "ptp": ptps,
            "status_turn": _status_turn(ptps),
        },
    )
