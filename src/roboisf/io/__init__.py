"""File formats at the edge of roboisf: units, atomic output, toolpath CSV, force logs, robot
programs (G-code, ABB RAPID, KUKA KRL). Everything read is converted to SI here."""

from roboisf.io.atomic import atomic_path, atomic_write, check_not_input, staged_directory
from roboisf.io.forcelog import (
    ForceLog,
    attach_to_toolpath,
    read_force_log,
    window_average,
    write_force_log,
)
from roboisf.io.toolpath_csv import TOOLPATH_COLUMNS, read_toolpath_csv, write_toolpath_csv
from roboisf.io.units import to_si

__all__ = [
    "TOOLPATH_COLUMNS",
    "ForceLog",
    "atomic_path",
    "atomic_write",
    "attach_to_toolpath",
    "check_not_input",
    "read_force_log",
    "read_toolpath_csv",
    "staged_directory",
    "to_si",
    "window_average",
    "write_force_log",
    "write_toolpath_csv",
]
