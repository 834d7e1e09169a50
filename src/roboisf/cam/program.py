"""What the program writers share: the tool, the cell placement, tool orientations, and the
result type the program parsers return.

Conventions (both controllers, see ``docs/toolpaths.md``):

* The programmed point is the toolpath **tip** (lowest point of the ball) in the **work frame**
  (origin at the blank centre, z up along the tool axis), in mm at 1 µm resolution.
* The **tool frame** has its z axis along the tool, pointing *out of the flange towards the ball*
  (ABB's tool0 convention). A straight tool of length L mounted on the flange axis has its TCP at
  ``(0, 0, L)`` in the ABB flange frame (tool0, z out of the flange) and at ``X = L`` with
  ``B = 90°`` in the KUKA flange frame (x out of the flange; the extra rotation puts the tool z on
  the flange x). With this choice the "pointing down" pose is ``R_work_tool = Rx(180°)``: ABB
  quaternion ``[0, 1, 0, 0]``, KUKA ``A, B, C = 0, 0, 180`` — away from KUKA's B = ±90° gimbal lock.
* A rotation γ of the tool about its own axis (free for a ball tool; used to pick a stiffer robot
  configuration) is ``R_work_tool = Rx(180°) · Rz(γ)``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames.rotations import vertical_tool
from roboisf.frames.se3 import check_rigid, check_rotation
from roboisf.path.toolpath import Toolpath

__all__ = [
    "MAX_MODULE_MOVES",
    "ProgramInputs",
    "ProgramPath",
    "RobotTool",
    "prepare_program",
    "tool_down_orientation",
]

F64 = NDArray[np.float64]

#: Programs are written at 1 µm (0.001 mm) resolution.
POSITION_DECIMALS = 3


@dataclass(frozen=True)
class RobotTool:
    """The forming tool as the robot controller sees it.

    Attributes
    ----------
    length : float, m — flange face to the ball tip (the TCP), along the flange axis
    mass : float, kg — tool + holder mass (payload data for the controller)
    cog : (3,) float, m — centre of gravity in the flange frame (default: half-way along the axis)
    name : str — controller identifier (``tBall``)
    """

    length: float = 0.2
    mass: float = 2.0
    cog: tuple[float, float, float] | None = None
    name: str = "tBall"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.length) and self.length > 0):
            raise InputError(f"must be > 0 mm, got {self.length * 1e3:g}", field="tool.length")
        if not (math.isfinite(self.mass) and self.mass > 0):
            raise InputError(f"must be > 0 kg, got {self.mass:g}", field="tool.mass")
        identifier(self.name, "tool.name")

    @property
    def cog_xyz(self) -> F64:
        """Centre of gravity (3,) m in the flange frame (z along the flange axis)."""
        return np.array(self.cog if self.cog is not None else (0.0, 0.0, self.length / 2))


def fmt_num(v: float, nd: int = 3) -> str:
    """Shortest fixed-point text of ``v`` at ``nd`` decimals (``12.500`` → ``12.5``, no ``-0``)."""
    s = f"{v:.{nd}f}"
    if "." in s:  # nd = 0 has no decimals to strip (10 stays 10)
        s = s.rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def identifier(name: str, what: str, max_len: int = 24) -> str:
    """Check a controller identifier (letter first, then letters, digits, ``_``)."""
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name) or len(name) > max_len:
        raise InputError(
            f"{name!r} is not a valid robot-program identifier (a letter, then letters, digits or "
            f"_, at most {max_len} characters)",
            field=what,
        )
    return name


def program_identifier(stem: str, max_len: int = 24) -> str:
    """A valid identifier derived from a file stem (``my-path.v2`` → ``my_path_v2``)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", stem)
    if not s or not s[0].isalpha():
        s = "isf_" + s
    return s[:max_len]


def tool_down_orientation(tool_rotation: ArrayLike = 0.0, n: int | None = None) -> F64:
    """``R_work_tool = Rx(π) · Rz(γ)`` — tool z along −z_work, rotated by γ about its own axis.

    tool_rotation : float or (N,) float, rad. Returns (N, 3, 3) (``n`` rows for a scalar γ).
    """
    g = np.asarray(tool_rotation, dtype=float)
    if g.ndim == 0:
        g = np.full(1 if n is None else n, float(g))
    return vertical_tool(g)


def orientations(
    tp: Toolpath, tool_rotation: ArrayLike = 0.0, R_work_tool: ArrayLike | None = None
) -> F64:
    """Per-point tool orientation (N, 3, 3) for ``tp``: ``R_work_tool`` if given, else tool down."""
    n = len(tp)
    if R_work_tool is not None:
        R = np.asarray(R_work_tool, dtype=float)
        if R.shape == (3, 3):
            R = np.broadcast_to(R, (n, 3, 3))
        if R.shape != (n, 3, 3):
            raise InputError(
                f"R_work_tool must have shape ({n}, 3, 3), got {R.shape}", field="R_work_tool"
            )
        return np.array(check_rotation(R, "R_work_tool"))
    g = np.asarray(tool_rotation, dtype=float)
    if g.ndim == 1 and g.shape != (n,):
        raise InputError(
            f"tool_rotation must be a scalar or ({n},), got {g.shape}", field="tool_rotation"
        )
    if not np.all(np.isfinite(g)):
        raise InputError("tool_rotation must be finite", field="tool_rotation")
    return tool_down_orientation(g, n)


def tip_mm(tp: Toolpath) -> F64:
    """Programmed points (N, 3) in mm, rounded to the program resolution (1 µm)."""
    return np.round(tp.tip * 1e3, POSITION_DECIMALS)


def check_placement(T_base_work: ArrayLike | None) -> F64:
    """Validate ``T_base_work`` (4, 4) m. ``None`` is refused: a robot program never puts the work
    object at the robot base silently (pass ``np.eye(4)`` to mean the base)."""
    if T_base_work is None:
        raise InputError(
            "a robot program needs the work-object placement T_base_work (the blank in the robot "
            "base frame); pass the identity explicitly to mean the robot base",
            field="T_base_work",
        )
    T = np.asarray(T_base_work, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError(
            f"T_base_work must be a finite (4, 4) transform, got shape {T.shape}",
            field="T_base_work",
        )
    return check_rigid(T, "T_base_work")


def split_chunks(n: int, max_moves: int) -> list[slice]:
    """Split ``n`` moves into consecutive routines of at most ``max_moves``."""
    if max_moves < 1:
        raise InputError(f"must be ≥ 1, got {max_moves}", field="max_moves")
    return [slice(a, min(a + max_moves, n)) for a in range(0, n, max_moves)]


#: Forming moves per loadable program module / sub-program (RAPID part modules, FANUC
#: sub-programs). A choice, not a controller number: at ~110 bytes a move it keeps one module near
#: 0.55 MB of text, far below the RAPID program memory of an IRC5/OmniCore controller (tens of MB,
#: depending on the memory option) even with two modules loaded at a time, and it is a size the
#: pendant's editor still opens. The writers take ``max_module_moves`` to change it.
MAX_MODULE_MOVES = 5000


def split_modules(lap: NDArray[np.int64], max_moves: int) -> list[slice]:
    """Split moves into consecutive modules of at most ``max_moves``, at lap ends where possible.

    Whole laps are packed greedily; a lap longer than ``max_moves`` is cut into pieces. A module
    boundary at a lap change puts any pause of the module change where the tool steps down.
    """
    if max_moves < 1:
        raise InputError(f"must be ≥ 1, got {max_moves}", field="max_module_moves")
    n = len(lap)
    starts = [0, *(np.flatnonzero(np.diff(lap) != 0) + 1).tolist(), n]
    out: list[slice] = []
    a = 0
    for b in starts[1:]:
        if b - a > max_moves:
            # the current module cannot take this lap: close it at the previous lap end if any
            prev = max((s for s in starts if a < s < b), default=a)
            if prev > a:
                out.append(slice(a, prev))
                a = prev
            while b - a > max_moves:
                out.append(slice(a, a + max_moves))
                a += max_moves
    if a < n:
        out.append(slice(a, n))
    return out


def read_program_text(path: Path) -> str:
    """The text of a program file (UTF-8, a BOM allowed); InputError naming the file otherwise."""
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"not UTF-8 text ({e.reason} at byte {e.start})", file=path) from None
    except OSError as e:
        raise InputError(f"cannot read the file ({e.strerror})", file=path) from None


#: A decimal number in program text (parsers).
NUMBER_RE = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class ProgramInputs:
    """Validated writer inputs: tool, placement (4, 4) m, orientations (N, 3, 3), programmed
    points (N, 3) mm at 1 µm, routine slices, safe height [mm]."""

    tool: RobotTool
    T_base_work: F64
    R_work_tool: F64
    tip_mm: F64
    chunks: list[slice]
    safe_height_mm: float


def prepare_program(
    tp: Toolpath,
    *,
    T_base_work: ArrayLike | None = None,
    tool: RobotTool | None = None,
    tool_rotation: ArrayLike = 0.0,
    R_work_tool: ArrayLike | None = None,
    safe_height: float = 10e-3,
    max_moves: int = 2000,
) -> ProgramInputs:
    """Check and convert what every program writer needs (raises InputError naming the field)."""
    check_safe_height(safe_height)
    return ProgramInputs(
        tool=tool or RobotTool(),
        T_base_work=check_placement(T_base_work),
        R_work_tool=orientations(tp, tool_rotation, R_work_tool),
        tip_mm=tip_mm(tp),
        chunks=split_chunks(len(tp), max_moves),
        safe_height_mm=safe_height * 1e3,
    )


def check_safe_height(safe_height: float) -> None:
    """Approach/retract height [m] must be finite and > 0."""
    if not (math.isfinite(safe_height) and safe_height > 0):
        raise InputError(f"must be > 0 mm, got {safe_height * 1e3:g}", field="safe_height")


@dataclass(frozen=True)
class ProgramPath:
    """A robot/CNC program read back: the forming moves in order.

    Attributes
    ----------
    tip : (N, 3) float, m — programmed TCP positions (work frame / work object)
    R_work_tool : (N, 3, 3) float or None — tool orientations (None for G-code)
    feed : float, m/s — programmed forming speed
    T_base_work : (4, 4) float or None — work object / base frame placement
    tool : RobotTool or None — tool data found in the program
    meta : dict — anything else parsed (zone, routine names, ...)
    """

    tip: F64
    R_work_tool: F64 | None
    feed: float
    T_base_work: F64 | None = None
    tool: RobotTool | None = None
    meta: dict[str, object] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.tip.shape[0])
