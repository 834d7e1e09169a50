"""Universal Robots' RTDE recorder (``record.py`` of UR's RTDE client, ``ur_rtde``'s
``RTDEReceiveInterface.startFileRecording``): ``timestamp`` [s] and ``actual_q_0..5`` [rad],
units fixed by the RTDE specification. Read only."""

from __future__ import annotations

import re

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import JointLogSpec

_MATCH = {
    "time": re.compile(r"timestamp"),
    **{f"q{i}": re.compile(rf"actual q {i - 1}") for i in range(1, 7)},
}

register_format(
    FileFormat(
        name="ur",
        kind="joint_log",
        label="UR RTDE recording",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.jointlog", "read_joint_log"),
        rank=30,
        spec=JointLogSpec(match=_MATCH, units={"time": "s", "angle": "rad"}),
    )
)
