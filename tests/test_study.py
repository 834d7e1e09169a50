"""Study files: validation that reports every problem at once; sensor ↔ tip wrench transforms."""

import math
from pathlib import Path

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames import make_transform, rpy_to_matrix, vertical_tool
from roboisf.study import ForceSensorSpec, StudyError, load_study, pose_to_transform
from roboisf.study.sensors import sensor_forces_to_work, sensor_to_tip, tip_to_sensor

rng = np.random.default_rng(5)


def test_pose_to_transform_units_and_errors():
    T = pose_to_transform([1000.0, 0, -50, 0, 0, 90], field="p")
    np.testing.assert_allclose(T[:3, 3], [1.0, 0, -0.05])
    np.testing.assert_allclose(T[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    with pytest.raises(InputError, match="6 finite numbers"):
        pose_to_transform([1, 2, 3], field="p")


def sensors():
    fixture = ForceSensorSpec(
        Path("f.csv"),
        "fixture",
        make_transform(rpy_to_matrix([0.1, -0.2, 0.7]), [0.01, -0.02, -0.08]),
        "workpiece",
    )
    flange = ForceSensorSpec(
        Path("r.csv"),
        "flange",
        make_transform(rpy_to_matrix([math.pi, 0, 0.3]), [0, 0, -0.19]),
        "tool",
    )
    return fixture, flange


@pytest.mark.parametrize("which", [0, 1], ids=["fixture", "flange"])
def test_sensor_tip_round_trip(which):
    s = sensors()[which]
    W = rng.normal(size=(20, 6)) * [100, 100, 500, 1, 1, 1]
    tip = rng.normal(size=(20, 3)) * 0.05
    R = vertical_tool(rng.uniform(-1, 1, 20))
    back = sensor_to_tip(tip_to_sensor(W, s, tip, R), s, tip, R)
    np.testing.assert_allclose(back, W, atol=1e-10)


@pytest.mark.parametrize("load_on", ["workpiece", "tool"])
@pytest.mark.parametrize("which", [0, 1], ids=["fixture", "flange"])
def test_the_forces_alone_are_the_wrenchs_force_part_bit_for_bit(which, load_on):
    # the force alignment turns only the forces (a 2.3 M-sample log: ~110 MiB of temporaries
    # instead of ~385 through the whole wrench): the same bits as sensor_to_tip's force columns,
    # with one tool orientation and one per sample, signed zeros and large and small values
    s = sensors()[which]
    s = ForceSensorSpec(s.file, s.mount, s.pose, load_on)
    n = 1003
    W = rng.normal(size=(n, 6)) * rng.choice([1e-3, 1.0, 1e3], size=(n, 6))
    W[::5, 0], W[::7, 1] = 0.0, -0.0
    for R in (vertical_tool(0.3), vertical_tool(rng.uniform(-1, 1, n))):
        whole = sensor_to_tip(W, s, rng.normal(size=(n, 3)), R)[:, :3]
        alone = sensor_forces_to_work(W[:, :3], s, R)
        assert alone.shape == (n, 3) and alone.tobytes() == whole.tobytes()


def test_fixture_sensor_by_hand():
    # dynamometer 0.1 m below the work origin, axes aligned, measuring the load on the workpiece.
    s = ForceSensorSpec(Path("f.csv"), "fixture", make_transform(p=[0, 0, -0.1]), "workpiece")
    # tool pushes the sheet straight down with 500 N at the tip (0.03, 0, −0.05)
    F_on_sheet = np.array([0.0, 0, -500])
    tip = np.array([[0.03, 0, -0.05]])
    # sensor reads F and the moment about its origin: r × F with r = tip − sensor = (0.03, 0, 0.05)
    m = np.cross([0.03, 0, 0.05], F_on_sheet)
    W_s = np.r_[F_on_sheet, m][None]
    W_tip = sensor_to_tip(W_s, s, tip, np.eye(3))
    np.testing.assert_allclose(W_tip, [[0, 0, 500, 0, 0, 0]], atol=1e-12)


def write_min_study(root: Path, text: str) -> Path:
    for f in (
        "path.csv",
        "cnc.ply",
        "robot.ply",
        "cnc_f.csv",
        "rob_f.csv",
        "joints.csv",
        "tool.json",
        "holder.json",
    ):
        (root / f).write_text("x")
    (root / "study.toml").write_text(text)
    return root


GOOD = """
[study]
name = "t"
[part]
kind = "cone"
opening_diameter = 87
wall_angle = 71
depth = 50
[tool]
ball_diameter = 10
compliance = "tool.json"
[tool_holder]
compliance = "holder.json"
offset = 66
[robot]
model = "irb7600-500-2.55"
placement = [1800, 0, 500, 0, 0, 0]
[runs.cnc]
machine = "cnc"
toolpath = "path.csv"
scan = "cnc.ply"
[runs.cnc.forces]
file = "cnc_f.csv"
mount = "fixture"
pose = [0, 0, -60, 0, 0, 0]
load_on = "workpiece"
[runs.robot]
machine = "robot"
toolpath = "path.csv"
scan = "robot.ply"
joints = "joints.csv"
forces = { file = "rob_f.csv", mount = "flange", pose = [0, 0, -190, 180, 0, 0], load_on = "tool" }
"""


def test_good_study_loads(tmp_path):
    st = load_study(write_min_study(tmp_path, GOOD))
    assert st.name == "t" and st.cnc.name == "cnc" and st.robot_run.joints.name == "joints.csv"
    assert st.tool.radius == pytest.approx(5e-3)
    assert st.holder.offset == pytest.approx(0.066)
    np.testing.assert_allclose(st.robot.T_base_work[:3, 3], [1.8, 0, 0.5])
    assert st.analysis.rim_band == pytest.approx(0.02)


def test_every_problem_is_reported_at_once(tmp_path):
    bad = (
        GOOD.replace('scan = "cnc.ply"', 'scan = "missing.ply"')
        .replace("wall_angle = 71", "wall_angle = 95")
        .replace('mount = "fixture"', 'mount = "table"')
        .replace("[study]", '[units]\nforce = "lbf"\n[study]\ncolour = 1')
    )
    with pytest.raises(StudyError) as e:
        load_study(write_min_study(tmp_path, bad))
    msg = str(e.value)
    for expected in (
        "runs.cnc.scan",
        "missing.ply",
        "part.wall_angle",
        "runs.cnc.forces.mount",
        "units.force",
        "study.colour",
    ):
        assert expected in msg, expected
    assert len(e.value.problems) == 5


def test_missing_study_file(tmp_path):
    with pytest.raises(InputError, match=r"no study\.toml in this folder"):
        load_study(tmp_path)
    # a mistyped path is said to be missing, not to lack a study.toml
    with pytest.raises(InputError, match=r"no such study folder") as ei:
        load_study(tmp_path / "nope")
    assert ei.value.file == str(tmp_path / "nope")


def test_a_cnc_and_a_robot_run_are_required(tmp_path):
    text = GOOD[: GOOD.index("[runs.robot]")]
    with pytest.raises(StudyError, match="needs a run with machine = 'robot'"):
        load_study(write_min_study(tmp_path, text))
