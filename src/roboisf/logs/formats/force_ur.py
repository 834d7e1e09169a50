"""Universal Robots RTDE recording: ``timestamp`` [s], ``actual_TCP_force_0..5`` — the wrench at
the TCP in the robot's base axes [N, N·m] (UR's definition; units fixed by RTDE). Read only."""

from __future__ import annotations

import re

from roboisf.formats import FileFormat, lazy, register_format
from roboisf.logs.logprofile import FORCES, MOMENTS, ForceLogSpec

_MATCH = {
    "time": re.compile(r"timestamp"),
    **{c: re.compile(rf"actual tcp force {k}") for k, c in enumerate((*FORCES, *MOMENTS))},
}

register_format(
    FileFormat(
        name="ur",
        kind="force_log",
        label="UR RTDE recording",
        suffixes=(".csv", ".txt"),
        reader=lazy("roboisf.logs.forcelog", "read_force_log"),
        rank=20,
        spec=ForceLogSpec(
            match=_MATCH,
            required=("time", *FORCES, *MOMENTS),
            units={"time": "s", "force": "N", "moment": "N*m"},
            frame="base",
            notes=(
                "UR RTDE actual_TCP_force: the wrench at the TCP in the robot's base axes (UR's "
                "definition), not a sensor frame; give the sensor pose that matches it",
            ),
        ),
    )
)
