"""Plausibility bounds: the range a real forming cell can have for every value a user gives.

A value can be finite, of the right sign and still absurd: a holder offset of 66 000 mm (written
in µm), a sheet 1e29 mm thick, a sensor 1e29 mm from the flange. Such a value used to run to the
end and give results in the thousands of millimetres. Every study, part and truth value with a
unit is checked against :data:`BOUNDS` where it is read; a value outside is refused with one line
naming the file and key, the range, and which unit slip would explain it (``66000 mm is outside
… (0–1000 mm); it is 66 mm if it was written in µm``).

The ranges are generous (an ISF cell, from a desktop CNC to a 4 m robot; a value at the edge of a
range is unusual, not wrong): they exist to catch slips of a factor 25.4–10⁶ and garbage, not to
second-guess a design. Values are in the unit their file uses (mm, deg, kg, N …). No numpy here:
the study and part readers call it before anything heavy is imported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roboisf.errors import InputError

__all__ = ["BOUNDS", "Bound", "check_part", "check_plausible", "check_tool_offset", "unit_slip"]


@dataclass(frozen=True)
class Bound:
    """``lo ≤ value ≤ hi`` in ``unit``; ``what`` names the quantity in messages.

    ``zero``: 0 itself is also accepted, as the documented "none" (a holder offset of 0: the
    nose at the tip), while a small non-zero value below ``lo`` is refused as a unit slip.
    """

    lo: float
    hi: float
    unit: str
    what: str
    zero: bool = False


#: unit → the slips that happen with it: (the unit the number was really written in, the factor
#: that turns such a number into ``unit``)
_SLIPS: dict[str, tuple[tuple[str, float], ...]] = {
    "mm": (("µm", 1e-3), ("m", 1e3), ("inch", 25.4), ("cm", 10.0)),
    "deg": (("rad", 180.0 / math.pi),),
    "kg": (("g", 1e-3),),
    "N": (("kN", 1e3),),
    "N·m": (("N·mm", 1e-3), ("kN·m", 1e3)),
    "N·m/rad": (("kN·m/rad", 1e3), ("N·mm/rad", 1e-3), ("N·m/deg", 180.0 / math.pi)),
    "mm/N": (("m/N", 1e3), ("µm/N", 1e-3)),
    "GPa": (("Pa", 1e-9), ("MPa", 1e-3)),
    "s": (("ms", 1e-3), ("µs", 1e-6)),
    "": (("%", 1e-2),),
}

#: name → bound (file units). Tool and holder: a desktop ball to a heavy holder; placements: a
#: 4 m robot's reach; poses of a sensor or a tool centre: within a metre and a half of the flange.
BOUNDS: dict[str, Bound] = {
    "ball_diameter": Bound(0.5, 100.0, "mm", "a forming tool's ball diameter"),
    "free_length": Bound(1.0, 1000.0, "mm", "a tool's free length"),
    "shank_diameter": Bound(0.5, 200.0, "mm", "a tool's shank diameter"),
    # 0 is the "not given" default (the nose at the tip); a real holder's nose is a millimetre or
    # more from the tip, so 0.066 is the 66 mm of a holder written in m
    "holder_offset": Bound(
        1.0, 1000.0, "mm", "a holder's offset from its nose to the tool tip", zero=True
    ),
    # a tool or holder material, from a polymer tool to tungsten carbide
    "youngs_modulus": Bound(0.1, 1500.0, "GPa", "a tool or holder material's Young's modulus"),
    "holder_length": Bound(0.1, 2000.0, "mm", "a holder section's length"),
    "holder_diameter": Bound(0.5, 1000.0, "mm", "a holder's diameter"),
    "placement": Bound(-6000.0, 6000.0, "mm", "a work object's position from the robot base"),
    # a robot program's tool: the ball (0.5 mm or more) and its shank stand out of the flange
    "tool_length": Bound(5.0, 2000.0, "mm", "a tool's length from the flange to the ball tip"),
    "flange_to_tip": Bound(-2000.0, 2000.0, "mm", "a tool tip's position from the flange"),
    # a --tool x,y,z: its distance from the flange (0: the flange itself, as a tracker target)
    "tool_offset": Bound(5.0, 2000.0, "mm", "a tool tip's distance from the flange", zero=True),
    "sensor_position": Bound(-2000.0, 2000.0, "mm", "a force sensor's position"),
    "angle": Bound(-720.0, 720.0, "deg", "a rotation angle"),
    "joint_stiffness": Bound(1e2, 1e10, "N·m/rad", "a robot joint's stiffness"),
    "tool_mass": Bound(0.0, 500.0, "kg", "the mass below a force sensor"),
    # robot identify --design: a load a laser-tracker experiment hangs on or presses into a robot
    "identification_load": Bound(1.0, 1e5, "N", "a load of a stiffness experiment"),
    "tool_cog": Bound(-2000.0, 2000.0, "mm", "a centre of gravity's position"),
    "time_offset": Bound(-7 * 86400.0, 7 * 86400.0, "s", "a log's time offset"),
    "sheet_thickness": Bound(0.02, 20.0, "mm", "a formed sheet's thickness"),
    "part_size": Bound(1.0, 5000.0, "mm", "a part's opening"),
    "part_depth": Bound(0.1, 3000.0, "mm", "a part's depth"),
    "flange_width": Bound(0.0, 1000.0, "mm", "a part's flange width"),
    "rim_band": Bound(0.0, 1000.0, "mm", "the rim band left out of the analysis"),
    "point_radius": Bound(0.005, 50.0, "mm", "the radius scan points are averaged over"),
    "max_distance": Bound(0.005, 200.0, "mm", "the scan's distance to the nominal"),
    # the virtual cell's truth (docs/virtual-cell.md)
    "stiffness_scale": Bound(0.01, 100.0, "", "a joint stiffness scale"),
    "drift": Bound(-50.0, 50.0, "mm", "a thermal drift"),
    "joint_offset": Bound(-20.0, 20.0, "deg", "a joint's zero offset"),
    "geometry_error": Bound(-100.0, 100.0, "mm", "a robot's geometry error"),
    "work_object_shift": Bound(-200.0, 200.0, "mm", "a work object's error"),
    "work_object_turn": Bound(-30.0, 30.0, "deg", "a work object's rotation error"),
    "sensor_bias": Bound(-1e4, 1e4, "N", "a force sensor's bias"),
    "sensor_gain": Bound(0.1, 10.0, "", "a force sensor's gain"),
    "crosstalk": Bound(-0.5, 0.5, "", "a force sensor's crosstalk"),
    "scan_shift": Bound(-200.0, 200.0, "mm", "a scan's misregistration"),
    "scan_rotation": Bound(-30.0, 30.0, "deg", "a scan's rotation error"),
    "springback_amplitude": Bound(0.0, 50.0, "mm", "a springback amplitude"),
    "coupling_depth": Bound(0.01, 1e4, "mm", "a springback coupling depth"),
    "cnc_compliance": Bound(0.0, 1.0, "mm/N", "a CNC's compliance"),
}


def unit_slip(value: float, bound: Bound) -> str:
    """The unit slip that would put ``value`` inside ``bound``, as a phrase; ``""`` when none."""
    for unit, factor in _SLIPS.get(bound.unit, ()):
        v = value * factor
        if bound.lo <= v <= bound.hi and v != 0:
            shown = f"{v:.6g} {bound.unit}".rstrip()
            return f"it is {shown} if it was written in {unit}"
    return ""


def check_plausible(
    value: Any,
    name: str,
    *,
    file: str | Path | None = None,
    field: str | None = None,
    line: int | None = None,
) -> float:
    """``value`` (a number in ``BOUNDS[name].unit``) as a float, or an :class:`InputError`.

    The message names the range a real cell has and the unit slip that would explain the value
    (``66000 mm is outside a holder's offset … (0–1000 mm); it is 66 mm if it was written in
    µm``); a non-finite value is refused as such.
    """
    b = BOUNDS[name]
    unit = f" {b.unit}" if b.unit else ""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"expected a finite number{unit}, got {value!r}", file=file, field=field)
    v = float(value)
    if b.lo <= v <= b.hi or (b.zero and v == 0):
        return v
    slip = unit_slip(v, b)
    why = slip or "no usual unit slip explains it: check the value"
    zero = ", or 0" if b.zero else ""
    raise InputError(
        f"{v:.6g}{unit} is outside what a real cell has for {b.what} "
        f"({b.lo:g} to {b.hi:g}{unit}{zero}); {why}",
        file=file,
        field=field,
        line=line,
    )


def check_tool_offset(
    xyz_mm: Any, *, field: str = "--tool", file: str | Path | None = None
) -> None:
    """Refuse a tool tip ``xyz_mm`` (3 numbers, mm, flange frame) whose distance from the
    flange is no tool's (``tool_offset``: 5–2000 mm, or 0 for the flange itself): ``0,0,0.306``
    — a 306 mm tool typed in m — gave a stiffness map, a plan or an identification of a tool
    0.3 mm long; it is refused naming that slip."""
    x, y, z = (float(v) for v in xyz_mm)
    check_plausible(math.sqrt(x * x + y * y + z * z), "tool_offset", field=field, file=file)


def check_part(part: Any, *, file: str | Path | None = None) -> None:
    """Refuse a part no forming cell makes: its sheet thickness, depth and size against
    :data:`BOUNDS`, and a sheet thicker than the part is deep or a tenth of its opening.

    ``part`` is any :class:`roboisf.parts.Part` (lengths in m); messages are in mm and name the
    part's keys (``part.sheet_thickness``, ``part.depth``).
    """
    t = float(part.sheet_thickness) * 1e3
    check_plausible(t, "sheet_thickness", file=file, field="part.sheet_thickness")
    depth = float(part.depth) * 1e3
    if math.isfinite(depth) and depth <= 0:
        raise InputError(
            f"the part does not reach below the sheet plane (its lowest point is {-depth:g} mm "
            "above z = 0): a formed part lies below the sheet plane, z ≤ 0 in the work frame; "
            "move or flip the geometry",
            file=file,
            field="part.depth",
        )
    check_plausible(depth, "part_depth", file=file, field="part.depth")
    lo, hi = part.bounds
    size = max(float(hi[0]) - float(lo[0]), float(hi[1]) - float(lo[1])) * 1e3
    check_plausible(size, "part_size", file=file, field="part")
    if t > depth or t > size / 10:
        raise InputError(
            f"a {t:g} mm sheet on a part {depth:g} mm deep and {size:g} mm wide cannot be formed "
            "(the sheet is at most as thick as the part is deep, and a tenth of its width); "
            "check the unit of sheet_thickness (mm)",
            file=file,
            field="part.sheet_thickness",
        )
