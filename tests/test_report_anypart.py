"""Deviation maps, contour figure and report on any part: position along each lap (arc length),
the top view, the contour by arc length for parts that are not round — checked against the
geometry they come from (a circle's r·φ, a square's 8a) and written end to end for a pyramid."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from report_fixtures import make_study, square_lap
from roboisf.errors import InputError
from roboisf.parts import Cone
from roboisf.report import FIGURES, HTML_FIGURES, figure_ids, write_report
from roboisf.report import aggregate as agg
from roboisf.report import interactive as ia
from roboisf.report import static as st
from roboisf.scan import by_arc_length, lap_arc_length
from roboisf.toolpath import step_down

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# -- arc length along a lap ----------------------------------------------------------------------
@pytest.mark.parametrize(("start", "clockwise"), [(0.0, False), (3.5, False), (1.0, True)])
def test_arc_length_is_r_phi_on_the_cone(start, clockwise):
    """On a surface of revolution s = r·φ from the point nearest +x (φ counted in the path's
    sense), up to the chord error of the polyline, wherever the toolpath starts its laps."""
    tp = step_down(Cone(), 5e-3, 5e-3, spacing=2e-3, start_angle=start, clockwise=clockwise)
    s, length = lap_arc_length(tp.contact, tp.lap)
    x, y = tp.contact[:, 0], tp.contact[:, 1]
    sense = -1.0 if clockwise else 1.0
    r, phi = np.hypot(x, y), np.mod(sense * np.arctan2(y, x), 2 * np.pi)
    checked = 0
    for lap in np.unique(tp.lap):
        m = tp.lap == lap
        if np.ptp(tp.contact[m, 2]) > 1e-9 or m.sum() < 8:
            continue  # the step between laps, not a contour
        rl = r[m].mean()
        assert np.ptp(r[m]) < 1e-9 * rl
        ref = np.argmin(np.minimum(phi[m], 2 * np.pi - phi[m]))
        dphi = np.mod(phi[m] - phi[m][ref], 2 * np.pi)
        theta = np.max(np.abs(np.diff(np.unwrap(phi[m]))))  # largest chord angle
        chord_err = rl * dphi * theta**2 / 24 + 1e-12  # polyline vs arc, per unit angle
        closed = np.isclose(dphi, 0.0, atol=1e-9) | np.isclose(dphi, 2 * np.pi, atol=1e-9)
        ok = ~closed  # the lap's start point repeated at its end sits at s = 0 or L
        assert np.all(np.abs(s[m][ok] - rl * dphi[ok]) <= chord_err[ok])
        assert length[m][0] == pytest.approx(2 * np.pi * rl, rel=theta**2 / 24 + 1e-12)
        checked += 1
    assert checked >= 10


@pytest.mark.parametrize("clockwise", [False, True])
def test_arc_length_starts_at_plus_x_whatever_the_lap_start(clockwise):
    n, r = 360, 40.0
    phi = np.radians(200.0) + (-1 if clockwise else 1) * 2 * np.pi * np.arange(n) / n
    P = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.full(n, -30.0)])
    s, length = lap_arc_length(P, np.zeros(n, dtype=int))
    turned = np.mod((-1 if clockwise else 1) * (phi - 0.0), 2 * np.pi)  # φ from +x, path sense
    theta = 2 * np.pi / n
    expect = r * turned
    assert length[0] == pytest.approx(2 * n * r * math.sin(theta / 2), rel=1e-12)  # polygon
    assert np.argmin(s) == np.argmin(np.abs(np.angle(np.exp(1j * phi))))
    assert np.allclose(s, expect * (length[0] / (2 * np.pi * r)), atol=1e-9)


def test_arc_length_of_a_square_is_exact_and_per_lap():
    t = np.arange(16) / 16  # corners at t = 1/8, 3/8, 5/8, 7/8 are sample points
    x1, y1, _, _ = square_lap(np.full(16, 10.0), t)
    x2, y2, _, _ = square_lap(np.full(16, 5.0), t)
    P = np.column_stack([np.r_[x1, x2], np.r_[y1, y2], np.r_[np.full(16, -1.0), np.full(16, -2.0)]])
    s, length = lap_arc_length(P, np.repeat([3, 4], 16))
    assert length == pytest.approx(np.repeat([80.0, 40.0], 16))
    assert s == pytest.approx(np.r_[80.0 * t, 40.0 * t])


def test_arc_length_bad_shapes():
    with pytest.raises(InputError):
        lap_arc_length(np.zeros((4, 2)), np.zeros(4))
    s, length = lap_arc_length(np.zeros((0, 3)), np.zeros(0))
    assert s.size == 0 and length.size == 0
    s, length = lap_arc_length(np.ones((1, 3)), [0])  # a lap of one point
    assert s[0] == 0.0 and length[0] == 0.0


def test_by_arc_length_bins_the_contour():
    t = np.arange(80) / 80
    x, y, ex, ey = square_lap(np.full(80, 10e-3), t)
    P = np.column_stack([x, y, np.full(80, -11e-3)])
    s, _ = lap_arc_length(P, np.zeros(80, dtype=int))
    assert s == pytest.approx(np.arange(80) * 1e-3)  # 1 mm apart from (a, 0)
    dn = np.where(s < 40.5e-3, 1e-3, -2e-3)
    delta = dn[:, None] * np.column_stack([ex, ey, np.zeros(80)])
    tab = by_arc_length(s, P[:, 2], delta, dn, z_level=-11e-3, bin_width=20.25e-3)
    assert tab["s_lo"].to_numpy() == pytest.approx([0, 20.25e-3, 40.5e-3, 60.75e-3])
    assert tab["n"].tolist() == [21, 20, 20, 19]  # bin edges between samples
    assert tab["mean_dn"].to_numpy() == pytest.approx([1e-3, 1e-3, -2e-3, -2e-3])
    assert by_arc_length(s, P[:, 2] - 1e-3, delta, dn, z_level=-11e-3).empty
    with pytest.raises(InputError):
        by_arc_length(s, P[:, 2], delta, dn, bin_width=0.0)


# -- the maps ------------------------------------------------------------------------------------
def _two_laps(dense: int = 16) -> pd.DataFrame:
    """A dense lap (``dense`` points) and a sparse one (4 points) on circles, value = position."""
    rows = []
    for lap, n, r in ((0, dense, 20.0), (1, 4, 10.0)):
        u = np.arange(n) / n
        rows.append(
            pd.DataFrame(
                {
                    "lap": lap,
                    "depth": 1.0 + lap,
                    "contact_x": r * np.cos(2 * np.pi * u),
                    "contact_y": r * np.sin(2 * np.pi * u),
                    "contact_z": -1.0 - lap,
                    "cnc_dn": u,
                    "cnc_valid": True,
                }
            )
        )
    return pd.concat(rows, ignore_index=True)


def test_lap_map_means_dense_laps_and_fills_sparse_ones_from_the_nearest_point():
    f = _two_laps()
    m = agg.lap_map(f, "cnc_dn", n_bins=8)
    assert m.position == pytest.approx((np.arange(8) + 0.5) / 8)
    assert m.depth == pytest.approx([1.0, 2.0])
    chord = 2 * np.sin(np.pi / 16) * 16 * 20.0
    assert m.length == pytest.approx([chord, 2 * np.sin(np.pi / 4) * 4 * 10.0])
    # dense lap: two points per cell (u = 2k/16, (2k+1)/16) → their mean
    assert m.values[0] == pytest.approx((np.arange(8) * 2 + 0.5) / 16)
    # sparse lap: points at u = 0, .25, .5, .75 in cells 0, 2, 4, 6; the empty cells take the
    # nearest point, periodic (cell 7, centre 15/16, is nearest u = 0)
    assert m.values[1] == pytest.approx([0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 0.0])
    assert np.isfinite(m.values).all()


def test_lap_map_keeps_holes_blank():
    f = _two_laps()
    f.loc[(f["lap"] == 1) & (f["cnc_dn"] == 0.5), "cnc_valid"] = False
    f.loc[(f["lap"] == 0) & (f["cnc_dn"] < 0.1), "cnc_valid"] = False  # u = 0, 1/16: cell 0
    m = agg.lap_map(f, "cnc_dn", n_bins=8)
    assert np.isnan(m.values[0, 0]) and np.isfinite(m.values[0, 1:]).all()
    # the hole's own cell and the empty cell whose nearest point it is stay blank
    assert np.isnan(m.values[1, 4]) and np.isnan(m.values[1, 3])
    assert np.isfinite(np.delete(m.values[1], [3, 4])).all()


def test_lap_map_default_cells_follow_the_data():
    pp, *_ = make_study(n_laps=12, points_per_lap=50, shape="pyramid")
    m = agg.lap_map(pp, "cnc_dn")
    assert m.position.size == 50
    assert m.values.shape == (12, 50)
    holes = ~pp["cnc_valid"].to_numpy()
    assert np.isnan(m.values).sum() <= holes.sum()  # no empty-bin stripes, only holes
    for lap, g in pp.groupby("lap"):  # each lap's closed polyline, computed independently
        P = g[["contact_x", "contact_y", "contact_z"]].to_numpy()
        closed = np.vstack([P, P[:1]])
        assert m.length[lap] == pytest.approx(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())


def test_top_view_drops_holes_and_decimates():
    pp, *_ = make_study(n_laps=12, points_per_lap=50, shape="pyramid")
    v = agg.top_view(pp, "robot_dn", max_points=100)
    assert v.x.size == 100 and np.isfinite(v.values).all()
    assert np.array_equal(v.x, agg.top_view(pp, "robot_dn", max_points=100).x)  # reproducible
    full = agg.top_view(pp, "robot_dn")
    assert full.x.size == int(pp["robot_valid"].sum())


def test_is_round_dispatch():
    cone, *_ = make_study(n_laps=8, points_per_lap=40)
    pyr, *_ = make_study(n_laps=8, points_per_lap=40, shape="pyramid")
    assert agg.is_round(cone) and not agg.is_round(pyr)  # from the data
    assert not agg.is_round(cone, symmetry=4) and agg.is_round(pyr, symmetry=0)  # stated order
    assert agg.is_round(pyr, kind="cone") and not agg.is_round(pyr, kind="pyramid")
    assert agg.is_round(cone, kind="mesh") and not agg.is_round(pyr, kind="mesh")  # the data


def test_contour_along_a_square_lap():
    pp, *_ = make_study(n_laps=200, points_per_lap=64, shape="pyramid")  # 0.5 mm laps
    c = agg.contour_along(pp, contour_z=-30.0)
    lap = pp[pp["lap"] == c.lap]
    assert abs(c.z + 30.0) <= 0.5
    assert c.s[0] == 0.0 and c.s[-1] == pytest.approx(c.length) and np.all(np.diff(c.s) > 0)
    assert (c.x[0], c.y[0]) == (c.x[-1], c.y[-1])
    a = np.abs(lap["contact_x"]).max()
    assert c.length == pytest.approx(8 * a, rel=0.01)  # a touch of spiral within the lap
    assert c.x[0] == pytest.approx(a) and c.y[0] == pytest.approx(0.0, abs=1e-9)
    k = np.flatnonzero(np.isfinite(c.experiment))
    comps = [lap[f"robot_compliance_{ax}"].to_numpy() for ax in ("dx", "dy", "dz")]
    mags = np.sqrt(sum(v**2 for v in comps))
    assert np.sort(c.experiment[k][:-1]) == pytest.approx(np.sort(mags[np.isfinite(mags)]))


# -- figures and the report of a pyramid ---------------------------------------------------------
@pytest.fixture(scope="module")
def pyramid():
    return make_study(n_laps=40, points_per_lap=64, shape="pyramid", name="pyramid-71")


def test_pyramid_figures_build(pyramid):
    pp = pyramid[0]
    fig = ia.deviation_map_figure(pp).to_go()  # validated by plotly
    assert [t.type for t in fig.data] == ["heatmap", "heatmap"]
    assert np.asarray(fig.data[0].x).max() < 100.0
    top = ia.deviation_top_figure(pp).to_go()
    assert [t.type for t in top.data] == ["scatter", "scatter"]
    contour, caption = ia.vjm_contour_figure(pp, -11.0)
    assert len(contour.to_go().data) == 4 and "long" in caption
    for png in (st.deviation_map_png(pp), st.deviation_top_png(pp), st.vjm_contour_png(pp, -11)):
        assert len(png.axes) >= 2


@pytest.mark.parametrize("stated", [True, False])
def test_pyramid_report_written_with_the_contour_not_the_polar_plot(pyramid, tmp_path, stated):
    pp, contrib, contrib_n, summary = pyramid
    if not stated:  # no part_symmetry: the kind and the data decide
        summary = {k: v for k, v in summary.items() if k != "part_symmetry"}
    # the PNGs once: they are drawn for the same figure ids as the HTML's (write_report's
    # ``ids``), and drawing them is most of the test's time
    path = write_report(pp, contrib, contrib_n, summary, tmp_path, png=stated)
    text = path.read_text(encoding="utf-8")
    ids = figure_ids(False)
    assert "vjm_contour" in ids and "vjm_polar" not in ids and "deviation_top" in ids
    assert text.count("Plotly.newPlot(") == len(HTML_FIGURES) + len(ids)
    for fid in ids:
        assert text.count(f'id="fig-{fid}"') == 1, fid
        if stated:
            assert (tmp_path / "figures" / f"{fid}.png").read_bytes().startswith(PNG_MAGIC)
    assert 'id="fig-vjm_polar"' not in text and not (tmp_path / "figures/vjm_polar.png").exists()
    assert re.search(r"Contour at z = -1\d\.\d\d mm \(lap \d+, [\d.]+ mm long\)", text)


def test_cone_report_keeps_the_polar_plot(tmp_path):
    path = write_report(*make_study(n_laps=12, points_per_lap=40), tmp_path, png=False)
    text = path.read_text(encoding="utf-8")
    assert figure_ids(True) == FIGURES and "vjm_polar" in FIGURES
    assert 'id="fig-vjm_polar"' in text and 'id="fig-vjm_contour"' not in text
    assert 'id="fig-deviation_top"' in text


def test_bad_part_symmetry_refused(pyramid, tmp_path):
    pp, contrib, contrib_n, summary = pyramid
    with pytest.raises(InputError, match="part_symmetry"):
        write_report(pp, contrib, contrib_n, {**summary, "part_symmetry": -1}, tmp_path)
    assert not any(tmp_path.iterdir())
