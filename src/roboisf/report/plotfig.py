"""The report's interactive figures as plain plotly JSON, without plotly's figure objects.

``plotly.graph_objects`` checks every property against the schema as it is set, and its
``make_subplots`` / ``update_xaxes`` walk property paths one by one: on the paper cone that was
~0.5 CPU-s of every report (~0.65 s for its eleven figures' HTML, of which building the objects
is most), on the critical path of ``roboisf analyze`` (the report is written after the scans).
The figures here are the same JSON built as dicts (:class:`Figure`, the few methods the report
uses, with plotly's semantics), and handed to ``plotly.io.to_html`` unvalidated.

What plotly's objects did on the way and this module does itself:

* the subplot grid of ``make_subplots`` (:func:`subplots`: its domain arithmetic, axis anchors,
  shared axes and subplot-title annotations, for the plain grids the report uses);
* ``None`` means "not set" (dropped), named colour scales are expanded (:func:`colorscale`;
  plotly.js does not know ``"RdBu_r"``), ``template="none"`` is the template of that name, and
  numpy arrays become plotly.js typed arrays (base64, plotly's own ``convert_to_base64``);
* ``update_xaxes(title_text=...)``: ``title_text`` is ``title.text``; dicts merge, other values
  replace.

tests/test_report_plotfig.py checks the grids against ``make_subplots`` bit for bit and every
report figure against plotly's validation (``Figure.to_go``).
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Mapping, Sequence
from typing import Any

__all__ = ["Figure", "colorscale", "subplots", "trace"]


def trace(kind: str, **props: Any) -> dict[str, Any]:
    """A trace of plotly type ``kind`` ("scatter", "heatmap", …) with ``props``."""
    return {"type": kind, **props}


@functools.cache
def _colorscale(name: str) -> tuple[tuple[float, str], ...]:
    from _plotly_utils.basevalidators import ColorscaleValidator

    scale = ColorscaleValidator("colorscale", "heatmap").validate_coerce(name)
    return tuple((float(a), str(b)) for a, b in scale)


def colorscale(name: str) -> list[list[Any]]:
    """The named colour scale (plotly's names, ``_r`` reversed) as plotly's validator expands
    it: ``[[0.0, "rgb(…)"], …]``."""
    return [[a, b] for a, b in _colorscale(name)]


#: plotly's template "none" — the report's (``style.py``) — as
#: ``plotly.io.templates["none"].to_plotly_json()`` gives it (tests/test_report_plotfig.py
#: compares the two on the installed plotly). Built through ``plotly.io`` it cost every report
#: 71 imported modules and 30–40 ms (docs/speed.md), in the serial tail of ``roboisf analyze``.
_TEMPLATE_NONE: dict[str, Any] = {"data": {"scatter": [{"type": "scatter"}]}}


@functools.cache
def _template(name: str) -> dict[str, Any]:
    if name == "none":
        return copy.deepcopy(_TEMPLATE_NONE)
    import plotly.io as pio

    return dict(pio.templates[name].to_plotly_json())


def _merge(into: dict[str, Any], props: Mapping[str, Any]) -> None:
    """plotly's ``update``: a dict merges into a dict, anything else replaces."""
    for k, v in props.items():
        if isinstance(v, Mapping) and isinstance(into.get(k), dict):
            _merge(into[k], v)
        else:
            into[k] = copy.deepcopy(v) if isinstance(v, (Mapping, list)) else v


def _magic(props: Mapping[str, Any]) -> dict[str, Any]:
    """``title_text=`` → ``title={"text": …}`` (the one magic underscore the report uses)."""
    out: dict[str, Any] = {}
    for k, v in props.items():
        if k == "title_text":
            _merge(out, {"title": {"text": v}})
        else:
            out[k] = v
    return out


def _clean(value: Any) -> Any:
    """``None`` dropped (plotly's "not set"), tuples as lists, recursively."""
    if isinstance(value, Mapping):
        return {k: _clean(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


class Figure:
    """A figure as ``data`` (list of trace dicts) and ``layout`` (dict): the part of
    ``plotly.graph_objects.Figure``'s interface the report uses, with its semantics."""

    def __init__(self, layout: Mapping[str, Any] | None = None) -> None:
        self.data: list[dict[str, Any]] = []
        self.layout: dict[str, Any] = {}
        self._cols = 0  # the subplot grid's columns (0: no grid)
        if layout:
            self.update_layout(layout)

    def add_trace(
        self, t: Mapping[str, Any], row: int | None = None, col: int | None = None
    ) -> None:
        """Append trace ``t``; with ``row``/``col`` (1-based) on that subplot's axes."""
        t = dict(t)
        if row is not None and col is not None:
            k = self._subplot(row, col)
            t["xaxis"], t["yaxis"] = f"x{k or ''}", f"y{k or ''}"
        self.data.append(t)

    def _subplot(self, row: int, col: int) -> int:
        if not self._cols:
            raise ValueError("row/col given for a figure without subplots")
        k = (row - 1) * self._cols + col
        return 0 if k == 1 else k

    def _axes(self, letter: str, row: int | None, col: int | None) -> list[str]:
        if row is not None and col is not None:
            k = self._subplot(row, col)
            return [f"{letter}axis{k or ''}"]
        keys = [k for k in self.layout if k == f"{letter}axis" or k.startswith(f"{letter}axis")]
        return keys or [f"{letter}axis"]

    def update_xaxes(self, row: int | None = None, col: int | None = None, **props: Any) -> None:
        """Merge ``props`` into the x axis of subplot (row, col), or into every x axis."""
        for key in self._axes("x", row, col):
            _merge(self.layout.setdefault(key, {}), _magic(props))

    def update_yaxes(self, row: int | None = None, col: int | None = None, **props: Any) -> None:
        """Merge ``props`` into the y axis of subplot (row, col), or into every y axis."""
        for key in self._axes("y", row, col):
            _merge(self.layout.setdefault(key, {}), _magic(props))

    def update_layout(self, layout: Mapping[str, Any] | None = None, **props: Any) -> None:
        """Merge ``layout`` and ``props`` into the layout."""
        for part in (layout or {}, props):
            for k, v in _magic(part).items():
                if k == "template" and isinstance(v, str):
                    v = _template(v)  # replaces, as plotly does with a named template
                    self.layout[k] = copy.deepcopy(v)
                    continue
                _merge(self.layout, {k: v})

    def update_annotations(self, **props: Any) -> None:
        """Merge ``props`` into every annotation."""
        for a in self.layout.get("annotations", []):
            _merge(a, props)

    def to_plotly_json(self) -> dict[str, Any]:
        """``{"data": […], "layout": {…}}`` as plotly.js reads it (numpy arrays as typed
        arrays); a new dict, the figure unchanged."""
        from _plotly_utils.utils import convert_to_base64

        out = {"data": _clean(self.data), "layout": _clean(self.layout)}
        convert_to_base64(out)
        return out

    def to_go(self) -> Any:
        """This figure as a ``plotly.graph_objects.Figure`` — validated (for tests and
        interactive use; the report does not need it)."""
        import plotly.graph_objects as go

        return go.Figure({"data": _clean(self.data), "layout": _clean(self.layout)})


def subplots(
    rows: int,
    cols: int,
    titles: Sequence[str],
    *,
    horizontal_spacing: float,
    vertical_spacing: float,
    shared_xaxes: bool = False,
    shared_yaxes: bool = False,
    title_font: Mapping[str, Any] | None = None,
) -> Figure:
    """``plotly.subplots.make_subplots(rows, cols, subplot_titles=titles, …)`` for a plain grid
    (start top-left, equal widths and heights, no spans, no insets): its axis domains with its
    arithmetic, anchors, shared axes (``matches`` and hidden tick labels: x shared down each
    column, matched to the bottom row's; y along each row, matched to the first column's) and
    title annotations (``title_font`` instead of its 16 pt)."""
    widths = [(1.0 - horizontal_spacing * (cols - 1)) / cols] * cols
    heights = [(1.0 - vertical_spacing * (rows - 1)) / rows] * rows
    fig = Figure()
    fig._cols = cols
    layout: dict[str, Any] = {}
    domains: list[tuple[list[float], list[float]]] = []
    for r in range(rows):
        # make_subplots' grid for start_cell "top-left": row r's start from the bottom
        rr = rows - 1 - r
        y0 = sum(heights[:rr]) + rr * vertical_spacing
        y1 = y0 + heights[-1 - r]
        y_s, y_e = min(max(y0, 0.0), 1.0), min(max(y1, 0.0), 1.0)
        for c in range(cols):
            x_s = sum(widths[:c]) + c * horizontal_spacing
            x_e = x_s + widths[c]
            k = r * cols + c + 1
            s = "" if k == 1 else str(k)
            layout[f"xaxis{s}"] = {"anchor": f"y{s}", "domain": [x_s, x_e]}
            layout[f"yaxis{s}"] = {"anchor": f"x{s}", "domain": [y_s, y_e]}
            domains.append(([x_s, x_e], [y_s, y_e]))
    if shared_xaxes:
        for c in range(cols):
            bottom = (rows - 1) * cols + c + 1
            first = "x" if bottom == 1 else f"x{bottom}"
            for r in range(rows - 1):
                k = r * cols + c + 1
                layout[f"xaxis{'' if k == 1 else k}"].update(matches=first, showticklabels=False)
    if shared_yaxes:
        for r in range(rows):
            k0 = r * cols + 1
            first = "y" if k0 == 1 else f"y{k0}"
            for c in range(1, cols):
                k = r * cols + c + 1
                layout[f"yaxis{k}"].update(matches=first, showticklabels=False)
    font = dict(title_font) if title_font is not None else {"size": 16}
    layout["annotations"] = [
        {
            "font": dict(font),
            "showarrow": False,
            "text": text,
            "x": sum(x) / 2.0,
            "xanchor": "center",
            "xref": "paper",
            "y": y[1],
            "yanchor": "bottom",
            "yref": "paper",
        }
        for text, (x, y) in zip(titles, domains, strict=False)
        if text
    ]
    fig.layout = layout
    return fig
