"""``kind = "cone"``: a constant-wall-angle cone (:class:`roboisf.parts.Cone`);
``opening_diameter`` [mm], ``wall_angle`` [deg], ``depth`` [mm]."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format
from roboisf.parts.kind import PartSpec


def build(table: dict[str, Any], where: Path | None, common: dict[str, Any]) -> Any:
    """The cone of a ``[part]`` table (mm, deg) with the ``common`` keys (m)."""
    from roboisf.parts.axisymmetric import Cone
    from roboisf.parts.io import part_number

    return Cone(
        opening_diameter=part_number(table, "opening_diameter", where) * 1e-3,
        wall_angle=math.radians(part_number(table, "wall_angle", where)),
        depth=part_number(table, "depth", where) * 1e-3,
        **common,
    )


register_format(
    FileFormat(
        name="cone",
        kind="part",
        label="cone",
        reader=build,
        rank=10,
        spec=PartSpec(keys=frozenset({"opening_diameter", "wall_angle", "depth"})),
    )
)
