"""Write a toolpath in any registered format, chosen by name or by the file suffix.

The formats are those of :mod:`roboisf.programs.registry` (built in: ``csv``, ``gcode``,
``rapid``, ``krl``, ``fanuc``, one module each in :mod:`roboisf.programs.formats`):

================  ==========================  ===========================================
format            suffixes                    writer
================  ==========================  ===========================================
``csv``           ``.csv``                    :func:`roboisf.cam.toolpath_csv.write_toolpath_csv`
``gcode``         ``.nc .gcode .ngc .tap``    :func:`roboisf.cam.gcode.write_gcode`
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

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.errors import InputError
from roboisf.programs.registry import WriteOptions, get_format, program_formats

if TYPE_CHECKING:  # the writers (numpy, pandas) load on the first write: checks stay fast
    from numpy.typing import ArrayLike

    from roboisf.cam.program import RobotTool
    from roboisf.path.toolpath import Toolpath
    from roboisf.robot.armconfig import ArmConfig

__all__ = [
    "check_program_name",
    "infer_format",
    "output_files",
    "write_toolpath",
]


def infer_format(path: str | Path, fmt: str | None = None) -> str:
    """Format for ``path``: ``fmt`` if given (checked against the suffix), else from the suffix."""
    suffix = Path(path).suffix.lower()
    if fmt is not None:
        f = get_format(fmt)
        if f.suffix_required and suffix not in f.suffixes:
            raise InputError(
                f"a {f.label} program must be written to a {' or '.join(f.suffixes)} file",
                file=path,
            )
        return fmt
    for f in program_formats():
        if suffix in f.suffixes:
            return f.name
    known = ", ".join(f"{s} ({f.name})" for f in program_formats() for s in f.suffixes)
    raise InputError(
        f"cannot tell the format from the suffix {suffix or '(none)'!r}; use one of {known} "
        "or pass --format",
        file=path,
    )


def check_program_name(path: str | Path, fmt: str) -> None:
    """Refuse, before any computation, a file name that is not a valid program name for ``fmt``
    (KRL DEF/DEFDAT, RAPID module, FANUC program: the writers name the program after the file)."""
    f = get_format(fmt)
    if f.check_name is not None:
        f.check_name(Path(path))


def output_files(path: str | Path, fmt: str) -> list[Path]:
    """Main files a write produces (KRL writes the ``.dat`` beside the ``.src``; long RAPID and
    FANUC programs also write part modules ``<stem>_<k>``, returned by :func:`write_toolpath`)."""
    return get_format(fmt).output_files(Path(path))


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
    fmt = infer_format(path, fmt)
    options = WriteOptions(
        T_base_work=T_base_work,
        tool=tool,
        tool_rotation=tool_rotation,
        config=config,
        safe_height=safe_height,
        gcode_notes=gcode_notes,
        work_offset=work_offset,
    )
    return fmt, get_format(fmt).write(tp, Path(path), options)
