"""A FANUC joint log: ``J1..J6`` as ABB's, the angles as the pendant shows them (which the FANUC
presets take: docs/robot.md). Read only when named: automatic detection reads J1..J6 as ABB."""

from __future__ import annotations

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import JointLogSpec, joint_match

register_format(
    FileFormat(
        name="fanuc",
        kind="joint_log",
        label="FANUC J1..J6 log",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.jointlog", "read_joint_log"),
        rank=15,
        spec=JointLogSpec(match=joint_match(r"j|joint ?"), auto=False),
    )
)
