"""File formats at the edge of roboisf: units, atomic output, toolpath CSV, force logs, CAM and
CNC programs (G-code, APT, Sinumerik, XYZ) and what the robot program writers share. Everything
read is converted to SI here. The robot controllers' formats (ABB RAPID, KUKA KRL, FANUC LS) live
one layer up, in :mod:`roboisf.programs`, because they need the robot's arm configuration.

The names below load their module on first use (PEP 562), so a command that only checks its
output folder (``roboisf.io.outdir``) does not import pandas and scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.io.atomic import atomic_path, atomic_write, check_not_input, staged_directory
    from roboisf.io.forcelog import (
        ForceLog,
        attach_to_toolpath,
        read_force_log,
        window_average,
        write_force_log,
    )
    from roboisf.io.gcode import read_gcode, write_gcode
    from roboisf.io.program import ProgramPath, RobotTool, tool_down_orientation
    from roboisf.io.toolpath_csv import TOOLPATH_COLUMNS, read_toolpath_csv, write_toolpath_csv
    from roboisf.io.units import to_si

_WHERE = {
    "atomic": ("atomic_path", "atomic_write", "check_not_input", "staged_directory"),
    "forcelog": (
        "ForceLog",
        "attach_to_toolpath",
        "read_force_log",
        "window_average",
        "write_force_log",
    ),
    "gcode": ("read_gcode", "write_gcode"),
    "program": ("ProgramPath", "RobotTool", "tool_down_orientation"),
    "toolpath_csv": ("TOOLPATH_COLUMNS", "read_toolpath_csv", "write_toolpath_csv"),
    "units": ("to_si",),
}
__all__ = [
    "TOOLPATH_COLUMNS",
    "ForceLog",
    "ProgramPath",
    "RobotTool",
    "atomic_path",
    "atomic_write",
    "attach_to_toolpath",
    "check_not_input",
    "read_force_log",
    "read_gcode",
    "read_toolpath_csv",
    "staged_directory",
    "to_si",
    "tool_down_orientation",
    "window_average",
    "write_force_log",
    "write_gcode",
    "write_toolpath_csv",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
