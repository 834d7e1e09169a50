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


def _scipy_bits() -> bool:
    """The formulas are scipy 1.17's (``_rotation_xp.py``): its bits are checked there; another
    scipy (the project allows ≥ 1.11) may round a conversion differently in the last place."""
    import scipy

    return scipy.__version__.startswith("1.17.")


def _same(a, b):
    """Equal to the bit on scipy 1.17, to 2e-15 (a few ulps of a rotation's entries) otherwise."""
    a, b = np.asarray(a), np.asarray(b)
    if _scipy_bits():
        return np.array_equal(a, b)
    return a.shape == b.shape and np.allclose(a, b, rtol=0.0, atol=2e-15)


def _scipy_wxyz(xyzw):
    """scipy's scalar-last quaternions as roboisf gives them: (w, x, y, z), w ≥ 0."""
    wxyz = xyzw[:, [3, 0, 1, 2]]
    return wxyz * np.where(wxyz[:, :1] < 0, -1.0, 1.0)


def test_the_conversions_are_scipys_bit_for_bit():
    """matrix ↔ quaternion ↔ rotation vector are written out in roboisf.frames.rotations (no
    scipy.spatial import on analyze's scan thread); scipy's Rotation is the oracle, to the bit
    on the scipy whose formulas they are (1.17: :func:`_same`):
    20 000 random rotations, angles under and just over the 1 mrad of the series, zero,
    half-turns about the axes and about a diagonal, and matrices off orthogonal by 1e-6 (the SVD
    path)."""
    from scipy.spatial.transform import Rotation

    from roboisf.frames.rotations import matrix_to_rotvec, rotvec_to_matrix

    rng = np.random.default_rng(31)
    v = np.concatenate(
        [
            rng.normal(size=(20_000, 3)),
            rng.normal(size=(2_000, 3)) * 1e-4,
            rng.normal(size=(2_000, 3)) * 6e-4,  # both sides of the series' 1e-3
            rng.normal(size=(200, 3)) * 1e-9,
            np.zeros((1, 3)),
            np.array([[math.pi, 0, 0], [0, math.pi, 0], [0, 0, math.pi]]),
            np.array([[1.0, 1.0, 1.0]]) * math.pi / math.sqrt(3.0),
            rng.normal(size=(100, 3)) * 10.0,  # beyond a turn
        ]
    )
    ref = Rotation.from_rotvec(v)
    M = ref.as_matrix()
    assert _same(rotvec_to_matrix(v), M)
    assert _same(matrix_to_rotvec(M), Rotation.from_matrix(M).as_rotvec())
    assert _same(matrix_to_quat(M), _scipy_wxyz(Rotation.from_matrix(M).as_quat()))
    off = M[:500] + rng.normal(size=(500, 3, 3)) * 1e-6  # not orthogonal: scipy's SVD first
    assert _same(matrix_to_quat(off), _scipy_wxyz(Rotation.from_matrix(off).as_quat()))
    assert _same(matrix_to_rotvec(off), Rotation.from_matrix(off).as_rotvec())
    q = rng.normal(size=(20_000, 4))  # not normalised: both normalise
    assert _same(quat_to_matrix(q), Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix())
    # shapes: one rotation in, one out; a (2, 3) batch keeps its leading shape
    assert matrix_to_quat(np.eye(3)).shape == (4,)
    assert matrix_to_rotvec(np.eye(3)).shape == (3,)
    assert rotvec_to_matrix(v[:6].reshape(2, 3, 3)).shape == (2, 3, 3, 3)


def test_a_left_handed_matrix_is_refused():
    from roboisf.frames.rotations import matrix_to_rotvec

    for f in (matrix_to_quat, matrix_to_rotvec):
        with pytest.raises(ValueError, match="Non-positive determinant"):
            f(np.diag([1.0, 1.0, -1.0]))
        bad = np.stack([np.eye(3), np.eye(3)])
        bad[1, 0, 2] = math.nan  # one rotation in a batch, and alone: named, not an SVD error
        with pytest.raises(ValueError, match="rotation matrix 1 is not finite"):
            f(bad)
        with pytest.raises(ValueError, match="rotation matrix 0 is not finite"):
            f(bad[1])


def test_converting_a_rotation_imports_no_scipy_spatial():
    """The conversions need numpy only (scipy.spatial with scipy.sparse and scipy.linalg is
    ~0.2 s of import: docs/speed.md); Euler angles still load scipy's Rotation."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from roboisf.frames import rotations as r\n"
        "R = r.rotvec_to_matrix([0.1, 0.2, 0.3])\n"
        "r.matrix_to_quat(R); r.matrix_to_rotvec(R); r.quat_to_matrix([1, 0, 0, 0])\n"
        "print(sorted(m for m in sys.modules if m.startswith('scipy')))\n"
        "r.matrix_to_rpy(R)\n"
        "print('scipy.spatial.transform' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split("\n")
    assert out[0] == "[]", out[0]
    assert out[1] == "True"  # the check can see an import


def test_one_rotation_converts_to_the_same_bits_as_a_batch():
    """A single rotation takes a path in Python floats (the online loop converts one every
    cycle: 2-13 µs instead of numpy's 35-125 µs on a one-row array); the same numbers as the
    batch and as scipy, half-turns and the series' edges included, and a matrix at scipy's
    orthogonality limit (1e-12) goes the batch's way (its SVD when scipy's test says so)."""
    from scipy.spatial.transform import Rotation

    from roboisf.frames.rotations import matrix_to_rotvec, rotvec_to_matrix

    rng = np.random.default_rng(32)
    v = np.concatenate(
        [
            rng.normal(size=(400, 3)),
            rng.normal(size=(200, 3)) * 7e-4,
            np.zeros((1, 3)),
            np.eye(3) * math.pi,
            rng.normal(size=(50, 3)) * 10.0,
        ]
    )
    M = rotvec_to_matrix(v)
    q = rng.normal(size=(400, 4))
    for k in range(len(v)):
        assert np.array_equal(rotvec_to_matrix(v[k]), M[k])
        assert np.array_equal(matrix_to_rotvec(M[k]), matrix_to_rotvec(M[k : k + 1])[0])
        assert np.array_equal(matrix_to_quat(M[k]), matrix_to_quat(M[k : k + 1])[0])
    for k in range(len(q)):
        assert np.array_equal(quat_to_matrix(q[k]), quat_to_matrix(q[k : k + 1])[0])
    # off orthogonal by 0.3e-12 … 3e-12 (either side of scipy's 1e-12): scipy's quaternion
    for eps in (0.3e-12, 0.8e-12, 0.95e-12, 1.05e-12, 3e-12):
        A = M[7].copy()
        A[0, 1] += eps
        ref = _scipy_wxyz(Rotation.from_matrix(A[None]).as_quat())[0]
        assert _same(matrix_to_quat(A), ref), eps
    with pytest.raises(ValueError, match="finite and non-zero"):
        quat_to_matrix([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="finite and non-zero"):
        quat_to_matrix([1.0, math.nan, 0.0, 0.0])


def test_a_rotation_vector_that_is_not_finite_gives_nan_as_scipy():
    """libm's sin of an infinite angle is NaN in C, an error in Python's math: NaN here too."""
    from scipy.spatial.transform import Rotation

    from roboisf.frames.rotations import rotvec_to_matrix

    for v in ([math.inf, 0.0, 0.0], [math.nan, 1.0, 0.0]):
        with np.errstate(invalid="ignore"):
            ref = Rotation.from_rotvec(v).as_matrix()
            assert np.isnan(ref).all()
            assert np.isnan(rotvec_to_matrix(v)).all()
            assert np.isnan(rotvec_to_matrix([v])).all()
