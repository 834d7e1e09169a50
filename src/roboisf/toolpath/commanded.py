"""A commanded version of a nominal toolpath, read from any program roboisf writes or imports.

A *commanded* path (a compensated command) keeps the nominal contacts and normals and carries
another programmed ``tip`` (:meth:`Toolpath.with_tip`). This module reads the tips back from

* roboisf's toolpath CSV (``compensated.csv``; any row count check below applies),
* a robot program of any format of :mod:`roboisf.programs.registry` with a reader — ABB RAPID
  module or module set (``.mod``), KUKA KRL (``.src`` + ``.dat``),
  FANUC TP (``.ls``): the forming moves of :func:`roboisf.programs.rapid.read_rapid`,
  :func:`roboisf.programs.krl.read_krl`, :func:`roboisf.programs.fanuc.read_fanuc` (approach and
  retract moves are not forming moves),
* a CAM program (G-code, Sinumerik, APT/CL, a point list): its feed moves, approach moves
  above the sheet plane dropped,

and pairs them point by point with the nominal path: the program must have exactly one forming
move per nominal point, in order, each within ``max_offset`` of its nominal tip (a command is a
correction, not another path). A robot program's work object and tool must be the cell's (to
``POSE_TOL``): the tips are in the work frame only if they are.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.path.toolpath import Toolpath

if TYPE_CHECKING:
    from roboisf.programs.registry import ProgramFormat

__all__ = ["POSE_TOL", "read_commanded", "robot_program_format"]

F64 = NDArray[np.float64]

#: Accepted difference [m] between a program's work object / tool length and the cell's.
POSE_TOL = 1e-5


def robot_program_format(path: Path) -> ProgramFormat | None:
    """The registered robot-program format whose suffixes (written or read) hold ``path``'s,
    with a reader; None for any other file."""
    from roboisf.programs.registry import program_formats

    suffix = path.suffix.lower()
    for f in program_formats():
        if f.kind == "robot" and f.read is not None and suffix in (*f.suffixes, *f.read_suffixes):
            return f
    return None


def _program_tips(
    path: Path, part_z_top: float, T_base_work: F64 | None, tool_length: float | None
) -> F64:
    """Forming-move tips (M, 3) m in the work frame of the program at ``path``."""
    suffix = path.suffix.lower()
    if suffix == ".csv":
        from roboisf.toolpath.importer import detect_toolpath_format

        if detect_toolpath_format(path) == "csv":
            from roboisf.cam.toolpath_csv import read_toolpath_csv

            return read_toolpath_csv(path).tip
    robot_format = robot_program_format(path)
    if robot_format is not None:
        assert robot_format.read is not None
        prog = robot_format.read(path)
        if T_base_work is not None and prog.T_base_work is not None:
            dt = float(np.linalg.norm(prog.T_base_work[:3, 3] - T_base_work[:3, 3]))
            dr = float(np.max(np.abs(prog.T_base_work[:3, :3] - T_base_work[:3, :3])))
            if dt > POSE_TOL or dr > POSE_TOL:
                raise InputError(
                    f"the program's work object is {dt * 1e3:.3f} mm (rotation entries "
                    f"{dr:.1e}) from the cell's placement: its tips are not in this cell's "
                    "work frame",
                    file=path,
                )
        if tool_length is not None and prog.tool is not None:
            if abs(prog.tool.length - tool_length) > POSE_TOL:
                raise InputError(
                    f"the program's tool is {prog.tool.length * 1e3:.3f} mm long, the cell's "
                    f"{tool_length * 1e3:.3f} mm: its TCP is not the cell's tip",
                    file=path,
                )
        return np.asarray(prog.tip, dtype=float)
    from roboisf.toolpath.importer import ImportOptions, detect_toolpath_format, read_cam_moves

    fmt = detect_toolpath_format(path)
    if fmt == "csv":
        from roboisf.cam.toolpath_csv import read_toolpath_csv

        return read_toolpath_csv(path).tip
    from roboisf.cam.cam import FEED

    moves = read_cam_moves(path, ImportOptions(fmt=fmt))
    keep = (moves.kind == FEED) & (moves.point[:, 2] <= part_z_top + 1e-6)
    return np.asarray(moves.point[keep], dtype=float)


def read_commanded(
    path: str | Path,
    nominal: Toolpath,
    *,
    T_base_work: F64 | None = None,
    tool_length: float | None = None,
    max_offset: float = 5e-3,
) -> Toolpath:
    """The commanded version of ``nominal`` that the program at ``path`` runs.

    Parameters
    ----------
    path : a toolpath CSV, robot program (``.mod``, ``.src``, ``.ls``) or CAM program
    nominal : the nominal toolpath the command corrects (its contacts and normals are kept)
    T_base_work : (4, 4) m — the cell's work object; a robot program with another is refused
    tool_length : m — the cell's tool length (TCP along the flange z); checked likewise
    max_offset : m — the largest accepted |commanded tip − nominal tip|

    Returns
    -------
    ``nominal.with_tip(tips)`` — (N, 3) m commanded tips, time at the nominal feed.

    Raises
    ------
    InputError
        naming the file: unreadable, another number of forming moves than nominal points, a
        point farther than ``max_offset`` from its nominal, another work object or tool.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("program not found", file=path, field="--toolpath")
    tips = _program_tips(path, 0.0, T_base_work, tool_length)
    n = len(nominal)
    if tips.shape != (n, 3):
        raise InputError(
            f"the program has {tips.shape[0]} forming moves but the cell's toolpath {n} "
            "points: a command for this cell has one move per toolpath point (same part, "
            "--step-down and --spacing as the study it corrects)",
            file=path,
            field="--toolpath",
        )
    off = np.linalg.norm(tips - nominal.tip, axis=1)
    if not np.all(np.isfinite(off)) or off.max() > max_offset:
        i = int(np.argmax(np.where(np.isfinite(off), off, np.inf)))
        raise InputError(
            f"move {i} is {off[i] * 1e3:.2f} mm from its nominal tip (at most "
            f"{max_offset * 1e3:g} mm for a correction of this path): a program of another "
            "part or cell?",
            file=path,
            field="--toolpath",
        )
    return nominal.with_tip(tips)
