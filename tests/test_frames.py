"""Frames: SE(3) identities, wrench transforms (adjoint, power invariance), compliance assembly."""

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames import (
    RIGID_TOL,
    abc_to_matrix,
    adjoint,
    check_compliance,
    check_rigid,
    check_rotation,
    compose,
    invert,
    make_transform,
    matrix_to_abc,
    matrix_to_quat,
    matrix_to_rpy,
    point_jacobian,
    quat_to_matrix,
    robot_part,
    rot_x,
    rot_y,
    rot_z,
    rotvec_to_matrix,
    rpy_to_matrix,
    serial_assembly,
    shift_wrench,
    skew,
    to_tip,
    transform_compliance,
    transform_points,
    transform_wrench,
    unskew,
    wrench_transform_matrix,
)

rng = np.random.default_rng(7)


def random_T(n=None):
    shape = () if n is None else (n,)
    R = rotvec_to_matrix(rng.normal(size=(*shape, 3)))
    return make_transform(R, rng.normal(size=(*shape, 3)))


def random_spd(n=6):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def test_skew_is_cross_product_and_unskew_inverts():
    v, u = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", skew(v), u), np.cross(v, u), atol=1e-14)
    np.testing.assert_allclose(unskew(skew(v)), v, atol=1e-15)


def test_invert_and_compose_batched():
    T = random_T(10)
    I = compose(T, invert(T))
    np.testing.assert_allclose(I, np.broadcast_to(np.eye(4), I.shape), atol=1e-13)
    np.testing.assert_allclose(invert(T), np.linalg.inv(T), atol=1e-12)


def test_transform_points_matches_homogeneous_product():
    T = random_T()
    p = rng.normal(size=(7, 3))
    ph = np.c_[p, np.ones(7)] @ T.T
    np.testing.assert_allclose(transform_points(T, p), ph[:, :3], atol=1e-14)


def test_adjoint_maps_rigid_velocity_fields():
    # A twist V_b = [v; ω] at b's origin moves a point x_b with v + ω × x_b; the same motion
    # expressed in a must move T_a_b x_b with the a-frame velocity.
    T = random_T()
    V_b = rng.normal(size=6)
    x_b = rng.normal(size=3)
    vel_b = V_b[:3] + np.cross(V_b[3:], x_b)
    V_a = adjoint(T) @ V_b
    x_a = transform_points(T, x_b[None])[0]
    vel_a = V_a[:3] + np.cross(V_a[3:], x_a)
    np.testing.assert_allclose(vel_a, T[:3, :3] @ vel_b, atol=1e-13)


def test_adjoint_is_a_homomorphism():
    A, B = random_T(), random_T()
    np.testing.assert_allclose(adjoint(A @ B), adjoint(A) @ adjoint(B), atol=1e-12)


def test_wrench_transform_is_inverse_transpose_adjoint():
    T_t_s = random_T(4)
    W_s = rng.normal(size=(4, 6))
    W_t = transform_wrench(W_s, T_t_s)
    X = np.swapaxes(np.linalg.inv(adjoint(T_t_s)), -1, -2)
    np.testing.assert_allclose(W_t, np.einsum("nij,nj->ni", X, W_s), atol=1e-12)
    np.testing.assert_allclose(wrench_transform_matrix(invert(T_t_s)), X, atol=1e-12)


def test_wrench_transform_matches_issue_formula():
    # f_t = R f_s, m_t = R (m_s + (p_s − p_t) × f_s), p's in sensor coordinates.
    T_t_s = random_T()
    R = T_t_s[:3, :3]
    W_s = rng.normal(size=6)
    p_t_in_s = invert(T_t_s)[:3, 3]  # tip origin in sensor coordinates
    p_s_in_s = np.zeros(3)
    f = R @ W_s[:3]
    m = R @ (W_s[3:] + np.cross(p_s_in_s - p_t_in_s, W_s[:3]))
    np.testing.assert_allclose(transform_wrench(W_s, T_t_s), np.r_[f, m], atol=1e-13)


def test_power_is_frame_invariant():
    T_t_s = random_T()
    W_s = rng.normal(size=6)
    V_s = rng.normal(size=6)
    V_t = adjoint(T_t_s) @ V_s
    W_t = transform_wrench(W_s, T_t_s)
    assert np.isclose(V_t @ W_t, V_s @ W_s, rtol=1e-12)


def test_shift_wrench_hand_example():
    # 10 N along x applied at (0, 0, 1): about the origin it gives m = r × f = (0, 10, 0)
    W = np.array([10.0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(shift_wrench(W, [0, 0, 1.0], [0, 0, 0]), [10, 0, 0, 0, 10, 0])


# -- rotations: hand-worked examples -------------------------------------------------------------


def test_elementary_rotations_by_hand():
    np.testing.assert_allclose(rot_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rot_x(np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(rot_y(np.pi / 2) @ [0, 0, 1], [1, 0, 0], atol=1e-15)


def test_rpy_is_z_y_x_intrinsic():
    rpy = np.array([0.1, -0.4, 2.0])
    np.testing.assert_allclose(
        rpy_to_matrix(rpy), rot_z(2.0) @ rot_y(-0.4) @ rot_x(0.1), atol=1e-15
    )
    np.testing.assert_allclose(matrix_to_rpy(rpy_to_matrix(rpy)), rpy, atol=1e-12)


def test_kuka_abc_hand_example():
    # A = 90°: tool x-axis points along base y
    R = abc_to_matrix(np.radians([90.0, 0.0, 0.0]))
    np.testing.assert_allclose(R[:, 0], [0, 1, 0], atol=1e-15)
    # C = 180° (B = A = 0): tool z points down (−z), the usual "tool vertical" ABC = 0, 0, 180
    R = abc_to_matrix(np.radians([0.0, 0.0, 180.0]))
    np.testing.assert_allclose(R[:, 2], [0, 0, -1], atol=1e-15)
    abc = np.radians([30.0, -20.0, 170.0])
    np.testing.assert_allclose(matrix_to_abc(abc_to_matrix(abc)), abc, atol=1e-12)


def test_abb_quaternion_hand_examples():
    # ABB q1..q4 = (w, x, y, z). 180° about x: [0, 1, 0, 0] flips y and z.
    np.testing.assert_allclose(quat_to_matrix([0, 1, 0, 0]), np.diag([1.0, -1, -1]), atol=1e-15)
    # 90° about z: [cos45, 0, 0, sin45]
    c = np.sqrt(0.5)
    np.testing.assert_allclose(quat_to_matrix([c, 0, 0, c]), rot_z(np.pi / 2), atol=1e-15)
    q = matrix_to_quat(rot_z(np.pi / 2))
    np.testing.assert_allclose(q, [c, 0, 0, c], atol=1e-15)
    R = rotvec_to_matrix(rng.normal(size=(5, 3)))
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(R)), R, atol=1e-13)
    assert np.all(matrix_to_quat(R)[:, 0] >= 0)


def test_zero_quaternion_is_an_error():
    with pytest.raises(ValueError):
        quat_to_matrix([0, 0, 0, 0])


# -- compliance ----------------------------------------------------------------------------------


def test_point_jacobian_moves_rotation_to_tip():
    # a rotation θ about z at a point 1 m behind the tip along −x moves the tip by θ × v = +y
    v = np.array([1.0, 0, 0])  # tip − point
    d = point_jacobian(v) @ np.r_[0, 0, 0, 0, 0, 1e-3]
    np.testing.assert_allclose(d, [0, 1e-3, 0, 0, 0, 1e-3], atol=1e-15)


def test_to_tip_is_the_adjoint_of_the_translation():
    k = random_spd()
    v = rng.normal(size=3)
    T_tip_point = make_transform(p=-v)  # point's origin in tip coordinates is −v
    np.testing.assert_allclose(to_tip(k, v), transform_compliance(k, T_tip_point), atol=1e-12)


def test_point_load_on_a_chain_matches_direct_computation():
    # Two torsion-free "elbow" springs on a chain: spring 1 at p1 with rotational compliance c1
    # about z, spring 2 at p2 with translational compliance c2 along y. A tip force F (y) is
    # resisted directly: spring 1 sees moment (tip − p1) × F, rotates, moves the tip by θ × r.
    p1, p2, tip = np.array([0.0, 0, 0]), np.array([0.5, 0, 0]), np.array([1.2, 0, 0])
    c1, c2 = 2e-6, 3e-7
    k1 = np.zeros((6, 6))
    k1[5, 5] = c1
    k2 = np.zeros((6, 6))
    k2[1, 1] = c2
    F = np.array([0, 100.0, 0])
    # direct: spring 1 rotation θz = c1 * Mz, Mz = (tip − p1)_x * Fy
    theta = c1 * (tip - p1)[0] * F[1]
    tip_disp_direct = np.array([0, theta * (tip - p1)[0] + c2 * F[1], 0])
    k_tip = serial_assembly([(k1, tip - p1), (k2, tip - p2)])
    d = k_tip @ np.r_[F, 0, 0, 0]
    np.testing.assert_allclose(d[:3], tip_disp_direct, rtol=1e-12)
    np.testing.assert_allclose(d[5], theta, rtol=1e-12)


def test_serial_assembly_keeps_spd_and_robot_part_inverts_it():
    kr, kth, kt = random_spd() * 1e-6, random_spd() * 1e-7, random_spd() * 1e-8
    vth, vt = rng.normal(size=3), rng.normal(size=3)
    kef = serial_assembly([(kr, np.zeros(3)), (kth, vth), (kt, vt)])
    assert np.allclose(kef, kef.T, rtol=0, atol=1e-20)
    assert np.all(np.linalg.eigvalsh(kef) > 0)
    np.testing.assert_allclose(robot_part(kef, [(kth, vth), (kt, vt)]), kr, atol=1e-18)


def test_serial_assembly_batched():
    k = np.stack([random_spd() for _ in range(3)])
    v = rng.normal(size=(3, 3))
    out = serial_assembly([(k, v)])
    for i in range(3):
        np.testing.assert_allclose(out[i], to_tip(k[i], v[i]), atol=1e-12)


def test_check_compliance_rejects_bad_matrices():
    with pytest.raises(InputError, match="6×6"):
        check_compliance(np.eye(5))
    bad = np.eye(6)
    bad[0, 1] = 1.0
    with pytest.raises(InputError, match="symmetric"):
        check_compliance(bad)
    with pytest.raises(InputError, match="positive"):
        check_compliance(-np.eye(6))
    with pytest.raises(InputError, match="NaN"):
        check_compliance(np.full((6, 6), np.nan))
    ok = check_compliance(random_spd())
    assert ok.shape == (6, 6)


def test_vertical_tool_by_hand():
    from roboisf.frames import vertical_tool

    R = vertical_tool(0.0)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 0, -1], atol=1e-15)  # tool z points down
    np.testing.assert_allclose(vertical_tool(0.3), rot_x(np.pi) @ rot_z(0.3), atol=1e-15)
    assert vertical_tool(np.zeros(4)).shape == (4, 3, 3)


# -- the one rigid-transform check --------------------------------------------------------------


def test_check_rigid_accepts_rigid_transforms_and_returns_floats():
    T = random_T(5)
    np.testing.assert_array_equal(check_rigid(T, "T"), T)
    out = check_rigid(np.eye(4, dtype=int), "T")
    assert out.dtype == np.float64
    # a 45° rotation typed with seven decimals is rigid within RIGID_TOL
    c = 0.7071068
    T45 = [[c, -c, 0, 0.1], [c, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    check_rigid(T45, "T_base_work")
    assert RIGID_TOL == 1e-6


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (lambda T: T @ np.diag([1.0, 1.0, -1.0, 1.0]), "det R = -1"),  # a mirror
        (lambda T: T @ np.diag([2.0, 1.0, 1.0, 1.0]), r"max \|R Rᵀ − I\|"),  # a scale
        (lambda T: T @ np.diag([0.0, 1.0, 1.0, 1.0]), "det R = 0"),  # degenerate
        (lambda T: T + np.diag([0.0, 0.0, 0.0, 1.0]), "last row"),
        (lambda T: T + np.r_[np.zeros((3, 4)), [[0.0, 0.0, 1e-12, 0.0]]], "last row"),
        (lambda T: np.where(np.eye(4) > 0, np.nan, T), "not finite"),
    ],
)
def test_check_rigid_names_what_is_wrong(damage, why):
    T = random_T()
    with pytest.raises(InputError, match=rf"\[T_flange_tip\]: must be a rigid transform.*{why}"):
        check_rigid(damage(T), "T_flange_tip", file="robot.toml")
    with pytest.raises(InputError, match=r"^robot\.toml"):
        check_rigid(damage(T), "T_flange_tip", file="robot.toml")


def test_check_rigid_has_one_tolerance_and_names_the_batch_index():
    T = random_T(4)
    E = np.zeros((3, 3))
    E[0, 1] = 0.8 * RIGID_TOL  # R Rᵀ − I ≈ E + Eᵀ: off-diagonal 0.8 × tolerance
    ok = T.copy()
    ok[2, :3, :3] = (np.eye(3) + E) @ T[2, :3, :3]
    check_rigid(ok, "F")
    bad = T.copy()
    bad[2, :3, :3] = (np.eye(3) + 2 * E) @ T[2, :3, :3]  # 1.6 × tolerance
    with pytest.raises(InputError, match="at index 2"):
        check_rigid(bad, "F")
    with pytest.raises(InputError, match=r"4×4 transform, got shape \(3, 3\)"):
        check_rigid(np.eye(3), "F")


def test_check_rotation_refuses_a_mirror_in_a_batch():
    R = rot_z(np.linspace(0, 1, 3))
    np.testing.assert_array_equal(check_rotation(R, "R_work_tool"), R)
    R[1] = R[1] @ np.diag([1.0, -1.0, 1.0])
    with pytest.raises(InputError, match=r"\[R_work_tool\].*det R = -1 at index 1"):
        check_rotation(R, "R_work_tool")


@pytest.mark.parametrize("where", ["robot", "cell", "program", "chain", "sensor"])
def test_every_transform_input_uses_the_one_check(where):
    # every consumer accepts a transform 0.5 × RIGID_TOL from orthonormal (the robot model, the
    # cell, the chain and the sensor refused 1e-9 before) and refuses one 2 × RIGID_TOL away
    # with the same message: one check, one tolerance
    from roboisf.robot import load_robot

    model = load_robot("irb4600-60-2.05")

    def consume(scale):
        E = np.eye(4)
        E[0, 1] = scale * RIGID_TOL
        if where == "robot":
            model.with_tool(E)
        elif where == "cell":
            from roboisf.cell.model import _rigid_transform

            _rigid_transform(E, "T_base_work")
        elif where == "program":
            from roboisf.cam.program import check_placement

            check_placement(E)
        elif where == "chain":
            from roboisf.robot.kinematics import Chain

            F = model.chain.F.copy()
            F[3] = F[3] @ E
            Chain(F=F, sign=model.chain.sign, offset=model.chain.offset)
        else:
            from roboisf.online.core import SensorSetup

            SensorSetup(T_flange_sensor=E)

    consume(0.5)
    with pytest.raises(
        InputError, match=r"must be a rigid transform.*max \|R Rᵀ − I\| = .* > 1e-06"
    ):
        consume(2.0)
