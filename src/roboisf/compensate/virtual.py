"""Compensation iterated against the virtual cell (form → measure → adjust → form again).

Each iteration "measures" the formed part from the cell's ground truth (``dn_robot``: no scan
noise, every point valid) and the forming wrench the cell's robot run sees (a measured wrench in a
real cell). Use :func:`roboisf.virtual.build_study` + ``analyze`` for the measured route.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roboisf.compensate.cell import cell_deflection_model
from roboisf.compensate.pipeline import Compensation, CompensationOptions, compensate
from roboisf.progress import Progress
from roboisf.virtual.cell import CellTruth, VirtualCell, simulate

__all__ = ["VirtualIterations", "cell_deflection_model", "iterate_virtual"]

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class VirtualIterations:
    """``truths[0]`` the nominal part; ``truths[k]`` formed with ``commands[k-1]``."""

    cell: VirtualCell
    commands: list[Compensation]
    truths: list[CellTruth]

    @property
    def mean_abs_dn(self) -> F64:
        """Mean |dn_robot| [m] of each formed part, (iterations + 1,)."""
        return np.array([np.mean(np.abs(t.dn_robot)) for t in self.truths])


def iterate_virtual(
    cell: VirtualCell,
    *,
    iterations: int = 3,
    options: CompensationOptions | None = None,
    progress: Progress | None = None,
) -> VirtualIterations:
    """Form the nominal part, then ``iterations`` compensated parts, each from the last one.

    With springback off, every iteration is the same compliance pre-deflection (one suffices).
    """
    o = options or CompensationOptions()
    model = cell_deflection_model(cell.cell)
    truth = simulate(cell, progress=progress)
    nominal = truth.toolpath
    truths, commands = [truth], []
    c_prev = np.zeros(len(nominal))
    for _ in range(iterations):
        comp = compensate(
            cell.part,
            nominal,
            model=model,
            wrench=truths[0].wrench_robot,
            deviation=truth.dn_robot,
            formed=truth.toolpath.tip,
            previous_offset=c_prev,
            options=o,
            progress=progress,
        )
        comp.gouge.raise_if_gouging()
        truth = simulate(cell, commanded=comp.toolpath, progress=progress)
        commands.append(comp)
        truths.append(truth)
        c_prev = comp.offset
    return VirtualIterations(cell, commands, truths)
