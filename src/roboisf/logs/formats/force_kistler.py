"""Kistler DynoWare ASCII export of a 3-component dynamometer (type 9257B).

A free-text header block, then tab-separated ``Time [s]``, ``Fx [N]``, ``Fy [N]``, ``Fz [N]``
with decimal commas (a European Windows locale); no moments. The reader also takes a DynoWare
export with moment columns (``Mx [N*m]`` …) or a units row under the header. Automatic detection
finds a DynoWare export as a tab-separated table (generic or 3-component) under a free-text
block. The writer: 9 decimals of time, 10 significant digits of force.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import (
    FORCE_MATCH,
    FORCE_TIME_MATCH,
    FORCES,
    MOMENT_MATCH,
    ForceLogSpec,
)

if TYPE_CHECKING:
    from roboisf.logs.forcelog import ForceLog


def _is_dynoware(t: Any) -> bool:
    return bool(t.separator == "tab" and t.preamble)


def write_kistler(log: ForceLog, path: str | Path) -> None:
    """Write the forces of ``log`` (SI) as a DynoWare ASCII export, atomically."""
    import numpy as np

    from roboisf.io.atomic import atomic_write
    from roboisf.io.table import format_rows

    n = len(log)
    rate = 1.0 / float(np.median(np.diff(log.time))) if n > 1 else 0.0
    head = (
        "DynoWare ASCII export\n"
        "Type 9257B 3-component dynamometer\n"
        f"Sampling rate [Hz]:\t{rate:.0f}\n"
        f"Number of samples:\t{n}\n"
        "\n"
        "Time [s]\tFx [N]\tFy [N]\tFz [N]\n"
    )
    body = format_rows(np.column_stack([log.time, log.force]), ["%.9f"] + ["%.10g"] * 3)
    body = body.replace(",", "\t").replace(".", ",")  # tab-separated, decimal commas
    with atomic_write(path) as fh:
        fh.write(head + body)


register_format(
    FileFormat(
        name="kistler",
        kind="force_log",
        label="Kistler DynoWare text",
        suffixes=(".txt", ".csv"),
        reader=lazy("roboisf.logs.forcelog", "read_force_log"),
        writer=write_kistler,
        rank=45,
        rounding={"time": 5e-10, "value": 5e-10},
        spec=ForceLogSpec(
            match={**FORCE_TIME_MATCH, **FORCE_MATCH, **MOMENT_MATCH},
            required=("time", *FORCES),
            refines=("generic", "dyno3"),
            accept=_is_dynoware,
        ),
    )
)
