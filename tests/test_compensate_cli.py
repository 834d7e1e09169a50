"""``roboisf compensate``: outputs, bad input (exit 2/3, nothing written), end to end."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pandas as pd
import pytest

from roboisf.cam.program import MAX_MODULE_MOVES
from roboisf.cam.toolpath_csv import read_toolpath_csv
from roboisf.cli.main import main
from roboisf.programs.rapid import read_rapid

COARSE = ["--step-down", "2", "--spacing", "3"]
FILES = {
    "compensated.csv",
    "compensated.mod",
    "compensated.src",
    "compensated.dat",
    "compensated.nc",
    "compensated.ls",
    "per_point.csv",
    "compensation.json",
    "compensation.html",
    "compensation.png",
}


def test_virtual_cell_outputs(tmp_path):
    out = tmp_path / "comp"
    args = ["-q", "compensate", "--virtual", "vwacf", *COARSE, "--iterations", "2", "--png"]
    assert main([*args, "-o", str(out)]) == 0
    names = {p.name for p in out.iterdir()}
    parts = names - FILES - {".roboisf-output.json"}
    assert FILES <= names and parts  # this path is above the module limit: a program set
    assert all(re.fullmatch(r"compensated_\d+\.(mod|ls)", n) for n in parts)
    for n in parts:  # each part module holds at most MAX_MODULE_MOVES forming moves
        text = (out / n).read_text()
        assert 0 < text.count("MoveL [[") + text.count(":L P[") <= MAX_MODULE_MOVES
    s = json.loads((out / "compensation.json").read_text())
    assert s["complete"] and s["gouge"]["ok"] and s["compliance"]["converged"]
    m = s["mean_abs_dn_per_iteration_mm"]
    assert len(m) == 3 and m[-1] < 0.1 < m[0]
    assert s["mean_abs_dn_after_virtual_cell_mm"] == pytest.approx(m[-1])
    tp = read_toolpath_csv(out / "compensated.csv")
    pp = pd.read_csv(out / "per_point.csv")
    assert len(pp) == len(tp)
    np.testing.assert_allclose(pp[["tip_x", "tip_y", "tip_z"]].to_numpy() * 1e-3, tp.tip, atol=2e-6)
    assert np.abs(read_rapid(out / "compensated.mod").tip - tp.tip).max() <= 0.5e-6 + 1e-12
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
    assert main([*args, "-o", str(out)]) == 0  # no PNG unless --png asks for it
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
    """A coarse virtual cone study and its analyze results (300 k scan points), the blank on the
    robot base's x-axis, where the cone's path crosses q6 = ±180° (the confdata test needs it)."""
    from roboisf.frames import make_transform
    from roboisf.virtual.cell import build_study, paper_cone_cell

    root = tmp_path_factory.mktemp("e2e")
    cell = paper_cone_cell(
        step_down=2e-3,
        spacing=3e-3,
        scan_points=300_000,
        force_rate=200.0,
        joint_rate=50.0,
        T_base_work=make_transform(p=[2.2, 0.0, 0.2]),
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
    shutil.copy2(res / "summary.json", bad / "summary.json")  # the study's fingerprint
    out = tmp_path / "o"
    args = ["compensate", str(st), "--results", str(bad), "-o", str(out), "--no-png"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "no valid measurement" in err and "indices" in err
    assert "--hold-gaps" in err, err  # the command's option, not only the Python argument
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
    # "before" says the points it is over (the analysis's tables use another set)
    assert s["n_points_before"] == int(pp["dn_before"].notna().sum()) > 0
    assert f"over its {s['n_points_before']} scanned" in (out / "compensation.html").read_text()
    assert s["springback"]["filled_from_neighbours"] == int(pp["filled"].sum())
    cmd = read_toolpath_csv(out / "compensated.csv")
    # the rim band (sheet bending, left out by the method) only gets the pre-deflection
    rim = cmd.depth <= 20e-3
    assert np.all(pp["springback_offset_dn"][cmd.depth <= 15e-3] == 0)
    assert np.all(pp["springback_offset_dn"][~rim] < -0.2)
    # its last 5 mm (--rim-blend) ramp up to the offset of the first lap below it
    ramp = rim & (cmd.depth > 15e-3)
    assert np.all(pp["springback_offset_dn"][ramp] < 0)
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
    base += ["--rim-blend", "0"]  # a blended point keeps part of c_k (c_k+1 = c_k − λ·b·S)
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


def test_rim_band_edge_has_no_step(analyzed, tmp_path):
    """The springback offset ramps in over the last 5 mm of the rim band: the largest lap-to-lap
    step of the per-lap mean offset (stated in the JSON) is below 0.55 mm on this 2 mm step-down
    path (2.5 laps of ramp), against the ≈0.9 mm ledge of a hard edge (--rim-blend 0); the
    analysed wall keeps the whole adjustment (same predicted after)."""
    _, st, res = analyzed
    base = ["-q", "compensate", str(st), "--results", str(res), "--no-png"]
    assert main([*base, "-o", str(tmp_path / "b")]) == 0
    assert main([*base, "--rim-blend", "0", "-o", str(tmp_path / "h")]) == 0
    sb = json.loads((tmp_path / "b" / "compensation.json").read_text())
    sh = json.loads((tmp_path / "h" / "compensation.json").read_text())
    assert sh["max_lap_step_springback_offset_mm"] > 0.8  # the ledge of a hard edge
    assert sb["max_lap_step_springback_offset_mm"] < 0.55
    assert sb["rim_blend_mm"] == 5.0
    key = "mean_abs_dn_after_predicted_mm"
    assert sb[key] == pytest.approx(sh[key], rel=1e-6)  # nothing lost below the band
    # the JSON figure is the per-lap mean offset's largest step, recomputed here
    pp = pd.read_csv(tmp_path / "b" / "per_point.csv")
    lap_mean = pp.groupby("lap")["springback_offset_dn"].mean().to_numpy()
    assert np.abs(np.diff(lap_mean)).max() == pytest.approx(
        sb["max_lap_step_springback_offset_mm"],
        rel=1e-5,  # per_point.csv: 6 digits
    )


def test_compensated_programs_are_a_loadable_set(analyzed, tmp_path):
    """The compensate output as a controller would load it: frames = the study's, confdata /
    S-T / CONFIG = the IK of the commanded path, names = files, the CNC program without the
    robot's pre-deflection, continuity, and a byte-identical report on a second run."""
    from roboisf.cam.gcode import read_gcode
    from roboisf.cell import cell_from_study
    from roboisf.compensate.pipeline import nominal_of
    from roboisf.programs.fanuc import read_fanuc
    from roboisf.programs.krl import read_krl
    from roboisf.robot.ik import ik_toolpath
    from roboisf.study.spec import load_study

    _, st, res = analyzed
    out = tmp_path / "c"
    args = ["-q", "compensate", str(st), "--results", str(res), "--no-png"]
    assert main([*args, "-o", str(out)]) == 0
    study = load_study(st)
    T = study.robot.T_base_work
    model = cell_from_study(study).robot
    cmd = read_toolpath_csv(out / "compensated.csv")
    q = np.degrees(ik_toolpath(model, cmd.tip, T, tool_rotation=study.robot.tool_rotation).q)
    step = np.linalg.norm(np.diff(cmd.tip, axis=0), axis=1).max()
    rapid, krl, ls = (
        read_rapid(out / "compensated.mod"),
        read_krl(out / "compensated.src"),
        read_fanuc(out / "compensated.ls"),
    )
    for prog in (rapid, krl, ls):
        assert np.abs(prog.tip - cmd.tip).max() <= 0.5e-6 + 1e-12
        np.testing.assert_allclose(prog.T_base_work, T, atol=1e-8)  # the study's work object
        assert prog.tool.length == pytest.approx(model.T_flange_tip[2, 3])  # the study's tool
        assert np.linalg.norm(np.diff(prog.tip, axis=0), axis=1).max() <= step + 1e-6
    assert len(cmd) <= MAX_MODULE_MOVES or len(rapid.meta["modules"]) > 1
    conf = rapid.meta["confdata"]
    np.testing.assert_array_equal(conf[:, :3], np.floor(np.round(q[:, [0, 3, 5]], 6) / 90))
    assert np.all(conf[:, 3] == (q[:, 4] < 0))  # front, elbow up: cfx = the q5 sign bit
    s, t = krl.meta["status_turn"]
    assert t == sum(1 << j for j in range(6) if q[0, j] < 0) and s == 2 + 4 * (q[0, 4] < 0)
    assert krl.meta["def"] == krl.meta["defdat"] == "compensated"
    assert all(c.startswith(("N U T", "F U T")) for c in ls.meta["config"])
    # G-code: nominal + springback adjustment only (per_point: c along the nominal normal)
    nom = nominal_of(cmd)
    pp = pd.read_csv(out / "per_point.csv")
    c = pp["springback_offset_dn"].to_numpy() * 1e-3
    nc = read_gcode(out / "compensated.nc")
    # bound: the G-code's 0.5 µm rounding + c from per_point.csv (6 significant digits of mm:
    # ≤ 5 nm for |c| < 10 mm) + the nominal rebuilt from the CSV's nm-rounded tips
    assert np.abs(nc.tip - (nom.tip + c[:, None] * nom.normal)).max() <= 0.5e-6 + 1e-8
    assert np.abs(nc.tip - cmd.tip).max() > 1e-4  # the robot pre-deflection is not in it
    assert "NOT in it: the robot/tool/holder pre-deflection" in (out / "compensated.nc").read_text()
    # the report is deterministic
    assert main([*args, "-o", str(tmp_path / "d")]) == 0
    a = (out / "compensation.html").read_bytes()
    assert a == (tmp_path / "d" / "compensation.html").read_bytes()


def test_confdata_from_the_joint_log_agrees_with_ik(analyzed, tmp_path):
    """Configuration data from the study's logged joints (the controller's commanded angles,
    interpolated at the toolpath points) equals the IK branch's, q6 around ±180° included:
    they differ only where q6 sits within the interpolation error of the 180° boundary."""
    from roboisf.cell import cell_from_study
    from roboisf.logs.jointlog import read_joint_log
    from roboisf.programs.rapid import read_rapid, write_rapid
    from roboisf.robot.armconfig import abb_confdata, arm_config, program_config
    from roboisf.study.spec import load_study

    _, st, _ = analyzed
    study = load_study(st)
    run = study.robot_run
    tp = read_toolpath_csv(run.toolpath)
    log = read_joint_log(run.joints)
    q = np.column_stack([np.interp(tp.time, log.time, log.q[:, j]) for j in range(6)])
    model = cell_from_study(study).robot
    T = study.robot.T_base_work
    from_log = arm_config(model, q)
    write_rapid(tp, tmp_path / "log.mod", T_base_work=T, config=from_log)
    conf = read_rapid(tmp_path / "log.mod").meta["confdata"]
    d = np.degrees(q)
    np.testing.assert_array_equal(conf[:, :3], np.floor(np.round(d[:, [0, 3, 5]], 6) / 90))
    # the path crosses q6 = ±180° (this one at +180°: quadrants 1 and 2)
    assert set(conf[:, 2].tolist()) in ({1, 2}, {-3, -2})
    ik = abb_confdata(program_config(model, tp, T, study.robot.tool_rotation))
    differ = np.any(conf != ik, axis=1)
    assert differ.mean() < 0.01
    assert np.all(np.abs(np.abs(d[differ, 5]) - 180) < 0.05)
