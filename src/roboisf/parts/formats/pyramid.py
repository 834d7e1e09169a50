"""``kind = "pyramid"``: a pyramid frustum (:class:`roboisf.parts.Pyramid`); ``top_length``,
``top_width`` [mm], ``wall_angle`` [deg], optional ``wall_angle_y`` [deg, default
``wall_angle``], ``depth`` [mm], optional ``corner_radius`` [mm, default 0]."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from roboisf.formats import FileFormat, register_format
from roboisf.parts.kind import PartSpec


def build(table: dict[str, Any], where: Path | None, common: dict[str, Any]) -> Any:
    """The pyramid of a ``[part]`` table (mm, deg) with the ``common`` keys (m)."""
    from roboisf.parts.io import part_number
    from roboisf.parts.pyramid import Pyramid

    ay = table.get("wall_angle_y")
    return Pyramid(
        top_length=part_number(table, "top_length", where) * 1e-3,
        top_width=part_number(table, "top_width", where) * 1e-3,
        wall_angle=math.radians(part_number(table, "wall_angle", where)),
        depth=part_number(table, "depth", where) * 1e-3,
        wall_angle_y=None
        if ay is None
        else math.radians(part_number(table, "wall_angle_y", where)),
        corner_radius=part_number(table, "corner_radius", where, 0.0) * 1e-3,
        **common,
    )


register_format(
    FileFormat(
        name="pyramid",
        kind="part",
        label="pyramid",
        reader=build,
        rank=40,
        spec=PartSpec(
            keys=frozenset(
                {"top_length", "top_width", "wall_angle", "wall_angle_y", "depth", "corner_radius"}
            )
        ),
    )
)
