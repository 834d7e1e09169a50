"""Toolpath and program formats in the file-format registry: one entry per format, one module
per entry.

Each format — roboisf's toolpath CSV, G-code, and every robot controller's program — is a
:class:`ProgramFormat` registered by one module of :mod:`roboisf.programs.formats` (or by a user's
module calling :func:`register`), as meshio registers its mesh formats. :func:`register` puts it
into the one registry of file formats (:mod:`roboisf.formats`) as a ``FileFormat`` of kind
``toolpath``, ``cnc`` or ``robot`` whose ``spec`` is the ``ProgramFormat`` (the program-specific
part: write options, program-name check); this module is the typed view of those kinds. The export
(:func:`roboisf.programs.export.write_toolpath`), the suffix inference, the program-name checks,
the companion files a command claims before writing (KRL's ``.dat``), the compensation's output
programs and the demo's programs all loop over :func:`program_formats`, so a new format is one new
file (see ``docs/extending.md``).

This module imports nothing heavy; a format's writer and reader load their module on first use.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from roboisf.errors import InputError
from roboisf.formats.registry import (
    FileFormat,
    file_formats,
    lazy,
    register_format,
    unregister_format,
)

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from roboisf.cam.program import RobotTool
    from roboisf.path.toolpath import Toolpath
    from roboisf.robot.armconfig import ArmConfig

__all__ = [
    "KINDS",
    "ProgramFormat",
    "WriteOptions",
    "find_format",
    "get_format",
    "lazy",
    "program_formats",
    "register",
    "robot_kwargs",
    "robot_writer",
    "unregister",
]

#: What a format holds: roboisf's own toolpath table, a CNC program (tip in the work frame,
#: machine work offsets), or a robot program (needs the work-object placement and the tool).
KINDS = ("toolpath", "cnc", "robot")
Kind = Literal["toolpath", "cnc", "robot"]


@dataclass(frozen=True)
class WriteOptions:
    """Everything a writer may use besides the toolpath (SI; each format takes what it needs).

    T_base_work : (4, 4) m or None — work object in the robot base (robot programs: required)
    tool : the robot tool (length, mass) or None
    tool_rotation : rad, scalar or (N,) — rotation of the tool about its own axis
    config : the arm configuration of every point (:func:`roboisf.robot.armconfig.program_config`)
    safe_height : m — approach/retract height above the part
    gcode_notes : comment lines of a CNC program's header
    work_offset : the CNC work offset holding the blank centre ("G54" … "G59")
    """

    T_base_work: ArrayLike | None = None
    tool: RobotTool | None = None
    tool_rotation: ArrayLike = 0.0
    config: ArmConfig | None = None
    safe_height: float = 10e-3
    gcode_notes: tuple[str, ...] = ()
    work_offset: str = "G54"


def robot_kwargs(o: WriteOptions) -> dict[str, Any]:
    """The keyword arguments every robot-program writer takes, from ``o``."""
    return {
        "T_base_work": o.T_base_work,
        "tool": o.tool,
        "tool_rotation": o.tool_rotation,
        "config": o.config,
        "safe_height": o.safe_height,
    }


def robot_writer(module: str, name: str) -> Callable[[Toolpath, Path, WriteOptions], list[Path]]:
    """A :attr:`ProgramFormat.write` calling the robot-program writer ``module.name(tp, path,
    **robot_kwargs(options))`` (imported on the first call)."""
    writer = lazy(module, name)

    def write(tp: Toolpath, path: Path, o: WriteOptions) -> list[Path]:
        files: list[Path] = writer(tp, path, **robot_kwargs(o))
        return files

    write.__name__ = write.__qualname__ = name
    return write


@dataclass(frozen=True)
class ProgramFormat:
    """One toolpath/program format.

    Attributes
    ----------
    name : the ``--format`` name (``"krl"``)
    suffixes : accepted file suffixes, lower case with the dot; the first is the default
    kind : one of :data:`KINDS`
    label : what the format is called in messages (``"KUKA KRL"``)
    write : ``write(tp, path, options) -> files written``, main file first
    read : ``read(path) -> ProgramPath`` (the forming moves), or None (write-only)
    companions : suffixes of files always written beside the main one (KRL's ``.dat``)
    read_suffixes : further suffixes the reader accepts but the writer never writes
    check_name : ``check_name(path)`` raises ``InputError`` if the file name cannot name the
        program (controllers name the program after the file); None: any name
    suffix_required : the file must have one of ``suffixes`` even when ``--format`` is given
    rank : listing order (help, error messages, the demo's ``--all-dialects``); ties by name
    """

    name: str
    suffixes: tuple[str, ...]
    kind: Kind
    label: str
    write: Callable[[Toolpath, Path, WriteOptions], list[Path]]
    read: Callable[[Path], Any] | None = None
    companions: tuple[str, ...] = ()
    read_suffixes: tuple[str, ...] = ()
    check_name: Callable[[Path], None] | None = None
    suffix_required: bool = False
    rank: int = 100

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"format name {self.name!r} is not an identifier")
        if self.kind not in KINDS:
            raise ValueError(f"format {self.name!r}: kind {self.kind!r} not in {KINDS}")
        bad = [
            s for s in (*self.suffixes, *self.companions, *self.read_suffixes) if not _is_suffix(s)
        ]
        if not self.suffixes or bad:
            raise ValueError(
                f"format {self.name!r}: suffixes must be lower case and start with '.', got "
                f"{bad or self.suffixes}"
            )

    def output_files(self, path: Path) -> list[Path]:
        """The main file and its companions (a long program may also write part files, which
        only the writer knows and returns)."""
        return [path, *(path.with_suffix(s) for s in self.companions)]


def _is_suffix(s: str) -> bool:
    return s.startswith(".") and len(s) > 1 and s == s.lower()


def register(fmt: ProgramFormat) -> ProgramFormat:
    """Add ``fmt`` to the registry of file formats; returns it. A program format's name or
    suffix already taken is a ``ValueError`` (two formats for one suffix would make the inference
    ambiguous)."""
    for other in program_formats():
        if other.name == fmt.name:
            raise ValueError(f"a format named {fmt.name!r} is already registered")
        shared = {*fmt.suffixes, *fmt.read_suffixes} & {*other.suffixes, *other.read_suffixes}
        if shared:
            raise ValueError(
                f"format {fmt.name!r}: suffix {sorted(shared)[0]} is {other.name!r}'s already"
            )
    register_format(
        FileFormat(
            name=fmt.name,
            kind=fmt.kind,
            label=fmt.label,
            suffixes=(*fmt.suffixes, *fmt.read_suffixes),
            reader=fmt.read,
            writer=fmt.write,
            companions=fmt.companions,
            rank=fmt.rank,
            spec=fmt,
        )
    )
    return fmt


def unregister(name: str) -> None:
    """Remove the program format ``name`` (a test's toy format); unknown names are ignored."""
    for kind in KINDS:
        unregister_format(kind, name)


def program_formats() -> tuple[ProgramFormat, ...]:
    """Every registered toolpath/program format, in listing order (``rank``, then name)."""
    return tuple(f.spec for f in file_formats(*KINDS) if isinstance(f.spec, ProgramFormat))


def get_format(name: str) -> ProgramFormat:
    """The format called ``name``; ``InputError`` (field ``format``) listing the known ones."""
    fmt = next((f for f in program_formats() if f.name == name), None)
    if fmt is None:
        names = ", ".join(f.name for f in program_formats())
        raise InputError(f"unknown format {name!r}; expected one of {names}", field="format")
    return fmt


def find_format(path: str | Path, name: str | None = None) -> ProgramFormat | None:
    """The format ``name`` if registered, else the one whose suffixes hold ``path``'s; None if
    neither (no error: for callers that only need a guess, such as claiming companion files)."""
    if name is not None:
        return next((f for f in program_formats() if f.name == name), None)
    suffix = Path(path).suffix.lower()
    return next((f for f in program_formats() if suffix in f.suffixes), None)
