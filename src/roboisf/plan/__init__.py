"""Placement and tool orientation: where to put the fixture in the robot's workspace and how to
turn the ball tool about its own axis so the robot gives way least (``docs/plan.md``)."""

from roboisf.plan.evaluate import (
    PlacementScore,
    evaluate_batch,
    evaluate_placement,
    margin_ok,
    path_sigma_min,
    sigma_min,
    smooth_schedule,
)
from roboisf.plan.problem import PlanProblem, placement_grid, placement_transforms
from roboisf.plan.setup import problem_from_cell
from roboisf.plan.sweep import PlanResult, evaluated_candidates, plan_placements

__all__ = [
    "PlacementScore",
    "PlanProblem",
    "PlanResult",
    "evaluate_batch",
    "evaluate_placement",
    "evaluated_candidates",
    "margin_ok",
    "path_sigma_min",
    "placement_grid",
    "placement_transforms",
    "plan_placements",
    "problem_from_cell",
    "sigma_min",
    "smooth_schedule",
]
