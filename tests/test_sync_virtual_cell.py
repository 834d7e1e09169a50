"""Done-when of issue #13 for alignment: a virtual cell whose loggers keep time as real equipment
does (2 % fast clock, 7 s offset, a 30 s pause, a force DAQ with its own clock) is analysed to the
same decomposition as the clean study — every share within 1 percentage point — because
``analyze`` aligns the logs (robot run by position, CNC run by the force signature).

The end-to-end pair is slow (two small studies); the alignment itself is covered fast by
test_sync.py, and the CLI options here fast (the writer is replaced).
"""

from pathlib import Path

import numpy as np
import pytest

from roboisf.cli.main import main
from roboisf.decompose import FACTORS
from roboisf.decompose.pipeline import analyze, write_results
from roboisf.virtual.cell import build_study, paper_cone_cell
from roboisf.virtual.equipment import Equipment
from summary_check import validated

SMALL = {
    "scan_points": 150_000,
    "force_rate": 50.0,
    "joint_rate": 20.0,
    "step_down": 2e-3,
    "spacing": 4e-3,
}
EQUIPMENT = Equipment(
    clock_scale=1.02,
    offset=7.0,
    pauses=((300.0, 30.0),),
    force_clock="own",
    force_offset=-3.0,
    force_clock_scale=0.999,
)


def test_cli_passes_the_equipment_options(tmp_path, monkeypatch):
    import roboisf.virtual.cell as vc

    seen = {}

    def fake(cell, out, *, progress=None, equipment=None, log_format="parquet"):
        seen["equipment"] = equipment

    monkeypatch.setattr(vc, "build_study", fake)
    args = ["-q", "virtual-cell", "cone", "-o", str(tmp_path / "s"), "--clock-scale", "1.02"]
    args += ["--clock-offset", "7", "--pause", "300,30", "--force-clock-offset", "-3"]
    assert main([*args, "--force-clock-scale", "0.999"]) == 0
    assert seen["equipment"] == EQUIPMENT
    assert main([*args, "--pause", "300"]) == 2  # one line, names --pause
    prof = ["--cnc-force-profile", "kistler", "--robot-force-profile", "ati"]
    assert main([*args, *prof, "--joint-profile", "kuka", "--overwrite"]) == 0
    eq = seen["equipment"]
    assert (eq.cnc_force_profile, eq.robot_force_profile, eq.joint_profile) == (
        "kistler",
        "ati",
        "kuka",
    )
    assert main([*args, "--joint-profile", "fanuc", "--overwrite"]) == 2


@pytest.fixture(scope="module")
def pair(tmp_path_factory, small_cone_settings, small_cone_analysis):
    """The clean study's analysis (shared, tests/conftest.py: the same cell, ideal equipment) and
    the drifting-clock study's."""
    assert small_cone_settings == SMALL
    root = tmp_path_factory.mktemp("sync")
    clean = small_cone_analysis
    study = build_study(paper_cone_cell(**SMALL), root / "drift", equipment=EQUIPMENT)
    drift = analyze(study)
    out = write_results(drift, root / "results", png=False)
    return clean, drift, study, out


@pytest.mark.slow
def test_drifting_logs_give_the_clean_decomposition(pair):
    clean, drift, study, _ = pair
    text = (study / "study.toml").read_text()
    assert 'sync = "position"' in text and 'sync = "force"' in text and 'clock = "own"' in text
    for table in ("contributions", "contributions_normal"):
        a = getattr(clean, table).set_index("factor").share_percent
        b = getattr(drift, table).set_index("factor").share_percent
        for f in FACTORS:
            assert b[f] == pytest.approx(a[f], abs=1.0), (table, f)
    # and per point: the forces land on the same points (the last point loses contact half-way
    # through its window in the equipment log: the tool lifts off there)
    for run in ("cnc", "robot"):
        d = np.abs(clean.per_point[f"{run}_Fz"] - drift.per_point[f"{run}_Fz"]).to_numpy()[:-1]
        assert np.percentile(d, 99) < 5.0 and np.median(d) < 1.5  # N; sensor noise 2 N


@pytest.mark.slow
def test_nominal_time_would_put_the_forces_on_the_wrong_points(pair, tmp_path):
    """The test can fail: the same logs matched by nominal time are far off."""
    clean, _, study, _ = pair
    import shutil

    s = tmp_path / "s"
    shutil.copytree(study, s)
    text = (s / "study.toml").read_text()
    text = text.replace('sync = "force"', 'sync = "time"').replace('sync = "position"', "")
    text = text.replace('clock = "own"', 'clock = "joint"')
    (s / "study.toml").write_text(text.replace("[runs.robot]", '[runs.robot]\nsync = "time"'))
    from roboisf.cam.toolpath_csv import read_toolpath_csv
    from roboisf.decompose.pipeline import run_tip_wrench
    from roboisf.study.spec import load_study

    st = load_study(s)
    W = run_tip_wrench(st, st.cnc, read_toolpath_csv(st.cnc.toolpath))
    d = np.abs(W[:, 0] - clean.per_point.cnc_Fx.to_numpy())
    assert np.median(d) > 20.0


@pytest.mark.slow
def test_summary_reports_the_alignment(pair):
    *_, study, out = pair
    s = validated(out / "summary.json")
    al = s["alignment"]
    assert set(al) == {"cnc", "robot"}
    for a in al.values():  # named inside the study folder, so the record survives a move
        assert not Path(a["source"]).is_absolute() and (study / a["source"]).is_file()
    rob, cnc = al["robot"], al["cnc"]
    assert rob["method"] == "position" and rob["residual_unit"] == "mm"
    assert rob["residual_max"] < 0.5 and rob["clock_scale"] == pytest.approx(1.02, abs=1e-3)
    assert rob["offset"] == pytest.approx(7.0, abs=0.1)
    assert len(rob["pauses"]) == 1 and rob["pauses"][0][1] == pytest.approx(30.6, abs=0.2)
    assert rob["force_clock"]["scale"] == pytest.approx(0.999 / 1.02, rel=1e-3)
    assert cnc["method"] == "force" and cnc["residual_unit"] == "points"
    # the CNC dynamometer runs on its own clock: 0.999 s per real s, 7/1.02 s real start, -3 s
    assert cnc["clock_scale"] == pytest.approx(0.999, abs=3e-3)
    html = (out / "report.html").read_text()
    assert "Alignment of the logs" in html and "by position (FK of the joint log)" in html


def test_summary_names_files_relative_to_the_study(tmp_path):
    from roboisf.decompose.pipeline import _in_study

    (tmp_path / "logs").mkdir()
    assert _in_study(tmp_path / "logs" / "f.parquet", tmp_path) == "logs/f.parquet"
    outside = tmp_path.parent / "elsewhere.csv"
    assert _in_study(outside, tmp_path) == str(outside.resolve())
    assert _in_study("", tmp_path) == ""


@pytest.mark.slow
def test_a_pyramid_run_is_timed_by_its_corners_from_a_drifting_clock(tmp_path):
    """A pyramid's force direction stands still along each side and turns at the corners, its
    first laps press too lightly to read and its last lap runs along the flat floor. The CNC
    run's force alignment must time it (1 % fast clock, 5 s offset: scale and offset found, no
    pause invented) and the diagnosis must blame nothing. It slipped early laps by quarter
    turns and blamed the force sensor, the scan and the robot (robot/VJM 0.14-0.29) until the
    bias was read off the floor and the anchors kept clear of the flat sides."""
    from roboisf.virtual.cell import pyramid_cell

    cell = pyramid_cell(
        scan_points=60_000, force_rate=200.0, joint_rate=50.0, step_down=1e-3, spacing=1e-3
    )
    equipment = Equipment(clock_scale=1.01, offset=5.0)
    study = build_study(cell, tmp_path / "pyramid", equipment=equipment)
    result = analyze(study)
    summary = result.summary.to_dict()
    cnc = summary["alignment"]["cnc"]
    assert cnc["method"] == "force"
    assert abs(cnc["clock_scale"] - 1.01) < 2e-4 and abs(cnc["offset"] - 5.0) < 0.1, cnc
    assert cnc["pauses"] == []
    verdicts = {d["suspect"]: d["verdict"] for d in summary["diagnosis"]}
    assert set(verdicts.values()) == {"ok"}, verdicts
    assert abs(summary["vjm_check"]["ratio"] - 1.0) < 0.05


@pytest.mark.slow
def test_a_vwacf_run_whose_last_laps_press_lighter_is_released_at_their_end(tmp_path):
    """The VWACF's last laps are small circles turned twice a second while its force steps
    down (500 → 30 N): released at a quarter of the run's force, 0.8 s early, its map slipped
    two turns and its first points were timed before the log began (refused). The release is
    carried on while the force stands clear of the log's rest."""
    from roboisf.virtual.cell import paper_vwacf_cell

    cell = paper_vwacf_cell(scan_points=60_000, force_rate=500.0, joint_rate=50.0)
    study = build_study(cell, tmp_path / "vwacf", equipment=Equipment(clock_scale=1.02, offset=7))
    summary = analyze(study).summary.to_dict()
    cnc = summary["alignment"]["cnc"]
    assert cnc["method"] == "force"
    assert abs(cnc["clock_scale"] - 1.02) < 5e-4 and abs(cnc["offset"] - 7.0) < 0.3, cnc
    assert cnc["pauses"] == []
    assert abs(summary["vjm_check"]["ratio"] - 1.0) < 0.05
    assert {d["verdict"] for d in summary["diagnosis"]} <= {"ok", "cannot_tell"}
