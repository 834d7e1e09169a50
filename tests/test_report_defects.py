"""Small defects of the report found by a new user (issue #30), each checked where it was."""

from __future__ import annotations

import numpy as np
import pytest

from report_fixtures import make_study, with_two_wall_angles
from roboisf.report import interactive as ia
from roboisf.report import static as st
from roboisf.report.document import _thickness_caption
from roboisf.report.model_check import check_tables
from roboisf.report.schema import check_contributions


@pytest.fixture(scope="module")
def small():
    return make_study(n_laps=30, points_per_lap=40)


def _near_equal_bars(contrib):
    """Neighbouring bars of nearly the same height: the labels sit side by side (the table
    checked and indexed by factor, as the report draws it)."""
    c = check_contributions(contrib, name="contributions").copy()
    c["R_m"] = [1.134, 1.132, 1.134, 1.132, 2.0]
    return c


def test_static_bar_labels_do_not_run_into_each_other(small):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    _, contrib, _, _ = small
    c = _near_equal_bars(contrib)
    fig = st.contributions_png(c, c)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in fig.axes:
        boxes = [t.get_window_extent(renderer) for t in ax.texts]
        assert len(boxes) == 8
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                assert not boxes[i].overlaps(boxes[j]), (ax.texts[i], ax.texts[j])


def test_plotly_axis_titles_have_no_literal_underscore(small):
    _, contrib, _, _ = small
    c = check_contributions(contrib, name="c")
    fig = ia.contributions_figure(c, c).to_go()
    titles = [fig.layout[k].title.text for k in fig.layout if k.startswith("yaxis")]
    assert "R<sub>m</sub> (mm)" in titles and not any("R_m" in (t or "") for t in titles)


def test_thickness_caption_promises_a_band_only_when_there_is_one(small):
    pp = small[0].copy()
    varying = _thickness_caption(pp, True)
    assert "5–95 % band" in varying
    pp["thickness_measured"] = pp.groupby("lap")["thickness_measured"].transform("mean")
    flat = _thickness_caption(pp, True)
    assert "5–95 %" not in flat and "no band" in flat
    assert "no measured thickness" in _thickness_caption(pp, False)


def test_thickness_caption_explains_the_rise_at_the_rim(small):
    pp = small[0].copy()
    assert "rim" not in _thickness_caption(pp, True)  # a constant wall angle: nothing to say
    first = pp["lap"] == pp["lap"].min()
    pp.loc[first, "thickness_predicted"] = 1.0  # the rounding into the rim: wall flatter
    assert "rounding into the rim" in _thickness_caption(pp, True)
    # a first lap at the sheet plane, a hair above it: "depth 0.0 mm", not "-0.0"
    pp["depth"] = pp["depth"] - pp.loc[pp["lap"] == pp["lap"].min(), "depth"].mean() - 1e-4
    assert "(depth 0.0 mm)" in _thickness_caption(pp, True)


def _ident(mode):
    return {
        "identification": {
            "mode": mode,
            "K": [1.0e6] * 6,
            "ci_low": [0.9e6] * 6,
            "ci_high": [1.1e6] * 6,
            "K_nominal": [2.0e6] * 6,
            "identified_joints": [2],
            "observability": "joints not separable (identified alone: [2])",
        }
    }


def test_scale_mode_does_not_call_joints_separately_identified():
    html = check_tables(_ident("scale"))
    assert ">yes<" not in html and ">no<" not in html
    assert html.count("common scale") == 6 and html.count("(alone: yes)") == 1
    per_joint = check_tables(_ident("joints"))
    assert per_joint.count(">yes<") == 1 and per_joint.count(">no<") == 5


def test_top_view_caption_names_the_sparse_corners(small, tmp_path):
    from roboisf.report import write_report

    pp, c, cn, s = small
    text = write_report(pp, c, cn, s, tmp_path, png=False).read_text(encoding="utf-8")
    block = text[text.index('id="figure-deviation_top"') :]
    cap = block[block.index("<figcaption>") : block.index("</figcaption>")]
    assert "scan holes" in cap and "corners" in cap and "subset leaves out" in cap
    assert np.isfinite(pp["thickness_predicted"]).all()


def test_thickness_shows_each_laps_spread_when_walls_differ_in_angle():
    """On a part with two wall angles the thickness figure drew the lap mean of the sine law
    alone (0.69 mm, a thickness no wall has): the band from the thinnest to the thickest wall
    of each lap is drawn beside it, named in the legend with the walls' angles, in both
    renderers; a part whose laps keep one angle draws no band."""
    from matplotlib.collections import PolyCollection

    from roboisf.report import aggregate as agg

    pp = with_two_wall_angles(make_study(n_laps=30, points_per_lap=40, shape="pyramid")[0])
    spread = agg.thickness_spread(pp)
    assert spread is not None
    assert spread.low == pytest.approx(1.22 * np.cos(np.radians(65.0)))
    assert spread.high == pytest.approx(1.22 * np.cos(np.radians(45.0)))
    assert (spread.angle_low, spread.angle_high) == (45.0, 65.0)
    assert "45°–65° walls" in spread.label

    fig = ia.thickness_figure(pp)  # HTML: the band's two edges, its legend entry once
    band = [t for t in fig.data if t.get("legendgroup") == "spread"]
    assert len(band) == 2 and sum(bool(t.get("showlegend")) for t in band) == 1
    assert np.asarray(band[0]["y"]) == pytest.approx(spread.high, abs=1e-6)
    assert np.asarray(band[1]["y"]) == pytest.approx(spread.low, abs=1e-6)
    assert band[1]["fill"] == "tonexty" and band[1]["name"] == spread.label
    names = [t.get("name") for t in fig.data if t.get("showlegend", True)]
    assert "predicted (sine law), lap mean" in names

    png = st.thickness_png(pp)  # PNG: a filled band with its legend entry
    ax = png.axes[0]
    fills = [
        c
        for c in ax.collections
        if isinstance(c, PolyCollection) and not c.get_label().startswith("_")
    ]  # the measured thickness' 5–95 % band has no legend entry
    assert [c.get_label() for c in fills] == [spread.label]
    ys = fills[0].get_paths()[0].vertices[:, 1]
    assert ys.min() == pytest.approx(spread.low.min()) and ys.max() == pytest.approx(
        spread.high.max()
    )
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert spread.label in legend and "predicted (sine law), lap mean" in legend
    assert "differ in angle (45° to 65°)" in _thickness_caption(pp, True)

    cone = make_study(n_laps=30, points_per_lap=40)[0]  # one wall angle per lap
    assert agg.thickness_spread(cone) is None
    assert not [t for t in ia.thickness_figure(cone).data if t.get("legendgroup") == "spread"]
    labels = [c.get_label() for c in st.thickness_png(cone).axes[0].collections]
    assert not any("thinnest" in label for label in labels)
    assert "differ in angle" not in _thickness_caption(cone, True)


def test_a_study_without_a_contour_height_reports_the_middle_of_the_analysed_wall(
    small_cone_study, small_cone_analysis
):
    # the virtual study no longer writes the paper's z = -11 mm, which lies in the rim band the
    # analysis leaves out: the report then said "the requested z = -11.00 mm" of a height nobody
    # had asked for. With none asked, summary.json gives the middle of the analysed wall — the
    # lap the report shows, without a note
    from roboisf.report import aggregate as agg

    assert "contour_z" not in (small_cone_study / "study.toml").read_text()
    assert small_cone_analysis.study.analysis.contour_z is None
    pp = small_cone_analysis.per_point
    used = pp.loc[pp["used"].to_numpy(dtype=bool), "contact_z"].to_numpy(dtype=float)
    cz = small_cone_analysis.summary.contour_z
    assert cz == pytest.approx((used.max() + used.min()) / 2, abs=1e-9)
    assert -small_cone_analysis.study.analysis.rim_band * 1e3 > cz
    _, z, note = agg.contour_lap(pp, cz)
    assert note is None and abs(z - cz) < 1.0
