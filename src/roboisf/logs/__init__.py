"""Measurement logs: force logs (the profiles of :mod:`roboisf.logs.formats`, their Parquet form
and the windowed averages), joint logs and measured wall thickness. Built on :mod:`roboisf.io`
(tables, units, timestamps, atomic output); every log is converted to SI when read.

The names below load their module on first use (PEP 562).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.logs.forcelog import (
        ForceLog,
        attach_to_toolpath,
        read_force_log,
        window_average,
        write_force_log,
    )

_WHERE = {
    "forcelog": (
        "ForceLog",
        "attach_to_toolpath",
        "read_force_log",
        "window_average",
        "write_force_log",
    ),
}
__all__ = [
    "ForceLog",
    "attach_to_toolpath",
    "read_force_log",
    "window_average",
    "write_force_log",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
