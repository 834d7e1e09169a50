"""File formats at the edge of roboisf: units, atomic output, toolpath CSV, force logs, robot
programs (G-code, ABB RAPID, KUKA KRL). Everything read is converted to SI here."""

from roboisf.io.atomic import atomic_path, atomic_write, check_not_input, staged_directory
from roboisf.io.toolpath_csv import TOOLPATH_COLUMNS, read_toolpath_csv, write_toolpath_csv
from roboisf.io.units import to_si

__all__ = [
    "TOOLPATH_COLUMNS",
    "atomic_path",
    "atomic_write",
    "check_not_input",
    "read_toolpath_csv",
    "staged_directory",
    "to_si",
    "write_toolpath_csv",
]
