"""FANUC TP in ASCII form (``.ls``; a long program calls part programs ``<stem>_<k>.ls``):
:mod:`roboisf.programs.fanuc`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.programs.registry import ProgramFormat, WriteOptions, register, robot_kwargs

if TYPE_CHECKING:
    from roboisf.io.program import ProgramPath
    from roboisf.path.toolpath import Toolpath


def _write(tp: Toolpath, path: Path, o: WriteOptions) -> list[Path]:
    from roboisf.programs.fanuc import write_fanuc

    return write_fanuc(tp, path, **robot_kwargs(o))


def _read(path: Path) -> ProgramPath:
    from roboisf.programs.fanuc import read_fanuc

    return read_fanuc(path)


def _check_name(path: Path) -> None:
    from roboisf.programs.fanuc import check_program_name

    check_program_name(path)


register(
    ProgramFormat(
        name="fanuc",
        suffixes=(".ls",),
        kind="robot",
        label="FANUC TP",
        write=_write,
        read=_read,
        check_name=_check_name,
        suffix_required=True,
        rank=40,
    )
)
