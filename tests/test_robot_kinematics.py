"""Robot models and batched kinematics: presets, FK/Jacobian vs finite differences, DH, pinocchio,
py-opw-kinematics, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames import make_transform, rpy_to_matrix
from roboisf.robot import chain_from_dh, list_robots, load_robot, load_urdf, to_urdf
from roboisf.robot.kinematics import chain_fk

TOOL = make_transform(rpy_to_matrix([0.1, -0.2, 0.3]), [0.03, -0.02, 0.35])


def _q(model, n=50, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(model.q_min, model.q_max, (n, 6))


def test_presets_listed_and_load():
    names = list_robots()
    assert {"irb7600-500-2.55", "kr210-r2700-2", "irb4600-60-2.05"} <= set(names)
    m = load_robot("irb7600-500-2.55")
    np.testing.assert_allclose(m.joint_stiffness, [3.73e6, 4.82e6, 4.04e6, 6.38e5, 7.59e5, 4.72e5])
    np.testing.assert_allclose(np.degrees(m.q_min[[1, 2]]), [-60, -180])
    assert m.default_placement is not None


def test_irb7600_opw_equals_design_dh():
    """The IRB 7600 preset is written twice (DH and OPW); both must be the same robot."""
    m = load_robot("irb7600-500-2.55")
    dh = chain_from_dh(
        [0.780, 0, 0, 1.056, 0, 0.250],
        [0.410, 1.075, 0.165, 0, 0, 0],
        [-np.pi / 2, 0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0],
        [0, -np.pi / 2, 0, 0, 0, np.pi],
    )
    q = _q(m)
    np.testing.assert_allclose(chain_fk(dh, q), m.fk(q), atol=1e-12)


def test_abb_home_pose_is_tool0():
    """ABB controller zero: flange ahead at (a1+c3+c4, 0, c1+c2−a2), z forward, x down."""
    m = load_robot("irb7600-500-2.55")
    T = m.fk(np.zeros(6))[0]
    np.testing.assert_allclose(
        T[:3, 3], [0.410 + 1.056 + 0.250, 0, 0.780 + 1.075 + 0.165], atol=1e-12
    )
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, 0], [0, 0, -1], atol=1e-12)
    # positive A2 leans forward (tip moves +x), positive A3 lowers the forearm
    T2 = m.fk(np.radians([0, 5, 0, 0, 0, 0]))[0]
    T3 = m.fk(np.radians([0, 0, 5, 0, 0, 0]))[0]
    assert T2[0, 3] > T[0, 3] and T3[2, 3] < T[2, 3]


@pytest.mark.parametrize("name", ["irb7600-500-2.55", "kr210-r2700-2", "irb4600-60-2.05"])
def test_fk_matches_py_opw_kinematics(name):
    """Controller-angle mapping vs an independent OPW implementation (θ = s·q − offset)."""
    from py_opw_kinematics import KinematicModel, Robot

    m = load_robot(name)
    g = m.opw
    s = m.chain.sign
    km = KinematicModel(
        a1=g.a1,
        a2=g.a2,
        b=g.b,
        c1=g.c1,
        c2=g.c2,
        c3=g.c3,
        c4=g.c4,
        offsets=tuple(float(x) for x in -m.chain.offset * s),
        flip_axes=tuple(bool(x < 0) for x in s),
    )
    q = _q(m, 30)
    T_ref = Robot(km, degrees=False).batch_forward(q).as_matrix()
    np.testing.assert_allclose(m.fk(q), T_ref, atol=1e-12)


@pytest.mark.parametrize("name", ["irb7600-500-2.55", "kr210-r2700-2"])
def test_jacobian_central_differences(name):
    m = load_robot(name).with_tool(TOOL)
    q = _q(m, 20, seed=1) * 0.9
    T, J = m.fk_jacobian(q)
    h = 1e-6
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        Tp, Tm = m.fk(q + dq, check_limits=False), m.fk(q - dq, check_limits=False)
        v = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        dR = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * h)
        W = dR @ np.swapaxes(T[:, :3, :3], 1, 2)  # [ω]×
        w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        np.testing.assert_allclose(J[:, :3, j], v, atol=1e-8)
        np.testing.assert_allclose(J[:, 3:, j], w, atol=1e-8)


@pytest.mark.parametrize("name", ["irb7600-500-2.55", "kr210-r2700-2"])
def test_fk_jacobian_match_pinocchio(tmp_path, name):
    pin = pytest.importorskip("pinocchio")
    m = load_robot(name).with_tool(TOOL)
    f = tmp_path / "r.urdf"
    f.write_text(to_urdf(m))
    pm = pin.buildModelFromUrdf(str(f))
    pd = pm.createData()
    fid = pm.getFrameId("tip")
    q = _q(m, 25, seed=2)
    T, J = m.fk_jacobian(q)
    for n in range(len(q)):
        pin.forwardKinematics(pm, pd, q[n])
        pin.updateFramePlacements(pm, pd)
        Jp = pin.computeFrameJacobian(pm, pd, q[n], fid, pin.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(pd.oMf[fid].homogeneous, T[n], atol=1e-12)
        np.testing.assert_allclose(Jp, J[n], atol=1e-12)
    # and back: the URDF loaded through pinocchio is the same robot
    u = load_urdf(f, tip_frame="tip")
    np.testing.assert_allclose(u.fk(q, check_limits=False), T, atol=1e-12)
    np.testing.assert_allclose(u.jacobian(q, check_limits=False), J, atol=1e-12)
    assert u.stiffness is None


def test_compliance_definition_and_deflection():
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    q = _q(m, 10, seed=3) * 0.8
    J = m.jacobian(q)
    k = m.compliance(q)
    k_ref = np.stack([Jn @ np.diag(1 / m.joint_stiffness) @ Jn.T for Jn in J])
    np.testing.assert_allclose(k, k_ref, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(k, np.swapaxes(k, 1, 2), atol=1e-20)
    W = np.random.default_rng(4).normal(size=(10, 6)) * 300
    np.testing.assert_allclose(
        m.deflection(q, W), np.einsum("nij,nj->ni", k, W), rtol=1e-10, atol=1e-16
    )


def test_with_tool_moves_tip_only():
    m = load_robot("irb7600-500-2.55")
    mt = m.with_tool(TOOL)
    q = _q(m, 5)
    np.testing.assert_allclose(mt.fk(q), m.fk(q) @ TOOL, atol=1e-14)
    assert m.T_flange_tip is not mt.T_flange_tip and np.allclose(m.T_flange_tip, np.eye(4))


# ---------------------------------------------------------------- bad input
def test_unknown_preset_lists_known():
    with pytest.raises(InputError, match=r"irb7600-500-2\.55"):
        load_robot("irb9999")


def test_wrong_joint_count_nan_and_limits():
    m = load_robot("irb7600-500-2.55")
    with pytest.raises(InputError, match=r"\(N, 6\)"):
        m.fk(np.zeros((3, 5)))
    q = np.zeros((3, 6))
    q[1, 2] = np.nan
    with pytest.raises(InputError, match="NaN"):
        m.jacobian(q)
    q = np.zeros((2, 6))
    q[1, 1] = np.radians(90)  # A2 limit is +85°
    with pytest.raises(InputError, match="A2"):
        m.compliance(q)


def test_missing_and_bad_stiffness(tmp_path):
    k = load_robot("kr210-r2700-2")
    q = np.radians([[0, -90, 90, 0, 45, 0]])
    assert k.fk(q).shape == (1, 4, 4)  # kinematics works without stiffness
    with pytest.raises(InputError, match="no joint stiffness"):
        k.compliance(q)
    with pytest.raises(InputError, match="> 0"):
        k.with_stiffness([1e6, 1e6, 0, 1e5, 1e5, 1e5])
    with pytest.raises(InputError, match="> 0"):
        k.with_stiffness([1e6, 1e6, -1, 1e5, 1e5, 1e5])


def test_bad_robot_file(tmp_path):
    f = tmp_path / "r.toml"
    f.write_text(
        'name = "x"\n[kinematics]\ntype = "opw"\na1 = 0.1\n[limits]\n'
        "q_min_deg=[0,0,0,0,0,0]\nq_max_deg=[1,1,1,1,1,1]\n"
    )
    with pytest.raises(InputError, match="missing OPW") as e:
        load_robot(f)
    assert str(f) in str(e.value)


@pytest.mark.parametrize("name", ["irb7600-500-2.55", "kr210-r2700-2", "irb4600-60-2.05"])
def test_opw_closed_form_equals_generic_chain(name):
    from roboisf.robot.kinematics import chain_fk_jacobian

    m = load_robot(name).with_tool(TOOL)
    q = _q(m, 40, seed=9)
    T, J = m.fk_jacobian(q)  # closed form (OPW)
    Tg, Jg = chain_fk_jacobian(m.chain, q, m.T_flange_tip)  # generic sweep
    np.testing.assert_allclose(T, Tg, atol=1e-13)
    np.testing.assert_allclose(J, Jg, atol=1e-13)


def test_urdf_loads_without_pinocchio(tmp_path, monkeypatch):
    """The URDF reader is the standard library's XML parser: pinocchio is only the tests' oracle."""
    import sys

    f = tmp_path / "r.urdf"
    m = load_robot("irb7600-500-2.55")
    f.write_text(to_urdf(m))
    monkeypatch.setitem(sys.modules, "pinocchio", None)  # import pinocchio → ImportError
    u = load_robot(f)
    q = _q(m, 50, seed=2)
    np.testing.assert_allclose(u.fk(q, check_limits=False), m.fk(q), atol=1e-12)


def test_deflection_does_positive_work():
    """A wrench on the tool moves the tip along it: Wᵀ δ = Wᵀ k W > 0 (k_c is PSD)."""
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    q = _q(m, 200, seed=4)
    W = np.random.default_rng(5).normal(size=(200, 6)) * [300, 300, 500, 20, 20, 20]
    work = np.einsum("ni,ni->n", W, m.deflection(q, W))
    assert np.all(work > 0)


ENGINES = ["numpy", "numba"]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["irb7600-500-2.55", "kr210-r2700-2"])
def test_deflection_and_compliance_match_pinocchio(tmp_path, name, engine):
    """δ = J K⁻¹ Jᵀ W and k_c from pinocchio's frame Jacobian, pose by pose, for each engine."""
    pin = pytest.importorskip("pinocchio")
    from roboisf.robot import vjm_kernel

    if engine == "numba" and not vjm_kernel.HAVE_NUMBA:
        pytest.skip("numba not installed")
    m = load_robot(name).with_tool(TOOL)
    if m.stiffness is None:
        m = m.with_stiffness([3.0e6, 4.0e6, 3.5e6, 6.0e5, 7.0e5, 4.5e5])
    f = tmp_path / "r.urdf"
    f.write_text(to_urdf(m))
    pm = pin.buildModelFromUrdf(str(f))
    pd = pm.createData()
    fid = pm.getFrameId("tip")
    q = _q(m, 40, seed=12)
    W = np.random.default_rng(13).normal(size=(40, 6)) * [300, 300, 500, 10, 10, 10]
    d = m.deflection(q, W, backend=engine)
    k = m.compliance(q, backend=engine)
    kinv = np.diag(1.0 / m.joint_stiffness)
    for n in range(len(q)):
        pin.forwardKinematics(pm, pd, q[n])
        pin.updateFramePlacements(pm, pd)
        Jp = pin.computeFrameJacobian(pm, pd, q[n], fid, pin.LOCAL_WORLD_ALIGNED)
        kp = Jp @ kinv @ Jp.T
        np.testing.assert_allclose(k[n], kp, rtol=1e-11, atol=1e-11 * np.abs(kp).max())
        dp = kp @ W[n]
        np.testing.assert_allclose(d[n], dp, rtol=1e-11, atol=1e-11 * np.abs(dp).max())


@pytest.mark.parametrize("engine", ENGINES)
def test_deflection_is_the_fk_displacement_of_the_joint_deflection(engine):
    """Independent of any Jacobian code: joints yield Δq = K⁻¹ JᵀW, so the tip moves by
    FK(q + εΔq) − FK(q) ≈ ε δ (central differences of the FK, O(ε²))."""
    from roboisf.robot import vjm_kernel

    if engine == "numba" and not vjm_kernel.HAVE_NUMBA:
        pytest.skip("numba not installed")
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    q = _q(m, 30, seed=14) * 0.9
    W = np.random.default_rng(15).normal(size=(30, 6)) * [300, 300, 500, 10, 10, 10]
    d = m.deflection(q, W, backend=engine)
    J = m.jacobian(q)
    dq = np.einsum("nji,nj->ni", J, W) / m.joint_stiffness  # joint deflection (rad)
    eps = 1e-3 / np.abs(dq).max()  # a joint step of ~1 mrad
    Tp = m.fk(q + eps * dq, check_limits=False)
    Tm = m.fk(q - eps * dq, check_limits=False)
    v = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * eps)
    dR = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * eps)
    Om = dR @ np.swapaxes(m.fk(q)[:, :3, :3], 1, 2)  # [θ]×
    w = np.stack([Om[:, 2, 1], Om[:, 0, 2], Om[:, 1, 0]], axis=1)
    np.testing.assert_allclose(d[:, :3], v, rtol=0, atol=1e-6 * np.abs(d[:, :3]).max())
    np.testing.assert_allclose(d[:, 3:], w, rtol=0, atol=1e-6 * np.abs(d[:, 3:]).max())
