"""Toolpaths: step-down and spiral generation for axisymmetric parts (generate) and for any part
(slice: z-levels of the ball-centre offset surface), the Toolpath type."""

from roboisf.toolpath.dispatch import toolpath_for_part
from roboisf.toolpath.generate import DEFAULT_FEED, ball_position, spiral, step_down, tip_levels
from roboisf.toolpath.slice import level_contour, scallop_step, sliced_spiral, sliced_step_down
from roboisf.toolpath.toolpath import Toolpath, tool_points

__all__ = [
    "DEFAULT_FEED",
    "Toolpath",
    "ball_position",
    "level_contour",
    "scallop_step",
    "sliced_spiral",
    "sliced_step_down",
    "spiral",
    "step_down",
    "tip_levels",
    "tool_points",
    "toolpath_for_part",
]
