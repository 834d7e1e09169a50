"""roboisf's toolpath CSV (``.csv``): :mod:`roboisf.cam.toolpath_csv`, read back exactly."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.programs.registry import ProgramFormat, WriteOptions, register

if TYPE_CHECKING:
    from roboisf.path.toolpath import Toolpath


def _write(tp: Toolpath, path: Path, o: WriteOptions) -> list[Path]:
    from roboisf.cam.toolpath_csv import write_toolpath_csv

    write_toolpath_csv(tp, path)
    return [path]


register(
    ProgramFormat(
        name="csv", suffixes=(".csv",), kind="toolpath", label="toolpath CSV", write=_write, rank=0
    )
)
