"""``kind = "vwacf"``: the paper's variable-wall-angle conical frustum
(:class:`roboisf.parts.VWACF`); ``opening_diameter`` [mm, default 88.15], ``arc_radius`` [mm],
``final_wall_angle`` [deg, default 90]."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format
from roboisf.parts.kind import PartSpec


def build(table: dict[str, Any], where: Path | None, common: dict[str, Any]) -> Any:
    """The VWACF of a ``[part]`` table (mm, deg) with the ``common`` keys (m)."""
    from roboisf.parts.axisymmetric import VWACF, VWACF_DEFAULT_ARC_RADIUS
    from roboisf.parts.io import part_number

    return VWACF(
        opening_diameter=part_number(table, "opening_diameter", where, 88.15) * 1e-3,
        arc_radius=part_number(table, "arc_radius", where, VWACF_DEFAULT_ARC_RADIUS * 1e3) * 1e-3,
        final_wall_angle=math.radians(part_number(table, "final_wall_angle", where, 90.0)),
        **common,
    )


register_format(
    FileFormat(
        name="vwacf",
        kind="part",
        label="VWACF",
        reader=build,
        rank=20,
        spec=PartSpec(keys=frozenset({"opening_diameter", "arc_radius", "final_wall_angle"})),
    )
)
