"""A joint table under generic names: a time column and ``q1..q6``, ``joint 1``/``axis 1`` (or
J/A prefixes), units in the header names, a ``# units:`` line or the study. Read only."""

from __future__ import annotations

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import JointLogSpec, joint_match

register_format(
    FileFormat(
        name="generic",
        kind="joint_log",
        label="generic q1..q6 table",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.jointlog", "read_joint_log"),
        rank=40,
        spec=JointLogSpec(match=joint_match(r"q|j|a|joint ?|axis ?|(?:.* )?a")),
    )
)
