"""Size limits of toolpath generation, in a module without numpy so that the command line can
show them in ``--help`` without importing the generators."""

from __future__ import annotations

__all__ = ["MAX_POINTS"]

#: Largest toolpath generated unless ``max_points`` says otherwise: 5 M points (the paper's cone
#: at 0.5 mm step-down and 1 mm spacing has 56 k; at 0.05 mm step-down 0.35 M).
MAX_POINTS = 5_000_000
