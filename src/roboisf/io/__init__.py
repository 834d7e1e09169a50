"""The format-neutral base at roboisf's file edge: units, atomic output, output folders, numeric
tables and text, timestamps and JSON values. Everything read is converted to SI here. The file
formats built on it live with their concept: CAM/CNC programs and the toolpath CSV in
:mod:`roboisf.cam`, force, joint and thickness logs in :mod:`roboisf.logs`, the robot controllers'
formats (ABB RAPID, KUKA KRL, FANUC LS) in :mod:`roboisf.programs`.

The names below load their module on first use (PEP 562), so a command that only checks its
output folder (``roboisf.io.outdir``) does not import pandas and scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.io.atomic import atomic_path, atomic_write, check_not_input, staged_directory
    from roboisf.io.units import to_si

_WHERE = {
    "atomic": ("atomic_path", "atomic_write", "check_not_input", "staged_directory"),
    "units": ("to_si",),
}
__all__ = [
    "atomic_path",
    "atomic_write",
    "check_not_input",
    "staged_directory",
    "to_si",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
