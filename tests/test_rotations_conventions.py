"""Hand-worked checks of the orientation conventions the robot programs use.

Tool frame: z along the tool, out of the flange towards the ball. "Tool pointing down" means the
tool z axis is −z_work.

ABB: orient = [q1, q2, q3, q4] = (w, x, y, z) of R_work_tool. A rotation by angle θ about unit
axis u is q = (cos θ/2, sin θ/2 · u). Pointing down needs a half-turn about a horizontal axis
u = (cos ψ, sin ψ, 0): q = (0, cos ψ, sin ψ, 0). ψ = 0 (half-turn about x) → [0, 1, 0, 0],
R = diag(1, −1, −1); ψ = 90° (about y) → [0, 0, 1, 0], R = diag(−1, 1, −1). Both send z → −z.

KUKA: R = Rz(A) Ry(B) Rx(C). Half-turn about x → (A, B, C) = (0, 0, 180).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.cam.program import tool_down_orientation
from roboisf.frames.rotations import abc_to_matrix, matrix_to_abc, matrix_to_quat, quat_to_matrix

DOWN = np.array([0.0, 0.0, -1.0])


def _same_quat(a, b, tol=1e-12):
    """q and −q are the same rotation."""
    a, b = np.asarray(a), np.asarray(b)
    return min(np.abs(a - b).max(), np.abs(a + b).max()) < tol


def test_abb_pointing_down_about_x():
    R = quat_to_matrix([0.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(R, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    np.testing.assert_allclose(R @ [0, 0, 1], DOWN, atol=1e-15)


def test_abb_pointing_down_about_y():
    R = quat_to_matrix([0.0, 0.0, 1.0, 0.0])
    np.testing.assert_allclose(R, np.diag([-1.0, 1.0, -1.0]), atol=1e-15)
    np.testing.assert_allclose(R @ [0, 0, 1], DOWN, atol=1e-15)


@pytest.mark.parametrize("psi_deg", [0, 30, 90, 135, -60])
def test_abb_pointing_down_family(psi_deg):
    psi = math.radians(psi_deg)
    q = [0.0, math.cos(psi), math.sin(psi), 0.0]
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R @ [0, 0, 1], DOWN, atol=1e-15)
    # the tool x axis is the horizontal axis mirrored about u: angle 2ψ in the xy plane
    np.testing.assert_allclose(R @ [1, 0, 0], [math.cos(2 * psi), math.sin(2 * psi), 0], atol=1e-15)


@pytest.mark.parametrize("gamma_deg", [0.0, 45.0, 90.0, 180.0, -120.0])
def test_tool_rotation_about_own_axis_quaternion(gamma_deg):
    """Rx(π)·Rz(γ): (0+i)(cos γ/2 + k sin γ/2) = i cos γ/2 + i·k sin γ/2 = i cos γ/2 − j sin γ/2,
    so q = [0, cos γ/2, −sin γ/2, 0] (a member of the family above with ψ = −γ/2)."""
    g = math.radians(gamma_deg)
    R = tool_down_orientation(g)[0]
    expect = [0.0, math.cos(g / 2), -math.sin(g / 2), 0.0]
    assert _same_quat(matrix_to_quat(R), expect)
    np.testing.assert_allclose(quat_to_matrix(expect), R, atol=1e-15)
    np.testing.assert_allclose(R @ [0, 0, 1], DOWN, atol=1e-15)
    # the rotation is about the tool's own axis: the tool x axis turns by −γ seen from above
    np.testing.assert_allclose(R @ [1, 0, 0], [math.cos(g), -math.sin(g), 0], atol=1e-15)


def test_quaternion_of_quarter_turn_about_z():
    """90° about z: q = (cos 45°, 0, 0, sin 45°); x → y."""
    R = quat_to_matrix([math.sqrt(0.5), 0, 0, math.sqrt(0.5)])
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)


def test_kuka_pointing_down():
    R = abc_to_matrix(np.radians([0.0, 0.0, 180.0]))
    np.testing.assert_allclose(R, np.diag([1.0, -1.0, -1.0]), atol=1e-15)


@pytest.mark.parametrize("gamma_deg", [0.0, 30.0, 90.0, -150.0])
def test_kuka_tool_rotation_is_minus_a(gamma_deg):
    """Rx(π) Rz(γ) = Rz(−γ) Rx(π)  (conjugating a z-rotation by a half-turn about x flips its
    sense), so (A, B, C) = (−γ, 0, 180)."""
    g = math.radians(gamma_deg)
    R = tool_down_orientation(g)[0]
    np.testing.assert_allclose(abc_to_matrix([-g, 0.0, math.pi]), R, atol=1e-15)
    abc = np.degrees(matrix_to_abc(R))
    # C = ±180 are the same; A = −γ (mod 360)
    assert abs(abs(abc[2]) - 180.0) < 1e-9 and abs(abc[1]) < 1e-9
    assert math.isclose(math.remainder(abc[0] + gamma_deg, 360.0), 0.0, abs_tol=1e-9)


def test_kuka_abc_order_by_hand():
    """A = 90° only: x → y. B = 90° only: x → −z (Ry(β) x = (cos β, 0, −sin β)). C = 90°: y → z.
    A = 90°, B = 90°: Rz(90°) Ry(90°) x = Rz(90°)(0, 0, −1) = (0, 0, −1);
    z → Rz(90°)(1, 0, 0) = y."""
    np.testing.assert_allclose(
        abc_to_matrix(np.radians([90, 0, 0])) @ [1, 0, 0], [0, 1, 0], atol=1e-15
    )
    np.testing.assert_allclose(
        abc_to_matrix(np.radians([0, 90, 0])) @ [1, 0, 0], [0, 0, -1], atol=1e-15
    )
    np.testing.assert_allclose(
        abc_to_matrix(np.radians([0, 0, 90])) @ [0, 1, 0], [0, 0, 1], atol=1e-15
    )
    R = abc_to_matrix(np.radians([90, 90, 0]))
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(R @ [0, 0, 1], [0, 1, 0], atol=1e-15)
