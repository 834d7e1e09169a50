"""Registration: known poses recovered; the unobservable rotation stays locked; failures refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.errors import ConvergenceError
from roboisf.frames.rotations import rotvec_to_matrix
from roboisf.frames.se3 import invert, make_transform
from roboisf.parts import Cone, MeshPart, tessellate
from roboisf.scan import register, synthetic_scan

CONE = Cone()


def _pose(shift_mm, tilt_deg, axis=(0.6, 0.8, 0.0), rot_z_deg=0.0):
    ax = np.asarray(axis, float) / np.linalg.norm(axis)
    R = rotvec_to_matrix(ax * math.radians(tilt_deg))
    if rot_z_deg:
        R = R @ rotvec_to_matrix([0, 0, math.radians(rot_z_deg)])
    return make_transform(R, np.asarray(shift_mm) * 1e-3)


@pytest.fixture(scope="module")
def shifted_scan():
    # the paper's acceptance case: shifted by (0.3, −0.2, 0.8) mm and tilted by 0.5°
    T_scan_work = _pose((0.3, -0.2, 0.8), 0.5)
    s = synthetic_scan(CONE, 120_000, noise=25e-6, outlier_fraction=0.01, T_scan_work=T_scan_work,
                       seed=4)  # fmt: skip
    return s


def test_axisymmetric_registration_recovers_shift_and_tilt(shifted_scan):
    reg = register(shifted_scan.points, CONE, "axisymmetric")
    T_true = invert(shifted_scan.T_scan_work)  # T_work_scan
    assert reg.dof == 5 and reg.method == "axisymmetric"
    err_t = np.abs(reg.T_work_scan[:3, 3] - T_true[:3, 3])
    assert err_t.max() < 10e-6, err_t
    dR = reg.T_work_scan[:3, :3] @ T_true[:3, :3].T
    ang = math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
    assert ang < 0.01
    assert abs(math.degrees(reg.tilt) - 0.5) < 0.01
    assert reg.rotvec[2] == pytest.approx(0.0, abs=1e-15)  # locked, exactly
    assert reg.rms < 40e-6 and reg.overlap > 0.98


def test_axisymmetric_registration_ignores_rotation_about_the_axis(shifted_scan):
    # a scan spun about the part axis is the same surface: the result has no z rotation
    T = _pose((0.3, -0.2, 0.8), 0.5, rot_z_deg=0.0) @ make_transform(
        rotvec_to_matrix([0, 0, math.radians(30.0)])
    )
    s = synthetic_scan(CONE, 60_000, noise=0.0, T_scan_work=T, seed=5)
    reg = register(s.points, CONE, "axisymmetric")
    assert reg.rotvec[2] == pytest.approx(0.0, abs=1e-15)
    P = reg.T_work_scan[:3, :3] @ s.points.T + reg.T_work_scan[:3, 3:4]
    assert np.abs(CONE.signed_distance(P.T)).max() < 1e-9


def test_none_keeps_identity_and_reports_quality(shifted_scan):
    reg = register(shifted_scan.points, CONE, "none")
    np.testing.assert_array_equal(reg.T_work_scan, np.eye(4))
    assert reg.dof == 0 and reg.rms > 0.1e-3  # 0.8 mm off: visible in the residual


def test_icp_on_a_cone_locks_the_rotation_about_its_axis(shifted_scan):
    # issue #12: icp on a surface of revolution used to refuse; now rz is locked and reported
    reg = register(shifted_scan.points, CONE, "icp")
    ref = register(shifted_scan.points, CONE, "axisymmetric")
    assert reg.dof == 5 and "rz" in reg.locked and "continuous" in reg.locked["rz"]
    np.testing.assert_allclose(reg.T_work_scan, ref.T_work_scan, atol=1e-12)


@pytest.fixture(scope="module")
def elliptic():
    m = tessellate(CONE, chordal_error=0.2e-3, edge=3e-3)
    V = m.vertices * np.array([1.25, 0.85, 1.0])  # elliptic cone: no rotational symmetry
    return MeshPart(V, m.faces)


def test_icp_recovers_a_6dof_pose_on_a_non_axisymmetric_part(elliptic):
    T_scan_work = _pose((0.4, -0.3, 0.5), 0.7, axis=(1, 1, 0.5))  # includes a z rotation
    s = synthetic_scan(elliptic, 40_000, noise=10e-6, T_scan_work=T_scan_work, seed=2)
    reg = register(s.points, elliptic, "icp")
    T_true = invert(T_scan_work)
    assert np.abs(reg.T_work_scan[:3, 3] - T_true[:3, 3]).max() < 5e-6
    dR = reg.T_work_scan[:3, :3] @ T_true[:3, :3].T
    assert math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) < 0.005
    with pytest.raises(ConvergenceError, match="limit"):
        register(s.points, elliptic, "icp", max_rotation=math.radians(0.2))


def test_refuses_non_overlap_and_non_convergence(shifted_scan):
    far = shifted_scan.points + np.array([0.5, 0.0, 0.0])
    with pytest.raises(ConvergenceError, match="does not overlap"):
        register(far, CONE, "axisymmetric")
    with pytest.raises(ConvergenceError, match="did not converge"):
        register(shifted_scan.points, CONE, "axisymmetric", max_iterations=1)


def test_flange_registration_is_not_fooled_by_a_wall_offset():
    # formed wall 0.5 mm off the nominal + the pose of the acceptance test: a wall fit trades
    # the offset for a z shift, the flange fit does not
    T_scan_work = _pose((0.3, -0.2, 0.8), 0.5)
    s = synthetic_scan(
        CONE,
        150_000,
        offset=lambda z, phi: np.where(z < -1e-9, -0.5e-3, 0.0),
        noise=25e-6,
        outlier_fraction=0.01,
        T_scan_work=T_scan_work,
        seed=8,
    )
    T_true = invert(T_scan_work)
    reg = register(s.points, CONE, "flange")
    assert reg.dof == 5 and reg.rotvec[2] == pytest.approx(0.0, abs=1e-15)
    assert np.abs(reg.T_work_scan[:3, 3] - T_true[:3, 3]).max() < 10e-6
    dR = reg.T_work_scan[:3, :3] @ T_true[:3, :3].T
    assert math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) < 0.01
    wall_fit = register(s.points, CONE, "axisymmetric")
    assert abs(wall_fit.T_work_scan[2, 3] - T_true[2, 3]) > 0.1e-3  # the caveat is real
    # no flange in view: refused
    wall_only = s.points[s.region == 1]
    with pytest.raises(ConvergenceError, match="flange"):
        register(wall_only, CONE, "flange")
