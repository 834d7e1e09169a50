"""Unit strings at the file boundary. Inside roboisf everything is SI (m, N, N·m, rad, s).

Files declare their units (a header comment, a TOML key or a CLI option); these helpers turn a
declared unit into the factor that converts the file's numbers to SI.
"""

from __future__ import annotations

import math

from roboisf.errors import InputError

__all__ = ["ANGLE_UNITS", "FORCE_UNITS", "LENGTH_UNITS", "MOMENT_UNITS", "TIME_UNITS", "to_si"]

LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "cm": 1e-2, "in": 0.0254}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
MOMENT_UNITS = {
    "N*m": 1.0,
    "Nm": 1.0,
    "N.m": 1.0,
    "N·m": 1.0,
    "N*mm": 1e-3,
    "Nmm": 1e-3,
    "N.mm": 1e-3,
}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "min": 60.0}

_KINDS = {
    "length": LENGTH_UNITS,
    "angle": ANGLE_UNITS,
    "force": FORCE_UNITS,
    "moment": MOMENT_UNITS,
    "time": TIME_UNITS,
}


def to_si(unit: str, kind: str, *, file: object = None, field: str | None = None) -> float:
    """Factor that converts a value in ``unit`` to SI, for a quantity of ``kind``.

    >>> to_si("mm", "length")
    0.001
    """
    table = _KINDS[kind]
    key = unit.strip()
    if key not in table:
        raise InputError(
            f"unknown {kind} unit {unit!r}; expected one of {', '.join(table)}",
            file=file,  # type: ignore[arg-type]
            field=field,
        )
    return table[key]
