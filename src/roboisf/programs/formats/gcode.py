"""ISO G-code for a CNC machine (``.nc .gcode .ngc .tap``): :mod:`roboisf.cam.gcode`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.programs.registry import ProgramFormat, WriteOptions, lazy, register

if TYPE_CHECKING:
    from roboisf.path.toolpath import Toolpath


def _write(tp: Toolpath, path: Path, o: WriteOptions) -> list[Path]:
    from roboisf.cam.gcode import write_gcode

    return write_gcode(
        tp, path, safe_height=o.safe_height, notes=o.gcode_notes, work_offset=o.work_offset
    )


register(
    ProgramFormat(
        name="gcode",
        suffixes=(".nc", ".gcode", ".ngc", ".tap"),
        kind="cnc",
        label="G-code",
        write=_write,
        read=lazy("roboisf.cam.gcode", "read_gcode"),
        rank=10,
    )
)
