"""The study report: a self-contained offline HTML page (plotly) and static PNGs (matplotlib).

Plotting lives only here; the rest of roboisf never imports plotly or matplotlib. The input is the
data contract of :mod:`roboisf.report.schema` (mm, deg, N, N·m, s).

The names below are loaded on first use (PEP 562): importing a light submodule — the history
rows of :mod:`roboisf.report.iterations`, the page helpers, the schema — does not import
matplotlib and plotly (≈ 0.4–0.5 s), which ``roboisf analyze`` loads beside the scan comparison
instead of before it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

#: public name → the submodule that defines it
_LAZY = {
    "FIGURES": "document",
    "HTML_FIGURES": "document",
    "figure_ids": "document",
    "read_headline": "document",
    "write_index": "document",
    "write_report": "document",
    "CONTRIBUTION_COLUMNS": "schema",
    "CONTRIBUTION_ROWS": "schema",
    "OPTIONAL_COLUMNS": "schema",
    "REQUIRED_COLUMNS": "schema",
    "FACTOR_COLORS": "style",
    "FACTOR_LABELS": "style",
    "RUN_COLORS": "style",
}

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
assert sorted(__all__) == sorted(_LAZY)


def __getattr__(name: str) -> Any:
    sub = _LAZY.get(name)
    if sub is None:  # a submodule (``from roboisf.report import static``) is imported as usual
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{sub}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
