"""Bad study folders: clear errors naming the file; nothing half-written in the output folder."""

import math
import shutil

import pytest

from roboisf.cli.main import main
from roboisf.decompose.pipeline import analyze
from roboisf.errors import InputError, RoboisfError
from roboisf.parts import Cone
from roboisf.scan import synthetic_scan, write_ply


@pytest.fixture(scope="module")
def study(small_cone_study_csv):
    """The small paper cone with CSV logs (tests/conftest.py, shared: copy before editing)."""
    return small_cone_study_csv


def copy(study, tmp_path):
    dst = tmp_path / "s"
    shutil.copytree(study, dst)
    return dst


def test_missing_file(study, tmp_path):
    s = copy(study, tmp_path)
    (s / "robot_scan.ply").unlink()
    assert main(["-q", "analyze", str(s), "-o", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out").exists()


def test_joint_log_that_stops_half_way(study, tmp_path):
    s = copy(study, tmp_path)
    lines = (s / "robot_joints.csv").read_text().splitlines()
    (s / "robot_joints.csv").write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    with pytest.raises(InputError, match=r"robot_joints\.csv.*half-way"):
        analyze(s)


def test_force_log_in_the_wrong_unit(study, tmp_path):
    s = copy(study, tmp_path)
    text = (s / "cnc_forces.csv").read_text().replace("force=N", "force=kgf", 1)
    (s / "cnc_forces.csv").write_text(text)
    with pytest.raises(InputError, match=r"cnc_forces\.csv"):
        analyze(s)


def test_force_log_that_is_not_text(study, tmp_path):
    s = copy(study, tmp_path)
    (s / "robot_forces.csv").write_bytes(bytes(range(256)) * 40)
    with pytest.raises(InputError, match=r"robot_forces\.csv"):
        analyze(s)


def test_force_log_shorter_than_the_toolpath(study, tmp_path):
    s = copy(study, tmp_path)
    lines = (s / "robot_forces.csv").read_text().splitlines()
    (s / "robot_forces.csv").write_text("\n".join(lines[: len(lines) // 3]) + "\n")
    with pytest.raises(InputError, match=r"robot_forces\.csv"):
        analyze(s)


def test_scan_of_the_wrong_part(study, tmp_path):
    s = copy(study, tmp_path)
    other = synthetic_scan(
        Cone(opening_diameter=0.07, wall_angle=math.radians(50), depth=0.04), 100_000, seed=1
    )
    write_ply(other.points, s / "robot_scan.ply")
    # registration or the overlap check refuses it, naming the file
    with pytest.raises(RoboisfError, match=r"robot_scan\.ply"):
        analyze(s)


def test_toolpath_of_another_part(study, tmp_path):
    s = copy(study, tmp_path)
    text = (
        (s / "study.toml").read_text().replace("opening_diameter = 87.0", "opening_diameter = 90.0")
    )
    (s / "study.toml").write_text(text)
    with pytest.raises(InputError, match=r"toolpath\.csv.*not on the nominal"):
        analyze(s)


def test_output_inside_the_study_is_refused(study, tmp_path):
    s = copy(study, tmp_path)
    assert main(["-q", "analyze", str(s), "-o", str(s / "results")]) == 2
    assert not (s / "results").exists()


def test_cli_analyze_writes_everything(study, tmp_path):
    out = tmp_path / "res"
    assert main(["-q", "analyze", str(study), "-o", str(out), "--no-png"]) == 0
    for name in (
        "report.html",
        "contributions.csv",
        "contributions_normal.csv",
        "per_point.parquet",
        "summary.json",
    ):
        assert (out / name).is_file(), name


def test_without_a_joint_log_the_configurations_come_from_ik(study, tmp_path):
    s = copy(study, tmp_path)
    text = (s / "study.toml").read_text().replace('joints = "robot_joints.csv"\n', "")
    (s / "study.toml").write_text(text)
    (s / "robot_joints.csv").unlink()
    with_log = analyze(study)
    with_ik = analyze(s)
    assert with_ik.summary.robot.joint_angles_from == "inverse kinematics of the toolpath"
    # the log holds the commanded angles, so IK of the same toolpath predicts the same VJM term
    a = with_log.per_point.vjm_dn.to_numpy()
    b = with_ik.per_point.vjm_dn.to_numpy()
    assert abs(a - b).max() < 1e-3  # mm; the log is sampled at 20 Hz and interpolated


# -- plausibility across the study's files (issue #11) --------------------------------------------
def _fail_fast(s, match):
    """analyze raises ``match`` before the scans (the long work): scans are removed, so reaching
    them would raise a different error."""
    for name in ("cnc_scan.ply", "robot_scan.ply"):
        # distinct bytes: a robot scan equal to the CNC's is refused first (check_distinct_runs)
        (s / name).write_text(f"ply\nformat ascii 1.0\ncomment {name}\nend_header\n")
    with pytest.raises(InputError, match=match):
        analyze(s)


def test_ball_diameter_that_contradicts_the_toolpath(study, tmp_path):
    s = copy(study, tmp_path)
    text = (s / "study.toml").read_text()
    assert "ball_diameter = 10.0" in text
    (s / "study.toml").write_text(text.replace("ball_diameter = 10.0", "ball_diameter = 12.0"))
    _fail_fast(s, r"study\.toml \[tool\.ball_diameter\].*Ø10 mm ball")


def test_forces_declared_in_kN_but_logged_in_N(study, tmp_path):
    s = copy(study, tmp_path)
    text = (s / "robot_forces.csv").read_text()
    assert "force=N " in text
    (s / "robot_forces.csv").write_text(text.replace("force=N ", "force=kN ", 1))
    _fail_fast(s, r"robot_forces\.csv.*kN.*units")


def test_joint_log_of_another_path(study, tmp_path):
    s = copy(study, tmp_path)
    lines = (s / "robot_joints.csv").read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("time,"))
    out = lines[: head + 1]
    for ln in lines[head + 1 :]:
        v = ln.split(",")
        v[1] = repr(float(v[1]) + 5.0)  # q1 + 5°: the robot is ~0.2 m elsewhere
        out.append(",".join(v))
    (s / "robot_joints.csv").write_text("\n".join(out) + "\n")
    _fail_fast(s, r"robot_joints\.csv.*forward kinematics.*another path")


def test_placement_of_1e9_mm(study, tmp_path):
    s = copy(study, tmp_path)
    text = (s / "study.toml").read_text()
    i = text.index("placement = [") + len("placement = [")
    (s / "study.toml").write_text(text[:i] + "1e9, " + text[text.index(",", i) + 1 :])
    # refused by the plausible range of a placement before the reach check (issue 29)
    with pytest.raises(InputError, match=r"\[robot\.placement\[x\]\].*outside what a real cell"):
        analyze(s)


def test_corrupt_truth_file_fails_before_the_analysis(study, tmp_path):
    s = copy(study, tmp_path)
    f = s / "truth" / "per_point.parquet"
    f.write_bytes(f.read_bytes()[:200])
    _fail_fast(s, r"truth/per_point\.parquet.*not a readable Parquet")


def test_truth_file_without_its_columns(study, tmp_path):
    import pandas as pd

    s = copy(study, tmp_path)
    f = s / "truth" / "per_point.parquet"
    pd.read_parquet(f).drop(columns=["dn_cnc"]).to_parquet(f)
    _fail_fast(s, r"per_point\.parquet \[dn_cnc\].*missing column")


def test_compensate_with_a_corrupt_per_point_parquet(study, tmp_path):
    from roboisf.compensate.study import compensate_study

    res = tmp_path / "res"
    res.mkdir()
    (res / "per_point.parquet").write_bytes(b"PAR1 not really")
    with pytest.raises(InputError, match=r"res/per_point\.parquet.*not a readable Parquet"):
        compensate_study(study, results=res)
    assert (
        main(["-q", "compensate", str(study), "--results", str(res), "-o", str(tmp_path / "o")])
        == 2
    )
    assert not (tmp_path / "o").exists()
