"""The virtual cell's truth file: loader, and each effect changes the formed part / logs as its
physics says (known answers: linear VJM scaling, a rigid rotation about the base axis, the
sensor model's affine map, a rigid scan transform)."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from roboisf.cell import at_ball_centre
from roboisf.errors import InputError
from roboisf.study.spec import ForceSensorSpec
from roboisf.virtual.cell import (
    STANDARD_GRAVITY,
    _force_log,
    _scan,
    paper_cone_cell,
    paper_vwacf_cell,
    scan_misregistration,
    simulate,
)
from roboisf.virtual.truth import TruthSpec, load_truth, truth_from_table

FAST = {"step_down": 3e-3, "spacing": 4e-3}

FULL = """
[robot]
joint_stiffness_scale = [0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
link_compliance = true
thermal_drift = [0.0, 0.0, 0.5]
[robot.kinematic_error]
joint_offset = [0.01, 0, 0, 0, 0, 0]
c2 = 0.2
[force_sensor]
bias = [30, 0, 0, 0, 0, 1.5]
gain = 1.02
crosstalk = 0.01
[tool]
mass = 4.0
cog = [0, 0, 150]
[scan]
shift = [0.3, 0, 0]
rotation = [0, 0, 0.2]
[springback]
deflection_coupling = 0.3
[cnc]
compliance = [1e-5, 1e-5, 2e-5]
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "truth.toml"
    p.write_text(text)
    return p


def test_loader_reads_every_key_in_file_units(tmp_path):
    t = load_truth(_write(tmp_path, FULL))
    np.testing.assert_array_equal(t.joint_stiffness_scale, [0.5, 0.6, 0.7, 0.8, 0.9, 1.0])
    assert t.link_compliance
    np.testing.assert_allclose(t.thermal_drift, [0, 0, 0.5e-3])
    assert t.joint_offset[0] == pytest.approx(math.radians(0.01))
    assert t.opw_error == {"c2": pytest.approx(0.2e-3)}
    np.testing.assert_array_equal(t.sensor_bias, [30, 0, 0, 0, 0, 1.5])
    np.testing.assert_array_equal(t.sensor_gain, np.full(6, 1.02))
    assert t.sensor_crosstalk[0, 1] == 0.01 and t.sensor_crosstalk[3, 3] == 0
    assert t.tool_mass == 4.0
    np.testing.assert_allclose(t.tool_cog, [0, 0, 0.15])
    np.testing.assert_allclose(t.scan_shift, [0.3e-3, 0, 0])
    np.testing.assert_allclose(t.scan_rotation, [0, 0, math.radians(0.2)])
    assert t.springback_coupling == 0.3
    np.testing.assert_allclose(t.cnc_compliance, [1e-8, 1e-8, 2e-8])
    assert not t.is_model and t.kinematic_error and not t.sensor_ideal
    # the table written to truth/truth.json reads back to the same truth
    table = t.to_table()
    back = truth_from_table({k: v for k, v in table.items() if k not in ("source", "is_model")})
    np.testing.assert_allclose(back.sensor_crosstalk, t.sensor_crosstalk)
    np.testing.assert_allclose(back.joint_offset, t.joint_offset)
    assert back.opw_error["c2"] == pytest.approx(t.opw_error["c2"])


def test_empty_truth_is_the_model():
    assert TruthSpec().is_model
    assert truth_from_table({}).is_model


@pytest.mark.parametrize(
    ("text", "field", "words"),
    [
        ("[robot]\njoint_stiffnes_scale = 0.5\n", "robot.joint_stiffnes_scale", "unknown key"),
        ("[robots]\nx = 1\n", "robots", "unknown key"),
        ("[robot]\njoint_stiffness_scale = [1, 2]\n", "robot.joint_stiffness_scale", "six"),
        # refused where it is read, with the range a real cell has (roboisf.plausible)
        ("[robot]\njoint_stiffness_scale = -1\n", "robot.joint_stiffness_scale[0]", "0.01 to 100"),
        ("[robot]\nlink_compliance = 1\n", "robot.link_compliance", "true or false"),
        ("[force_sensor]\nbias = [1, 2, 3]\n", "force_sensor.bias", "6 numbers"),
        ("[force_sensor]\ncrosstalk = [[0, 1], [1, 0]]\n", "force_sensor.crosstalk", "6×6"),
        ("[scan]\nshift = 'left'\n", "scan.shift", "3 numbers"),
        ("[springback]\ndeflection_coupling = 1.5\n", "truth.springback_coupling", "[0, 1)"),
        ("[robot.kinematic_error]\nd4 = 0.1\n", "robot.kinematic_error.d4", "unknown key"),
        ("[tool]\nmass = true\n", "tool.mass", "finite number"),
    ],
)
def test_loader_bad_files_name_file_and_key(tmp_path, text, field, words):
    p = _write(tmp_path, text)
    with pytest.raises(InputError) as e:
        load_truth(p)
    assert e.value.field == field
    assert e.value.file == str(p)
    assert words.replace("six", "6 numbers") in str(e.value) or words in str(e.value)


def test_loader_missing_and_broken_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_truth(tmp_path / "nope.toml")
    with pytest.raises(InputError, match="not valid TOML"):
        load_truth(_write(tmp_path, "[robot\n"))


@pytest.fixture(scope="module")
def nominal():
    cell = paper_cone_cell(**FAST)
    return cell, simulate(cell)


def _truth_cell(**truth):
    return paper_cone_cell(**FAST, truth=TruthSpec(**truth))


def test_joint_scale_half_doubles_robot_term(nominal):
    _, t0 = nominal
    t1 = simulate(_truth_cell(joint_stiffness_scale=np.full(6, 0.5)))
    # VJM deflection is linear in K⁻¹ at the same configuration and wrench
    np.testing.assert_array_equal(t1.q, t0.q)
    np.testing.assert_allclose(t1.robot, 2 * t0.robot, rtol=1e-12, atol=1e-15)
    # and only the robot term moves the robot part
    np.testing.assert_allclose(
        t1.dn_robot - t0.dn_robot, np.einsum("ij,ij->i", t0.robot, t0.toolpath.normal), atol=1e-15
    )
    np.testing.assert_array_equal(t1.dn_cnc, t0.dn_cnc)


def test_joint_offset_of_axis_1_rotates_the_tip_about_the_base_axis(nominal):
    cell, t0 = nominal
    eps = math.radians(0.01)
    t1 = simulate(_truth_cell(joint_offset=np.array([eps, 0, 0, 0, 0, 0])))
    # known answer: the whole arm turns by ε about the base z axis (work axes ∥ base axes)
    r = t0.toolpath.tip + cell.cell.T_base_work[:3, 3]
    c, s = math.cos(eps), math.sin(eps)
    expected = np.column_stack([c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1], r[:, 2]]) - r
    np.testing.assert_allclose(t1.robot_kinematic, expected, atol=1e-12)


def test_thermal_drift_grows_linearly_with_time(nominal):
    _, t0 = nominal
    t1 = simulate(_truth_cell(thermal_drift=np.array([0.0, 0.0, 1e-3])))
    tt = t0.toolpath.time
    np.testing.assert_allclose(t1.robot_kinematic[:, 2], 1e-3 * (tt - tt[0]) / (tt[-1] - tt[0]))


def test_cnc_compliance_and_springback_coupling(nominal):
    _, t0 = nominal
    c = np.array([1e-8, 2e-8, 3e-8])
    t1 = simulate(_truth_cell(cnc_compliance=c, springback_coupling=0.25))
    n = t0.toolpath.normal
    cnc = t0.wrench_cnc[:, :3] * c
    np.testing.assert_allclose(t1.cnc_machine, cnc)
    dn_c = np.einsum("ij,ij->i", cnc, n)
    dn_r = np.einsum("ij,ij->i", t0.robot, n)
    # the CNC part: its own deflection, partly recovered by springback
    np.testing.assert_allclose(t1.dn_cnc - t0.dn_cnc, dn_c - 0.25 * dn_c, atol=1e-15)
    # the robot part: springback recovers 25 % of the robot's normal deflection
    np.testing.assert_allclose(t1.dn_robot - t0.dn_robot, -0.25 * dn_r, atol=1e-15)


def _robot_log(cell, truth_cell, truth):
    tp = truth.toolpath
    sensor = ForceSensorSpec(Path("f.csv"), "flange", cell.T_tip_sensor, "tool")
    # the sensor model's algebra on continuous readings (the default counts round it;
    # tests/test_virtual_log_bytes.py)
    cell = dataclasses.replace(cell, force_resolution=(0.0, 0.0))
    return _force_log(
        cell, tp, truth.wrench_robot, sensor, np.random.default_rng(3), truth_cell.truth
    ).wrench


def test_sensor_bias_gain_crosstalk_and_tool_weight(nominal):
    cell, t0 = nominal
    W0 = _robot_log(cell, cell, t0)
    bias = np.array([30.0, -5.0, 2.0, 0.1, -0.2, 1.5])
    Wb = _robot_log(cell, _truth_cell(sensor_bias=bias), t0)
    np.testing.assert_allclose(Wb - W0, np.broadcast_to(bias, W0.shape), atol=1e-9)
    # gain and crosstalk: the affine map of the noisy reading (same noise draw)
    C = 0.01 * (np.ones((6, 6)) - np.eye(6))
    g = np.array([1.02, 0.98, 1.0, 1.01, 1.0, 0.99])
    Wg = _robot_log(cell, _truth_cell(sensor_gain=g, sensor_crosstalk=C), t0)
    np.testing.assert_allclose(Wg, W0 @ (np.diag(g) @ (np.eye(6) + C)).T, rtol=1e-12, atol=1e-9)
    # the tool's weight: |F| = m g, pointing down the work z (= +z of the downward tool)
    Ww = _robot_log(cell, _truth_cell(tool_mass=4.0, tool_cog=np.array([0.0, 0.0, 0.15])), t0)
    dF = (Ww - W0)[:, :3]
    np.testing.assert_allclose(np.linalg.norm(dF, axis=1), 4.0 * STANDARD_GRAVITY, rtol=1e-12)
    # the sensor's z is the tool axis, which points down: the weight is +z in sensor axes
    np.testing.assert_allclose(dF[:, 2], 4.0 * STANDARD_GRAVITY, rtol=1e-12)
    # a centre of gravity on the tool axis puts no moment on the sensor
    np.testing.assert_allclose((Ww - W0)[:, 3:], 0.0, atol=1e-9)


def test_scan_misregistration_moves_the_scan_rigidly(nominal, tmp_path):
    from roboisf.scan.readers import read_scan

    _, t0 = nominal
    shift = np.array([0.3e-3, -0.1e-3, 0.0])
    rot = np.radians([0.0, 0.0, 0.2])
    T = scan_misregistration(TruthSpec(scan_shift=shift, scan_rotation=rot))
    assert T is not None
    assert scan_misregistration(TruthSpec()) is None
    c = paper_cone_cell(**FAST, scan_points=5000, n_holes=0, outlier_fraction=0.0)
    _scan(c, t0, t0.dn_robot, tmp_path / "a.ply", np.random.default_rng(1), 7)
    _scan(c, t0, t0.dn_robot, tmp_path / "b.ply", np.random.default_rng(1), 7, T)
    a = read_scan(tmp_path / "a.ply").points
    b = read_scan(tmp_path / "b.ply").points
    dz, tx, ty = c.misplacement
    from roboisf.frames import make_transform, rpy_to_matrix

    M = make_transform(rpy_to_matrix([tx, ty, 0.0]), [0.0, 0.0, dz])
    # b = M T M⁻¹ a (the same sampled points, moved by the misregistration in work coordinates)
    A = M @ T @ np.linalg.inv(M)
    np.testing.assert_allclose(b, a @ A[:3, :3].T + A[:3, 3], atol=2e-9)
    assert np.max(np.linalg.norm(b - a, axis=1)) > 0.3e-3


def test_link_compliance_adds_the_beams_to_the_joints(nominal):
    from roboisf.virtual.links import link_deflection

    cell, t0 = nominal
    t1 = simulate(_truth_cell(link_compliance=True))
    links = link_deflection(cell.cell.robot, t0.q, t0.wrench_robot, cell.cell.T_base_work)
    links = at_ball_centre(links, cell.cell.tool.radius)
    np.testing.assert_allclose(t1.robot, t0.robot + links, rtol=1e-12, atol=1e-15)
    assert np.mean(np.linalg.norm(links[:, :3], axis=1)) > 0.05 * np.mean(
        np.linalg.norm(t0.robot, axis=1)
    )


# --------------------------------------------------------------------------- the paper scenario


def test_scenario_loads_and_file_keys_override(tmp_path):
    from roboisf.virtual.truth import scenario_table

    cone = load_truth(scenario="paper", part="cone")
    vw = load_truth(scenario="paper", part="vwacf")
    # one robot for both parts
    np.testing.assert_array_equal(cone.joint_stiffness_scale, vw.joint_stiffness_scale)
    assert cone.link_compliance and vw.link_compliance
    assert cone.source == "scenario paper (cone)"
    table = scenario_table("paper", "cone")
    assert truth_from_table(table).springback_coupling == cone.springback_coupling
    over = _write(
        tmp_path,
        "[robot]\njoint_stiffness_scale = 0.5\n[force_sensor]\nbias = [30, 0, 0, 0, 0, 0]\n",
    )
    mixed = load_truth(over, scenario="paper", part="cone")
    np.testing.assert_array_equal(mixed.joint_stiffness_scale, np.full(6, 0.5))
    assert mixed.link_compliance  # the scenario's other [robot] keys stay
    assert mixed.springback_coupling == cone.springback_coupling
    assert mixed.sensor_bias[0] == 30
    with pytest.raises(InputError, match="no scenario 'paper' for the part 'pyramid'"):
        load_truth(scenario="paper", part="pyramid")


def test_cli_truth_errors_exit_2(tmp_path, capsys):
    from roboisf.cli.main import main

    bad = _write(tmp_path, "[robot]\nstiffness = 0.5\n")
    out = tmp_path / "S"
    assert main(["virtual-cell", "cone", "-o", str(out), "--truth", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "robot.stiffness" in err and "unknown key" in err and str(bad) in err
    assert main(["virtual-cell", "pyramid", "-o", str(out), "--scenario", "paper"]) == 2
    assert "--scenario" in capsys.readouterr().err
    assert not out.exists()


def _ideal_book(cell):
    """Per-axis Table 5 of the noise-free truth over the analysed wall (what analyze measures
    up to scan noise and registration), and the truth's robot term per depth."""
    from roboisf.decompose.core import contribution_rows, decompose
    from roboisf.scan import default_rim_band

    t = simulate(cell)
    tp = t.toolpath
    used = tp.depth > default_rim_band(cell.part.depth)
    vjm = cell.cell.robot.deflection(t.q, t.wrench_robot, T_base_work=t.T_base_work)[:, :3]
    d = decompose(
        tp.normal, t.dn_cnc, t.dn_robot, t.tool_cnc, t.tool_robot, t.holder_robot, vjm, used
    )
    rows = {r["factor"]: r for r in contribution_rows(d, projected=False)}
    return t, d, rows


@pytest.mark.parametrize(
    ("part", "share", "springback"), [("cone", 40.28, 1.132), ("vwacf", 59.98, 0.530)]
)
def test_paper_scenario_reproduces_table_5(part, share, springback):
    from roboisf.virtual.cell import PAPER_TABLE5, paper_scenario_cell

    assert PAPER_TABLE5[part]["robot_share_percent"] == share
    assert PAPER_TABLE5[part]["springback_R_m_mm"] == springback
    cell = paper_scenario_cell(part)
    assert not cell.truth.is_model
    t, d, rows = _ideal_book(cell)
    assert rows["robot_compliance"]["share_percent"] == pytest.approx(share, abs=3.0)
    assert rows["springback"]["R_m"] * 1e3 == pytest.approx(springback, rel=0.10)
    # the nominal cell (truth = model) is far from the paper: the scenario is what moves it
    _, _, nominal = _ideal_book(paper_cone_cell() if part == "cone" else paper_vwacf_cell())
    assert nominal["robot_compliance"]["share_percent"] < share - 10
    if part == "cone":
        # the paper: the cone's robot error grows from ~0.3 mm (z = −10 mm) to ~1.3 mm (−100 mm)
        tp = t.toolpath
        rc = d.vectors["robot_compliance"]

        def band(lo, hi):
            s = (tp.depth >= lo) & (tp.depth < hi)
            return float(np.linalg.norm(np.mean(np.abs(rc[s]), axis=0)))

        top, bottom = band(8e-3, 12e-3), band(85e-3, 95e-3)
        assert 0.2e-3 < top < 0.5e-3
        assert 0.9e-3 < bottom < 1.5e-3
        assert bottom > 2.5 * top


def test_study_max_distance_key_and_the_cell_sets_it_when_the_part_deviates_more(tmp_path):
    from dataclasses import replace as dc_replace

    from roboisf.study.spec import StudyError, load_study
    from roboisf.virtual.cell import _max_distance
    from test_study import GOOD, write_min_study

    assert load_study(write_min_study(tmp_path, GOOD)).analysis.max_distance == 3e-3
    text = GOOD.replace("[runs.cnc]", "[analysis]\nmax_distance = 6\n[runs.cnc]")
    assert load_study(write_min_study(tmp_path, text)).analysis.max_distance == pytest.approx(6e-3)
    with pytest.raises(StudyError, match=r"analysis\.max_distance"):
        load_study(write_min_study(tmp_path, text.replace("max_distance = 6", "max_distance = -1")))
    t0 = simulate(paper_cone_cell(**FAST))
    assert _max_distance(t0) == {}  # the nominal cone stays well inside 3 mm
    big = dc_replace(t0, dn_robot=t0.dn_robot + 2e-3)
    worst = float(np.max(np.abs(big.dn_robot)))
    got = _max_distance(big)["max_distance"]
    assert got >= (worst + 2e-3) * 1e3 and got < (worst + 2e-3) * 1e3 + 1


def test_crosstalk_keys_state_their_units():
    """``crosstalk_force`` (N per N) fills the force-to-force block, ``crosstalk_moment`` (mm =
    N·m per kN) the force-to-moment block in m; nothing else; both add to ``crosstalk``."""
    from roboisf.virtual.truth import truth_from_table

    t = truth_from_table({"force_sensor": {"crosstalk_force": 0.02, "crosstalk_moment": 3.0}})
    C = t.sensor_crosstalk
    off = np.ones((3, 3)) - np.eye(3)
    np.testing.assert_array_equal(C[:3, :3], 0.02 * off)
    np.testing.assert_array_equal(C[3:, :3], np.full((3, 3), 3e-3))
    np.testing.assert_array_equal(C[:, 3:], 0.0)
    # 1000 N on Fz reads 3 N·m on every moment channel and 20 N on Fx, Fy
    r = t.sensor_matrix() @ np.array([0, 0, 1000.0, 0, 0, 0])
    np.testing.assert_allclose(r, [20, 20, 1000, 3, 3, 3])
    both = truth_from_table(
        {"force_sensor": {"crosstalk": 0.001, "crosstalk_moment": 1.0}}
    ).sensor_crosstalk
    assert both[3, 0] == pytest.approx(0.002) and both[0, 3] == 0.001
    with pytest.raises(InputError, match="crosstalk_moment"):
        truth_from_table({"force_sensor": {"crosstalk_moment": "x"}})
