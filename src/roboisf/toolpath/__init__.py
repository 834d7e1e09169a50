"""Toolpaths: step-down and spiral generation for axisymmetric parts, the Toolpath type."""

from roboisf.toolpath.generate import DEFAULT_FEED, ball_position, spiral, step_down, tip_levels
from roboisf.toolpath.toolpath import Toolpath, tool_points

__all__ = [
    "DEFAULT_FEED",
    "Toolpath",
    "ball_position",
    "spiral",
    "step_down",
    "tip_levels",
    "tool_points",
]
