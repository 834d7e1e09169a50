"""The static (PNG) figures have a fixed layout (issue #16: one draw per figure instead of
constrained layout's measuring draw + drawing draw). These tests guard what constrained layout
used to guarantee: no text is cut off at the figure's edge and no axes' labels run into another
axes' labels, for every figure of the report, round part and not."""

from __future__ import annotations

import contextlib
from itertools import combinations

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from report_fixtures import make_study
from roboisf.report import document as doc
from roboisf.report import static as st
from roboisf.report.schema import check_contributions, check_per_point, check_summary


@pytest.fixture(scope="module")
def figures():
    pp, c, cn, summary = make_study(n_laps=40, points_per_lap=60)
    pp = check_per_point(pp)
    c, cn = check_contributions(c, name="c"), check_contributions(cn, name="cn")
    s = check_summary(summary)
    figs = doc._figures(pp, c, cn, s["contour_z"], True)
    figs["vjm_contour"] = doc._figures(pp, c, cn, s["contour_z"], False)["vjm_contour"]
    return figs


def _drawn(fig: Figure) -> FigureCanvasAgg:
    fig.set_dpi(st.DPI)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas


def _axis_texts(ax: Axes) -> list[Text]:
    texts: list[Text] = [ax.title, ax._left_title, ax._right_title]  # type: ignore[attr-defined]
    for axis in (ax.xaxis, ax.yaxis):
        texts.append(axis.label)
        for tick in axis._update_ticks():  # the ticks drawn (within the view limits)
            texts += [tick.label1, tick.label2]
    return [t for t in texts if t.get_visible() and t.get_text().strip()]


def _extent(t: Text, renderer) -> Bbox:
    return t.get_window_extent(renderer)


@pytest.mark.parametrize(
    "fid", [*doc.FIGURES, "vjm_contour"], ids=lambda f: f if isinstance(f, str) else ""
)
def test_no_text_cut_off_or_overlapping(figures, fid):
    fig = figures[fid].png()
    assert fig.get_layout_engine() is None  # fixed layout: savefig draws once
    renderer = _drawn(fig).get_renderer()
    W, H = fig.bbox.width, fig.bbox.height
    texts = [*fig.texts, *(t for leg in fig.legends for t in leg.get_texts())]
    for ax in fig.axes:
        texts += [*_axis_texts(ax), *ax.texts]
        if ax.get_legend() is not None:
            texts += ax.get_legend().get_texts()
    texts = [t for t in texts if t.get_visible() and t.get_text().strip()]
    assert len(texts) > 5
    for t in texts:
        bb = _extent(t, renderer)
        assert bb.x0 >= -1 and bb.y0 >= -1 and bb.x1 <= W + 1 and bb.y1 <= H + 1, (
            fid,
            t.get_text(),
            bb.bounds,
            (W, H),
        )
    # decorations of different axes (colorbars are axes too) must not overlap
    groups = [[_extent(t, renderer) for t in _axis_texts(ax)] for ax in fig.axes]
    groups.append([_extent(t, renderer) for t in (fig._suptitle,) if t is not None])  # type: ignore[attr-defined]
    groups.append([leg.get_window_extent(renderer) for leg in fig.legends])
    for a, b in combinations(range(len(groups)), 2):
        for ba in groups[a]:
            for bb in groups[b]:
                ov = Bbox.intersection(ba, bb)
                assert ov is None or ov.width < 1 or ov.height < 1, (fid, a, b, ba, bb)
    # and no axes' texts run into another axes' plotting area
    for i, ax in enumerate(fig.axes):
        box = ax.get_window_extent(renderer)
        for j, g in enumerate(groups[: len(fig.axes)]):
            if j == i:
                continue
            for bb in g:
                ov = Bbox.intersection(box, bb)
                assert ov is None or ov.width < 2 or ov.height < 2, (fid, i, j, bb)


def test_save_png_draws_each_figure_once(figures, tmp_path, monkeypatch):
    calls = []
    draw = Figure.draw

    def counting(self, renderer):
        calls.append(self)
        return draw(self, renderer)

    monkeypatch.setattr(Figure, "draw", counting)
    for fid, spec in figures.items():
        calls.clear()
        path = st.save_png(spec.png(), tmp_path / f"{fid}.png")
        assert len(calls) == 1, fid
        data = path.read_bytes()
        w, h = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
        fig = spec.png()
        assert (w, h) == tuple(np.round(fig.get_size_inches() * st.DPI).astype(int)), fid


def test_reductions_shared_between_renderers_change_nothing(tmp_path, monkeypatch):
    # issue #16: inside write_report each reduction (lap profiles, maps, contours) is computed
    # once and drawn by both renderers; the report must be the very same bytes as when every
    # figure computes its own, and the reductions must actually be shared
    from roboisf.report import aggregate as agg
    from roboisf.report import write_report

    study = make_study(n_laps=20, points_per_lap=40)
    # shared: within reused(), a second identical call returns the same object
    with agg.reused():
        pp = study[0]
        assert agg.lap_profile(pp, ["cnc_dn"]) is agg.lap_profile(pp, ["cnc_dn"])
        assert agg.lap_map(pp, "robot_dn") is agg.lap_map(pp, "robot_dn")
        assert agg.lap_profile(pp, ["cnc_dn"]) is not agg.lap_profile(pp, ["robot_dn"])
    assert agg.lap_profile(pp, ["cnc_dn"]) is not agg.lap_profile(pp, ["cnc_dn"])  # outside
    shared = write_report(*study, tmp_path / "shared", png=True)
    monkeypatch.setattr(agg, "reused", _no_reuse)
    own = write_report(*study, tmp_path / "own", png=True)
    assert shared.read_bytes() == own.read_bytes()
    for fid in doc.FIGURES:
        a = (shared.parent / "figures" / f"{fid}.png").read_bytes()
        b = (own.parent / "figures" / f"{fid}.png").read_bytes()
        assert a == b, fid


@contextlib.contextmanager
def _no_reuse():
    yield
