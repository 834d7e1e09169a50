"""Moved to :mod:`roboisf.cell.forces` (the force model belongs to the cell); kept importable."""

from roboisf.cell.forces import ForceModel, aerens_axial_force, tip_wrench

__all__ = ["ForceModel", "aerens_axial_force", "tip_wrench"]
