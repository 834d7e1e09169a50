"""What the report states in words (issue #30): the study kind at the top, the numbers that hold
by construction, the analysed share and rim band, the diagnosis, the robot panel's reason, the
contour drawn where the data are, and the 3D view of the formed part."""

from __future__ import annotations

import re

import numpy as np
import pytest

from report_fixtures import make_study
from roboisf.report import aggregate as agg
from roboisf.report import interactive as ia
from roboisf.report import read_headline, write_report
from roboisf.report.statements import scope_sentence, study_kind, verdict_lines

TUNED = {"truth_source": "scenario paper (cone)", "model_equals_truth": False}


@pytest.fixture(scope="module")
def small():
    return make_study(n_laps=30, points_per_lap=40)


def _write(small, tmp_path, **summary_extra):
    pp, c, cn, s = small
    path = write_report(pp, c, cn, {**s, **summary_extra}, tmp_path, png=False)
    return path, path.read_text(encoding="utf-8")


def _banner(text: str) -> str:
    m = re.search(r'<div class="kind kind-(\w+)" id="study-kind">(.*?)</div>', text, flags=re.S)
    assert m, "no study-kind banner"
    return m.group(1) + ": " + m.group(2)


@pytest.mark.parametrize(
    ("truth", "kind", "words"),
    [
        (None, "measured", "Measured study."),
        ({"model_equals_truth": False, "truth_source": "soft.toml"}, "virtual", "Virtual cell."),
        (TUNED, "virtual_tuned", "tuned so this analysis reproduces the paper"),
    ],
)
def test_the_top_says_what_kind_of_study_it_is(small, tmp_path, truth, kind, words):
    extra = {} if truth is None else {"truth": truth}
    path, text = _write(small, tmp_path, **extra)
    banner = _banner(text)
    assert banner.startswith(kind + ":") and words in banner
    # before the headline cards: the first thing read
    assert text.index('id="study-kind"') < text.index('class="cards"')
    assert read_headline(path)["study_kind"] == kind


def test_tuned_shares_are_marked_by_construction_and_measured_are_not(small, tmp_path):
    _, measured = _write(small, tmp_path / "m")
    _, tuned = _write(small, tmp_path / "t", truth=TUNED)
    assert 'class="bc"' not in measured
    cards = tuned[tuned.index('class="cards"') : tuned.index('class="verdict"')]
    assert cards.count('class="bc"') == 2  # robot share and springback share
    assert 'Robot compliance share <span class="bc"' in cards


def test_model_check_by_construction_is_marked(small, tmp_path):
    check = {"ratio": 1.0, "ci_low": 0.99, "ci_high": 1.01, "verdict": "consistent"}
    _, plain = _write(small, tmp_path / "a", vjm_check=check)
    _, built = _write(small, tmp_path / "b", vjm_check={**check, "by_construction": True})
    assert 'class="bc"' not in plain and "model holds" in plain
    cards = built[built.index('class="cards"') : built.index('class="verdict"')]
    assert 'Robot model check <span class="bc"' in cards and "holds by construction" in cards
    # the estimate at the interval's precision: "0.997 (95 % [1.00, 1.00])" put it outside
    c = {**check, "ratio": 0.99696, "ci_low": 0.99601, "ci_high": 0.99904, "by_construction": True}
    _, built = _write(small, tmp_path / "c", vjm_check=c)
    assert "0.997 (95 % [0.996, 0.999])" in built


def test_scope_states_rim_band_share_and_points_beyond_the_distance(small, tmp_path):
    s = {
        "n_points": 5404,
        "n_points_used": 1616,
        "rim_band_mm": 20.0,
        "max_distance_mm": 5.0,
        "beyond_max_distance": {"cnc": {"n": 0, "of": 124474}, "robot": {"n": 37, "of": 124649}},
    }
    _, text = _write(small, tmp_path, **s)
    m = re.search(r'<p class="scope" id="analysis-scope">(.*?)</p>', text, flags=re.S)
    assert m
    line = m.group(1)
    assert "1616 of 5404 toolpath points analysed (30 %)" in line
    assert "the top 20.0 mm of depth left out" in line and "scan holes" in line
    assert "beyond the analysis distance (5 mm)" in line and "robot 37 of 124649 (0.0 %)" in line


def test_scope_falls_back_on_the_used_column(small):
    pp = small[0]
    used = (pp["depth"] > 10).to_numpy()
    text = scope_sentence({"rim_band_mm": 10.0}, len(pp), int(used.sum()))
    share = round(100 * used.mean())
    assert f"{int(used.sum())} of {len(pp)} toolpath points analysed ({share} %)" in text
    assert scope_sentence({}, len(pp), None) == ""


DIAG = [
    {
        "suspect": "force_bias",
        "verdict": "ok",
        "estimate": 0.4,
        "ci_low": -1.2,
        "ci_high": 2.0,
        "unit": "N",
        "explanation": "no constant offset between the runs",
    },
    {
        "suspect": "robot_stiffness",
        "verdict": "fault",
        "estimate": 0.5,
        "ci_low": 0.48,
        "ci_high": 0.52,
        "unit": "× nominal",
        "explanation": "the robot gives way twice as much as its model",
    },
    {
        "suspect": "scan_rotation",
        "verdict": "cannot_tell",
        "estimate": None,
        "ci_low": None,
        "ci_high": None,
        "unit": "deg",
        "explanation": "a round part hides a rotation about z",
    },
]


def test_diagnosis_rendered_faults_first_with_its_headline(small, tmp_path):
    head = "The robot is softer than its model (0.50× nominal stiffness)."
    _, text = _write(small, tmp_path, diagnosis=DIAG, diagnosis_headline=head)
    block = text[text.index('id="diagnosis"') :]
    assert head in block
    rows = re.findall(r'<tr class="v-(\w+)">', block)
    assert rows == ["fault", "cannot_tell", "ok"]
    assert "robot joint stiffness" in block and "0.500 [0.480, 0.520] × nominal" in block
    assert "cannot tell" in block and "— deg" in block  # no estimate: a dash, no 'None'
    assert "None" not in block[: block.index("</table>")]
    # near the top: before the first section
    assert text.index('id="diagnosis"') < text.index('<section id="contributions"')
    _, without = _write(small, tmp_path / "none")
    assert 'id="diagnosis"' not in without


def test_diagnosis_in_the_terminal_headline_or_one_line_per_fault():
    # the analysis' headline comes as its terminal line: said once, not "diagnosis: diagnosis:"
    s = {"study": "s", "diagnosis": DIAG, "diagnosis_headline": "diagnosis: robot 2x softer"}
    lines = verdict_lines(s)
    assert [ln for ln in lines if "diagnosis" in ln] == ["diagnosis: robot 2x softer"]
    s = {"study": "s", "diagnosis": {"headline": "Scan shifted 0.3 mm.", "entries": DIAG}}
    assert "diagnosis: Scan shifted 0.3 mm." in verdict_lines(s)
    lines = verdict_lines({"study": "s", "diagnosis": DIAG})  # no headline: one line each
    assert any(ln.startswith("diagnosis: robot joint stiffness — fault") for ln in lines)
    assert any("scan rotation — cannot tell" in ln for ln in lines)
    assert not any("force sensor bias" in ln for ln in lines)


def test_dimensionless_estimates_read_as_ratios_not_as_a_lone_1():
    """summary.json's unit "1" (SI for a pure number) shows as "×" for a ratio, "N/N" for a
    crosstalk and nothing for a fraction; it printed "3.105 [2.859, 4.252] 1"."""
    from roboisf.report.statements import _estimate

    def row(suspect):
        return {"suspect": suspect, "estimate": 3.105, "ci_low": 2.859, "ci_high": 4.252,
                "unit": "1"}  # fmt: skip

    assert _estimate(row("robot_stiffness")) == "3.105 [2.859, 4.252] ×"
    assert _estimate(row("force_gain")).endswith("] ×")
    assert _estimate(row("force_crosstalk")).endswith("] N/N")
    assert _estimate(row("springback_coupling")) == "3.105 [2.859, 4.252]"
    assert _estimate({**row("scan_shift"), "unit": "mm"}).endswith("] mm")


def test_report_shows_the_headline_without_its_terminal_prefix(small, tmp_path):
    _, text = _write(small, tmp_path, diagnosis=DIAG, diagnosis_headline="diagnosis: robot soft")
    assert '<p class="verdict" id="diagnosis-headline">robot soft</p>' in text


def test_study_kind_words():
    assert study_kind({}).kind == "measured"
    k = study_kind({"truth": {"model_equals_truth": True}})
    assert k.kind == "virtual" and "holds by construction" in k.sentence


def test_robot_panel_caption_gives_the_springback_coupling(small, tmp_path):
    coupling = {"coupling": 0.88, "depth_mm": 50.0}
    _, text = _write(small, tmp_path / "c", truth={**TUNED, "springback_coupling": coupling})
    cap = re.search(
        r'<figure id="figure-factors_depth">.*?<figcaption>(.*?)</figcaption>', text, re.S
    )
    assert cap and "c(depth) = 0.88·exp(−depth / 50 mm)" in cap.group(1)
    _, plain = _write(small, tmp_path / "p", truth=TUNED)
    cap = re.search(
        r'<figure id="figure-factors_depth">.*?<figcaption>(.*?)</figcaption>', plain, re.S
    )
    assert cap and "coupling" not in cap.group(1)


def test_contour_in_the_rim_band_shows_the_middle_of_the_analysed_wall(small, tmp_path):
    """The paper's contour height, z = −11 mm, lies inside the 20 mm rim band of a deep part:
    the figure showed the first lap below the band (a "fallback lap" at z ≈ −20 mm, where the
    rim's transition still shows). A height in the band, or none asked, gives the lap nearest
    the middle of the analysed wall, and the page says which height it shows and why."""
    pp = small[0].copy()  # 30 laps down to 103 mm
    z = pp.groupby("lap")["contact_z"].mean()
    lap, _, note = agg.contour_lap(pp, float(z.iloc[2]))
    assert lap == int(z.index[2]) and note is None  # no rim band: the lap asked for
    pp["used"] = (pp["depth"] > 20.0) & pp["cnc_valid"] & pp["robot_valid"]  # a 20 mm rim band
    cz = pp.loc[pp["used"], "contact_z"]
    middle = (cz.max() + cz.min()) / 2
    laps_used = z[pp.groupby("lap")["used"].any()]
    best = int((laps_used - middle).abs().idxmin())
    for asked in (-11.0, float(z.iloc[2]), None):
        lap, zl, note = agg.contour_lap(pp, asked)
        assert lap == best and zl == pytest.approx(z.loc[best]), asked
        assert note is not None and "middle of the analysed wall" in note, asked
        assert (asked is None) == ("no contour height was asked for" in note)
    assert "requested z = -11.00 mm" in agg.contour_lap(pp, -11.0)[2]
    assert "rim band" in agg.contour_lap(pp, -11.0)[2]
    # a height on the analysed wall is kept, whatever the middle
    deep = float(z.iloc[25])
    assert agg.contour_lap(pp, deep) == (int(z.index[25]), pytest.approx(deep), None)
    # a hole on the wall, not the band: the nearest lap with data, as before
    holed = pp.copy()
    holed.loc[holed["lap"] == int(z.index[25]), "robot_valid"] = False
    lap, _, note = agg.contour_lap(holed, deep)
    assert lap in (int(z.index[24]), int(z.index[26])) and f"lap {int(z.index[25])}" in note

    # the page: the caption and the study table name the lap shown and why
    _, c, cn, s = small
    path = write_report(pp, c, cn, {**s, "contour_z": -11.0}, tmp_path / "a", png=False)
    text = path.read_text(encoding="utf-8")
    block = text[text.index('<figure id="figure-vjm_polar">') :]
    cap = block[block.index("<figcaption>") : block.index("</figcaption>")]
    assert f"Contour at z = {z.loc[best]:.2f} mm (lap {best})" in cap
    assert "requested z = -11.00 mm" in cap and "middle of the analysed wall" in cap
    assert f"lap {best} at z = {z.loc[best]:.2f} mm (asked: z = -11 mm" in text
    s_none = {k: v for k, v in s.items() if k != "contour_z"}
    path = write_report(pp, c, cn, s_none, tmp_path / "b", png=False)
    text = path.read_text(encoding="utf-8")
    assert "no contour height was asked for" in text
    assert f"lap {best} at z = {z.loc[best]:.2f} mm (none asked" in text


def test_part_view_keeps_whole_laps_breaks_between_them_and_masks_holes(small):
    pp = small[0]  # 30 laps × 40 points
    view = agg.part_view(pp, max_points=500)
    assert view.lap_step == 3 and view.n_total == len(pp)  # 10 laps × 40 = 400 ≤ 500 < 15 × 40
    sep = np.isnan(view.x)
    assert sep.sum() == 9  # one break between consecutive laps kept
    assert (~sep).sum() == 400
    # the rows between breaks are whole laps, in toolpath order
    rows = np.split(np.arange(view.x.size), np.flatnonzero(sep))
    xs = pp["contact_x"].to_numpy()
    for k, r in enumerate(rows):
        r = r[~sep[r]]
        lap = pp["lap"].unique()[3 * k]
        np.testing.assert_array_equal(view.x[r], xs[pp["lap"].to_numpy() == lap])
    assert set(view.values) == {c for c, _ in agg.PART_VIEW_TERMS}
    full = agg.part_view(pp, max_points=len(pp))
    assert full.lap_step == 1
    holes = ~pp["robot_valid"].to_numpy()
    assert holes.any()
    keep = ~np.isnan(full.x)
    assert np.isnan(full.values["robot_dn"][keep][holes]).all()
    assert np.isfinite(full.values["tool_dn"][keep]).all()  # a model term is never masked


def test_part_figure_lines_break_at_holes_and_toggle(small):
    pp = small[0]
    fig = ia.part_figure(pp).to_go()  # validated by plotly
    assert len(fig.data) == len(agg.PART_VIEW_TERMS)
    assert [t.visible for t in fig.data] == [True] + [False] * (len(fig.data) - 1)
    assert all(t.type == "scatter3d" and t.mode == "lines" for t in fig.data)
    total = fig.data[0]  # the robot part's deviation: NaN (a break) at its scan holes
    n_holes = int((~pp["robot_valid"]).sum())
    n_laps = pp["lap"].nunique()
    assert np.isnan(np.asarray(total.x, dtype=float)).sum() == n_holes + n_laps - 1
    tool = fig.data[2]
    assert np.isnan(np.asarray(tool.x, dtype=float)).sum() == n_laps - 1
    buttons = fig.layout.updatemenus[0].buttons
    assert [b.label for b in buttons] == [t.name for t in fig.data]
    for k, b in enumerate(buttons):
        vis = b.args[0]["visible"]
        assert vis[k] and sum(vis) == 1
    for t in fig.data:  # each its own symmetric colour scale around 0
        assert t.line.cmin == pytest.approx(-t.line.cmax) and t.line.cmax > 0


def test_part_view_comes_first_and_carries_plotly_js(small, tmp_path):
    _, text = _write(small, tmp_path)
    assert text.index('id="fig-part_3d"') < text.index('id="fig-contributions"')
    assert text.index("* plotly.js v") < text.index('id="fig-part_3d"')


def test_part_view_box_keeps_the_parts_proportions_within_the_camera(small):
    """plotly's "data" aspect mode scales the box to unit volume: a flat or long part grew past
    the fixed camera and was cut off (a 160 × 80 × 25 mm pyramid, a 12 mm deep cone). The box
    is the data's proportions with the longest side 1 (the flattest at least MIN_ASPECT)."""
    from roboisf.report.interactive import MIN_ASPECT, _aspect, part_figure

    scene = part_figure(small[0]).to_go().layout.scene  # validated by plotly
    assert scene.aspectmode == "manual"
    r = scene.aspectratio
    assert max(r.x, r.y, r.z) == 1.0 and min(r.x, r.y, r.z) >= MIN_ASPECT
    x = np.array([-80.0, 80.0, np.nan])
    assert _aspect(x, np.array([-40.0, 40.0]), np.array([-25.0, 0.0])) == {
        "x": 1.0, "y": 0.5, "z": 0.1562
    }  # fmt: skip
    assert _aspect(x, x, np.array([-1.0, 0.0]))["z"] == MIN_ASPECT


def test_experiment_vs_vjm_captions_give_the_mismatch(small, tmp_path):
    check = {"ratio": 2.0, "ci_low": 1.98, "ci_high": 2.02, "verdict": "mismatch"}
    _, text = _write(small, tmp_path / "m", vjm_check=check)
    for fid in ("vjm_path", "vjm_polar"):
        block = text[text.index(f'<figure id="figure-{fid}">') :]
        cap = block[block.index("<figcaption>") : block.index("</figcaption>")]
        assert "2.00× the VJM" in cap and "does not hold" in cap, fid
    _, ok = _write(small, tmp_path / "o", vjm_check={**check, "verdict": "consistent"})
    assert "does not hold:" not in ok


def test_table_numbers_read_floating_point_zeros_as_zero():
    """A moment of 9.2e-21 N·m and a compliance coupling of -2.9e-24 m/N were printed as such,
    and -0.0 as "-0.000"; real small values keep their scientific form."""
    from roboisf.report.page import fmt

    assert [fmt(v) for v in (9.182e-21, -2.923e-24, -0.0, -0.00004)] == [
        "0.000", "0.000", "0.000", "-4.000e-05"
    ]  # fmt: skip
    assert fmt(2.5e-9) == "2.500e-09" and fmt(1.574e-4) == "1.574e-04" and fmt(-0.5) == "-0.500"
    assert fmt(-0.0001, 2) == "-1.000e-04" and fmt(-0.004, 2) == "-4.000e-03"
