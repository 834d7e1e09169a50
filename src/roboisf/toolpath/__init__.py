"""Toolpaths: step-down and spiral generation for axisymmetric parts (generate) and for any part
(slice: z-levels of the ball-centre offset surface), the Toolpath type.

The names below load their module on first use (PEP 562), so that ``roboisf --help`` and the size
limits (:mod:`roboisf.toolpath.limits`) do not import numpy.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from roboisf.toolpath.dispatch import toolpath_for_part
    from roboisf.toolpath.generate import (
        DEFAULT_FEED,
        ball_position,
        spiral,
        step_down,
        tip_levels,
    )
    from roboisf.toolpath.slice import (
        level_contour,
        scallop_step,
        sliced_spiral,
        sliced_step_down,
    )
    from roboisf.toolpath.toolpath import Toolpath, tool_points

_WHERE = {
    "dispatch": ("toolpath_for_part",),
    "generate": ("DEFAULT_FEED", "ball_position", "spiral", "step_down", "tip_levels"),
    "slice": ("level_contour", "scallop_step", "sliced_spiral", "sliced_step_down"),
    "toolpath": ("Toolpath", "tool_points"),
}
_MODULE_OF = {name: module for module, names in _WHERE.items() for name in names}

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
assert sorted(__all__) == sorted(_MODULE_OF)


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'roboisf.toolpath' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"roboisf.toolpath.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
