"""ABB RAPID module (``.mod``) for a forming toolpath.

Layout written::

    MODULE ISF_cone
      ! roboisf 0.1.0: 52000 points, ...
      PERS tooldata tBall := [TRUE,[[0,0,200],[1,0,0,0]],[2,[0,0,100],[1,0,0,0],0,0,0]];
      PERS wobjdata wBlank := [FALSE,TRUE,"",[[1600,0,700],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
      CONST speeddata vForm := [12.5,500,5000,1000];
      PROC main()
        ConfL\\Off;
        MoveJ Offs(<first point>,0,0,<safe>),v200,fine,tBall\\WObj:=wBlank;
        ISF_cone_1;
        ISF_cone_2;
        ...
        MoveL Offs(<last point>,0,0,<safe>),v50,fine,tBall\\WObj:=wBlank;
      ENDPROC
      PROC ISF_cone_1()
        MoveL [[x,y,z],[q1,q2,q3,q4],[0,0,0,0],[9E9,...]],vForm,z0,tBall\\WObj:=wBlank;
        ...
      ENDPROC
    ENDMODULE

* ``tooldata``: robhold TRUE, TCP = ball tip at ``(0, 0, L)`` in tool0 (z along the tool),
  mass and centre of gravity.
* ``wobjdata``: user frame ``uframe = T_base_work`` (robot base = world), object frame identity.
  Robtargets are the toolpath tip in the work frame, mm at 1 µm.
* Orientation ``[q1, q2, q3, q4] = (w, x, y, z)`` of ``R_work_tool``; tool pointing down is
  ``[0, 1, 0, 0]``; a rotation γ about the tool axis gives ``[0, cos γ/2, −sin γ/2, 0]``.
* ``confdata`` is ``[0,0,0,0]`` (or the given one) with ``ConfL\\Off``: the controller picks the
  configuration closest to the current one, as usual for long contour programs.
* Forming moves are split into PROCs of at most ``max_moves`` (default 2000) because controllers
  limit routine size; ``main`` calls them in order.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from roboisf import __version__
from roboisf.errors import InputError
from roboisf.frames.rotations import matrix_to_quat, quat_to_matrix
from roboisf.io.atomic import atomic_write
from roboisf.io.program import (
    NUMBER_RE,
    ProgramPath,
    RobotTool,
    fmt_num,
    identifier,
    prepare_program,
    program_identifier,
)
from roboisf.toolpath.toolpath import Toolpath

__all__ = ["ZONES", "read_rapid", "write_rapid"]

#: Predefined RAPID zonedata names.
ZONES = ("fine", "z0", "z1", "z5", "z10", "z15", "z20", "z30", "z40", "z50", "z60", "z80", "z100")


def _pose(p: np.ndarray, q: np.ndarray) -> str:
    xyz = ",".join(fmt_num(x) for x in p)
    return f"[[{xyz}],[{','.join(fmt_num(x, 9) for x in q)}]]"


def write_rapid(
    tp: Toolpath,
    path: str | Path,
    *,
    T_base_work: ArrayLike | None = None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    R_work_tool: ArrayLike | None = None,
    zone: str = "z0",
    conf: tuple[int, int, int, int] = (0, 0, 0, 0),
    safe_height: float = 10e-3,
    max_moves: int = 2000,
    module: str | None = None,
    wobj_name: str = "wBlank",
) -> None:
    """Write ``tp`` as an ABB RAPID module (see the module docstring for the layout).

    Parameters
    ----------
    tp : the toolpath (work frame)
    path : output ``.mod``
    T_base_work : (4, 4) float, m — work object placement in the robot base (identity if None)
    tool : the tool data (length, mass, cog); default :class:`RobotTool`
    tool_rotation : float or (N,) float, rad — rotation of the tool about its own axis
    R_work_tool : (N, 3, 3) float, optional — full orientations (override ``tool_rotation``)
    zone : RAPID zonedata name (``fine``, ``z0``, ``z1``, …)
    conf : confdata [cf1, cf4, cf6, cfx]
    safe_height : float, m — approach/retract height above the first/last point
    max_moves : int — forming moves per PROC
    module : module name (default: from the file name)
    """
    path = Path(path)
    if zone not in ZONES:
        raise InputError(f"unknown zone {zone!r}; expected one of {', '.join(ZONES)}", field="zone")
    name = identifier(module, "module", 26) if module else program_identifier(path.stem, 26)
    identifier(wobj_name, "wobj_name", 32)
    prog = prepare_program(
        tp,
        T_base_work=T_base_work,
        tool=tool,
        tool_rotation=tool_rotation,
        R_work_tool=R_work_tool,
        safe_height=safe_height,
        max_moves=max_moves,
    )
    tool, T, p, chunks = prog.tool, prog.T_base_work, prog.tip_mm, prog.chunks
    q = matrix_to_quat(prog.R_work_tool)
    qb = matrix_to_quat(T[:3, :3])
    cog = tool.cog_xyz * 1e3
    v = tp.feed * 1e3
    cf = ",".join(str(int(c)) for c in conf)
    tail = f",vForm,{zone},{tool.name}\\WObj:={wobj_name};\n"
    ext = "[9E9,9E9,9E9,9E9,9E9,9E9]"
    up = fmt_num(prog.safe_height_mm)
    out = [
        f"MODULE {name}\n",
        f"  ! roboisf {__version__}: ISF toolpath, {len(tp)} points, {tp.n_laps} laps, "
        f"ball radius {fmt_num(tp.tool_radius * 1e3)} mm\n",
        "  ! robtargets: ball tip in the work object (mm); quaternion q1..q4 = (w,x,y,z) of "
        "the tool frame (z along the tool)\n",
        f"  PERS tooldata {tool.name} := [TRUE,[[0,0,{fmt_num(tool.length * 1e3)}],[1,0,0,0]],"
        f"[{fmt_num(tool.mass)},[{fmt_num(cog[0])},{fmt_num(cog[1])},{fmt_num(cog[2])}],[1,0,0,0],0,0,0]];\n",
        f'  PERS wobjdata {wobj_name} := [FALSE,TRUE,"",{_pose(T[:3, 3] * 1e3, qb)},'
        "[[0,0,0],[1,0,0,0]]];\n",
        f"  CONST speeddata vForm := [{fmt_num(v)},500,5000,1000];\n",
        "  PROC main()\n",
        "    ConfL\\Off;\n",
        f"    MoveJ Offs({_pose(p[0], q[0])[:-1]},[{cf}],{ext}],0,0,{up}),"
        f"v200,fine,{tool.name}\\WObj:={wobj_name};\n",
    ]
    out += [f"    {name}_{k + 1};\n" for k in range(len(chunks))]
    out += [
        f"    MoveL Offs({_pose(p[-1], q[-1])[:-1]},[{cf}],{ext}],0,0,{up}),"
        f"v50,fine,{tool.name}\\WObj:={wobj_name};\n",
        "  ENDPROC\n",
    ]
    for k, sl in enumerate(chunks):
        out.append(f"  PROC {name}_{k + 1}()\n")
        out.extend(
            f"    MoveL {_pose(pp, qq)[:-1]},[{cf}],{ext}]{tail}"
            for pp, qq in zip(p[sl], q[sl], strict=True)
        )
        out.append("  ENDPROC\n")
    out.append("ENDMODULE\n")
    with atomic_write(path) as fh:
        fh.write("".join(out))


_NUM = NUMBER_RE
_MOVEL = re.compile(
    rf"^\s*MoveL\s+\[\[({_NUM}),({_NUM}),({_NUM})\],\[({_NUM}),({_NUM}),({_NUM}),({_NUM})\]"
    rf",\[([^\]]*)\],\[[^\]]*\]\]\s*,\s*(\w+)\s*,\s*(\w+)\s*,\s*(\w+)"
)
_PROC = re.compile(r"^\s*PROC\s+(\w+)\s*\(")
_TOOL = re.compile(
    rf"tooldata\s+(\w+)\s*:=\s*\[\s*\w+\s*,\s*\[\[({_NUM}),({_NUM}),({_NUM})\],\[[^\]]*\]\]\s*,"
    rf"\s*\[({_NUM})\s*,\s*\[({_NUM}),({_NUM}),({_NUM})\]"
)
_WOBJ = re.compile(
    rf"wobjdata\s+(\w+)\s*:=\s*\[[^,]*,[^,]*,\s*\"[^\"]*\"\s*,\s*\[\[({_NUM}),({_NUM}),({_NUM})\],"
    rf"\[({_NUM}),({_NUM}),({_NUM}),({_NUM})\]\]"
)
_SPEED = re.compile(rf"speeddata\s+(\w+)\s*:=\s*\[({_NUM})")


def read_rapid(path: str | Path) -> ProgramPath:
    """Parse a RAPID module written by :func:`write_rapid` (or of the same shape).

    Returns the ``MoveL`` robtargets inside the forming PROCs (every PROC except ``main``), in
    the order ``main`` calls them, with orientations, the speed of the first forming move, the
    work object placement and the tool data.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("RAPID module not found", file=path)
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    procs: dict[str, list[tuple[list[float], str, str]]] = {}
    order: list[str] = []
    current = None
    for lineno, ln in enumerate(lines, start=1):
        s = ln.split("!", 1)[0]
        m = _PROC.match(s)
        if m:
            current = m.group(1)
            procs[current] = []
            continue
        if re.match(r"^\s*ENDPROC", s):
            current = None
            continue
        if current == "main":
            call = re.match(r"^\s*(\w+)\s*;\s*$", s)
            if call:
                order.append(call.group(1))
            continue
        if current is not None and re.match(r"^\s*MoveL\b", s):
            m = _MOVEL.match(s)
            if not m:
                raise InputError(
                    "cannot parse this MoveL (expected an inline robtarget)", file=path, line=lineno
                )
            vals = [float(x) for x in m.groups()[:7]]
            procs[current].append((vals, m.group(9), m.group(10)))
    routines = [r for r in order if r in procs] or [r for r in procs if r != "main"]
    rows = [row for r in routines for row in procs[r]]
    if not rows:
        raise InputError("no forming MoveL found in the module's PROCs", file=path)
    a = np.array([r[0] for r in rows])
    qn = np.linalg.norm(a[:, 3:], axis=1)
    if np.any(np.abs(qn - 1) > 1e-4):
        raise InputError("robtarget quaternion is not unit", file=path)
    speeds = {m.group(1): float(m.group(2)) for m in _SPEED.finditer(text)}
    sp = rows[0][1]
    if sp in speeds:
        feed = speeds[sp] * 1e-3
    elif re.fullmatch(r"v\d+", sp):
        feed = float(sp[1:]) * 1e-3
    else:
        raise InputError(f"speeddata {sp!r} is not defined in the module", file=path)
    T = None
    w = _WOBJ.search(text)
    if w:
        g = [float(x) for x in w.groups()[1:]]
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(g[3:])
        T[:3, 3] = np.array(g[:3]) * 1e-3
    tool = None
    t = _TOOL.search(text)
    if t:
        g = [float(x) for x in t.groups()[1:]]
        if g[0] != 0 or g[1] != 0:
            raise InputError(
                "only straight tools with the TCP on the flange axis are read back",
                file=path,
                field="tooldata",
            )
        tool = RobotTool(
            length=g[2] * 1e-3,
            mass=g[3],
            cog=(g[4] * 1e-3, g[5] * 1e-3, g[6] * 1e-3),
            name=t.group(1),
        )
    return ProgramPath(
        tip=a[:, :3] * 1e-3,
        R_work_tool=quat_to_matrix(a[:, 3:]),
        feed=feed,
        T_base_work=T,
        tool=tool,
        meta={"zone": rows[0][2], "routines": routines, "quaternions": a[:, 3:]},
    )
