"""The data contract between the analysis and the report: which columns and keys must be there.

The analysis (``roboisf analyze``, the virtual cell) hands the report three tables and a dict; this
module names every column, says which are optional, and checks an input before anything is drawn,
so a missing column is an :class:`~roboisf.errors.InputError` naming it, never a KeyError deep in a
plotting call. Units of the tables (the report's, not SI): lengths mm, angles deg, forces N,
moments N·m, time s.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from roboisf.errors import InputError

if TYPE_CHECKING:  # pandas is imported where a table is checked: the diagnosis's numbers
    import pandas as pd  # (report.statements, via report.page) load without it

__all__ = [
    "AXES",
    "CONTRIBUTION_COLUMNS",
    "CONTRIBUTION_ROWS",
    "FACTORS",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "RUNS",
    "WRENCH",
    "check_contributions",
    "check_per_point",
    "check_summary",
]

#: The four terms of δR = δc + δs + δt + δth, in the order the report shows them.
FACTORS: tuple[str, ...] = ("tool", "tool_holder", "springback", "robot_compliance")
#: Deviation components: work-frame x, y, z and the component on the surface normal (tool side).
AXES: tuple[str, ...] = ("dx", "dy", "dz", "dn")
#: The two formed parts.
RUNS: tuple[str, ...] = ("cnc", "robot")
#: Wrench components at the tool tip in work axes, [f; m].
WRENCH: tuple[str, ...] = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")

_GEOMETRY = (
    "index",
    "lap",
    "time",
    "angle_deg",
    "depth",
    "contact_x",
    "contact_y",
    "contact_z",
    "normal_x",
    "normal_y",
    "normal_z",
    "wall_angle_deg",
)
_WRENCHES = tuple(f"{run}_{c}" for run in RUNS for c in WRENCH)
_MEASURED = tuple(f"{run}_{a}" for run in RUNS for a in AXES)
_VALID = tuple(f"{run}_valid" for run in RUNS)
_TERMS = tuple(f"{term}_{a}" for term in (*FACTORS, "vjm", "delta") for a in AXES)

#: Columns ``per_point`` must have. Geometry columns must be finite everywhere; deviations and
#: contributions may be NaN where a scan has a hole (``*_valid`` False).
REQUIRED_COLUMNS: tuple[str, ...] = (
    *_GEOMETRY,
    *_WRENCHES,
    *_MEASURED,
    *_VALID,
    *_TERMS,
    "thickness_predicted",
)
#: Columns the report uses when present (and says so when they are not).
OPTIONAL_COLUMNS: tuple[str, ...] = (
    "cnc_n_points",
    "robot_n_points",
    "thickness_measured",
    *(f"truth_{f}_dn" for f in FACTORS),
)
_MUST_BE_FINITE = (*_GEOMETRY, *_WRENCHES, "thickness_predicted")

CONTRIBUTION_COLUMNS: tuple[str, ...] = (
    "factor",
    "mean_abs_dx",
    "mean_abs_dy",
    "mean_abs_dz",
    "R_m",
    "share_percent",
)
CONTRIBUTION_ROWS: tuple[str, ...] = (*FACTORS, "total")


def check_per_point(per_point: Any, *, name: str = "per_point") -> pd.DataFrame:
    """Check the per-point table and return it sorted in toolpath order.

    Parameters
    ----------
    per_point : pandas.DataFrame
        One row per toolpath point with :data:`REQUIRED_COLUMNS` (mm, deg, N, N·m, s).

    Raises
    ------
    InputError
        Not a DataFrame, empty, a required column missing, a column not numeric, or a geometry or
        force column with NaN/inf. The error's ``field`` names the column.
    """
    import pandas as pd

    if not isinstance(per_point, pd.DataFrame):
        raise InputError(f"expected a pandas DataFrame, got {type(per_point).__name__}", field=name)
    if len(per_point) == 0:
        raise InputError(
            "the per-point table is empty (expected one row per toolpath point)", field=name
        )
    missing = [c for c in REQUIRED_COLUMNS if c not in per_point.columns]
    if missing:
        shown = ", ".join(missing[:8]) + (f" … ({len(missing)} in all)" if len(missing) > 8 else "")
        raise InputError(f"missing required column(s): {shown}", field=missing[0])
    numeric = [c for c in (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS) if c in per_point.columns]
    for col in numeric:
        if not (
            pd.api.types.is_numeric_dtype(per_point[col])
            or pd.api.types.is_bool_dtype(per_point[col])
        ):
            raise InputError(f"column must be numeric, got dtype {per_point[col].dtype}", field=col)
    for col in _MUST_BE_FINITE:
        values = per_point[col].to_numpy(dtype=float)
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{int(bad.sum())} non-finite value(s), first at row {row}; this column must be "
                "finite at every toolpath point",
                field=col,
            )
    return per_point.sort_values("index", kind="stable").reset_index(drop=True)


def check_contributions(table: Any, *, name: str) -> pd.DataFrame:
    """Check a contribution table (the paper's Table 5) and return it indexed by factor.

    Parameters
    ----------
    table : pandas.DataFrame
        Columns :data:`CONTRIBUTION_COLUMNS`, rows (``factor``) :data:`CONTRIBUTION_ROWS`;
        mm and %.
    name
        Which table this is (for the error message), e.g. ``"contributions_normal"``.
    """
    import pandas as pd

    if not isinstance(table, pd.DataFrame):
        raise InputError(f"expected a pandas DataFrame, got {type(table).__name__}", field=name)
    missing = [c for c in CONTRIBUTION_COLUMNS if c not in table.columns]
    if missing:
        raise InputError(f"{name}: missing column(s) {', '.join(missing)}", field=missing[0])
    factors = [str(f) for f in table["factor"]]
    absent = [r for r in CONTRIBUTION_ROWS if r not in factors]
    if absent:
        raise InputError(f"{name}: missing row(s) factor={', '.join(absent)}", field="factor")
    out = table.assign(factor=factors).drop_duplicates("factor").set_index("factor")
    values = out.loc[list(CONTRIBUTION_ROWS), list(CONTRIBUTION_COLUMNS[1:])]
    try:
        arr = values.to_numpy(dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: values must be numbers ({exc})", field=name) from None
    if not np.isfinite(arr).all():
        raise InputError(f"{name}: NaN or inf in the table", field=name)
    return values.astype(float)


def check_summary(summary: Any) -> dict[str, Any]:
    """Check the summary dict and fill the defaults (``contour_z`` None: the middle of the
    analysed wall, see :func:`roboisf.report.aggregate.contour_lap`; empty ``warnings``,
    ``part_symmetry`` None: decided from the part kind or the data, see
    :func:`roboisf.report.aggregate.is_round`)."""
    if not isinstance(summary, Mapping):
        raise InputError(f"expected a dict, got {type(summary).__name__}", field="summary")
    if "study" not in summary:
        raise InputError("summary must name the study (key 'study')", field="study")
    out = dict(summary)
    cz = out.get("contour_z")
    try:
        out["contour_z"] = None if cz is None else float(cz)
        if out["contour_z"] is not None and not np.isfinite(out["contour_z"]):
            raise ValueError
    except (TypeError, ValueError):
        raise InputError(
            f"contour_z must be a number in mm (or absent), got {cz!r}", field="contour_z"
        ) from None
    sym = out.get("part_symmetry")
    if sym is not None and (
        isinstance(sym, bool) or not isinstance(sym, int | np.integer) or sym < 0
    ):
        raise InputError(
            f"part_symmetry must be the symmetry order (0 continuous, n ≥ 1), got {sym!r}",
            field="part_symmetry",
        )
    out["part_symmetry"] = None if sym is None else int(sym)
    warnings = out.get("warnings") or []
    if isinstance(warnings, str) or not all(isinstance(w, str) for w in warnings):
        raise InputError("warnings must be a list of strings", field="warnings")
    out["warnings"] = list(warnings)
    return out
