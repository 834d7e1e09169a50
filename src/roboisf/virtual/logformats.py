"""The virtual cell's force and joint logs in the layouts real equipment exports.

Every layout is a force-log or joint-log format of the registry (:mod:`roboisf.formats`; one
module each in :mod:`roboisf.logs.formats`, which states the layout, units and rounding), written
with that format's registered writer — the very layout its registered reader detects and reads.
The profiles offered are the registered ones with a text writer: ``roboisf`` (roboisf's CSV),
``ati`` (ATI Net F/T demo CSV), ``kistler`` (DynoWare text of a 3-component dynamometer, decimal
commas), ``dyno3``, ``generic``; joint logs ``roboisf``, ``abb`` (``Time,J1..J6``, s and degrees,
no units in the header), ``kuka`` (trace CSV, ``A1..A6``, semicolons, decimal commas).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from numpy.typing import ArrayLike

from roboisf.logs.forcelog import force_profiles_written, write_force_log
from roboisf.logs.jointlog import joint_profiles_written, write_joint_log

if TYPE_CHECKING:
    from roboisf.logs.forcelog import ForceLog

__all__ = ["force_profiles", "joint_profiles", "write_force_profile", "write_joint_profile"]


def force_profiles() -> tuple[str, ...]:
    """The force-log layouts the virtual cell can write (registered, with a text writer)."""
    return force_profiles_written()


def joint_profiles() -> tuple[str, ...]:
    """The joint-log layouts the virtual cell can write (registered, with a text writer)."""
    return joint_profiles_written()


def write_force_profile(log: ForceLog, path: str | Path, profile: str = "roboisf") -> None:
    """Write ``log`` (SI) in ``profile``'s layout with its registered writer, atomically."""
    write_force_log(log, path, profile=profile)


def write_joint_profile(
    path: str | Path, time: ArrayLike, q: ArrayLike, profile: str = "roboisf"
) -> None:
    """Write joint angles ``q`` (N, 6) [rad] at ``time`` (N,) [s] in ``profile``'s layout with
    its registered writer, atomically."""
    write_joint_log(path, time, q, profile=profile)
