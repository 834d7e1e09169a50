"""FANUC TP program in ASCII form (``.ls``) for a forming toolpath, and its reader.

Layout written (``cone.ls``; compile it to ``.tp`` with FANUC's ASCII upload or Roboguide)::

    /PROG  CONE
    /ATTR
    OWNER       = MNEDITOR;
    COMMENT     = "roboisf ISF";
    ...
    DEFAULT_GROUP   = 1,*,*,*,*;
    /MN
       1:  ! roboisf 0.1.0 ISF toolpath ;
       2:  PR[90]=LPOS    ;                 ← the user frame, element by element (mm, deg)
       3:  PR[90,1]=2200.000    ;
       ...
       9:  UFRAME[1]=PR[90]    ;
      10:  PR[91]=LPOS    ;                 ← the tool frame: ball tip at Z = L on the flange
      ...
      17:  UTOOL[1]=PR[91]    ;
      18:  UFRAME_NUM=1 ;
      19:  UTOOL_NUM=1 ;
      20:J P[1] 20% FINE    ;               ← approach above the first point
      21:L P[2] 75cm/min CNT100    ;        ← forming moves
      ...
    /POS
    P[1]{
       GP1:
        UF : 1, UT : 1,     CONFIG : 'N U T, 0, 0, 0',
        X =    41.321  mm,  Y =     0.000  mm,  Z =     9.500  mm,
        W =   180.000 deg,  P =     0.000 deg,  R =     0.000 deg
    };
    /END

* Positions ``P[i]`` are the toolpath tip in the user frame ``UF`` = the work frame (mm, 1 µm),
  with the tool frame ``UT`` at the ball tip. The frames are set by the program itself from
  position registers ``PR[90]``/``PR[91]`` (``pr_frame``/``pr_tool`` to choose others): the PR
  is first made Cartesian (``=LPOS``) and then given the frame's six values.
* Orientation ``W, P, R`` (deg): ``R_work_tool = Rz(R) Ry(P) Rx(W)``; tool pointing down is
  ``W, P, R = 180, 0, 0``.
* ``CONFIG`` of every position from the joint angles of the IK branch
  (:func:`~roboisf.robot.armconfig.fanuc_config`); without joint angles ``'N U T, 0, 0, 0'`` with a
  header note.
* Speed: ``mm/sec`` when the feed is a whole number of mm/s, else ``cm/min`` (whole numbers; the
  rounding, if any, is stated in the header). ``CNT100`` blends the forming moves.
* A path longer than ``max_module_moves`` becomes a main program that ``CALL`` s sub-programs
  ``<NAME>_1``, ``<NAME>_2``, … (files ``<stem>_1.ls``, …), one per block of whole laps.
* Program names: the file stem in upper case — a letter, then letters, digits or ``_``; at most
  36 characters with the ``_<k>`` suffix (R-30iB; older controllers take 8).
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from roboisf import __version__
from roboisf.cam.program import (
    MAX_MODULE_MOVES,
    NUMBER_RE,
    ProgramPath,
    RobotTool,
    prepare_program,
    program_identifier,
    read_program_text,
    split_modules,
)
from roboisf.errors import InputError
from roboisf.frames.rotations import abc_to_matrix, matrix_to_abc
from roboisf.io.atomic import atomic_write
from roboisf.path.toolpath import Toolpath
from roboisf.robot.armconfig import ArmConfig, fanuc_config

__all__ = ["check_program_name", "read_fanuc", "write_fanuc"]

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_MAX_NAME = 36


def _wpr_deg(R: np.ndarray) -> np.ndarray:
    """(N, 3) ``W, P, R`` degrees of rotations (N, 3, 3): ``R = Rz(R) Ry(P) Rx(W)``."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # P = ±90°: one valid (W, R) pair
        abc = np.degrees(matrix_to_abc(R))
    return abc[..., ::-1]


def _speed(feed: float) -> tuple[str, str | None]:
    """TP speed text of ``feed`` [m/s] and a note when it had to be rounded."""
    mm_s = feed * 1e3
    if abs(mm_s - round(mm_s)) < 1e-9 and round(mm_s) >= 1:
        return f"{round(mm_s)}mm/sec", None
    cm_min = feed * 6e3
    c = max(1, round(cm_min))
    note = None if abs(cm_min - c) < 1e-9 else f"feed {cm_min:g} cm/min rounded to {c} cm/min"
    return f"{c}cm/min", note


def _pos_block(i: int, p: Sequence[float], wpr: Sequence[float], conf: str) -> str:
    return (
        f"P[{i}]{{\n   GP1:\n\tUF : 1, UT : 1,\t\tCONFIG : '{conf}',\n"
        f"\tX = {p[0]:9.3f}  mm,\tY = {p[1]:9.3f}  mm,\tZ = {p[2]:9.3f}  mm,\n"
        f"\tW = {wpr[0]:9.3f} deg,\tP = {wpr[1]:9.3f} deg,\tR = {wpr[2]:9.3f} deg\n}};\n"
    )


def _attr(name: str, n_lines: int) -> str:
    return (
        f'/PROG  {name}\n/ATTR\nOWNER\t\t= MNEDITOR;\nCOMMENT\t\t= "roboisf ISF";\n'
        "PROG_SIZE\t= 0;\nCREATE\t\t= DATE 00-01-01  TIME 00:00:00;\n"
        "MODIFIED\t= DATE 00-01-01  TIME 00:00:00;\nFILE_NAME\t= ;\nVERSION\t\t= 0;\n"
        f"LINE_COUNT\t= {n_lines};\nMEMORY_SIZE\t= 0;\nPROTECT\t\t= READ_WRITE;\n"
        "TCD:  STACK_SIZE\t= 0,\n      TASK_PRIORITY\t= 50,\n      TIME_SLICE\t= 0,\n"
        "      BUSY_LAMP_OFF\t= 0,\n      ABORT_REQUEST\t= 0,\n      PAUSE_REQUEST\t= 0;\n"
        "DEFAULT_GROUP\t= 1,*,*,*,*;\nCONTROL_CODE\t= 00000000 00000000;\n/MN\n"
    )


def _program(name: str, body: list[str], positions: list[str]) -> str:
    mn = "".join(f"{k:4d}:{ln} ;\n" for k, ln in enumerate(body, start=1))
    pos = "/POS\n" + "".join(positions) + "/END\n"
    return _attr(name, len(body)) + mn + pos


def joint_positions_program(name: str, q_deg: np.ndarray, comment: str) -> str:
    """A TP program (``.ls`` text) that moves to each row of ``q_deg`` (N, 6) — joint angles
    J1…J6 in degrees, the pendant's — with a joint move at 10 % and ``FINE``, and pauses there
    (``PAUSE``: the operator loads and measures, then resumes). Positions in joint
    representation (``J1= … deg``), no frames used."""
    if not re.fullmatch(r"[A-Z][A-Z0-9_]{0,31}", name):
        raise InputError(f"not a FANUC program name: {name!r}", field="name")
    body = [f"  ! {comment} "]
    positions = []
    for i, q in enumerate(np.asarray(q_deg, dtype=float).tolist(), start=1):
        body += [f"J P[{i}] 10% FINE    ", "  PAUSE"]
        positions.append(
            f"P[{i}]{{\n   GP1:\n\tUF : 0, UT : 0,\n"
            f"\tJ1= {q[0]:9.3f} deg,\tJ2= {q[1]:9.3f} deg,\tJ3= {q[2]:9.3f} deg,\n"
            f"\tJ4= {q[3]:9.3f} deg,\tJ5= {q[4]:9.3f} deg,\tJ6= {q[5]:9.3f} deg\n}};\n"
        )
    return _program(name, body, positions)


def _frame_lines(pr: int, values: np.ndarray, target: str) -> list[str]:
    out = [f"  PR[{pr}]=LPOS    "]
    out += [f"  PR[{pr},{j + 1}]={v:.3f}    " for j, v in enumerate(values)]
    out.append(f"  {target}=PR[{pr}]    ")
    return out


def check_program_name(path: str | Path) -> None:
    """Refuse a file name that does not give a FANUC program name (the program is named after
    the file: a letter, then letters, digits or _, at most 32 characters)."""
    path = Path(path)
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,31}", path.stem):
        raise InputError(
            f"the file name {path.stem!r} does not give a FANUC program name (a letter, then "
            "letters, digits or _)",
            file=path,
        )


def write_fanuc(
    tp: Toolpath,
    path: str | Path,
    *,
    T_base_work: ArrayLike | None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    R_work_tool: ArrayLike | None = None,
    config: ArmConfig | None = None,
    safe_height: float = 10e-3,
    max_module_moves: int = MAX_MODULE_MOVES,
    pr_frame: int = 90,
    pr_tool: int = 91,
    frame_number: int = 1,
    tool_number: int = 1,
) -> list[Path]:
    """Write ``tp`` as a FANUC ``.ls`` program (module docstring); return the files written.

    Parameters
    ----------
    tp : the toolpath (work frame)
    path : output ``.ls`` whose stem is a TP program name
    T_base_work : (4, 4) float, m — the user frame (work frame in the robot world; required,
        the identity means the robot base)
    tool : tool data (length); default :class:`RobotTool`
    tool_rotation : float or (N,) float, rad — rotation about the tool axis per point
    R_work_tool : (N, 3, 3), optional — full orientations (override ``tool_rotation``)
    config : ArmConfig, optional — joint angles of every point for the CONFIG strings
    safe_height : float, m — approach/retract height above the first/last point
    max_module_moves : int — forming moves per (sub-)program
    pr_frame, pr_tool : position registers used to set the frames
    frame_number, tool_number : UFRAME and UTOOL numbers
    """
    path = Path(path)
    if path.suffix.lower() != ".ls":
        raise InputError("a FANUC TP program must be written to a .ls file", file=path)
    name = path.stem.upper()
    prog = prepare_program(
        tp,
        T_base_work=T_base_work,
        tool=tool,
        tool_rotation=tool_rotation,
        R_work_tool=R_work_tool,
        safe_height=safe_height,
    )
    mods = split_modules(tp.lap, max_module_moves) if len(tp) > max_module_moves else []
    longest = f"{name}_{len(mods)}" if mods else name
    if not _NAME.fullmatch(name) or len(longest) > _MAX_NAME:
        raise InputError(
            f"the file name {path.stem!r} does not give a FANUC program name (a letter, then "
            f"letters, digits or _, at most {_MAX_NAME} characters with the _<k> suffix of the "
            f"sub-programs); rename it, e.g. {program_identifier(path.stem, 24)}.ls",
            file=path,
        )
    for what, v, hi in (
        ("pr_frame", pr_frame, 200),
        ("pr_tool", pr_tool, 200),
        ("frame_number", frame_number, 9),
        ("tool_number", tool_number, 10),
    ):
        if not (isinstance(v, int) and 1 <= v <= hi):
            raise InputError(f"must be an integer in 1…{hi}, got {v!r}", field=what)
    if pr_frame == pr_tool:
        raise InputError("the frame and tool registers must differ", field="pr_tool")
    tool, T, p = prog.tool, prog.T_base_work, prog.tip_mm
    wpr = _wpr_deg(prog.R_work_tool)
    if config is not None:
        if len(config) != len(tp):
            raise InputError(
                f"expected joint angles for the {len(tp)} points, got {len(config)}",
                field="config",
            )
        confs = fanuc_config(config)
        conf_note = "CONFIG from the joint angles of the IK branch"
    else:
        confs = ["N U T, 0, 0, 0"] * len(tp)
        conf_note = "no robot model: CONFIG N U T, 0, 0, 0 (check it)"
    speed, speed_note = _speed(tp.feed)
    up = np.array([0.0, 0.0, prog.safe_height_mm])
    uf = np.concatenate([T[:3, 3] * 1e3, _wpr_deg(T[:3, :3])])
    ut = np.array([0.0, 0.0, tool.length * 1e3, 0.0, 0.0, 0.0])
    body = [
        f"  ! roboisf {__version__} ISF toolpath",
        f"  ! {len(tp)} points, {tp.n_laps} laps",
        f"  ! {conf_note}",
        *([f"  ! {speed_note}"] if speed_note else []),
        *_frame_lines(pr_frame, uf, f"UFRAME[{frame_number}]"),
        *_frame_lines(pr_tool, ut, f"UTOOL[{tool_number}]"),
        f"  UFRAME_NUM={frame_number}",
        f"  UTOOL_NUM={tool_number}",
        "J P[1] 20% FINE   ",
    ]
    positions = [_pos_block(1, p[0] + up, wpr[0], confs[0])]
    move = f" {speed} CNT100   "
    files: list[tuple[Path, str]] = []

    p_l, wpr_l = p.tolist(), wpr.tolist()  # Python floats format several times faster

    def moves(sl: slice, first_index: int) -> tuple[list[str], list[str]]:
        b, ps = [], []
        for k, i in enumerate(range(sl.start, sl.stop)):
            j = first_index + k
            b.append(f"L P[{j}]{move}")
            ps.append(_pos_block(j, p_l[i], wpr_l[i], confs[i]))
        return b, ps

    if not mods:
        b, ps = moves(slice(0, len(tp)), 2)
        body += b
        positions += ps
        last = len(tp) + 2
    else:
        for k, sl in enumerate(mods, start=1):
            sub = f"{name}_{k}"
            b, ps = moves(sl, 1)
            head = [
                f"  ! part {k} of {len(mods)} of {name}: moves {sl.start + 1}..{sl.stop}",
                f"  UFRAME_NUM={frame_number}",
                f"  UTOOL_NUM={tool_number}",
            ]
            files.append((path.with_name(f"{path.stem}_{k}.ls"), _program(sub, head + b, ps)))
            body.append(f"  CALL {sub}    ")
        last = 2
    body.append(f"L P[{last}] 50mm/sec FINE   ")
    positions.append(_pos_block(last, p[-1] + up, wpr[-1], confs[-1]))
    files.append((path, _program(name, body, positions)))
    with contextlib.ExitStack() as stack:
        for f, text in files:
            stack.enter_context(atomic_write(f)).write(text)
    return [files[-1][0], *(f for f, _ in files[:-1])]  # main first, then the parts


_NUM = NUMBER_RE
_LINE = re.compile(r"^\s*(\d+):(.*);\s*$")
_POSBLK = re.compile(
    r"P\[(\d+)\]\s*\{\s*GP1\s*:\s*UF\s*:\s*(\d+)\s*,\s*UT\s*:\s*(\d+)\s*,\s*"
    r"CONFIG\s*:\s*'([^']*)'\s*,\s*"
    rf"X\s*=\s*({_NUM})\s*mm\s*,\s*Y\s*=\s*({_NUM})\s*mm\s*,\s*Z\s*=\s*({_NUM})\s*mm\s*,\s*"
    rf"W\s*=\s*({_NUM})\s*deg\s*,\s*P\s*=\s*({_NUM})\s*deg\s*,\s*R\s*=\s*({_NUM})\s*deg\s*\}}\s*;",
    re.S,
)
_MOVE = re.compile(r"^([JL])\s+P\[(\d+)\]\s+(\S+)\s+(FINE|CNT\d+)")


def _read_ls(path: Path) -> tuple[str, list[str], dict[int, tuple]]:
    if not path.is_file():
        raise InputError("FANUC .ls program not found", file=path)
    text = read_program_text(path)
    m = re.search(r"^/PROG\s+(\w+)", text, re.M)
    if not m or "/MN" not in text or "/END" not in text:
        raise InputError("not a TP program (expected /PROG, /MN and /END)", file=path)
    mn, _, rest = text.partition("/MN")[2].partition("/POS")
    body = []
    for k, ln in enumerate(mn.strip("\n").splitlines(), start=1):
        lm = _LINE.match(ln)
        if not lm or int(lm.group(1)) != k:
            raise InputError(f"expected line {k}: '<n>:<instruction> ;'", file=path)
        body.append(lm.group(2).strip())
    pos = {}
    for pm in _POSBLK.finditer(rest):
        g = pm.groups()
        pos[int(g[0])] = (int(g[1]), int(g[2]), g[3], [float(x) for x in g[4:]])
    return m.group(1), body, pos


def read_fanuc(path: str | Path) -> ProgramPath:
    """Parse a ``.ls`` program (and the sub-programs it CALLs, from the same folder) written by
    :func:`write_fanuc`: the ``L`` forming moves in order (the approach ``J`` and the final
    retract ``FINE`` move are left out), orientations, CONFIG strings (``meta["config"]``), the
    feed, the user frame as ``T_base_work`` and the tool length."""
    path = Path(path)
    name, body, pos = _read_ls(path)
    pr: dict[int, list[float]] = {}
    frames: dict[str, list[float]] = {}
    rows: list[tuple] = []
    speeds: list[str] = []
    called: list[str] = []

    def take(body: list[str], pos: dict[int, tuple], where: Path, top: bool) -> None:
        for ln in body:
            s = ln.strip()
            if m := re.fullmatch(rf"PR\[(\d+),(\d)\]=({_NUM})", s):
                pr.setdefault(int(m.group(1)), [0.0] * 6)[int(m.group(2)) - 1] = float(m.group(3))
            elif m := re.fullmatch(r"(UFRAME|UTOOL)\[\d+\]=PR\[(\d+)\]", s):
                frames[m.group(1)] = list(pr.get(int(m.group(2)), [0.0] * 6))
            elif m := re.fullmatch(r"CALL\s+(\w+)", s):
                sub = where.with_name(f"{m.group(1).lower()}.ls")
                if not sub.is_file():
                    sub = where.with_name(f"{m.group(1)}.ls")
                called.append(m.group(1))
                _, b2, p2 = _read_ls(sub)
                take(b2, p2, sub, False)
            elif m := _MOVE.match(s):
                i = int(m.group(2))
                if i not in pos:
                    raise InputError(f"P[{i}] is used but not defined in /POS", file=where)
                if m.group(1) == "L" and m.group(4) != "FINE":
                    rows.append(pos[i])
                    speeds.append(m.group(3))

    take(body, pos, path, True)
    if not rows:
        raise InputError("no forming L moves found", file=path)
    a = np.array([r[3] for r in rows])
    sp = re.fullmatch(r"(\d+(?:\.\d+)?)(mm/sec|cm/min)", speeds[0])
    if not sp:
        raise InputError(f"cannot read the speed {speeds[0]!r}", file=path)
    feed = float(sp.group(1)) * (1e-3 if sp.group(2) == "mm/sec" else 1e-2 / 60)
    T = None
    if "UFRAME" in frames:
        f = np.array(frames["UFRAME"])
        T = np.eye(4)
        T[:3, :3] = abc_to_matrix(np.radians(f[3:][::-1]))
        T[:3, 3] = f[:3] * 1e-3
    tool = RobotTool(length=frames["UTOOL"][2] * 1e-3) if "UTOOL" in frames else None
    return ProgramPath(
        tip=a[:, :3] * 1e-3,
        R_work_tool=abc_to_matrix(np.radians(a[:, 3:][:, ::-1])),
        feed=feed,
        T_base_work=T,
        tool=tool,
        meta={
            "name": name,
            "config": [r[2] for r in rows],
            "frames": [(r[0], r[1]) for r in rows],
            "wpr_deg": a[:, 3:],
            "sub_programs": called,
        },
    )
