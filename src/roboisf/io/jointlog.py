"""Joint-angle logs: what the robot controller recorded along the path.

Format (the roboisf numeric-CSV layout of :mod:`roboisf.io.table`)::

    # units: time=s angle=deg
    time,q1,q2,q3,q4,q5,q6
    0.000,0.0,12.5,20.1,0.0,50.2,-180.0

Angles in the **controller's convention** (as logged; see ``docs/robot.md``), degrees by default
(``angle=rad`` accepted); time in s (``ms``/``min`` accepted). Inside roboisf: rad and s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.io.table import format_rows, read_table
from roboisf.io.units import to_si

__all__ = ["JOINT_COLUMNS", "JointLog", "read_joint_log", "write_joint_log"]

F64 = NDArray[np.float64]
JOINT_COLUMNS = ("time", "q1", "q2", "q3", "q4", "q5", "q6")


@dataclass(frozen=True, eq=False)
class JointLog:
    """time : (N,) s, strictly increasing; q : (N, 6) rad (controller convention); path."""

    time: F64
    q: F64
    path: Path | None = None


def read_joint_log(path: str | Path) -> JointLog:
    """Read a joint log CSV into SI (errors name the file line)."""
    p = Path(path)
    t = read_table(p, JOINT_COLUMNS, what="joint log")
    units = {"time": "s", "angle": "deg"}
    if "units" not in t.meta:
        raise InputError(
            "missing '# units: time=s angle=deg' line (angles must declare deg or rad)",
            file=p,
            field="units",
        )
    for tok in t.meta["units"].split():
        k, _, v = tok.partition("=")
        if k not in units or not v:
            raise InputError(
                f"bad units entry {tok!r}; expected time=… angle=…", file=p, field="units"
            )
        units[k] = v
    ft = to_si(units["time"], "time", file=p, field="units.time")
    fa = to_si(units["angle"], "angle", file=p, field="units.angle")
    time = t.column("time") * ft
    if time.size > 1:
        bad = np.flatnonzero(np.diff(time) <= 0)
        if bad.size:
            raise InputError(
                "time must increase strictly", file=p, line=int(t.lines[bad[0] + 1]), field="time"
            )
    q = np.stack([t.column(f"q{i}") for i in range(1, 7)], axis=1) * fa
    return JointLog(time=time, q=q, path=p)


def write_joint_log(path: str | Path, time: ArrayLike, q: ArrayLike) -> None:
    """Write ``time`` (N,) s and ``q`` (N, 6) rad as a joint log (deg), atomically."""
    tt = np.asarray(time, dtype=float).reshape(-1)
    qq = np.asarray(q, dtype=float)
    if qq.shape != (tt.size, 6):
        raise InputError(f"expected q of shape ({tt.size}, 6), got {qq.shape}", field="q")
    data = np.column_stack([tt, np.degrees(qq)])
    body = "# units: time=s angle=deg\n" + ",".join(JOINT_COLUMNS) + "\n"
    body += format_rows(data, ["%.6f"] + ["%.9f"] * 6)
    with atomic_write(path) as f:
        f.write(body)
