"""Compensation: compliance pre-deflection, springback displacement adjustment, gouge check and
the compensated robot program. Equations and conventions: ``docs/compensate.md``."""

from roboisf.compensate.adjust import Adjustment, displacement_adjustment, smooth_on_laps
from roboisf.compensate.compliance import ComplianceCompensation, DeflectionModel, precompensate
from roboisf.compensate.gouge import GougeReport, gouge_check
from roboisf.compensate.pipeline import (
    Compensation,
    CompensationOptions,
    compensate,
    lap_table,
    nominal_of,
    write_compensation,
)

__all__ = [
    "Adjustment",
    "Compensation",
    "CompensationOptions",
    "ComplianceCompensation",
    "DeflectionModel",
    "GougeReport",
    "compensate",
    "displacement_adjustment",
    "gouge_check",
    "lap_table",
    "nominal_of",
    "precompensate",
    "smooth_on_laps",
    "write_compensation",
]
