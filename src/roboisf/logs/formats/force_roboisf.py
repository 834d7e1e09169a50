"""roboisf's own force-log CSV (``# units:`` / ``# frame:`` lines, ``time,Fx,…,Mz``):
:mod:`roboisf.logs.forcelog`."""

from __future__ import annotations

from roboisf.formats import FileFormat, lazy, register_format

_MODULE = "roboisf.logs.forcelog"

register_format(
    FileFormat(
        name="roboisf",
        kind="force_log",
        label="roboisf force-log CSV",
        suffixes=(".csv",),
        reader=lazy(_MODULE, "read_force_log"),
        writer=lazy(_MODULE, "write_force_log"),
        detect=lazy(_MODULE, "is_roboisf_force_log"),
        rank=0,
        rounding={"time": 5e-10, "value": 5e-10},
    )
)
