"""What a log profile registers besides its reader and writer: how its text table is found.

A force-log or joint-log *profile* (an instrument's or a controller's export layout) is a
:class:`roboisf.formats.FileFormat` whose ``spec`` is a :class:`ForceLogSpec` or a
:class:`JointLogSpec`: the regular expressions that find its columns in a header
(:func:`roboisf.io.table.read_log_table`), the columns it needs and the units its layout fixes.
The readers' automatic detection (:func:`roboisf.logs.forcelog.detect_force_format`,
:func:`roboisf.logs.jointlog.detect_joint_format`) tries the registered profiles in rank order.

The column patterns shared by several profiles are defined here once. Imports nothing heavy.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = [
    "FORCES",
    "FORCE_MATCH",
    "MOMENTS",
    "MOMENT_MATCH",
    "MOMENT_OR_TORQUE_MATCH",
    "TORQUE_MATCH",
    "ForceLogSpec",
    "JointLogSpec",
    "joint_match",
    "study_formats",
]

Match = dict[str, re.Pattern[str]]

FORCE_MATCH: Match = {f"F{a}": re.compile(rf"f ?{a}|force ?{a}") for a in "xyz"}
MOMENT_MATCH: Match = {f"M{a}": re.compile(rf"m ?{a}|moment ?{a}") for a in "xyz"}
TORQUE_MATCH: Match = {f"M{a}": re.compile(rf"t ?{a}|torque ?{a}") for a in "xyz"}
MOMENT_OR_TORQUE_MATCH: Match = {
    f"M{a}": re.compile(rf"[mt] ?{a}|moment ?{a}|torque ?{a}") for a in "xyz"
}
#: a force log's time column, under the names loggers give it
FORCE_TIME_MATCH: Match = {
    "time": re.compile(r"time|t|zeit|timestamp|seconds|sec|time stamp|elapsed time")
}
FORCES = tuple(FORCE_MATCH)
MOMENTS = tuple(MOMENT_MATCH)
#: a joint log's time column
JOINT_TIME = re.compile(r"time|t|zeit|timestamp|time stamp|sec|seconds|elapsed time")


def joint_match(prefix: str) -> Match:
    """Matchers of a joint log whose axes are named ``<prefix><i>`` (``prefix`` a regex)."""
    return {
        "time": JOINT_TIME,
        **{f"q{i}": re.compile(rf"(?:{prefix}) ?{i}") for i in range(1, 7)},
    }


@dataclass(frozen=True)
class ForceLogSpec:
    """How a force-log profile's text table is read (SI conversion is the reader's).

    match : canonical column (``time``, ``Fx`` … ``Mz``, or the profile's own such as ATI's
        ``rdt``) → pattern the normalised header name must fullmatch
    required : the columns that must be found
    units : quantity (``time``, ``force``, ``moment``) → unit the layout fixes (the file states
        none)
    refines : in automatic detection, a table found by one of these profiles is this profile's
        when ``accept(table)`` holds (a DynoWare export is a tab-separated generic table under
        a free-text block)
    accept : ``accept(table) -> bool`` for ``refines``
    time : ``time(table) -> (N,) s`` when the layout has no time column (ATI: RDT sequence /
        sample rate); None: the ``time`` column
    time_column : the column a timestamp error names (ATI: ``rdt``)
    frame : the frame the layout's wrench is in when the file names none (None: ``sensor``)
    notes : what a reader should know about the values (UR: the wrench is in the base axes)
    moments : ``"any"`` (all three or none), or ``"none"`` (a 3-component layout: moment
        columns are an error)
    """

    match: Match
    required: tuple[str, ...]
    units: dict[str, str] | None = None
    refines: tuple[str, ...] = ()
    accept: Callable[[Any], bool] | None = None
    time: Callable[[Any], Any] | None = None
    time_column: str = "time"
    frame: str | None = None
    notes: tuple[str, ...] = ()
    moments: str = "any"


@dataclass(frozen=True)
class JointLogSpec:
    """How a joint-log profile's text table is read: ``match`` (``time``, ``q1`` … ``q6``), the
    ``units`` the layout fixes (quantity ``time``/``angle`` → unit), ``auto``: tried by the
    automatic detection (False: only when named, as FANUC's J1..J6, which auto reads as ABB), and
    ``unstated_units``: the units the registered writer writes in but the file does not state (a
    study reading such a file must give them)."""

    match: Match
    units: dict[str, str] | None = None
    auto: bool = True
    unstated_units: dict[str, str] | None = None


def study_formats(kind: str) -> tuple[str, ...]:
    """``format`` values a study accepts for a log of ``kind`` ("force_log", "joint_log"):
    ``auto``, every registered text profile, and ``columns`` (header names given in the
    study). Here, not in the log readers' modules: reading a study imports no table library
    (pandas, pyarrow: ~0.2 s of start-up, docs/speed.md)."""
    from roboisf.formats import file_formats

    return ("auto", *(f.name for f in file_formats(kind) if not f.binary), "columns")
