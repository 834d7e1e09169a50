"""The report's plotly figures as plain JSON (roboisf.report.plotfig): the subplot grids are
make_subplots' bit for bit, and every figure is what plotly's own validation makes of it —
valid, and unchanged by it (no property it would coerce, drop or reject)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from plotly.subplots import make_subplots

from report_fixtures import make_study, with_two_wall_angles
from roboisf.report import interactive as ia
from roboisf.report import plotfig as pf
from roboisf.report.document import FIGURES
from roboisf.report.schema import check_contributions


def _layout(d: dict) -> dict:
    return {k: v for k, v in d.items() if k != "template"}


@pytest.mark.parametrize(
    "rows, cols, hspace, vspace, shared",
    [
        (1, 2, 0.09, 0.0, {}),
        (2, 2, 0.09, 0.2, {"shared_xaxes": True}),
        (1, 2, 0.09, 0.0, {"shared_yaxes": True}),
        (3, 1, 0.09, 0.13, {"shared_xaxes": True}),
        (1, 2, 0.2, 0.0, {}),
        (3, 4, 0.05, 0.07, {"shared_xaxes": True, "shared_yaxes": True}),
    ],
)
def test_subplot_grids_are_make_subplots(rows, cols, hspace, vspace, shared):
    titles = [f"t{k}" if k != 2 else "" for k in range(rows * cols)]  # an untitled one too
    ref = make_subplots(
        rows=rows,
        cols=cols,
        subplot_titles=titles,
        horizontal_spacing=hspace,
        vertical_spacing=vspace,
        **shared,
    )
    ours = pf.subplots(
        rows, cols, titles, horizontal_spacing=hspace, vertical_spacing=vspace, **shared
    )
    assert _layout(ours.to_plotly_json()["layout"]) == _layout(ref.layout.to_plotly_json())
    for r in range(1, rows + 1):
        for c in range(1, cols + 1):
            ref.add_trace({"type": "scatter", "x": [1]}, row=r, col=c)
            ours.add_trace({"type": "scatter", "x": [1]}, row=r, col=c)
    assert ours.to_plotly_json()["data"] == [t.to_plotly_json() for t in ref.data]


def test_figure_updates_follow_plotly():
    fig = pf.Figure(layout={"xaxis": {"title": {"standoff": 8}}, "template": "none"})
    fig.update_xaxes(title_text="depth (mm)", range=[0, 1])
    fig.update_layout({"legend": {"x": 0}}, legend={"y": 1.0}, hovermode="closest")
    ref = {"title": {"standoff": 8, "text": "depth (mm)"}, "range": [0, 1]}
    assert fig.layout["xaxis"] == ref  # merged, not replaced
    assert fig.layout["legend"] == {"x": 0, "y": 1.0}
    assert fig.to_go().to_plotly_json()["layout"] == fig.to_plotly_json()["layout"]
    fig.add_trace(pf.trace("scatter", x=np.arange(3.0), fillcolor=None, line={"dash": None}))
    (t,) = fig.to_plotly_json()["data"]
    assert "fillcolor" not in t and t["line"] == {}  # None: not set
    assert t["x"]["dtype"] == "f8" and "bdata" in t["x"]  # a typed array, as plotly writes it
    with pytest.raises(ValueError, match="without subplots"):
        fig.add_trace(pf.trace("scatter"), row=1, col=1)


def test_named_colour_scales_are_expanded():
    scale = pf.colorscale("RdBu_r")
    assert scale[0] == [0.0, "rgb(5,48,97)"] and scale[-1][0] == 1.0  # reversed RdBu
    assert pf.colorscale("RdBu")[0][1] == scale[-1][1]


@pytest.fixture(scope="module")
def figures():
    pp, contrib, contrib_n, _ = make_study(n_laps=30, points_per_lap=40)
    c, cn = check_contributions(contrib, name="c"), check_contributions(contrib_n, name="n")
    return {
        "contributions": ia.contributions_figure(c, cn),
        "forces": ia.forces_figure(pp),
        "deviation_depth": ia.deviation_depth_figure(pp),
        "deviation_map": ia.deviation_map_figure(pp),
        "deviation_top": ia.deviation_top_figure(pp),
        "factors_depth": ia.factors_depth_figure(pp),
        "vjm_path": ia.vjm_path_figure(pp),
        "vjm_polar": ia.vjm_polar_figure(pp, -11.0)[0],
        "vjm_contour": ia.vjm_contour_figure(pp, -11.0)[0],
        "thickness": ia.thickness_figure(pp),
        "part_3d": ia.part_figure(pp),
        # walls of two angles: the thickness' thinnest–thickest band
        "thickness_two_walls": ia.thickness_figure(
            with_two_wall_angles(make_study(n_laps=30, points_per_lap=40, shape="pyramid")[0])
        ),
    }


@pytest.mark.parametrize("name", [*FIGURES, "vjm_contour", "part_3d", "thickness_two_walls"])
def test_every_report_figure_is_valid_and_unchanged_by_plotly(figures, name):
    fig = figures[name]
    ours = fig.to_plotly_json()
    validated = fig.to_go().to_plotly_json()  # raises on a property plotly does not know
    assert json.dumps(ours, sort_keys=True) == json.dumps(validated, sort_keys=True)


@pytest.mark.parametrize("name", ["none", "plotly_white"])
def test_a_named_template_is_plotlys(name):
    """The template "none" is a constant here (plotly.io's 71 modules not imported for it);
    any template is what plotly.io gives, key order included (the report's bytes)."""
    import plotly.io as pio

    want = dict(pio.templates[name].to_plotly_json())
    got = pf._template(name)
    assert got == want
    assert json.dumps(got) == json.dumps(want)
