"""A 3-component dynamometer's table: a time column and Fx, Fy, Fz (moments unknown: the
reader's ``moments_known`` is False; moment columns are an error). The writer:
``Time [s];Fx [N];Fy [N];Fz [N]`` (moments dropped), 9 decimals of time, 10 significant digits."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import (
    FORCE_MATCH,
    FORCE_TIME_MATCH,
    FORCES,
    MOMENT_OR_TORQUE_MATCH,
    ForceLogSpec,
)

if TYPE_CHECKING:
    from roboisf.logs.forcelog import ForceLog


def write_dyno3(log: ForceLog, path: str | Path) -> None:
    """Write the forces of ``log`` (SI) as ``Time [s];Fx [N];Fy [N];Fz [N]``, atomically."""
    import numpy as np

    from roboisf.io.atomic import atomic_write
    from roboisf.io.table import format_rows

    head = "Time [s];Fx [N];Fy [N];Fz [N]\n"
    rows = format_rows(np.column_stack([log.time, log.force]), ["%.9f"] + ["%.10g"] * 3)
    with atomic_write(path) as fh:
        fh.write(head + rows.replace(",", ";").rstrip("\n") + "\n")


register_format(
    FileFormat(
        name="dyno3",
        kind="force_log",
        label="3-component dynamometer table",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.forcelog", "read_force_log"),
        writer=write_dyno3,
        rank=50,
        rounding={"time": 5e-10, "value": 5e-10},
        spec=ForceLogSpec(
            match={**FORCE_TIME_MATCH, **FORCE_MATCH, **MOMENT_OR_TORQUE_MATCH},
            required=("time", *FORCES),
            moments="none",
        ),
    )
)
