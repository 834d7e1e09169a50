"""ATI Net F/T demo CSV (the ATI Net F/T Java demo's data collection).

Layout as the demo writes it: a block of ``key: value`` lines (``Start Time``, ``RDT Sample
Rate``, ``Force Units``, ``Counts per Unit Force``, ``Torque Units``, ``Counts per Unit
Torque``), then the header ``Status (hex), RDT Sequence, F/T Sequence, Fx, Fy, Fz, Tx, Ty, Tz,
Time`` and quoted rows. ``Time`` is the receiving computer's wall clock, so the time axis is the
RDT sequence divided by the sample rate (starting at 0 at the first sample). Values in the
``Force Units`` / ``Torque Units`` of the head (the writer: N and N·m, 10 significant digits).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import FORCE_MATCH, FORCES, MOMENTS, TORQUE_MATCH, ForceLogSpec

if TYPE_CHECKING:
    from roboisf.io.table import LogTable
    from roboisf.logs.forcelog import ForceLog


def _time(t: LogTable) -> Any:
    """(N,) s: RDT sequence / RDT sample rate, from 0."""
    from roboisf.errors import InputError
    from roboisf.io.table import finite_float

    rate_txt = t.preamble.get("rdt sample rate")
    if rate_txt is None:
        raise InputError(
            "ATI log without the 'RDT Sample Rate:' line: the time axis is the RDT "
            "sequence divided by that rate",
            file=t.path,
            field="rdt sample rate",
        )
    rate = finite_float(rate_txt, file=t.path, field="rdt sample rate")
    if rate <= 0:
        raise InputError(f"RDT Sample Rate must be > 0 Hz, got {rate_txt}", file=t.path)
    seq = t.data["rdt"]
    return (seq - seq[0]) / rate


def write_ati(log: ForceLog, path: str | Path) -> None:
    """Write ``log`` (SI) as the ATI demo does, atomically; uniform sampling required (the
    reader's time axis is the RDT sequence / rate, from 0 at the first sample)."""
    import numpy as np

    from roboisf.errors import InputError
    from roboisf.io.atomic import atomic_write
    from roboisf.io.table import format_rows

    t, W = log.time, log.wrench
    dt = np.diff(t)
    rate = 1.0 / float(np.median(dt)) if t.size > 1 else 1000.0
    if t.size > 1 and np.max(np.abs(dt * rate - 1.0)) > 1e-6:
        raise InputError(
            "an ATI log is uniformly sampled (its time is RDT sequence / rate); this log's "
            "sample spacing varies",
            field="profile",
        )
    seq = np.rint(t * rate)
    data = np.column_stack([seq, seq * 7, W])
    rows = format_rows(data, ["%d", "%d"] + ["%.10g"] * 6).splitlines()
    stamp = '","Mar 14, 2024 10:21:07 AM"'
    head = (
        "Start Time: 3/14/24 10:21 AM\n"
        f"RDT Sample Rate: {rate:.12g}\n"
        '"PLEASE NOTE: The sample rate is read from the Net F/T when the program starts."\n'
        "Force Units: N\nCounts per Unit Force: 1000000.0\n"
        "Torque Units: Nm\nCounts per Unit Torque: 1000000.0\n"
        "Status (hex), RDT Sequence, F/T Sequence, Fx, Fy, Fz, Tx, Ty, Tz, Time\n"
    )
    body = "\n".join('"0x0","' + r.replace(",", '","') + stamp for r in rows)
    with atomic_write(path) as fh:
        fh.write(head + body + "\n")


register_format(
    FileFormat(
        name="ati",
        kind="force_log",
        label="ATI Net F/T CSV",
        suffixes=(".csv",),
        reader=lazy("roboisf.logs.forcelog", "read_force_log"),
        writer=write_ati,
        rank=10,
        rounding={"time": 1e-9, "value": 5e-10},
        spec=ForceLogSpec(
            match={"rdt": re.compile(r"rdt ?sequence|rdtsequence"), **FORCE_MATCH, **TORQUE_MATCH},
            required=("rdt", *FORCES, *MOMENTS),
            time=_time,
            time_column="rdt",
        ),
    )
)
