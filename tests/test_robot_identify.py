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
