"""A 6-component force table: a time column and Fx…Fz, Mx…Mz (or Tx…Tz), any separator and
decimal mark, units in the header names (``Fx [N]``), a units row or a ``# units:`` line. The
writer: ``time [s],Fx [N],…,Mz [N*m]``, 9 decimals of time, 10 significant digits of wrench."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import (
    FORCE_MATCH,
    FORCE_TIME_MATCH,
    FORCES,
    MOMENT_OR_TORQUE_MATCH,
    MOMENTS,
    ForceLogSpec,
)

if TYPE_CHECKING:
    from roboisf.logs.forcelog import ForceLog


def write_generic(log: ForceLog, path: str | Path) -> None:
    """Write ``log`` (SI) as ``time [s],Fx [N],…,Mz [N*m]`` rows, atomically."""
    import numpy as np

    from roboisf.io.atomic import atomic_write
    from roboisf.io.table import format_rows

    head = "time [s],Fx [N],Fy [N],Fz [N],Mx [N*m],My [N*m],Mz [N*m]\n"
    data = np.column_stack([log.time, log.wrench])
    body = format_rows(data, ["%.9f"] + ["%.10g"] * 6).rstrip("\n")
    with atomic_write(path) as fh:
        fh.write(head + body + "\n")


register_format(
    FileFormat(
        name="generic",
        kind="force_log",
        label="6-component force table",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.forcelog", "read_force_log"),
        writer=write_generic,
        rank=40,
        rounding={"time": 5e-10, "value": 5e-10},
        spec=ForceLogSpec(
            match={**FORCE_TIME_MATCH, **FORCE_MATCH, **MOMENT_OR_TORQUE_MATCH},
            required=("time", *FORCES, *MOMENTS),
        ),
    )
)
