"""Robot programs: the controllers' formats (ABB RAPID, KUKA KRL, FANUC LS) and the export of a
toolpath to any program format (:func:`roboisf.programs.export.write_program`).

This package sits above :mod:`roboisf.robot` (the arm configuration each controller writes —
confdata, S/T, CONFIG — comes from :mod:`roboisf.robot.armconfig`) and above :mod:`roboisf.io`
(tables, text, units, atomic output) and :mod:`roboisf.cam` (the CNC formats, what every program
writer shares), so neither imports it.

The names below load their module on first use (PEP 562).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.programs.fanuc import read_fanuc, write_fanuc
    from roboisf.programs.krl import read_krl, write_krl
    from roboisf.programs.rapid import read_rapid, write_rapid

_WHERE = {
    "fanuc": ("read_fanuc", "write_fanuc"),
    "krl": ("read_krl", "write_krl"),
    "rapid": ("read_rapid", "write_rapid"),
}
__all__ = ["read_fanuc", "read_krl", "read_rapid", "write_fanuc", "write_krl", "write_rapid"]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
