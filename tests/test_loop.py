"""The loop through the CLI (issue #27): form, compensate, re-form in the same virtual cell with the
compensated program, iterate, and analyse the study's history — exactly the commands of
docs/compensate.md, "The loop", on a cell whose robot is softer than the model (joints 0.6×).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roboisf.cam.toolpath_csv import read_toolpath_csv
from roboisf.cli.main import main
from roboisf.compensate.study import STALL_RATIO, stopping_rule
from roboisf.decompose.core import decompose
from roboisf.errors import InputError
from roboisf.programs.fanuc import read_fanuc
from roboisf.programs.krl import read_krl
from roboisf.programs.rapid import read_rapid
from roboisf.study import load_study
from roboisf.toolpath.commanded import read_commanded
from summary_check import validated

# a coarse cone (2 mm step-down, 4 mm spacing), 100 k-point scans, slow logs: seconds per part
CELL = ["--step-down", "2", "--spacing", "4", "--scan-points", "100000"]
CELL += ["--force-rate", "50", "--joint-rate", "20"]
#: the program each iteration re-forms: RAPID, KRL, FANUC (every robot format roboisf writes)
PROGRAMS = ("compensated.mod", "compensated.src", "compensated.ls")


def _run(*args: str) -> None:
    assert main(["-q", *args]) == 0, args


@pytest.fixture(scope="module")
def loop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """S1 … S4 (each the previous plus one re-formed run), C1 … C4, R (analyze S4)."""
    d = tmp_path_factory.mktemp("loop")
    truth = d / "truth.toml"
    truth.write_text("[robot]\njoint_stiffness_scale = 0.6\n")
    cell = ["virtual-cell", "cone", "--truth", str(truth), *CELL]
    _run(*cell, "-o", str(d / "S1"))
    for k in range(1, 4):
        _run("compensate", str(d / f"S{k}"), "--no-png", "-o", str(d / f"C{k}"))
        program = d / f"C{k}" / PROGRAMS[k - 1]
        _run(
            *cell,
            "--toolpath",
            str(program),
            "--from",
            str(d / f"S{k}"),
            "-o",
            str(d / f"S{k + 1}"),
        )
    _run("compensate", str(d / "S4"), "--no-png", "-o", str(d / "C4"))
    _run("analyze", str(d / "S4"), "--no-png", "-o", str(d / "R"))
    return d


def _wall_mean_abs(truth_file: Path, used: np.ndarray) -> float:
    return float(np.mean(np.abs(pd.read_parquet(truth_file)["dn_robot"].to_numpy()[used])))


def test_three_iterations_reach_the_target(loop):
    """The done-when of issue #27: three iterations bring the wall's mean |dn| to ≤ 0.05 mm or
    95 % below the first part's — measured (analyze's history) and in the noise-free truth."""
    hist = pd.read_csv(loop / "R" / "iterations.csv")
    assert list(hist["run"]) == ["robot", "robot_2", "robot_3", "robot_4"]
    m = hist["mean_abs_dn_mm"].to_numpy()
    assert m[0] > 1.0  # springback + a robot 1/0.6 × the model's: far from right
    assert np.all(np.diff(m) < 0)
    assert m[-1] <= 0.05 or m[-1] <= 0.05 * m[0]
    assert hist["improvement_percent"].iloc[-1] >= 95.0
    used = pd.read_parquet(loop / "R" / "per_point.parquet")["used"].to_numpy(dtype=bool)
    true = [_wall_mean_abs(loop / "S4" / "truth" / "per_point.parquet", used)]
    true += [
        _wall_mean_abs(loop / "S4" / "truth" / "runs" / f"robot_{k}" / "per_point.parquet", used)
        for k in (2, 3, 4)
    ]
    np.testing.assert_allclose(m, true, atol=0.02)  # the scans measure what was formed
    assert true[-1] <= 0.05
    # the stopping rule: continue while above the target, stop once there
    stops = [json.loads((loop / f"C{k}" / "compensation.json").read_text()) for k in (1, 2, 3, 4)]
    reasons = [s["stopping"]["reason"] for s in stops]
    assert reasons[-1] == "target" and reasons[0] == "continue"
    assert stops[0]["run"] == "robot" and stops[-1]["run"] == "robot_4"


def test_history_terms_hold_across_runs(loop):
    """The compensated runs' command offset is booked as its own term: the robot compliance
    recovered from every run is the same physical deflection (and the truth's), while the
    command grows to cancel it and the springback. Without the command term the robot term of
    a compensated run would be ≈ −(springback) and change from run to run."""
    hist = pd.read_csv(loop / "R" / "iterations.csv")
    rc = hist["robot_compliance_rms_mm"].to_numpy()
    assert rc[0] > 0.3 and np.ptp(rc) < 0.05 * rc[0]
    sb = hist["springback_rms_mm"].to_numpy()
    # the CNC run is the same part in every row; the wall points differ a little (each robot
    # scan has its own holes), so the statistic moves by a few 0.1 µm
    assert np.ptp(sb) < 1e-3
    cmd = hist["command_rms_mm"].to_numpy()
    assert cmd[0] == 0 and np.all(cmd[1:] > 1.0)
    s = validated(loop / "R" / "summary.json")
    assert [r["run"] for r in s["iterations"]] == list(hist["run"])
    # the last run's truth is the run's own (truth/runs/robot_4): the recovered robot term
    assert s["truth"]["rms_error_dn_mm"]["robot_compliance"] < 0.03
    html = (loop / "R" / "report.html").read_text()
    assert 'id="iterations"' in html and "robot_4_toolpath.csv" in html


def test_each_program_is_loadable_and_is_what_was_formed(loop):
    """Every iteration's robot programs read back (RAPID, KRL, FANUC) to the commanded CSV, and
    the run the virtual cell formed carries exactly those tips and the compensation's state."""
    for k, (reader, name) in enumerate(
        (
            (read_rapid, "compensated.mod"),
            (read_krl, "compensated.src"),
            (read_fanuc, "compensated.ls"),
        ),
        start=1,
    ):
        tp = read_toolpath_csv(loop / f"C{k}" / "compensated.csv")
        assert np.abs(reader(loop / f"C{k}" / name).tip - tp.tip).max() < 1e-6
        formed = read_toolpath_csv(loop / "S4" / f"robot_{k + 1}_toolpath.csv")
        np.testing.assert_allclose(formed.tip, tp.tip, atol=1e-6)
        np.testing.assert_allclose(formed.contact, tp.contact, atol=1e-9)
        state = pd.read_csv(loop / "S4" / f"robot_{k + 1}_compensation.csv")
        ours = pd.read_csv(loop / f"C{k}" / "per_point.csv")
        np.testing.assert_array_equal(state["springback_offset_dn"], ours["springback_offset_dn"])
    study = load_study(loop / "S4")
    assert [r.name for r in study.robot_runs] == ["robot", "robot_2", "robot_3", "robot_4"]
    assert study.robot_runs[0].compensation is None
    assert study.for_run("robot_3").robot_run.compensation.name == "robot_3_compensation.csv"


def test_offsets_are_updated_not_restarted(loop):
    """compensate on a compensated run starts from that run's offsets (c_k of its
    ``compensation``): the new springback offset is c_k − λ·S[D_k], close to c_k once the part
    is nearly right — not the one-step offset of a part compensated from scratch."""
    c3 = pd.read_csv(loop / "C3" / "per_point.csv")["springback_offset_dn"].to_numpy()
    c4 = pd.read_csv(loop / "C4" / "per_point.csv")["springback_offset_dn"].to_numpy()
    c1 = pd.read_csv(loop / "C1" / "per_point.csv")["springback_offset_dn"].to_numpy()
    assert np.abs(c4 - c3).max() < 0.1 * np.abs(c3).max()
    assert np.mean(np.abs(c4)) > 1.1 * np.mean(np.abs(c1))  # c1 = −λ·S[D_0]: λ = 0.8 of it


def _err(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert main(["-q", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    return err


def test_from_another_cell_is_refused(loop, tmp_path, capsys):
    """--from checks the cell: another seed or step-down than the study's is a one-line error,
    nothing written."""
    cell = ["virtual-cell", "cone", "--truth", str(loop / "truth.toml"), *CELL]
    prog = str(loop / "C1" / "compensated.mod")
    out = tmp_path / "x"
    tail = ["--toolpath", prog, "--from", str(loop / "S1"), "-o", str(out)]
    assert "seed = 0" in _err(capsys, *cell, "--seed", "3", *tail)
    other = [*cell[:4], "--step-down", "2.5", *cell[6:]]
    err = _err(capsys, *other, *tail)
    assert "compensated.mod" in err and "forming moves" in err
    assert not out.exists()
    assert "--from needs --toolpath" in _err(
        capsys, *cell, "--from", str(loop / "S1"), "-o", str(out)
    )


def test_read_commanded_refuses_what_is_not_a_command(loop, tmp_path):
    """A program with a move too far from its nominal, another work object or another tool is
    refused naming the file; the CSV of a compensation reads back exactly."""
    from roboisf.virtual.cell import cell_toolpath, paper_cone_cell

    cell = paper_cone_cell(step_down=2e-3, spacing=4e-3)
    nominal = cell_toolpath(cell)
    good = loop / "C1" / "compensated.csv"
    tp = read_commanded(good, nominal)
    np.testing.assert_array_equal(tp.tip, read_toolpath_csv(good).tip)
    np.testing.assert_array_equal(tp.contact, nominal.contact)
    with pytest.raises(InputError, match="mm from its nominal tip"):
        read_commanded(good, nominal, max_offset=0.1e-3)
    T = cell.cell.T_base_work.copy()
    T[0, 3] += 1e-3
    with pytest.raises(InputError, match="work object"):
        read_commanded(loop / "C1" / "compensated.mod", nominal, T_base_work=T)
    with pytest.raises(InputError, match="tool is"):
        read_commanded(loop / "C1" / "compensated.mod", nominal, tool_length=0.1)
    short = tmp_path / "short.csv"
    lines = good.read_text().splitlines()
    short.write_text("\n".join(lines[:-3]) + "\n")
    with pytest.raises(InputError, match="forming moves"):
        read_commanded(short, nominal)


def test_stopping_rule():
    """Target reached → stop; less than (1 − STALL_RATIO) gained on the previous part → stop
    (stalled); else continue. NaN points (not judged) are left out."""
    dn = np.array([0.04e-3, -0.04e-3, np.nan])
    assert stopping_rule(dn, None)["reason"] == "target"
    big = 10 * dn
    assert stopping_rule(big, None)["reason"] == "continue"
    assert stopping_rule(big, big / STALL_RATIO * 1.01)["reason"] == "continue"
    r = stopping_rule(big, big / STALL_RATIO * 0.99)
    assert r["reason"] == "stalled" and r["stop"]
    assert r["ratio_to_previous"] == pytest.approx(STALL_RATIO / 0.99)


def test_decompose_books_the_command_apart():
    """The robot compliance of a compensated run is the measured deviation minus the command
    offset (and the other terms); the command as a scan sees it — its normal part — is kept as
    its own vector (the tangential part is no scan's: tests/test_decompose_core.py)."""
    rng = np.random.default_rng(1)
    n = rng.normal(size=(5, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    z = np.zeros((5, 3))
    cmd = rng.normal(size=(5, 3)) * 1e-3
    dn_r = np.einsum("ij,ij->i", cmd, n) + 0.2e-3
    d = decompose(n, np.zeros(5), dn_r, z, z, z, z, np.ones(5, bool), cmd)
    np.testing.assert_allclose(d.normal["robot_compliance"], 0.2e-3, atol=1e-15)
    np.testing.assert_allclose(d.vectors["command"], np.einsum("ij,ij->i", cmd, n)[:, None] * n)
    d0 = decompose(n, np.zeros(5), dn_r, z, z, z, z, np.ones(5, bool))
    assert np.all(d0.vectors["command"] == 0)
    np.testing.assert_allclose(d0.normal["robot_compliance"], dn_r)


def test_compensate_virtual_takes_a_part_file_and_a_truth(tmp_path):
    """`compensate --virtual PART.toml --truth T.toml`: any part, a cell that is not the model.
    The truth is applied: the first part of a robot 0.6× as stiff deviates more, and the
    iteration still brings it down."""
    part = tmp_path / "cone60.toml"
    part.write_text(
        '[part]\nkind = "cone"\nopening_diameter = 80.0\nwall_angle = 60.0\ndepth = 35.0\n'
    )
    truth = tmp_path / "t.toml"
    truth.write_text("[robot]\njoint_stiffness_scale = 0.6\n")
    means = []
    for extra in ([], ["--truth", str(truth)]):
        out = tmp_path / f"C{len(means)}"
        args = ["compensate", "--virtual", str(part), *extra, "--iterations", "2"]
        _run(*args, "--step-down", "2", "--spacing", "4", "--no-png", "-o", str(out))
        means.append(
            json.loads((out / "compensation.json").read_text())["mean_abs_dn_per_iteration_mm"]
        )
    assert means[1][0] > means[0][0] + 0.05  # the softer robot's first part
    assert means[1][-1] < 0.1 * means[1][0]


def test_reform_without_from_and_from_gcode(loop, tmp_path):
    """Without --from the study holds the CNC run and one robot run formed with the program (its
    toolpath the commanded CSV, its compensation beside it); the G-code of a compensation (the
    nominal + springback offsets, no pre-deflection) re-forms too."""
    cell = ["virtual-cell", "cone", "--truth", str(loop / "truth.toml"), *CELL]
    _run(*cell, "--toolpath", str(loop / "C1" / "compensated.csv"), "-o", str(tmp_path / "X"))
    st = load_study(tmp_path / "X")
    assert [r.name for r in st.robot_runs] == ["robot"]
    rob = st.robot_run
    assert rob.toolpath.name == "robot_toolpath.csv" and rob.compensation is not None
    np.testing.assert_allclose(
        read_toolpath_csv(rob.toolpath).tip,
        read_toolpath_csv(loop / "C1" / "compensated.csv").tip,
        atol=1e-9,
    )
    # the same part as the --from route's robot_2 (same cell, the same command — there read from
    # the RAPID module, whose positions are rounded to 1 µm per axis): the truth agrees (mm)
    a = pd.read_parquet(tmp_path / "X" / "truth" / "per_point.parquet")["dn_robot"]
    b = pd.read_parquet(loop / "S2" / "truth" / "runs" / "robot_2" / "per_point.parquet")
    np.testing.assert_allclose(a, b["dn_robot"], atol=0.5e-3 * np.sqrt(3))
    _run(*cell, "--toolpath", str(loop / "C1" / "compensated.nc"), "-o", str(tmp_path / "G"))
    g = read_toolpath_csv(tmp_path / "G" / "robot_toolpath.csv")
    pp = pd.read_csv(loop / "C1" / "per_point.csv")
    nominal = read_toolpath_csv(loop / "S1" / "toolpath.csv")
    c = pp["springback_offset_dn"].to_numpy()[:, None] * 1e-3 * nominal.normal
    np.testing.assert_allclose(g.tip, nominal.tip + c, atol=2e-6)  # G-code: 1 µm resolution


def test_results_of_another_run_are_refused(loop, tmp_path, capsys):
    """analyze's output is the last run's (summary.json → robot_run): compensate --results of
    it for another run is a one-line error, not a silent mix."""
    s = validated(loop / "R" / "summary.json")
    assert s["robot_run"] == "robot_4"
    args = ["compensate", str(loop / "S4"), "--results", str(loop / "R"), "--no-png"]
    err = _err(capsys, *args, "--run", "robot_2", "-o", str(tmp_path / "c"))
    assert "robot_4" in err and "robot_2" in err
    _run(*args, "-o", str(tmp_path / "ok"))  # the last run: accepted
