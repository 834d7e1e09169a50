"""CAM and CNC toolpath files: G-code (ISO), Sinumerik, APT/CL, XYZ point lists, roboisf's toolpath
CSV, and what every program writer shares (:mod:`roboisf.cam.program`: the tool, the cell
placement, tool orientations). Built on :mod:`roboisf.io` (tables, text, units, atomic output);
the robot controllers' formats live one layer up, in :mod:`roboisf.programs`. Each CAM format
registers itself in :mod:`roboisf.formats` from :mod:`roboisf.cam.formats`.

The names below load their module on first use (PEP 562).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.cam.gcode import read_gcode, write_gcode
    from roboisf.cam.program import ProgramPath, RobotTool, tool_down_orientation
    from roboisf.cam.toolpath_csv import TOOLPATH_COLUMNS, read_toolpath_csv, write_toolpath_csv

_WHERE = {
    "gcode": ("read_gcode", "write_gcode"),
    "program": ("ProgramPath", "RobotTool", "tool_down_orientation"),
    "toolpath_csv": ("TOOLPATH_COLUMNS", "read_toolpath_csv", "write_toolpath_csv"),
}
__all__ = [
    "TOOLPATH_COLUMNS",
    "ProgramPath",
    "RobotTool",
    "read_gcode",
    "read_toolpath_csv",
    "tool_down_orientation",
    "write_gcode",
    "write_toolpath_csv",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
