"""Poses as files and the command line write them: one parser, one formatter, the convention named.

A pose is a row of numbers, a position ``x, y, z`` then a rotation in one of these conventions
(:class:`PoseFormat`):

* ``"rpy"`` — ``roll, pitch, yaw``: ``R = Rz(yaw) · Ry(pitch) · Rx(roll)`` (Z-Y'-X'' Euler
  angles; :func:`roboisf.frames.rpy_to_matrix`). ``study.toml`` poses, ``--placement``,
  ``--sensor-pose``, robot files' ``rpy_deg``.
* ``"abc"`` — KUKA ``A, B, C`` = yaw, pitch, roll (the same matrix in the controller's order;
  :func:`roboisf.frames.abc_to_matrix`). ``--work-frame``.
* ``"yaw"`` — one angle about z: a fixture level on the floor (``robot``/``plan --placement``).
* ``"none"`` — the position only (``--tool x,y,z``).

and in the units it names: lengths ``"mm"`` or ``"m"``, angles ``"deg"`` or ``"rad"``. Inside
roboisf a pose is ``T`` (4, 4) with its translation in m (docs/conventions.md). The parser refuses
anything else with one :class:`~roboisf.errors.InputError` naming the file and field and the
expected numbers; :func:`format_pose` writes a transform back in the same convention, so
``parse_pose(format_pose(T, f), f)`` gives back ``T``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames.rotations import (
    abc_to_matrix,
    matrix_to_abc,
    matrix_to_rpy,
    rot_z,
    rpy_to_matrix,
)
from roboisf.frames.se3 import make_transform

__all__ = [
    "XYZ_ABC_MM_DEG",
    "XYZ_MM",
    "XYZ_RPY_MM_DEG",
    "XYZ_RPY_M_DEG",
    "XYZ_YAW_MM_DEG",
    "PoseFormat",
    "format_pose",
    "parse_pose",
    "pose_numbers",
    "pose_transform",
]

F64 = NDArray[np.float64]

_ANGLES = {"rpy": ("roll", "pitch", "yaw"), "abc": ("A", "B", "C"), "yaw": ("yaw",), "none": ()}
_LENGTH_TO_M = {"mm": 1e-3, "m": 1.0}
_M_TO_LENGTH = {"mm": 1e3, "m": 1.0}


@dataclass(frozen=True)
class PoseFormat:
    """How a pose is written: ``x, y, z`` in ``length``, then the ``rotation`` convention's
    angles in ``angle`` (module docstring)."""

    rotation: Literal["rpy", "abc", "yaw", "none"] = "rpy"
    length: Literal["mm", "m"] = "mm"
    angle: Literal["deg", "rad"] = "deg"

    @property
    def names(self) -> tuple[str, ...]:
        """The numbers in order, ``("x", "y", "z", "roll", "pitch", "yaw")``."""
        return ("x", "y", "z", *_ANGLES[self.rotation])

    @property
    def units(self) -> str:
        """``"mm and deg"``, or ``"mm"`` for a position."""
        return self.length if self.rotation == "none" else f"{self.length} and {self.angle}"


#: ``[x, y, z, roll, pitch, yaw]`` in mm and deg: study.toml, ``--placement``, ``--sensor-pose``
XYZ_RPY_MM_DEG = PoseFormat("rpy", "mm", "deg")
#: ``xyz_m`` and ``rpy_deg``: robot files' ``[tool]`` and ``[placement]``
XYZ_RPY_M_DEG = PoseFormat("rpy", "m", "deg")
#: KUKA ``X, Y, Z, A, B, C`` in mm and deg: ``--work-frame``
XYZ_ABC_MM_DEG = PoseFormat("abc", "mm", "deg")
#: ``x, y, z, yaw`` in mm and deg: a placement level on the floor (``robot``, ``plan``, ``predict``)
XYZ_YAW_MM_DEG = PoseFormat("yaw", "mm", "deg")
#: ``x, y, z`` in mm: a position (``--tool``)
XYZ_MM = PoseFormat("none", "mm", "deg")


def pose_numbers(
    values: Any,
    fmt: PoseFormat = XYZ_RPY_MM_DEG,
    *,
    field: str,
    file: str | Path | None = None,
    position_only: bool = False,
    strings: bool = True,
    alternatives: str = "",
) -> list[float]:
    """The finite numbers of a pose, in the file's units, checked against ``fmt``.

    ``values`` is a sequence of numbers (a TOML array: booleans are refused) or, with
    ``strings``, a comma-separated string (the command line). ``position_only`` also accepts
    ``x, y, z`` alone. Anything else is an :class:`InputError` on ``field`` (and ``file``) saying
    what was expected (and the caller's ``alternatives``, e.g. ``"'base' or a study"``).
    """
    names = fmt.names
    counts = (3, len(names)) if position_only and len(names) > 3 else (len(names),)
    text = isinstance(values, str)
    v: list[float] | None = None
    if text and strings:
        try:
            v = [float(t) for t in values.split(",")]
        except ValueError:
            v = None
    elif (
        not text
        and isinstance(values, Sequence | np.ndarray)
        and all(
            isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool)
            for x in values
        )
    ):
        v = [float(x) for x in values]
    if v is None or len(v) not in counts or not all(math.isfinite(x) for x in v):
        what = _expected(fmt, counts, text and strings)
        what += f", {alternatives}" if alternatives else ""
        raise InputError(f"expected {what}, got {values!r}", file=file, field=field)
    return v


def _expected(fmt: PoseFormat, counts: tuple[int, ...], text: bool) -> str:
    """``6 comma-separated numbers x,y,z,roll,pitch,yaw (mm, deg)`` for the command line,
    ``[x, y, z, roll, pitch, yaw] in mm and deg (6 finite numbers)`` for a file."""
    sep = "," if text else ", "
    angles = fmt.names[3:]
    listed = sep.join(fmt.names[:3])
    if angles:
        rest = sep + sep.join(angles)
        listed += f"[{rest}]" if len(counts) > 1 else rest
    n = " or ".join(str(c) for c in counts)
    if text:
        return f"{n} comma-separated numbers {listed} ({fmt.units.replace(' and ', ', ')})"
    return f"[{listed}] in {fmt.units} ({n} finite numbers)"


def pose_transform(numbers: ArrayLike, fmt: PoseFormat = XYZ_RPY_MM_DEG) -> F64:
    """``T`` (4, 4), translation in m, of a pose's numbers (``x, y, z`` [+ angles]) written in
    ``fmt``; no checks (:func:`parse_pose` checks)."""
    v = np.asarray(numbers, dtype=float)
    scale = _LENGTH_TO_M[fmt.length]
    p = v[:3] * scale if scale != 1.0 else v[:3]
    a = v[3:]
    if a.size == 0 or fmt.rotation == "none":
        return make_transform(None, p)
    if fmt.angle == "deg":
        a = np.radians(a)
    if fmt.rotation == "rpy":
        R = rpy_to_matrix(a)
    elif fmt.rotation == "abc":
        R = abc_to_matrix(a)
    else:
        R = rot_z(a[0])
    return make_transform(R, p)


def parse_pose(values: Any, fmt: PoseFormat = XYZ_RPY_MM_DEG, **check: Any) -> F64:
    """``T`` (4, 4), translation in m, of a pose written in ``fmt`` — a sequence of numbers or a
    comma-separated string, checked by :func:`pose_numbers` (``check``: its ``field``, ``file``,
    ``position_only`` — ``x, y, z`` alone, unrotated —, ``strings``, ``alternatives``)."""
    return pose_transform(pose_numbers(values, fmt, **check), fmt)


def format_pose(
    T: ArrayLike, fmt: PoseFormat = XYZ_RPY_MM_DEG, *, decimals: int = 9
) -> list[float]:
    """The numbers of ``T`` (4, 4), translation in m, written in ``fmt``, each rounded to
    ``decimals`` (the inverse of :func:`parse_pose`; pitch / B in [−90°, 90°]). A ``"yaw"`` or
    ``"none"`` format needs a ``T`` whose rotation it can say: anything else is an error."""
    A = np.asarray(T, dtype=float)
    scale = _M_TO_LENGTH[fmt.length]
    p = A[:3, 3] * scale if scale != 1.0 else A[:3, 3]
    R = A[:3, :3]
    if fmt.rotation == "rpy":
        a = matrix_to_rpy(R)
    elif fmt.rotation == "abc":
        a = matrix_to_abc(R)
    else:
        yaw = math.atan2(R[1, 0], R[0, 0]) if fmt.rotation == "yaw" else 0.0
        if np.max(np.abs(R - rot_z(yaw))) > 1e-9:
            raise ValueError(f"a {fmt.rotation!r} pose cannot say this rotation: {R.tolist()}")
        a = np.array([yaw] if fmt.rotation == "yaw" else [])
    if fmt.angle == "deg":
        a = np.degrees(a)
    return [round(float(x), decimals) for x in (*p, *a)]
