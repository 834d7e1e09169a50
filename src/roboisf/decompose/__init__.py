"""The error decomposition of the paper: springback, tool, tool holder, robot compliance."""

from roboisf.decompose.core import (
    FACTORS,
    Decomposition,
    contribution_rows,
    decompose,
    resultant_mean_deviation,
)

__all__ = ["FACTORS", "Decomposition", "contribution_rows", "decompose", "resultant_mean_deviation"]
