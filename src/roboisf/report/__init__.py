"""The study report: a self-contained offline HTML page (plotly) and static PNGs (matplotlib).

Plotting lives only here; the rest of roboisf never imports plotly or matplotlib. The input is the
data contract of :mod:`roboisf.report.schema` (mm, deg, N, N·m, s).
"""

from roboisf.report.document import (
    FIGURES,
    HTML_FIGURES,
    figure_ids,
    read_headline,
    write_index,
    write_report,
)
from roboisf.report.schema import (
    CONTRIBUTION_COLUMNS,
    CONTRIBUTION_ROWS,
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
)
from roboisf.report.style import FACTOR_COLORS, FACTOR_LABELS, RUN_COLORS

__all__ = [
    "CONTRIBUTION_COLUMNS",
    "CONTRIBUTION_ROWS",
    "FACTOR_COLORS",
    "FACTOR_LABELS",
    "FIGURES",
    "HTML_FIGURES",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "RUN_COLORS",
    "figure_ids",
    "read_headline",
    "write_index",
    "write_report",
]
