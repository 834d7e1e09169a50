"""What a part kind registers besides its builder: the keys of its ``[part]`` table.

Imports nothing heavy (the registry loads every part kind's module to list the kinds)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PartSpec"]


@dataclass(frozen=True)
class PartSpec:
    """What a part kind's ``[part]`` table holds besides the common keys (``kind``,
    ``sheet_thickness``, ``flange_width``): its ``keys``, and whether it has a ``flange_width``
    (False: the flange is in its geometry, as a mesh's)."""

    keys: frozenset[str]
    flange: bool = True
