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
    # a crosstalk in newtons per kilonewton: 1.574e-04 N/N printed as such beside "0.000"
    assert _estimate(row("force_crosstalk")) == "3105.00 [2859.00, 4252.00] N/kN"
    small = {**row("force_crosstalk"), "estimate": 1.574e-4, "ci_low": 0.0, "ci_high": 5.406e-4}
    assert _estimate(small) == "0.16 [0.00, 0.54] N/kN"
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
    and -0.0 as "-0.000"."""
    from roboisf.report.page import fmt

    assert [fmt(v) for v in (9.182e-21, -2.923e-24, -0.0, 0.0)] == ["0.000"] * 4
    assert fmt(-0.5) == "-0.500" and fmt(-0.0004999, 3) == "-0.00050"


def test_table_numbers_never_switch_to_e_notation():
    """Real small values printed in e-notation beside fixed-point neighbours (a crosstalk of
    1.574e-04, a mean Δ of -1.511e-05 mm beside 0.0057, a Table-4 entry 8.817e-06 beside
    0.0003), large ones likewise (a joint stiffness 3.730e+06 beside 638000). Fixed point
    throughout: a real value below the column's last decimal keeps two significant digits (it
    is not a zero, which reads 0.000), large values have their digits grouped by three."""
    from roboisf.report.page import GROUP_SEPARATOR as G
    from roboisf.report.page import fmt

    assert fmt(1.574e-4) == "0.00016" and fmt(-1.511e-05, 4) == "-0.000015"
    assert fmt(8.817e-06, 4) == "0.0000088" and fmt(2.5e-9) == "0.0000000025"
    assert fmt(-0.0001, 2) == "-0.00010" and fmt(-0.004, 2) == "-0.0040"
    assert fmt(0.0057, 4) == "0.0057" and fmt(0.001, 3) == "0.001"  # at the column's precision
    assert fmt(3.73e6, 0) == f"3{G}730{G}000" and fmt(638000, 0) == f"638{G}000"
    assert fmt(-12345.678, 1) == f"-12{G}345.7" and fmt(9999.5, 0) == "10000"
    for v in (1.574e-4, -1.511e-05, 3.73e6, 1e12, 2.5e-9, -7e-13):
        assert "e" not in fmt(v).lower(), v


def test_compliance_table_in_millionths_of_si(small, tmp_path):
    """The compliance statistics (SI, 1e-9 … 1e-6) printed 8.522e-07 beside 0.000: shown in
    µm/N, µm/(N·m), µrad/N and µrad/(N·m) at four decimals, the unit in its own column."""
    from roboisf.report.page import compliance_table

    stats = {
        "k_11": {"mean": 8.522e-07, "std": 1.22e-08, "min": 8.239e-07, "max": 8.771e-07},
        "k_16": {"mean": 3.812e-08, "std": 1.754e-09, "min": 3.5e-08, "max": 4.222e-08},
        "k_61": {"mean": 3.812e-08, "std": 1.754e-09, "min": 3.5e-08, "max": 4.222e-08},
        "k_36": {"mean": 1e-21, "std": 0.0, "min": 0.0, "max": 2e-21},
        "k_55": {"mean": 1.728e-06, "std": 3.028e-09, "min": 1.723e-06, "max": 1.735e-06},
    }
    text = compliance_table(stats)
    rows = {
        m.group(1): m.group(2)
        for m in re.finditer(r"<tr><td>k<sub>(\d\d)</sub></td>(.*?)</tr>", text)
    }
    cells = {k: re.findall(r"<td>([^<]*)</td>", v) for k, v in rows.items()}
    assert cells["11"] == ["µm/N", "0.8522", "0.0122", "0.8239", "0.8771"]
    assert cells["16"] == ["µm/(N·m)", "0.0381", "0.0018", "0.0350", "0.0422"]
    assert cells["61"][0] == "µrad/N" and cells["55"][:2] == ["µrad/(N·m)", "1.7280"]
    assert cells["36"][1:] == ["0.0000"] * 4  # floating-point zeros
    assert "e-0" not in text
    # the report's own table
    _, page = _write(small, tmp_path)
    table = page[page.index("Cartesian compliance") :]
    table = table[: table.index("</table>")]
    assert "µm/N" in table and "e-0" not in table


def test_report_tables_have_no_e_notation(small, tmp_path):
    """Every table of the report, with tiny real values in the summary (Δ, Table 4, the
    terms' means, a crosstalk): fixed point only."""
    diag = [{"suspect": "force_crosstalk", "verdict": "ok", "estimate": 2.758e-05,
             "ci_low": 0.0, "ci_high": 5.406e-04, "unit": "1", "explanation": "x"}]  # fmt: skip
    fc = {"dx": {"Fx": 0.0789, "Mz": 8.817e-06}, "dz": {"Fx": 0.0448, "Mz": 0.0}}
    terms = {"delta": {"mean_mm": -1.511e-05, "rms_mm": 0.0057, "mean_abs_mm": 0.0046,
                       "std_mm": 0.0057}}  # fmt: skip
    vjm = {"x": 0.0002, "y": 4.3e-05, "z": 6.145e-05, "resultant": 0.0002}
    _, page = _write(small, tmp_path, diagnosis=diag, force_contributions=fc,
                     terms_normal=terms, vjm_vs_experiment=vjm)  # fmt: skip
    tables = re.findall(r"<table>.*?</table>", page, flags=re.S)
    assert len(tables) >= 5
    for t in tables:
        assert not re.search(r"\d\.\d+e[+-]\d", t), t[:200]
    assert "0.03 [0.00, 0.54] N/kN" in page
    assert "<td>0.0000088</td>" in page and "<td>-0.000015</td>" in page


def test_every_suspect_of_the_diagnosis_has_a_name_on_the_page():
    # a suspect added to the diagnosis without a name here read as its key with spaces
    # ("force moment bias") beside "force sensor bias"
    from roboisf.decompose.diagnose import SUSPECTS
    from roboisf.report.statements import _SUSPECTS

    assert set(SUSPECTS) <= set(_SUSPECTS), set(SUSPECTS) - set(_SUSPECTS)


def test_study_section_reads_like_the_tables_not_in_e_notation(small, tmp_path):
    """The "Study" key–value list: a compliance echoed in m/N reads in µm/N as the compliance
    table does (0.9401, not 9.40099e-07), any other tiny float in fixed point, a float zero in
    the scaled unit 0.0000."""
    tool = {"ball_diameter_mm": 10, "method": "beam",
            "lateral_compliance_m_per_N": 9.40099e-07,
            "holder_lateral_compliance_m_per_N": 0.0, "gap_m": 1.03274e-07}  # fmt: skip
    _, page = _write(small, tmp_path, tool=tool)
    section = page[page.index('id="study"') :]
    section = section[: section.index("</section>")]
    assert not re.search(r"\de[+-]\d", section), section
    assert "lateral_compliance_m_per_N = 0.9401 µm/N" in section
    assert "holder_lateral_compliance_m_per_N = 0.0000 µm/N" in section
    assert "gap_m = 0.000000103274" in section
    assert "ball_diameter_mm = 10," in section
