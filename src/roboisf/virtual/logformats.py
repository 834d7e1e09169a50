"""Writers of force and joint logs in the layouts real equipment exports (virtual cell).

Independent of roboisf's readers: these write what the equipment writes, so that a reader can be
tested against it. Layouts (``FORCE_PROFILES``, ``JOINT_PROFILES``):

* ``roboisf`` — roboisf's own CSV (:mod:`roboisf.io.forcelog`, :mod:`roboisf.io.jointlog`).
* ``ati`` — ATI Net F/T demo CSV: six header rows (start time, RDT sample rate, force units,
  counts per unit force, torque units, counts per unit torque), then
  ``Status (hex),RDT Sequence,F/T Sequence,Fx,Fy,Fz,Tx,Ty,Tz,Time``; forces in N and torques in
  N·m with one count per unit, so the values are the physical ones; ``Time`` in s on the
  logger's clock (ATI's demo writes the receiving computer's clock).
* ``kistler`` — a DynoWare ASCII export of a 3-component dynamometer: a header block, then
  tab-separated ``Time [s]``, ``Fx [N]``, ``Fy [N]``, ``Fz [N]`` with decimal commas (a
  European Windows locale); no moments.
* ``abb`` — a joint log with ``Time,J1..J6`` in s and degrees (a RAPID logging routine).
* ``kuka`` — a KUKA trace exported to CSV: semicolon-separated, ``Time [s];A1 [deg];…;A6
  [deg]``, decimal commas.

Numbers are written with 9 decimals (time) and 10 significant digits (values).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.io.forcelog import ForceLog, write_force_log
from roboisf.io.jointlog import write_joint_log
from roboisf.io.table import format_rows

__all__ = ["FORCE_PROFILES", "JOINT_PROFILES", "write_force_profile", "write_joint_profile"]

F64 = NDArray[np.float64]

FORCE_PROFILES = ("roboisf", "ati", "kistler")
JOINT_PROFILES = ("roboisf", "abb", "kuka")


def _table(data: F64, fmts: list[str], sep: str, decimal: str) -> str:
    """Rows with separator ``sep`` and decimal mark ``decimal``."""
    text = format_rows(data, fmts)
    if sep == "," and decimal == ",":
        raise ValueError("a decimal comma needs another separator")
    text = text.replace(",", "\x00")
    if decimal == ",":
        text = text.replace(".", ",")
    return text.replace("\x00", sep)


def write_force_profile(log: ForceLog, path: str | Path, profile: str = "roboisf") -> None:
    """Write ``log`` (SI) in ``profile``'s layout (module docstring), atomically."""
    if profile == "roboisf":
        write_force_log(log, path)
        return
    n = len(log)
    rate = 1.0 / float(np.median(np.diff(log.time))) if n > 1 else 0.0
    if profile == "ati":
        head = (
            "Start Time,01/01/2026 08:00:00\n"
            f"RDT Sample Rate,{rate:.0f}\n"
            "Force Units,N\nCounts per Unit Force,1\nTorque Units,Nm\nCounts per Unit Torque,1\n"
            "Status (hex),RDT Sequence,F/T Sequence,Fx,Fy,Fz,Tx,Ty,Tz,Time\n"
        )
        seq = np.arange(1, n + 1, dtype=float)
        data = np.column_stack([np.zeros(n), seq, seq, log.wrench, log.time])
        body = _table(data, ["%d", "%d", "%d"] + ["%.10g"] * 6 + ["%.9f"], ",", ".")
        body = "\n".join("0x" + ln if ln else ln for ln in body.split("\n"))
    elif profile == "kistler":
        head = (
            "DynoWare ASCII export\n"
            "Type 9257B 3-component dynamometer\n"
            f"Sampling rate [Hz]:\t{rate:.0f}\n"
            f"Number of samples:\t{n}\n"
            "\n"
            "Time [s]\tFx [N]\tFy [N]\tFz [N]\n"
        )
        data = np.column_stack([log.time, log.force])
        body = _table(data, ["%.9f"] + ["%.10g"] * 3, "\t", ",")
    else:
        raise InputError(
            f"unknown force log profile {profile!r}; expected one of {', '.join(FORCE_PROFILES)}",
            field="profile",
        )
    with atomic_write(path) as fh:
        fh.write(head + body)


def write_joint_profile(
    path: str | Path, time: ArrayLike, q: ArrayLike, profile: str = "roboisf"
) -> None:
    """Write joint angles ``q`` (N, 6) [rad] at ``time`` (N,) [s] in ``profile``'s layout."""
    if profile == "roboisf":
        write_joint_log(path, time, q)
        return
    t = np.asarray(time, dtype=float).reshape(-1)
    qq = np.degrees(np.asarray(q, dtype=float))
    if qq.shape != (t.size, 6):
        raise InputError(f"expected q of shape ({t.size}, 6), got {qq.shape}", field="q")
    data = np.column_stack([t, qq])
    fmts = ["%.6f"] + ["%.9f"] * 6
    if profile == "abb":
        head = "Time,J1,J2,J3,J4,J5,J6\n"
        body = _table(data, fmts, ",", ".")
    elif profile == "kuka":
        head = "Time [s];" + ";".join(f"A{i} [deg]" for i in range(1, 7)) + "\n"
        body = _table(data, fmts, ";", ",")
    else:
        raise InputError(
            f"unknown joint log profile {profile!r}; expected one of {', '.join(JOINT_PROFILES)}",
            field="profile",
        )
    with atomic_write(path) as fh:
        fh.write(head + body)
