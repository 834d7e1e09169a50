"""Write a toolpath in any supported format, chosen by name or by the file suffix.

================  ==========================  ===========================================
format            suffixes                    writer
================  ==========================  ===========================================
``csv``           ``.csv``                    :func:`roboisf.io.toolpath_csv.write_toolpath_csv`
``gcode``         ``.nc .gcode .ngc .tap``    :func:`roboisf.io.gcode.write_gcode`
``rapid``         ``.mod``                    :func:`roboisf.programs.rapid.write_rapid`
``krl``           ``.src`` (+ ``.dat``)       :func:`roboisf.programs.krl.write_krl`
``fanuc``         ``.ls``                     :func:`roboisf.programs.fanuc.write_fanuc`
================  ==========================  ===========================================

Robot programs (RAPID, KRL, FANUC) need the work-object placement ``T_base_work``: there is no
default (the identity, passed explicitly, means the robot base). With ``config`` (the joint angles
of every point, :func:`roboisf.robot.armconfig.program_config`) they carry the controller's
configuration data (confdata, S/T, CONFIG).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.errors import InputError

if TYPE_CHECKING:  # the writers (numpy, pandas) load on the first write: checks stay fast
    from numpy.typing import ArrayLike

    from roboisf.io.program import RobotTool
    from roboisf.path.toolpath import Toolpath
    from roboisf.robot.armconfig import ArmConfig

__all__ = [
    "FORMAT_SUFFIXES",
    "ROBOT_FORMATS",
    "check_program_name",
    "infer_format",
    "output_files",
    "write_toolpath",
]

#: Format name → accepted file suffixes (the first is the default).
FORMAT_SUFFIXES: dict[str, tuple[str, ...]] = {
    "csv": (".csv",),
    "gcode": (".nc", ".gcode", ".ngc", ".tap"),
    "rapid": (".mod",),
    "krl": (".src",),
    "fanuc": (".ls",),
}

#: Formats that are robot programs (they need the placement and the tool).
ROBOT_FORMATS = ("rapid", "krl", "fanuc")


def infer_format(path: str | Path, fmt: str | None = None) -> str:
    """Format for ``path``: ``fmt`` if given (checked against the suffix), else from the suffix."""
    suffix = Path(path).suffix.lower()
    if fmt is not None:
        if fmt not in FORMAT_SUFFIXES:
            raise InputError(
                f"unknown format {fmt!r}; expected one of {', '.join(FORMAT_SUFFIXES)}",
                field="format",
            )
        if fmt == "krl" and suffix != ".src":
            raise InputError("a KRL program must be written to a .src file", file=path)
        if fmt == "fanuc" and suffix != ".ls":
            raise InputError("a FANUC TP program must be written to a .ls file", file=path)
        return fmt
    for name, suffixes in FORMAT_SUFFIXES.items():
        if suffix in suffixes:
            return name
    known = ", ".join(f"{s} ({n})" for n, ss in FORMAT_SUFFIXES.items() for s in ss)
    raise InputError(
        f"cannot tell the format from the suffix {suffix or '(none)'!r}; use one of {known} "
        "or pass --format",
        file=path,
    )


def check_program_name(path: str | Path, fmt: str) -> None:
    """Refuse, before any computation, a file name that is not a valid program name for ``fmt``
    (KRL DEF/DEFDAT, RAPID module, FANUC program: the writers name the program after the file)."""
    path = Path(path)
    if fmt == "krl":
        from roboisf.programs.krl import krl_name

        krl_name(path)
    elif fmt == "rapid":
        from roboisf.programs.rapid import _module_name

        _module_name(path, None)
    elif fmt == "fanuc" and not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,31}", path.stem):
        raise InputError(
            f"the file name {path.stem!r} does not give a FANUC program name (a letter, then "
            "letters, digits or _)",
            file=path,
        )


def output_files(path: str | Path, fmt: str) -> list[Path]:
    """Main files a write produces (KRL writes the ``.dat`` beside the ``.src``; long RAPID and
    FANUC programs also write part modules ``<stem>_<k>``, returned by :func:`write_toolpath`)."""
    path = Path(path)
    return [path, path.with_suffix(".dat")] if fmt == "krl" else [path]


def write_toolpath(
    tp: Toolpath,
    path: str | Path,
    fmt: str | None = None,
    *,
    T_base_work: ArrayLike | None = None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    config: ArmConfig | None = None,
    safe_height: float = 10e-3,
    gcode_notes: tuple[str, ...] = (),
    work_offset: str = "G54",
) -> tuple[str, list[Path]]:
    """Write ``tp`` to ``path`` in ``fmt`` (inferred from the suffix if None).

    ``T_base_work`` (required for robot programs), ``tool``, ``tool_rotation`` [rad] and
    ``config`` apply to the robot programs (RAPID, KRL, FANUC); ``work_offset`` and
    ``gcode_notes`` to G-code; ``safe_height`` [m] to every program format. Returns the format
    and the files written.
    """
    from roboisf.io.gcode import write_gcode
    from roboisf.io.toolpath_csv import write_toolpath_csv
    from roboisf.programs.fanuc import write_fanuc
    from roboisf.programs.krl import write_krl
    from roboisf.programs.rapid import write_rapid

    fmt = infer_format(path, fmt)
    if fmt == "csv":
        write_toolpath_csv(tp, path)
        return fmt, [Path(path)]
    if fmt == "gcode":
        files = write_gcode(
            tp, path, safe_height=safe_height, notes=gcode_notes, work_offset=work_offset
        )
        return fmt, files
    writers: dict[str, Callable[..., list[Path]]] = {
        "rapid": write_rapid,
        "krl": write_krl,
        "fanuc": write_fanuc,
    }
    writer = writers[fmt]
    files = writer(
        tp,
        path,
        T_base_work=T_base_work,
        tool=tool,
        tool_rotation=tool_rotation,
        config=config,
        safe_height=safe_height,
    )
    return fmt, files
