"""The static (PNG) figures have a fixed layout (issue #16: one draw per figure instead of
constrained layout's measuring draw + drawing draw). These tests guard what constrained layout
used to guarantee: no text is cut off at the figure's edge and no axes' labels run into another
axes' labels, for every figure of the report, round part and not."""

from __future__ import annotations

import contextlib
import dataclasses
from itertools import combinations

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from report_fixtures import make_study, with_two_wall_angles
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
    walls = with_two_wall_angles(make_study(n_laps=40, points_per_lap=60, shape="pyramid")[0])
    figs["thickness_two_walls"] = dataclasses.replace(
        figs["thickness"], png=lambda: st.thickness_png(walls)
    )
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
    "fid",
    [*doc.FIGURES, "vjm_contour", "thickness_two_walls"],
    ids=lambda f: f if isinstance(f, str) else "",
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


#: Least clear space between two tick labels [pt]: more than a word space at the figures' tick
#: size (2.9 pt at 9 pt), so "100" of one axes and "0" of the next do not read as "1000" (they
#: stood 2.2 pt apart).
TICK_GAP_PT = 4.0


def _tick_labels(fig: Figure) -> list[Text]:
    out: list[Text] = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for tick in axis._update_ticks():  # the ticks drawn (within the view limits)
                out += [t for t in (tick.label1, tick.label2) if t.get_visible()]
    return [t for t in out if t.get_text().strip()]


def _corners(t: Text, renderer, pad: float) -> np.ndarray:
    """The (4, 2) corners in pixels of the rectangle ``t`` covers, rotated with the text and
    grown by ``pad`` on every side: a rotated label's axis-aligned box covers its neighbour's
    even when the words stand apart."""
    bb = t.get_window_extent(renderer)
    W, H = bb.width, bb.height
    th = np.radians(t.get_rotation() % 180.0)
    c, s = abs(np.cos(th)), abs(np.sin(th))
    if abs(c - s) > 1e-3:  # W = w·c + h·s, H = w·s + h·c: the unrotated w, h
        w, h = np.linalg.solve([[c, s], [s, c]], [W, H])
    else:  # 45°: only w + h is known; the box itself is the safe side
        w, h, th = W, H, 0.0
    u = np.array([np.cos(th), np.sin(th)])
    v = np.array([-u[1], u[0]])
    half_u, half_v = (w / 2 + pad) * u, (h / 2 + pad) * v
    centre = np.array([(bb.x0 + bb.x1) / 2, (bb.y0 + bb.y1) / 2])
    return np.array([centre + a + b for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))
                     for a, b in [(a * half_u, b * half_v)]])  # fmt: skip


def _polygons_overlap(p: np.ndarray, q: np.ndarray) -> bool:
    """Separating-axis test of two convex quadrilaterals (4, 2)."""
    for poly in (p, q):
        for k in range(4):
            edge = poly[(k + 1) % 4] - poly[k]
            axis = np.array([-edge[1], edge[0]])
            a, b = p @ axis, q @ axis
            if a.max() <= b.min() or b.max() <= a.min():
                return False
    return True


def tick_label_clashes(fig: Figure) -> list[tuple[str, str]]:
    """Pairs of tick labels (of any axes of ``fig``, colorbars and polar axes included) whose
    rectangles, each grown by half of :data:`TICK_GAP_PT` and turned with the text, overlap once
    drawn."""
    renderer = _drawn(fig).get_renderer()
    pad = TICK_GAP_PT / 2 * st.DPI / 72.0
    labels = _tick_labels(fig)
    quads = [_corners(t, renderer, pad) for t in labels]
    return [
        (labels[i].get_text(), labels[j].get_text())
        for i, j in combinations(range(len(labels)), 2)
        if _polygons_overlap(quads[i], quads[j])
    ]


def test_the_clash_check_sees_touching_labels_and_turned_ones_apart():
    """The check itself: two labels 1 pt apart clash, 10 pt apart do not; turned labels whose
    axis-aligned boxes overlap but whose words stand apart do not."""
    for gap_pt, clash in ((1.0, True), (10.0, False)):
        fig = Figure(figsize=(4, 2))
        ax = fig.add_axes((0.1, 0.3, 0.8, 0.6))
        ax.set_xlim(0, 4)
        renderer = _drawn(fig).get_renderer()
        w = ax.text(0, 0, "100").get_window_extent(renderer).width  # px at DPI
        ax.texts[0].remove()
        step = (w + gap_pt * st.DPI / 72.0) / ax.get_window_extent(renderer).width * 4
        ax.set_xticks([1, 1 + step], ["100", "100"])
        assert bool(tick_label_clashes(fig)) is clash, gap_pt
    fig = Figure(figsize=(4, 2))
    ax = fig.add_axes((0.1, 0.4, 0.8, 0.5))
    ax.set_xlim(0, 4)
    ax.set_xticks([1, 1.3], ["a long turned label", "a long turned label"], rotation=60)
    renderer = _drawn(fig).get_renderer()
    a, b = (t.get_window_extent(renderer) for t in ax.get_xticklabels())
    assert a.overlaps(b) and tick_label_clashes(fig) == []


@pytest.mark.parametrize(
    "fid",
    [*doc.FIGURES, "vjm_contour", "thickness_two_walls"],
    ids=lambda f: f if isinstance(f, str) else "",
)
def test_tick_labels_do_not_collide(figures, fid):
    """No two tick labels touch (the deviation map's "100" ran into the next panel's "0", the
    polar plot's radial labels 0.4, 0.5, 0.6 into each other)."""
    assert tick_label_clashes(figures[fid].png()) == [], fid
