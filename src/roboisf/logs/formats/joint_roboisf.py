"""roboisf's own joint-log CSV (``# units: time=s angle=deg``, ``time,q1,…,q6``):
:mod:`roboisf.logs.jointlog`."""

from __future__ import annotations

from roboisf.formats import FileFormat, lazy, register_format

_MODULE = "roboisf.logs.jointlog"

register_format(
    FileFormat(
        name="roboisf",
        kind="joint_log",
        label="roboisf joint-log CSV",
        suffixes=(".csv",),
        reader=lazy(_MODULE, "read_joint_log"),
        writer=lazy(_MODULE, "write_joint_log"),
        detect=lazy(_MODULE, "is_roboisf_joint_log"),
        rank=0,
        rounding={"time": 5e-7, "angle": 8.8e-12},
    )
)
