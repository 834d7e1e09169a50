"""Presets against independent URDFs (pinocchio), the URDF reader (passive/mimic joints, OPW
extraction), FANUC's J2/J3 coupling, and ``roboisf robot list``.

The URDFs in tests/data/urdf are public robot descriptions (origins in tests/data/urdf/README.md).
"""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.robot import list_robots, load_robot, load_urdf
from roboisf.robot.opw_fit import fit_opw
from roboisf.robot.presets import preset_info
from roboisf.robot.urdf import read_urdf_arm

pin = pytest.importorskip("pinocchio")

URDF = Path(__file__).parent / "data" / "urdf"

# preset → (URDF file, J23 coupling of the pendant angles: q3_urdf = q3 + c·q2)
PRESET_URDF = {
    "irb4600-60-2.05": ("irb4600_60_205.urdf", 0.0),
    "irb6640-185-2.80": ("irb6640_185_280.urdf", 0.0),
    "irb6700-200-2.60": ("irb6700_200_260.urdf", 0.0),
    "kr210-r2700-2": ("kr210_r2700_2.urdf", 0.0),
    "kr240-r2900-2": ("kr240_r2900_2.urdf", 0.0),
    "kr500-r2800-2": ("kr500_r2800_2.urdf", 0.0),
    "r2000ic-210f": ("r2000ic210f.urdf", 1.0),
    "m900ib-700": ("m900ib700.urdf", 1.0),
}
#: URDFs whose angles are rounded in the file (their OPW model is snapped, not the file to 1e-9:
#: tests/test_robot_urdf_rounding.py)
ROUNDED = {"m0609.urdf"}
ALL_URDFS = sorted(p.name for p in URDF.glob("*.urdf") if p.name not in ROUNDED)


def _pin_fk(urdf: Path, q_urdf: np.ndarray, frame: str = "tool0") -> np.ndarray:
    """``T_base_frame`` (N, 4, 4) by pinocchio; joints not named joint_1..6 (passive) at 0."""
    m = pin.buildModelFromUrdf(str(urdf))
    d = m.createData()
    names = read_urdf_arm(urdf).joints
    idx = [m.joints[m.getJointId(n)].idx_q for n in names]
    fid = m.getFrameId(frame)
    out = np.empty((len(q_urdf), 4, 4))
    for k, qk in enumerate(q_urdf):
        qq = pin.neutral(m)
        qq[idx] = qk
        pin.framesForwardKinematics(m, d, qq)
        out[k] = d.oMf[fid].homogeneous
    return out


def _q(model, n, seed):
    return np.random.default_rng(seed).uniform(model.q_min, model.q_max, (n, 6))


def test_every_preset_has_a_reference():
    assert set(PRESET_URDF) | {"irb7600-500-2.55"} == set(list_robots())


@pytest.mark.parametrize("name", sorted(PRESET_URDF))
def test_preset_fk_equals_its_urdf(name):
    """FK of the preset (controller angles) = pinocchio FK of the public URDF, 1,000 poses."""
    f, c23 = PRESET_URDF[name]
    m = load_robot(name)
    q = _q(m, 1000, seed=zlib.crc32(name.encode()) % 1000)  # hash() varies per run
    q_urdf = q.copy()
    q_urdf[:, 2] += c23 * q[:, 1]  # FANUC: the ROS/URDF J3 is the pendant's J3 + J2
    T = m.fk(q)
    Tp = _pin_fk(URDF / f, q_urdf)
    assert np.max(np.abs(T[:, :3, 3] - Tp[:, :3, 3])) < 1e-9
    assert np.max(np.abs(T[:, :3, :3] - Tp[:, :3, :3])) < 1e-9
    if c23 == 0:
        # and the limits are the URDF's (rounded to 0.1°; IRB 4600 axis 5 from the data sheet)
        arm = read_urdf_arm(URDF / f)
        lo, hi = np.degrees(arm.q_min), np.degrees(arm.q_max)
        assert np.max(np.abs(np.degrees(m.q_min) - lo)) < 0.15 or name.startswith("irb4600")
        assert np.max(np.abs(np.degrees(m.q_max) - hi)) < 0.15 or name.startswith("irb4600")


def test_fanuc_coupling_is_needed():
    """Without the J2/J3 coupling the FANUC preset does not match the URDF (the test can fail)."""
    m = load_robot("m900ib-700")
    q = _q(m, 50, seed=3)
    Tp = _pin_fk(URDF / "m900ib700.urdf", q)  # pendant angles given straight to the URDF
    assert np.max(np.abs(m.fk(q)[:, :3, 3] - Tp[:, :3, 3])) > 1e-2


def test_issue_15_corrections():
    g = load_robot("kr210-r2700-2").opw
    assert g is not None
    assert (g.a1, g.c1, g.a2, g.c2, g.c3, g.c4) == (0.33, 0.645, -0.115, 1.15, 1.22, 0.215)
    m = load_robot("irb4600-60-2.05")
    assert np.degrees(m.q_min[4]) == pytest.approx(-125) and np.degrees(m.q_max[4]) == (
        pytest.approx(120)
    )


def test_irb7600_preset_against_the_150_350_urdf():
    """No public URDF of the 500/2.55: the 150/3.50's differs only in the forearm length c3."""
    arm = read_urdf_arm(URDF / "irb7600_150_350.urdf")
    fit = fit_opw(arm.chain, arm.q_min, arm.q_max)
    assert fit is not None
    ch, g = fit
    m = load_robot("irb7600-500-2.55")
    p = m.opw
    assert p is not None
    for k in ("a1", "a2", "b", "c1", "c2", "c4"):
        assert getattr(g, k) == pytest.approx(getattr(p, k), abs=1e-12), k
    assert g.c3 == pytest.approx(2.012) and p.c3 == pytest.approx(1.056)
    np.testing.assert_array_equal(ch.sign, m.chain.sign)
    np.testing.assert_allclose(ch.offset, m.chain.offset, atol=1e-12)
    np.testing.assert_allclose(arm.q_min, m.q_min, atol=1e-3)
    np.testing.assert_allclose(arm.q_max, m.q_max, atol=1e-3)


@pytest.mark.parametrize("f", ALL_URDFS)
def test_load_urdf_equals_pinocchio_and_fits_opw(f):
    """Every URDF (passive/mimic branches included) loads; FK = pinocchio; OPW form found."""
    u = load_urdf(URDF / f)
    assert u.opw is not None, f
    q = _q(u, 300, seed=5)
    Tp = _pin_fk(URDF / f, q)
    T = u.fk(q)
    assert np.max(np.abs(T - Tp)) < 1e-9
    # the generic chain (no OPW) is the same robot too
    g = load_urdf(URDF / f, opw=False)
    assert g.opw is None
    assert np.max(np.abs(g.fk(q) - Tp)) < 1e-9


def test_passive_joints_are_named():
    arm = read_urdf_arm(URDF / "irb6640_185_280.urdf")
    assert arm.joints == [f"joint_{i}" for i in range(1, 7)]
    assert {"joint_cylinder", "joint_piston"} <= set(arm.skipped)
    u = load_urdf(URDF / "m900ia260l.urdf")
    assert "pjoint_1" in u.source and "skipped" in u.source


def test_mimic_joint_on_the_tool_chain_is_refused(tmp_path):
    text = (URDF / "irb4600_60_205.urdf").read_text()
    text = text.replace(
        '<joint type="revolute" name="joint_6">',
        '<joint type="revolute" name="joint_6">\n    <mimic joint="joint_5" multiplier="1"/>',
    )
    f = tmp_path / "bad.urdf"
    f.write_text(text)
    with pytest.raises(InputError, match=r"joint_6.*mimics"):
        load_urdf(f)
    f.write_text("<robot><link name='a'/>")
    with pytest.raises(InputError, match="not valid XML"):
        load_urdf(f)


def test_non_opw_chain_gets_no_opw(tmp_path):
    """A wrist whose axes do not meet is not OPW: fit_opw says None (FK check, not guessed)."""
    text = (URDF / "irb4600_60_205.urdf").read_text()
    # shift joint 6 sideways by 5 cm: axes 4, 5, 6 no longer meet
    import re

    text = re.sub(
        r'(<joint type="revolute" name="joint_6">\s*<origin xyz=")([^"]*)"',
        lambda mm: mm.group(1) + '0.135 0.05 0"',
        text,
    )
    f = tmp_path / "skew.urdf"
    f.write_text(text)
    u = load_urdf(f)
    assert u.opw is None


def test_fanuc_jacobian_and_torque_mapping():
    """J with respect to the pendant angles (col 2 += col 3) = finite differences of FK; the
    VJM deflection = δ of pinocchio's URDF Jacobian through the coupling, J_q = J_urdf A."""
    m = load_robot("r2000ic-210f").with_stiffness([4e6, 4e6, 3e6, 6e5, 6e5, 4e5])
    q = _q(m, 20, seed=8)
    _, J = m.fk_jacobian(q)
    h = 1e-7
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        Tp, Tm = m.fk(q + dq, check_limits=False), m.fk(q - dq, check_limits=False)
        v = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:, :3, j], v, atol=1e-6)
    # pinocchio: Jacobian of the URDF at q_urdf = A q, LOCAL_WORLD_ALIGNED at tool0
    pm = pin.buildModelFromUrdf(str(URDF / "r2000ic210f.urdf"))
    pd = pm.createData()
    fid = pm.getFrameId("tool0")
    A = np.eye(6)
    A[2, 1] = 1.0
    W = np.array([150.0, -80.0, 450.0, 5.0, -3.0, 1.0])
    d = m.deflection(q, W)
    for k in range(len(q)):
        qq = A @ q[k]
        Jp = pin.computeFrameJacobian(pm, pd, qq, fid, pin.LOCAL_WORLD_ALIGNED)
        Jq = Jp @ A
        dk = Jq @ ((Jq.T @ W) / m.stiffness)
        np.testing.assert_allclose(d[k], dk, rtol=1e-10, atol=1e-15)


def test_fanuc_ik_round_trip():
    from roboisf.robot import opw_ik

    m = load_robot("m900ib-700")
    q = _q(m, 200, seed=11)
    T = m.fk(q)
    for br in (("front", "up", "noflip"), ("front", "up", "flip")):
        qi, ok = opw_ik(m, T, shoulder=br[0], elbow=br[1], wrist=br[2])
        np.testing.assert_allclose(m.fk(qi[ok], check_limits=False), T[ok], atol=1e-9)


def test_geometric_stiffness_with_coupling():
    from roboisf.robot import geometric_stiffness

    m = load_robot("r2000ic-210f")
    q = _q(m, 5, seed=1)
    W = np.array([100.0, 50.0, -300.0, 2.0, 1.0, -1.0])
    K = geometric_stiffness(m, q, W)
    h = 1e-6
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        tp = np.einsum("nij,i->nj", m.jacobian(q + dq, check_limits=False), W)
        tm = np.einsum("nij,i->nj", m.jacobian(q - dq, check_limits=False), W)
        np.testing.assert_allclose(K[:, :, j], (tp - tm) / (2 * h), atol=1e-4)


def test_preset_info_and_list(capsys):
    from roboisf.cli.main import main

    i = preset_info("kr210-r2700-2")
    g = load_robot("kr210-r2700-2").opw
    assert i.reach_m == pytest.approx(0.33 + 1.15 + np.hypot(0.115, 1.22))
    assert i.payload_kg == 210 and i.stiffness_source is None
    assert preset_info("irb7600-500-2.55").stiffness_source is not None
    assert g is not None
    assert main(["robot", "list"]) == 0
    out = capsys.readouterr().out
    for name in list_robots():
        assert name in out
    assert (
        "unknown — identify" in out and "2.705" in out and "kroshu/kuka_robot_descriptions" in out
    )


def test_unknown_stiffness_points_to_identify():
    m = load_robot("kr240-r2900-2")
    with pytest.raises(InputError, match="roboisf robot identify"):
        m.deflection(np.zeros((1, 6)) + np.radians([0, -90, 90, 0, 30, 0]), np.zeros(6))


@pytest.mark.parametrize("name", ["m900ib-700", "r2000ic-210f"])
def test_fanuc_compiled_kernels_equal_numpy(name):
    """The compiled VJM, IK and plan kernels carry the J2/J3 coupling: same numbers as numpy."""
    pytest.importorskip("numba")
    from roboisf.frames import make_transform
    from roboisf.parts import Cone
    from roboisf.robot import ik_toolpath
    from roboisf.robot.ik_numba import path_vjm
    from roboisf.toolpath import step_down

    m = (
        load_robot(name)
        .with_tool(make_transform(None, [0, 0, 0.3]))
        .with_stiffness([4e6, 4e6, 3e6, 6e5, 6e5, 4e5])
    )
    rng = np.random.default_rng(0)
    q = rng.uniform(m.q_min, m.q_max, (2000, 6))
    W = rng.normal(0, 300, (2000, 6))
    dp = m.deflection(q, W, backend="numpy")
    assert np.max(np.abs(m.deflection(q, W, backend="numba") - dp)) <= 1e-14 * np.abs(dp).max()
    kp = m.compliance(q, backend="numpy")
    assert np.max(np.abs(m.compliance(q, backend="numba") - kp)) <= 1e-14 * np.abs(kp).max()
    tp = step_down(Cone(), step_down=5e-3)
    a = ik_toolpath(m, tp.tip, backend="numba", singular_threshold=None)
    b = ik_toolpath(m, tp.tip, backend="numpy", singular_threshold=None)
    assert np.max(np.abs(a.q - b.q)) < 1e-12
    np.testing.assert_allclose(m.fk(a.q), a.T_base_tip, atol=1e-9)
    P = m.default_placement
    Ww = np.array([100.0, 50.0, 400.0, 0.0, 0.0, 0.0])
    g = m.opw
    assert g is not None
    r = path_vjm(m, tp.tip, P, np.zeros(1), Ww[None], None, (g.c2 + g.c3, 0.02))
    assert r.status == 0 and r.d_robot is not None
    d = m.deflection(b.q, Ww, T_base_work=P, backend="numpy")
    assert np.max(np.abs(r.q - b.q)) < 1e-12
    assert np.max(np.abs(r.d_robot - d[:, :3])) < 1e-15


def test_couple23_must_be_a_linkage_factor(tmp_path):
    text = (Path(__file__).parents[1] / "src/roboisf/robot/presets/m900ib-700.toml").read_text(
        encoding="utf-8"
    )
    f = tmp_path / "bad.toml"
    f.write_text(text.replace("couple23 = 1", "couple23 = 0.5"), encoding="utf-8")
    with pytest.raises(InputError, match="couple23"):
        load_robot(f)
