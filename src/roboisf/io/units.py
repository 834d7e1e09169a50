"""Unit strings at the file boundary. Inside roboisf everything is SI (m, N, N·m, rad, s).

Files declare their units (a header comment, a TOML key or a CLI option); these helpers turn a
declared unit into the factor that converts the file's numbers to SI.
"""

from __future__ import annotations

import math

from roboisf.errors import InputError

__all__ = [
    "ANGLE_UNITS",
    "FORCE_UNITS",
    "LENGTH_UNITS",
    "MOMENT_UNITS",
    "TIME_UNITS",
    "log_unit_to_si",
    "to_si",
]

LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "cm": 1e-2, "in": 0.0254}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
#: Spellings instruments write, accepted in log files (not in study.toml, which keeps the short
#: list above): a unit not here is an error, never a guess.
LOG_ALIASES = {
    "angle": {
        "°": "deg",
        "degree": "deg",
        "degrees": "deg",
        "radian": "rad",
        "radians": "rad",
    },
    "force": {"n": "N", "kn": "kN", "lbf": "lbf", "lb": "lbf"},
    "moment": {
        "n-m": "N*m",
        "nm": "N*m",
        "n m": "N*m",
        "n*m": "N*m",
        "n.m": "N*m",
        "n·m": "N*m",
        "nmm": "N*mm",
        "n-mm": "N*mm",
        "n*mm": "N*mm",
        "lbf-in": "lbf*in",
        "lbf*in": "lbf*in",
        "lbf in": "lbf*in",
        "in-lb": "lbf*in",
        "in-lbf": "lbf*in",
        "lbf-ft": "lbf*ft",
        "ft-lb": "lbf*ft",
        "knm": "kN*m",
        "kn*m": "kN*m",
    },
    "time": {
        "sec": "s",
        "secs": "s",
        "second": "s",
        "seconds": "s",
        "msec": "ms",
        "millisec": "ms",
        "us": "us",
        "µs": "us",
    },
    "length": {"millimeter": "mm", "millimetre": "mm", "meter": "m", "metre": "m"},
}
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
_LBF = 4.4482216152605  # N (exact by definition of the pound-force)
_LOG_EXTRA = {
    "force": {"lbf": _LBF},
    "moment": {"lbf*in": _LBF * 0.0254, "lbf*ft": _LBF * 0.3048, "kN*m": 1e3},
    "time": {"us": 1e-6},
    "angle": {},
    "length": {},
}

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


def log_unit_to_si(unit: str, kind: str, *, file: object = None, field: str | None = None) -> float:
    """Like :func:`to_si`, also accepting the spellings instruments write (``°``, ``Nm``,
    ``N-m``, ``lbf``, ``lbf-in``, ``sec``, ``msec`` …; case-insensitive for those).

    >>> log_unit_to_si("°", "angle") == to_si("deg", "angle")
    True
    """
    key = unit.strip().strip("[]()").strip()
    if key in _KINDS[kind]:
        return _KINDS[kind][key]
    alias = LOG_ALIASES[kind].get(key.lower())
    if alias is not None:
        if alias in _KINDS[kind]:
            return _KINDS[kind][alias]
        return _LOG_EXTRA[kind][alias]
    known = list(_KINDS[kind]) + list(_LOG_EXTRA[kind])
    raise InputError(
        f"unknown {kind} unit {unit!r}; expected one of {', '.join(known)}",
        file=file,  # type: ignore[arg-type]
        field=field,
    )
