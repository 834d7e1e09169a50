"""Compensation: compliance pre-deflection, springback displacement adjustment, gouge check and
the compensated robot program. Equations and conventions: ``docs/compensate.md``.

The names below load their module on first use (PEP 562): the online loop and its simulated
devices use :mod:`~roboisf.compensate.compliance` without the pipeline's pandas or the
adjustment's scipy.ndimage.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roboisf._lazy import attach

if TYPE_CHECKING:
    from roboisf.compensate.adjust import Adjustment, displacement_adjustment, smooth_on_laps
    from roboisf.compensate.compliance import (
        ComplianceCompensation,
        DeflectionModel,
        precompensate,
    )
    from roboisf.compensate.gouge import GougeReport, gouge_check
    from roboisf.compensate.pipeline import (
        Compensation,
        CompensationOptions,
        compensate,
        lap_table,
        nominal_of,
        write_compensation,
    )

_WHERE = {
    "adjust": ("Adjustment", "displacement_adjustment", "smooth_on_laps"),
    "compliance": ("ComplianceCompensation", "DeflectionModel", "precompensate"),
    "gouge": ("GougeReport", "gouge_check"),
    "pipeline": (
        "Compensation",
        "CompensationOptions",
        "compensate",
        "lap_table",
        "nominal_of",
        "write_compensation",
    ),
}
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
__getattr__, __dir__, _MODULE_OF = attach(__name__, globals(), _WHERE)
