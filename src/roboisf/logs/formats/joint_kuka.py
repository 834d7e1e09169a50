"""A KUKA joint trace: ``A1..A6`` (``axis 1``, ``AxisActPos A1`` of a trace's text export), any
separator, decimal commas. The writer: a trace exported to CSV, ``Time [s];A1 [deg];…;A6 [deg]``
semicolon-separated with decimal commas, 6 decimals of time, 9 of angle."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import JointLogSpec, joint_match


def write_kuka(path: str | Path, time: Any, q: Any) -> None:
    """Write ``q`` (N, 6) rad at ``time`` (N,) s as a KUKA trace CSV (s, deg), atomically."""
    import numpy as np

    from roboisf.io.atomic import atomic_write
    from roboisf.io.table import format_rows
    from roboisf.logs.jointlog import joint_rows

    t, deg = joint_rows(time, q)
    head = "Time [s];" + ";".join(f"A{i} [deg]" for i in range(1, 7)) + "\n"
    body = format_rows(np.column_stack([t, deg]), ["%.6f"] + ["%.9f"] * 6)
    with atomic_write(path) as fh:
        fh.write(head + body.replace(",", ";").replace(".", ","))


register_format(
    FileFormat(
        name="kuka",
        kind="joint_log",
        label="KUKA A1..A6 trace",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.jointlog", "read_joint_log"),
        writer=write_kuka,
        rank=20,
        rounding={"time": 5e-7, "angle": 8.8e-12},
        spec=JointLogSpec(match=joint_match(r"a|axis ?|(?:.* )?a")),
    )
)
