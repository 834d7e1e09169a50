"""KUKA KRL (``.src`` and its data list ``.dat``): :mod:`roboisf.programs.krl`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.programs.registry import ProgramFormat, WriteOptions, register, robot_kwargs

if TYPE_CHECKING:
    from roboisf.io.program import ProgramPath
    from roboisf.path.toolpath import Toolpath


def _write(tp: Toolpath, path: Path, o: WriteOptions) -> list[Path]:
    from roboisf.programs.krl import write_krl

    return write_krl(tp, path, **robot_kwargs(o))


def _read(path: Path) -> ProgramPath:
    from roboisf.programs.krl import read_krl

    return read_krl(path)


def _check_name(path: Path) -> None:
    from roboisf.programs.krl import krl_name

    krl_name(path)


register(
    ProgramFormat(
        name="krl",
        suffixes=(".src",),
        kind="robot",
        label="KRL",
        write=_write,
        read=_read,
        companions=(".dat",),
        check_name=_check_name,
        suffix_required=True,
        rank=30,
    )
)
