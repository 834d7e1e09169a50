"""Toolpaths: step-down and spiral generation for axisymmetric parts, the Toolpath type."""

from roboisf.toolpath.generate import DEFAULT_FEED, lap_levels, spiral, step_down
from roboisf.toolpath.toolpath import Toolpath, tool_points

__all__ = ["DEFAULT_FEED", "Toolpath", "lap_levels", "spiral", "step_down", "tool_points"]
