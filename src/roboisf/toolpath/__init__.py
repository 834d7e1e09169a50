"""Toolpaths: step-down and spiral generation for axisymmetric parts (generate) and for any part
(slice: z-levels of the ball-centre offset surface), the Toolpath type.

The names below load their module on first use (PEP 562), so that ``roboisf --help`` and the size
limits (:mod:`roboisf.toolpath.limits`) do not import numpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.path.toolpath import Toolpath, tool_points
    from roboisf.toolpath.dispatch import toolpath_for_part
    from roboisf.toolpath.generate import (
        DEFAULT_FEED,
        ball_position,
        spiral,
        step_down,
        tip_levels,
    )
    from roboisf.toolpath.geometry import contour_curvature, meridian_curvature, rim_distance
    from roboisf.toolpath.slice import (
        level_contour,
        scallop_step,
        sliced_spiral,
        sliced_step_down,
    )

_WHERE = {
    "dispatch": ("toolpath_for_part",),
    "generate": ("DEFAULT_FEED", "ball_position", "spiral", "step_down", "tip_levels"),
    "geometry": ("contour_curvature", "meridian_curvature", "rim_distance"),
    "slice": ("level_contour", "scallop_step", "sliced_spiral", "sliced_step_down"),
    ".path.toolpath": ("Toolpath", "tool_points"),  # the value object lives below the formats
}
__all__ = [
    "DEFAULT_FEED",
    "Toolpath",
    "ball_position",
    "contour_curvature",
    "level_contour",
    "meridian_curvature",
    "rim_distance",
    "scallop_step",
    "sliced_spiral",
    "sliced_step_down",
    "spiral",
    "step_down",
    "tip_levels",
    "tool_points",
    "toolpath_for_part",
]
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
