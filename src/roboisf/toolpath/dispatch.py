"""The one choice of toolpath generator for a part, whatever its kind.

Axisymmetric parts (cone, VWACF, profile) use the generatrix generator
(:mod:`roboisf.toolpath.generate`: exact, and ``max_wall_step`` refines laps along a shallow
wall); every other part kind (pyramid, mesh, CAD) — and any part given a ``scallop_height`` — the
slicer of the ball-centre surface (:mod:`roboisf.toolpath.slice`).
"""

from __future__ import annotations

from roboisf.errors import InputError
from roboisf.parts import AxisymmetricPart, Part
from roboisf.path.toolpath import Toolpath
from roboisf.toolpath import generate
from roboisf.toolpath.generate import DEFAULT_FEED, MAX_POINTS
from roboisf.toolpath.slice import sliced_spiral, sliced_step_down

__all__ = ["toolpath_for_part"]


def toolpath_for_part(
    part: Part,
    tool_radius: float,
    step: float,
    *,
    spacing: float = 1e-3,
    feed: float = DEFAULT_FEED,
    spiral: bool = False,
    max_wall_step: float | None = None,
    scallop_height: float | None = None,
    max_points: int | None = MAX_POINTS,
) -> Toolpath:
    """The toolpath of ``part`` (lengths m, feed m/s): step-down laps, or a spiral.

    ``max_wall_step`` applies to axisymmetric parts only (an InputError for other kinds, which
    space their laps along the wall with ``scallop_height``).
    """
    if isinstance(part, AxisymmetricPart) and scallop_height is None:
        gen = generate.spiral if spiral else generate.step_down
        return gen(
            part,
            tool_radius,
            step,
            spacing=spacing,
            feed=feed,
            max_wall_step=max_wall_step,
            max_points=max_points,
        )
    if max_wall_step is not None:
        raise InputError(
            f"applies to axisymmetric parts only, without a scallop height (part kind "
            f"{part.kind!r}); the scallop height spaces the laps along the wall of any part",
            field="max_wall_step",
        )
    sliced = sliced_spiral if spiral else sliced_step_down
    return sliced(
        part,
        tool_radius,
        step,
        scallop_height=scallop_height,
        spacing=spacing,
        feed=feed,
        max_points=max_points,
    )
