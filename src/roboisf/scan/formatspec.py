"""What a scan format registers besides its reader: the length unit it fixes, if any.

Imports nothing heavy (the registry loads every scan format's module to list them)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ScanSpec"]


@dataclass(frozen=True)
class ScanSpec:
    """A scan format whose coordinates are in a ``unit`` the format fixes (so a declared
    ``--unit``/``scan_unit`` does not apply): ``unit`` (``"m"``), its name in messages
    (``"metres"``) and why (``"by the standard"``)."""

    unit: str
    unit_name: str
    why: str
