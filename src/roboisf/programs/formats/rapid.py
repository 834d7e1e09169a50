"""ABB RAPID module (``.mod``; a long program is a main module and part modules
``<stem>_<k>.mod``): :mod:`roboisf.programs.rapid`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.programs.registry import ProgramFormat, WriteOptions, register, robot_kwargs

if TYPE_CHECKING:
    from roboisf.io.program import ProgramPath
    from roboisf.path.toolpath import Toolpath


def _write(tp: Toolpath, path: Path, o: WriteOptions) -> list[Path]:
    from roboisf.programs.rapid import write_rapid

    return write_rapid(tp, path, **robot_kwargs(o))


def _read(path: Path) -> ProgramPath:
    from roboisf.programs.rapid import read_rapid

    return read_rapid(path)


def _check_name(path: Path) -> None:
    from roboisf.programs.rapid import module_name

    module_name(path)


register(
    ProgramFormat(
        name="rapid",
        suffixes=(".mod",),
        kind="robot",
        label="ABB RAPID",
        write=_write,
        read=_read,
        read_suffixes=(".modx",),
        check_name=_check_name,
        suffix_required=False,
        rank=20,
    )
)
