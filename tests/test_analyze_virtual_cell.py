"""Acceptance of ``analyze`` on virtual-cell studies of both paper parts (issue #6).

The cell knows every contribution per toolpath point; analyze must recover each one from the raw
files (force logs in the sensors' frames, joint log, scans) within 20 µm RMS of the truth on the
normal component, the shares within 2 percentage points, and Δ(VJM − experiment) near zero in
the normal book (the cell used the same VJM).
"""

import numpy as np
import pandas as pd
import pytest

from roboisf.decompose import FACTORS
from roboisf.decompose.pipeline import analyze, write_results
from roboisf.virtual.cell import build_study, paper_cone_cell, paper_vwacf_cell
from summary_check import validated

pytestmark = pytest.mark.slow


#: Scan size and log rates of each part's study (the paper's toolpaths, 34,825 and 17,719
#: points, are kept). The error budget was measured on both parts at 600 k scan points, forces
#: at 200 Hz and joints at 50 Hz (largest RMS error, the robot term in both: cone 6.0 µm, VWACF
#: 12.1 µm; shares within 0.07 points). The cone at 150 k points, 50 Hz and 20 Hz measured
#: 10.6 µm (shares within 0.01 points; rim and deep thickness and R_m within 3 µm of the large
#: study's), still 1.9× under the 20 µm acceptance, for 60 % of the CPU. The VWACF at those
#: settings measured 20.6 µm — over the acceptance — so it keeps 600 k points.
SETTINGS = {
    "cone": {"scan_points": 150_000, "force_rate": 50.0, "joint_rate": 20.0},
    "vwacf": {"scan_points": 600_000, "force_rate": 200.0, "joint_rate": 50.0},
}


@pytest.fixture(scope="module", params=["cone", "vwacf"])
def analysed(request, tmp_path_factory):
    make = {"cone": paper_cone_cell, "vwacf": paper_vwacf_cell}[request.param]
    cell = make(**SETTINGS[request.param])
    root = tmp_path_factory.mktemp(request.param)
    study = build_study(cell, root / "study")
    result = analyze(study)
    out = write_results(result, root / "results", png=False)
    return result, out


def test_every_contribution_recovered_within_20_um(analysed):
    result, _ = analysed
    rms = result.summary.truth["rms_error_dn_mm"]
    assert set(rms) == set(FACTORS)
    for factor, err in rms.items():
        assert err < 0.020, (factor, err)
    # and the robot term is not trivially small: the test could fail
    pp = result.per_point[result.per_point.used]
    assert np.abs(pp.truth_robot_compliance_dn).mean() > 0.1


def test_shares_within_2_points_of_the_truth(analysed):
    result, _ = analysed
    truth = result.summary.truth
    for table, book in (
        (result.contributions, "shares_per_axis"),
        (result.contributions_normal, "shares_normal"),
    ):
        got = table.set_index("factor")["share_percent"]
        for factor in FACTORS:
            assert got[factor] == pytest.approx(truth[book][factor], abs=2.0), (book, factor)


def test_vjm_matches_experiment_in_the_normal_book(analysed):
    result, _ = analysed
    d = result.summary.vjm_vs_experiment
    assert d["resultant"] < 0.01  # mm; the per-axis book keeps the unobservable tangential part
    assert result.summary.vjm_vs_experiment_per_axis["resultant"] > d["resultant"]


def test_output_files(analysed):
    result, out = analysed
    c = pd.read_csv(out / "contributions.csv")
    assert list(c.columns) == [
        "factor",
        "mean_abs_dx",
        "mean_abs_dy",
        "mean_abs_dz",
        "R_m",
        "share_percent",
    ]
    assert list(c.factor) == ["tool", "tool_holder", "springback", "robot_compliance", "total"]
    pp = pd.read_parquet(out / "per_point.parquet")
    assert len(pp) == len(result.per_point)
    s = validated(out / "summary.json")
    assert s["study"] == result.study.name and "compliance_stats" in s
    html = (out / "report.html").read_text()
    assert "plotly" in html.lower() and 'src="http' not in html


def test_paper_like_magnitudes(analysed):
    """The cells are tuned to the paper's orders of magnitude (Bharti et al. 2024)."""
    result, _ = analysed
    rows = result.contributions.set_index("factor")
    if result.study.name == "cone-71":
        assert rows.loc["springback", "R_m"] == pytest.approx(1.132, rel=0.05)
        assert rows.loc["tool", "mean_abs_dx"] < rows.loc["springback", "mean_abs_dx"]
    else:
        assert rows.loc["springback", "R_m"] == pytest.approx(0.53, rel=0.15)
    assert rows.loc["robot_compliance", "share_percent"] > 10.0


def test_measured_thickness_attached(analysed):
    result, _ = analysed
    pp = result.per_point
    assert "thickness_measured" in pp
    if result.study.name == "cone-71":
        near_rim = pp.thickness_measured[(pp.depth > 1.5) & (pp.depth < 2.5)].mean()
        deep = pp.thickness_measured[pp.depth > 40].mean()
        assert near_rim == pytest.approx(0.25, abs=0.03)  # the paper: ~0.25 mm near the rim
        assert deep == pytest.approx(0.397, abs=0.01)  # sine law 1.22·cos 71°
