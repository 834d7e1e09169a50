r"""ABB RAPID program (``.mod``) for a forming toolpath.

Layout written — a path of at most ``max_module_moves`` moves (default
:data:`~roboisf.cam.program.MAX_MODULE_MOVES`) is one module::

    MODULE cone
      ! roboisf 0.1.0: 52000 points, ...
      PERS tooldata tBall := [TRUE,[[0,0,306],[1,0,0,0]],[2,[0,0,153],[1,0,0,0],0,0,0]];
      PERS wobjdata wBlank := [FALSE,TRUE,"",[[2200,0,200],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
      CONST speeddata vForm := [12.5,500,5000,1000];
      PROC main()
        ConfJ\On;
        ConfL\Off;
        MoveJ Offs(<first point + IK confdata>,0,0,<safe>),v200,fine,tBall\WObj:=wBlank;
        cone_1;
        cone_2;
        MoveL Offs(<last point>,0,0,<safe>),v50,fine,tBall\WObj:=wBlank;
      ENDPROC
      PROC cone_1()
        MoveL [[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[9E9,...]],vForm,z0,tBall\WObj:=wBlank;
        ...
      ENDPROC
    ENDMODULE

A longer path is a *program set*: the main module ``cone.mod`` (data, approach, retract) and part
modules ``cone_1.mod``, ``cone_2.mod``, … of at most ``max_module_moves`` moves each, split at lap
ends where possible. ``main`` loads them one after the other while the robot moves — the next
part is loaded (``StartLoad \Dynamic``) while the current one runs, linked by ``WaitLoad``, called
by late binding (``%"cone_2_run"%``: the main module holds no static reference to a routine that
is not loaded yet) and removed by ``UnLoad``; at most two part modules are in program memory at a
time. Copy all files into the folder ``sDir`` names on the controller (``HOME:`` by default).

* ``tooldata``: robhold TRUE, TCP = ball tip at ``(0, 0, L)`` in tool0 (z along the tool),
  mass and centre of gravity.
* ``wobjdata``: user frame ``uframe = T_base_work`` (robot base = world), object frame identity.
  Robtargets are the toolpath tip in the work frame, mm at 1 µm. There is no default placement.
* Orientation ``[q1, q2, q3, q4] = (w, x, y, z)`` of ``R_work_tool``; tool pointing down is
  ``[0, 1, 0, 0]``; a rotation γ about the tool axis gives ``[0, cos γ/2, −sin γ/2, 0]``.
* ``confdata`` of every robtarget from the joint angles of the IK branch
  (:func:`~roboisf.robot.armconfig.abb_confdata`: quadrants of axes 1, 4, 6 and the cfx bits). The
  approach ``MoveJ`` runs with ``ConfJ\On`` so the robot takes that branch; the forming
  ``MoveL`` run with ``ConfL\Off`` (the path is continuous from there). Without joint angles
  (no robot model) confdata is ``[0,0,0,0]`` and both checks are off, said in the header.
* Forming moves are split into PROCs of at most ``max_moves`` (default 2000) inside each module.
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
    fmt_num,
    identifier,
    prepare_program,
    program_identifier,
    read_program_text,
    split_chunks,
    split_modules,
)
from roboisf.errors import InputError
from roboisf.frames.rotations import matrix_to_quat, quat_to_matrix
from roboisf.io.atomic import atomic_write
from roboisf.path.toolpath import Toolpath
from roboisf.robot.armconfig import ArmConfig, abb_confdata

__all__ = ["ZONES", "module_name", "read_rapid", "write_rapid"]

#: Predefined RAPID zonedata names.
ZONES = ("fine", "z0", "z1", "z5", "z10", "z15", "z20", "z30", "z40", "z50", "z60", "z80", "z100")


def _pose(p: Sequence[float], q: Sequence[float]) -> str:
    xyz = ",".join(fmt_num(x) for x in p)
    return f"[[{xyz}],[{','.join(fmt_num(x, 9) for x in q)}]]"


_EXT = "[9E9,9E9,9E9,9E9,9E9,9E9]"


def _target(p: Sequence[float], q: Sequence[float], cf: Sequence[int]) -> str:
    return f"{_pose(p, q)[:-1]},[{','.join(str(int(c)) for c in cf)}],{_EXT}]"


def _targets(p: list[list[float]], q: list[list[float]], cf: list[list[int]]) -> list[str]:
    """:func:`_target` of every row, the same text: a target's orientation, confdata and
    external axes are formatted once per distinct value (an ISF path holds its tool's
    orientation: one or a few for a whole part), only its position per row (35 k targets of
    one orientation: 0.22–0.26 → 0.08–0.11 s)."""
    tails: dict[tuple[float | int, ...], str] = {}
    out = []
    for (x, y, z), qq, cc in zip(p, q, cf, strict=True):
        key = (*qq, *cc)  # ±0 share a key: fmt_num writes both as 0
        tail = tails.get(key)
        if tail is None:
            tail = tails[key] = _target((0.0, 0.0, 0.0), qq, cc)[len("[[0,0,0]") :]
        out.append(f"[[{fmt_num(x)},{fmt_num(y)},{fmt_num(z)}]{tail}")
    return out


def _procs(
    name: str, moves: list[str], tail: str, max_moves: int, offset: int
) -> tuple[list[str], list[str]]:
    """PROC blocks of at most ``max_moves`` MoveL each; returns (text lines, routine names)."""
    lines: list[str] = []
    names: list[str] = []
    for k, sl in enumerate(split_chunks(len(moves), max_moves)):
        r = f"{name}_{offset + k + 1}"
        names.append(r)
        lines.append(f"  PROC {r}()\n")
        lines.extend(f"    MoveL {m}{tail}" for m in moves[sl])
        lines.append("  ENDPROC\n")
    return lines, names


def write_rapid(
    tp: Toolpath,
    path: str | Path,
    *,
    T_base_work: ArrayLike | None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    R_work_tool: ArrayLike | None = None,
    config: ArmConfig | None = None,
    zone: str = "z0",
    safe_height: float = 10e-3,
    max_moves: int = 2000,
    max_module_moves: int = MAX_MODULE_MOVES,
    module: str | None = None,
    wobj_name: str = "wBlank",
    load_dir: str = "HOME:",
) -> list[Path]:
    """Write ``tp`` as an ABB RAPID module or program set (module docstring); return the files.

    Parameters
    ----------
    tp : the toolpath (work frame)
    path : output ``.mod`` (the main module; part modules ``<stem>_<k>.mod`` go beside it)
    T_base_work : (4, 4) float, m — work object placement in the robot base (required; the
        identity means the robot base)
    tool : the tool data (length, mass, cog); default :class:`RobotTool`
    tool_rotation : float or (N,) float, rad — rotation of the tool about its own axis
    R_work_tool : (N, 3, 3) float, optional — full orientations (override ``tool_rotation``)
    config : ArmConfig, optional — joint angles of every point (IK branch or joint log) for the
        confdata; None writes ``[0,0,0,0]`` with the configuration checks off
    zone : RAPID zonedata name (``fine``, ``z0``, ``z1``, …)
    safe_height : float, m — approach/retract height above the first/last point
    max_moves : int — forming moves per PROC
    max_module_moves : int — forming moves per loadable module (split above it)
    module : module name (default: the file stem, which must then be a RAPID name)
    load_dir : controller folder the part modules are loaded from
    """
    path = Path(path)
    if zone not in ZONES:
        raise InputError(f"unknown zone {zone!r}; expected one of {', '.join(ZONES)}", field="zone")
    name = module_name(path, module)
    identifier(wobj_name, "wobj_name", 32)
    if '"' in load_dir or "\\" in load_dir:
        raise InputError(f"not a RAPID string: {load_dir!r}", field="load_dir")
    prog = prepare_program(
        tp,
        T_base_work=T_base_work,
        tool=tool,
        tool_rotation=tool_rotation,
        R_work_tool=R_work_tool,
        safe_height=safe_height,
        max_moves=max_moves,
    )
    tool, T, p = prog.tool, prog.T_base_work, prog.tip_mm
    q = matrix_to_quat(prog.R_work_tool)
    wobj_pose = _pose((T[:3, 3] * 1e3).tolist(), matrix_to_quat(T[:3, :3]).tolist())
    cog = tool.cog_xyz * 1e3
    if config is not None:
        if len(config) != len(tp):
            raise InputError(
                f"expected joint angles for the {len(tp)} points, got {len(config)}",
                field="config",
            )
        cf = abb_confdata(config)
        conf_note = "confdata from the joint angles of the IK branch (ConfJ on for the approach)"
        conf_j = "ConfJ\\On"
    else:
        cf = np.zeros((len(tp), 4), dtype=np.int64)
        conf_note = "no robot model given: confdata [0,0,0,0], configuration checks off"
        conf_j = "ConfJ\\Off"
    tail = f",vForm,{zone},{tool.name}\\WObj:={wobj_name};\n"
    up = fmt_num(prog.safe_height_mm)
    # Python floats: formatting numpy scalars one by one is several times slower
    moves = _targets(p.tolist(), q.tolist(), cf.tolist())
    modules = split_modules(tp.lap, max_module_moves) if len(tp) > max_module_moves else []
    if modules and len(f"{name}_{len(modules)}_run") > 32:
        raise InputError(
            f"the module name {name!r} is too long for {len(modules)} part modules (RAPID names "
            "have at most 32 characters): use a shorter file name",
            file=path,
        )
    out = [
        f"MODULE {name}\n",
        f"  ! roboisf {__version__}: ISF toolpath, {len(tp)} points, {tp.n_laps} laps, "
        f"ball radius {fmt_num(tp.tool_radius * 1e3)} mm\n",
        "  ! robtargets: ball tip in the work object (mm); quaternion q1..q4 = (w,x,y,z) of "
        "the tool frame (z along the tool)\n",
        f"  ! {conf_note}\n",
    ]
    if modules:
        out.append(
            f"  ! program set: this main module and {len(modules)} part modules "
            f"{name}_1.mod … {name}_{len(modules)}.mod (at most {max_module_moves} moves each), "
            "loaded in turn from sDir\n"
        )
    out += [
        f"  PERS tooldata {tool.name} := [TRUE,[[0,0,{fmt_num(tool.length * 1e3)}],[1,0,0,0]],"
        f"[{fmt_num(tool.mass)},[{fmt_num(cog[0])},{fmt_num(cog[1])},{fmt_num(cog[2])}],"
        "[1,0,0,0],0,0,0]];\n",
        f'  PERS wobjdata {wobj_name} := [FALSE,TRUE,"",{wobj_pose},[[0,0,0],[1,0,0,0]]];\n',
        f"  CONST speeddata vForm := [{fmt_num(tp.feed * 1e3)},500,5000,1000];\n",
    ]
    if modules:
        out += [
            f'  CONST string sDir := "{load_dir}";\n',
            "  VAR loadsession ldNext;\n",
        ]
    out += [
        "  PROC main()\n",
        f"    {conf_j};\n",
        "    ConfL\\Off;\n",
        f"    MoveJ Offs({moves[0]},0,0,{up}),v200,fine,{tool.name}\\WObj:={wobj_name};\n",
    ]
    files: list[tuple[Path, str]] = []
    if not modules:
        procs, names = _procs(name, moves, tail, max_moves, 0)
        out += [f"    {r};\n" for r in names]
    else:
        procs = []
        f1 = f"{name}_1.mod"
        out += [
            f'    StartLoad \\Dynamic, sDir \\File:="{f1}", ldNext;\n',
            "    WaitLoad ldNext;\n",
        ]
        for k, sl in enumerate(modules, start=1):
            mod = f"{name}_{k}"
            if k < len(modules):
                out.append(f'    StartLoad \\Dynamic, sDir \\File:="{name}_{k + 1}.mod", ldNext;\n')
            out.append(f'    %"{mod}_run"%;\n')
            if k < len(modules):
                out.append("    WaitLoad ldNext;\n")
            out.append(f'    UnLoad sDir \\File:="{mod}.mod";\n')
            sub, names = _procs(mod, moves[sl], tail, max_moves, 0)
            text = [
                f"MODULE {mod}\n",
                f"  ! roboisf {__version__}: part {k} of {len(modules)} of {name}.mod, moves "
                f"{sl.start + 1}…{sl.stop} (data in {name}.mod)\n",
                f"  PROC {mod}_run()\n",
                *(f"    {r};\n" for r in names),
                "  ENDPROC\n",
                *sub,
                "ENDMODULE\n",
            ]
            files.append((path.with_name(f"{mod}.mod"), "".join(text)))
    out += [
        f"    MoveL Offs({moves[-1]},0,0,{up}),v50,fine,{tool.name}\\WObj:={wobj_name};\n",
        "  ENDPROC\n",
        *procs,
        "ENDMODULE\n",
    ]
    files.append((path, "".join(out)))
    with contextlib.ExitStack() as stack:
        for f, body in files:
            stack.enter_context(atomic_write(f)).write(body)
    return [files[-1][0], *(f for f, _ in files[:-1])]  # main first, then the parts


def module_name(path: Path, module: str | None = None) -> str:
    """The RAPID module name of a program written to ``path``: ``module`` if given, else the file
    stem, which must be a RAPID identifier (``InputError`` naming the file otherwise)."""
    if module:
        return identifier(module, "module", 26)
    stem = path.stem
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,25}", stem):
        raise InputError(
            f"the file name {stem!r} is not a RAPID module name (a letter, then letters, digits "
            f"or _, at most 26 characters here); rename the file, e.g. "
            f"{program_identifier(stem, 26)}.mod, or pass the module name",
            file=path,
        )
    return stem


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


_Item = tuple[str, object]


def _strip_comment(line: str) -> str:
    """The line without its ``!`` comment (a ``!`` inside a string is text)."""
    if "!" not in line:  # most lines of a program (its moves): no scan character by character
        return line
    quoted = False
    for i, ch in enumerate(line):
        if ch == '"':
            quoted = not quoted
        elif ch == "!" and not quoted:
            return line[:i]
    return line


def _parse_module(path: Path, procs: dict[str, list[_Item]], files: list[str]) -> str:
    """Add the PROCs of the module at ``path`` to ``procs`` (items: moves and calls in order) and
    the module files it loads to ``files``; return its text."""
    if not path.is_file():
        raise InputError("RAPID module not found", file=path)
    text = read_program_text(path)
    current: list[_Item] | None = None
    cname = ""
    for lineno, ln in enumerate(text.splitlines(), start=1):
        s = _strip_comment(ln)
        m = _PROC.match(s)
        if m:
            cname = m.group(1)
            current = procs.setdefault(cname, [])
            continue
        if re.match(r"^\s*ENDPROC", s):
            current = None
            continue
        if current is None:
            continue
        ld = re.match(r'^\s*(?:Start)?Load\b.*\\File\s*:=\s*"([^"]+)"', s)
        if ld:
            files.append(ld.group(1))
            continue
        call = re.match(r'^\s*(?:(\w+)|%\s*"(\w+)"\s*%)\s*;\s*$', s)
        if call:
            current.append(("call", call.group(1) or call.group(2)))
            continue
        if cname != "main" and re.match(r"^\s*MoveL\b", s):
            mm = _MOVEL.match(s)
            if not mm:
                raise InputError(
                    "cannot parse this MoveL (expected an inline robtarget)", file=path, line=lineno
                )
            vals = [float(x) for x in mm.groups()[:7]]
            current.append(("move", (vals, mm.group(8), mm.group(9), mm.group(10))))
    return text


def read_rapid(path: str | Path) -> ProgramPath:
    """Parse a RAPID module or program set written by :func:`write_rapid` (or of that shape).

    Returns the ``MoveL`` robtargets of the routines ``main`` calls — directly, or by late
    binding in the part modules it loads (read from the same folder) — in call order, with
    orientations, confdata (``meta["confdata"]`` (N, 4)), the speed of the first forming move,
    the work object placement and the tool data.
    """
    path = Path(path)
    procs: dict[str, list[_Item]] = {}
    loads: list[str] = []
    text = _parse_module(path, procs, loads)
    if "main" not in procs:
        raise InputError("no PROC main() in the module", file=path)
    for f in loads:
        part = path.with_name(Path(f).name)
        _parse_module(part, procs, [])
    rows: list[tuple[list[float], str, str, str]] = []
    routines: list[str] = []

    def expand(r: str, depth: int) -> None:
        if depth > 8:
            raise InputError(f"routine calls nested too deep at {r!r}", file=path)
        for kind, item in procs.get(r, []):
            if kind == "call":
                assert isinstance(item, str)
                if item in procs and item != "main":
                    if any(k == "move" for k, _ in procs[item]):
                        routines.append(item)
                    expand(item, depth + 1)
            elif r != "main":
                rows.append(item)  # type: ignore[arg-type]

    expand("main", 0)
    if not rows:
        raise InputError("no forming MoveL found in the routines main calls", file=path)
    a = np.array([r[0] for r in rows])
    qn = np.linalg.norm(a[:, 3:], axis=1)
    if np.any(np.abs(qn - 1) > 1e-4):
        raise InputError("robtarget quaternion is not unit", file=path)
    try:
        conf = np.array([[int(c) for c in r[1].split(",")] for r in rows], dtype=np.int64)
    except ValueError:
        raise InputError("confdata must be four integers", file=path) from None
    if conf.shape != (len(rows), 4):
        raise InputError("confdata must be four integers [cf1,cf4,cf6,cfx]", file=path)
    speeds = {m.group(1): float(m.group(2)) for m in _SPEED.finditer(text)}
    sp = rows[0][2]
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
        meta={
            "zone": rows[0][3],
            "routines": routines,
            "quaternions": a[:, 3:],
            "confdata": conf,
            "modules": [path.name, *(Path(f).name for f in loads)],
        },
    )
