"""An ABB joint log: a time column and ``J1..J6`` (``joint 1`` …), as a RAPID logging routine
writes it. The writer: ``Time,J1,…,J6`` in s and degrees with no units in the header (a RAPID
routine states none: the study gives them), 6 decimals of time, 9 of angle."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import JointLogSpec, joint_match


def write_abb(path: str | Path, time: Any, q: Any) -> None:
    """Write ``q`` (N, 6) rad at ``time`` (N,) s as ``Time,J1,…,J6`` (s, deg), atomically."""
    import numpy as np

    from roboisf.io.atomic import atomic_write
    from roboisf.io.table import format_rows
    from roboisf.logs.jointlog import joint_rows

    t, deg = joint_rows(time, q)
    body = format_rows(np.column_stack([t, deg]), ["%.6f"] + ["%.9f"] * 6)
    with atomic_write(path) as fh:
        fh.write("Time,J1,J2,J3,J4,J5,J6\n" + body)


register_format(
    FileFormat(
        name="abb",
        kind="joint_log",
        label="ABB J1..J6 log",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.jointlog", "read_joint_log"),
        writer=write_abb,
        rank=10,
        rounding={"time": 5e-7, "angle": 8.8e-12},
        spec=JointLogSpec(
            match=joint_match(r"j|joint ?"), unstated_units={"time": "s", "angle": "deg"}
        ),
    )
)
