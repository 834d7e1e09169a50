"""``roboisf compensate``: outputs, bad input (exit 2/3, nothing written), end to end."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from roboisf.cli.main import main
from roboisf.io.toolpath_csv import read_toolpath_csv

COARSE = ["--step-down", "2", "--spacing", "3"]
FILES = {
    "compensated.csv",
    "compensated.mod",
    "compensated.src",
    "compensated.dat",
    "compensated.nc",
    "per_point.csv",
    "compensation.json",
    "compensation.html",
    "compensation.png",
}


def test_virtual_cell_outputs(tmp_path):
    out = tmp_path / "comp"
    assert (
        main(
            ["-q", "compensate", "--virtual", "vwacf", *COARSE, "--iterations", "2", "-o", str(out)]
        )
        == 0
    )
    assert {p.name for p in out.iterdir()} == FILES | {".roboisf-output.json"}
    s = json.loads((out / "compensation.json").read_text())
    assert s["complete"] and s["gouge"]["ok"] and s["compliance"]["converged"]
    m = s["mean_abs_dn_per_iteration_mm"]
    assert len(m) == 3 and m[-1] < 0.1 < m[0]
    assert s["mean_abs_dn_after_virtual_cell_mm"] == pytest.approx(m[-1])
    tp = read_toolpath_csv(out / "compensated.csv")
    pp = pd.read_csv(out / "per_point.csv")
    assert len(pp) == len(tp)
    np.testing.assert_allclose(pp[["tip_x", "tip_y", "tip_z"]].to_numpy() * 1e-3, tp.tip, atol=2e-6)
    assert "MoveL" in (out / "compensated.mod").read_text()
    assert "LIN" in (out / "compensated.src").read_text()
    assert "<html" in (out / "compensation.html").read_text().lower()


def test_no_springback_compensates_compliance_only(tmp_path):
    out = tmp_path / "c"
    args = [
        "-q",
        "compensate",
        "--virtual",
        "cone",
        *COARSE,
        "--iterations",
        "1",
        "--no-springback",
    ]
    assert main([*args, "-o", str(out), "--no-png"]) == 0
    s = json.loads((out / "compensation.json").read_text())
    assert s["springback"] is None and s["terms"] == {"compliance": True, "springback": False}
    pp = pd.read_csv(out / "per_point.csv")
    assert np.all(pp["springback_offset_dn"] == 0)
    assert not (out / "compensation.png").exists()


@pytest.mark.parametrize(
    "args, code, text",
    [
        ([], 2, "either a STUDY"),
        (["--virtual", "sphere"], 2, "unknown part"),
        (["--virtual", "cone", "--gain", "3"], 2, "gain"),
        (["--virtual", "cone", "--no-compliance", "--no-springback"], 2, "nothing to compensate"),
        (["--virtual", "cone", "--smooth-along", "-1"], 2, "--smooth-along"),
        (["--virtual", "cone", "--max-iter", "1", "--tol", "1e-9"], 3, "did not converge"),
    ],
)
def test_bad_input(tmp_path, capsys, args, code, text):
    out = tmp_path / "o"
    assert main(["compensate", *args, *COARSE, "-o", str(out)]) == code
    assert text in capsys.readouterr().err
    assert not out.exists()


def test_results_folder_without_per_point(tmp_path, capsys):
    from roboisf.virtual.cell import build_study, paper_cone_cell

    st = build_study(
        paper_cone_cell(step_down=2e-3, spacing=3e-3, scan_points=20_000), tmp_path / "st"
    )
    (tmp_path / "res").mkdir()
    out = tmp_path / "o"
    assert main(["compensate", str(st), "--results", str(tmp_path / "res"), "-o", str(out)]) == 2
    assert "per_point.parquet" in capsys.readouterr().err
    assert not out.exists()


@pytest.fixture(scope="module")
def analyzed(tmp_path_factory):
    """A coarse virtual cone study and its analyze results (300 k scan points)."""
    from roboisf.virtual.cell import build_study, paper_cone_cell

    root = tmp_path_factory.mktemp("e2e")
    cell = paper_cone_cell(
        step_down=2e-3, spacing=3e-3, scan_points=300_000, force_rate=200.0, joint_rate=50.0
    )
    st = build_study(cell, root / "st")
    assert main(["-q", "analyze", str(st), "-o", str(root / "res"), "--no-png"]) == 0
    return cell, st, root / "res"


def test_scan_gap_where_compensation_is_asked(analyzed, tmp_path, capsys):
    """Laps without scan data: exit 2 naming the points, or --hold-gaps with per-point flags."""
    _, st, res = analyzed
    pp = pd.read_parquet(res / "per_point.parquet")
    gap = pp["lap"] >= pp["lap"].max() - 5  # the bottom 12 mm were not scanned
    pp.loc[gap, "robot_valid"] = False
    pp.loc[gap, "robot_dn"] = 0.0  # what a scan comparison reports in a hole
    bad = tmp_path / "res"
    bad.mkdir()
    pp.to_parquet(bad / "per_point.parquet")
    out = tmp_path / "o"
    args = ["compensate", str(st), "--results", str(bad), "-o", str(out), "--no-png"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "no valid measurement" in err and "indices" in err
    assert not out.exists()
    assert main(["-q", *args, "--hold-gaps"]) == 0
    got = pd.read_csv(out / "per_point.csv")
    held = got["held"].to_numpy()
    assert held.any() and np.all(held <= gap.to_numpy())
    assert np.all(got["springback_offset_dn"][held] == 0)  # held at c_k = 0, not fed back
    s = json.loads((out / "compensation.json").read_text())
    assert s["springback"]["held_indices"] == np.flatnonzero(held).tolist()


@pytest.mark.slow
def test_end_to_end_study_analyze_compensate_form_again(analyzed, tmp_path):
    """Virtual study → analyze → compensate from the measured part → form the command again."""
    from roboisf.virtual.cell import simulate

    cell, st, res = analyzed
    out = tmp_path / "comp"
    code = main(["-q", "compensate", str(st), "--results", str(res), "-o", str(out)])
    assert code == 0
    s = json.loads((out / "compensation.json").read_text())
    assert s["complete"] and s["gouge"]["ok"]
    # the scan has holes: filled from neighbours and flagged, never fed back as zeros
    pp = pd.read_csv(out / "per_point.csv")
    assert s["springback"]["filled_from_neighbours"] == int(pp["filled"].sum())
    cmd = read_toolpath_csv(out / "compensated.csv")
    # the rim band (sheet bending, left out by the method) only gets the pre-deflection
    rim = cmd.depth <= 20e-3
    assert np.all(pp["springback_offset_dn"][rim] == 0)
    assert np.all(pp["springback_offset_dn"][~rim] < -0.2)
    before, after = simulate(cell), simulate(cell, commanded=cmd)
    wall = before.toolpath.depth > 20e-3
    m0 = np.mean(np.abs(before.dn_robot[wall]))
    m1 = np.mean(np.abs(after.dn_robot[wall]))
    assert m1 < 0.25 * m0  # one measured step with λ = 0.8 (ideal: 0.2)
    # the predicted "after" of the report agrees with forming the command
    assert s["mean_abs_dn_after_predicted_mm"] == pytest.approx(m1 * 1e3, rel=0.05)


def test_previous_offsets_are_the_iteration_state(analyzed, tmp_path):
    """With λ = 1 the new offset is −S[D] whatever c_k was (D_k accounts for c_k): the same
    command with or without --previous; a wrong-length --previous is refused."""
    _, st, res = analyzed
    base = ["-q", "compensate", str(st), "--results", str(res), "--gain", "1", "--no-png"]
    assert main([*base, "-o", str(tmp_path / "a")]) == 0
    prev = tmp_path / "prev"
    prev.mkdir()
    pp = pd.read_csv(tmp_path / "a" / "per_point.csv")
    pd.DataFrame({"springback_offset_dn": np.full(len(pp), -0.4)}).to_csv(
        prev / "per_point.csv", index=False
    )
    assert main([*base, "--previous", str(prev), "-o", str(tmp_path / "b")]) == 0
    a = pd.read_csv(tmp_path / "a" / "per_point.csv")
    b = pd.read_csv(tmp_path / "b" / "per_point.csv")
    rim = a["springback_offset_dn"] == 0  # out of the region: c_k is kept there
    np.testing.assert_allclose(
        b["springback_offset_dn"][~rim], a["springback_offset_dn"][~rim], atol=1e-9
    )
    np.testing.assert_allclose(b["springback_offset_dn"][rim], -0.4)
    pd.DataFrame({"springback_offset_dn": [0.0]}).to_csv(prev / "per_point.csv", index=False)
    assert main([*base, "--previous", str(prev), "-o", str(tmp_path / "c")]) == 2
    assert not (tmp_path / "c").exists()
