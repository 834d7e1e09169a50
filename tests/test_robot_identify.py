"""Joint-stiffness identification: recovery within CIs, coverage, non-excited joints, CSV."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames import make_transform
from roboisf.robot import (
    CalibrationData,
    PoorExcitationWarning,
    identify_stiffness,
    load_robot,
    read_calibration_csv,
)

TOOL = make_transform(None, [0.30, 0.10, 0.40])  # an offset calibration tool
SIG = 2e-6


def _experiments(m, n, seed, rot=False):
    rng = np.random.default_rng(seed)
    q = rng.uniform(m.q_min * 0.7, m.q_max * 0.7, (n, 6))
    W = rng.normal(size=(n, 6)) * [1500, 1500, 1500, 150, 150, 150]
    d = m.deflection(q, W)
    d = d + rng.normal(size=d.shape) * SIG
    return CalibrationData(q, W, d if rot else d[:, :3])


def test_recovers_stiffness_within_ci():
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    r = identify_stiffness(m, _experiments(m, 40, 0), sigma_translation=SIG)
    K = m.joint_stiffness
    np.testing.assert_allclose(r.K, K, rtol=0.02)
    assert r.residual_rms == pytest.approx(SIG, rel=0.3)
    assert r.condition_number < 100
    assert not r.weak.any() and r.identified.all()
    # 95 % CI coverage over repeated synthetic campaigns
    hits = []
    for seed in range(1, 60):
        rr = identify_stiffness(m, _experiments(m, 25, seed), sigma_translation=SIG)
        hits.append((rr.K_ci[:, 0] <= K) & (K <= rr.K_ci[:, 1]))
    cover = np.mean(hits)
    assert 0.88 < cover < 0.99


def test_non_excited_joint_is_an_error_or_fixed():
    """At the bare flange translations never see joint 6 (its axis passes through the tip)."""
    m = load_robot("irb7600-500-2.55")
    data = _experiments(m, 30, 5)
    with pytest.raises(InputError, match=r"joint\(s\) \[6\]"):
        identify_stiffness(m, data, sigma_translation=SIG)
    r = identify_stiffness(m, data, sigma_translation=SIG, fixed={5: 4.72e5})
    assert not r.identified[5] and r.K[5] == pytest.approx(4.72e5)
    np.testing.assert_allclose(r.K[:5], m.joint_stiffness[:5], rtol=0.05)


def test_weakly_excited_joint_warns():
    """A tip only 1 mm off the A6 axis and forces only: joint 6 is barely loaded → flagged."""
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0.001, 0.0, 0.05]))
    rng = np.random.default_rng(7)
    q = np.tile(np.radians([0, 10, 10, 0, 60, 0]), (30, 1)) + rng.normal(size=(30, 6)) * 0.02
    W = np.zeros((30, 6))
    W[:, :3] = rng.normal(size=(30, 3)) * 1000
    d = m.deflection(q, W) + rng.normal(size=(30, 6)) * SIG
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = identify_stiffness(m, CalibrationData(q, W, d[:, :3]), sigma_translation=SIG)
    assert r.weak[5]
    assert any(issubclass(x.category, PoorExcitationWarning) for x in w)


def test_calibration_csv_round_trip(tmp_path):
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    data = _experiments(m, 12, 3, rot=True)
    f = tmp_path / "calib.csv"
    rows = np.column_stack(
        [np.degrees(data.q), data.wrench, data.displacement[:, :3] * 1e3, data.displacement[:, 3:]]
    )
    f.write_text(
        "# units: angle=deg length=mm force=N moment=N*m rotation=rad\n# frame: base\n"
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz,rx,ry,rz\n"
        + "\n".join(",".join(f"{v:.17g}" for v in r) for r in rows)
        + "\n"
    )
    back = read_calibration_csv(f, m)
    np.testing.assert_allclose(back.q, data.q, rtol=1e-14)
    np.testing.assert_allclose(back.displacement, data.displacement, rtol=1e-12, atol=1e-20)


def test_calibration_csv_bad_cell(tmp_path):
    f = tmp_path / "calib.csv"
    f.write_text(
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz\n" + ",".join(["0"] * 14 + ["abc"]) + "\n"
    )
    with pytest.raises(InputError) as e:
        read_calibration_csv(f)
    assert "calib.csv:2" in str(e.value)


def test_measured_rotations_make_joint6_identifiable():
    """With rotations measured too, the bare flange identifies all six joints."""
    m = load_robot("irb7600-500-2.55")
    data = _experiments(m, 30, 11, rot=True)
    r = identify_stiffness(m, data, sigma_translation=SIG, sigma_rotation=SIG)
    np.testing.assert_allclose(r.K, m.joint_stiffness, rtol=0.05)
    assert r.identified.all() and not r.weak.any()


def test_too_few_experiments():
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    with pytest.raises(InputError, match="add experiments"):
        identify_stiffness(m, _experiments(m, 2, 0), sigma_translation=SIG)


@pytest.mark.parametrize("dof", [1, 2, 3, 7, 30, 1000])
@pytest.mark.parametrize("confidence", [0.68, 0.9, 0.95, 0.99])
def test_t_quantile_is_scipy_stats_students_t(dof, confidence):
    # the CI's quantile comes from scipy.special (scipy.stats is 0.6 s to import): the oracle is
    # scipy.stats' Student's t, and the 95 % two-sided value at dof 1 is 12.706 (any t table)
    from scipy import stats
    from scipy.special import stdtrit

    p = 0.5 + confidence / 2
    assert stdtrit(dof, p) == pytest.approx(stats.t.ppf(p, dof), rel=1e-13)
    if dof == 1 and confidence == 0.95:
        assert stdtrit(dof, p) == pytest.approx(12.706, abs=5e-4)


# --------------------------------------------------------------------------------------------
# the designed experiment (issue #26): all six joints from a virtual experiment


def _designed(name: str, prior: np.ndarray | None = None):
    from roboisf.robot import load_robot
    from roboisf.robot.identify import design_experiment

    m = load_robot(name)
    if prior is not None:
        m = m.with_stiffness(prior)
    m = m.with_tool(make_transform(None, [0.25, 0.0, 0.306]))  # a bracket off joint 6's axis
    return m, design_experiment(m, m.default_placement, sigma=0.02e-3)


@pytest.mark.parametrize("name", ["irb7600-500-2.55", "kr210-r2700-2"])
def test_designed_experiment_recovers_all_six_joints(name):
    """The design's poses and loads, deflected by a robot whose joints are 0.5–1.5× the prior
    and measured with 0.02 mm noise: every joint within 10 %, the 95 % intervals covering."""
    from roboisf.robot.identify import CalibrationData, identify_stiffness

    prior = (
        None
        if name.startswith("irb7600")
        else 0.6 * np.array([3.73e6, 4.82e6, 4.04e6, 6.38e5, 7.59e5, 4.72e5])
    )  # a guessed prior for a robot without published values
    m, d = _designed(name, prior)
    assert len(d.q) == 24 and np.all(d.rel_se < 0.05)
    rng = np.random.default_rng(7)
    covered = total = 0
    for _ in range(10):
        K_true = m.joint_stiffness * rng.uniform(0.5, 1.5, 6)
        truth = m.with_stiffness(K_true)
        dfl = truth.deflection(d.q, d.wrench, check_limits=False)[:, :3]
        dfl = dfl + rng.normal(0, 0.02e-3, dfl.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no joint weakly excited
            r = identify_stiffness(
                m, CalibrationData(d.q, d.wrench, dfl), sigma_translation=0.02e-3
            )
        np.testing.assert_allclose(r.K, K_true, rtol=0.10)
        covered += int(np.sum((r.K_ci[:, 0] <= K_true) & (K_true <= r.K_ci[:, 1])))
        total += 6
    assert covered >= 0.85 * total, (covered, total)


def test_design_needs_a_point_off_joint_six():
    """A load on joint 6's axis never twists it: the design says so (a bracket is needed)."""
    from roboisf.robot import load_robot
    from roboisf.robot.identify import design_experiment

    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0, 0, 0.306]))
    with pytest.raises(InputError, match=r"joint\(s\) \[6\].*bracket"):
        design_experiment(m, m.default_placement)


def test_design_cli_round_trip(tmp_path):
    """``robot identify --design`` writes the sheet, the program and the expected intervals; the
    sheet filled with a virtual robot's deflections identifies it with ``robot identify``."""
    import tomllib

    import pandas as pd

    from roboisf.cli.main import main
    from roboisf.robot import load_robot, load_stiffness

    out = tmp_path / "design"
    assert main(["-q", "robot", "identify", "--design", "-o", str(out), "--tool", "0,0,306"]) == 0
    assert {p.name for p in out.iterdir()} >= {"experiment.csv", "experiment.mod", "design.toml"}
    des = tomllib.loads((out / "design.toml").read_text(encoding="utf-8"))["design"]
    assert des["tool_mm"] == [250.0, 0.0, 306.0]
    assert "MoveAbsJ" in (out / "experiment.mod").read_text(encoding="utf-8")
    sheet = (out / "experiment.csv").read_text(encoding="utf-8").splitlines()
    t = pd.read_csv(out / "experiment.csv", comment="#")
    q = np.radians(t[[f"q{i}" for i in range(1, 7)]].to_numpy())
    W = t[["Fx", "Fy", "Fz", "Mx", "My", "Mz"]].to_numpy()
    m = load_robot("irb7600-500-2.55").with_tool(make_transform(None, [0.25, 0, 0.306]))
    K_true = m.joint_stiffness * np.array([0.7, 1.2, 0.9, 1.3, 0.8, 1.1])
    dfl = m.with_stiffness(K_true).deflection(q, W, check_limits=False)[:, :3] * 1e3
    head = [ln for ln in sheet if ln.startswith("#") or ln.startswith("q1")]
    rows = [ln for ln in sheet if ln and not ln.startswith("#") and not ln.startswith("q1")]
    filled = [
        r.rstrip(",") + "," + ",".join(f"{v:.5f}" for v in d)
        for r, d in zip(rows, dfl, strict=True)
    ]
    (tmp_path / "measured.csv").write_text("\n".join(head + filled) + "\n", encoding="utf-8")
    k_out = tmp_path / "K.toml"
    args = ["-q", "robot", "identify", str(tmp_path / "measured.csv"), "--tool", "250,0,306"]
    assert main([*args, "-o", str(k_out)]) == 0
    np.testing.assert_allclose(load_stiffness(k_out), K_true, rtol=1e-3)
