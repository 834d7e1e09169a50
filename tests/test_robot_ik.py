"""IK along a forming toolpath: round trip, orientation convention, continuity, errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from roboisf.errors import UnreachableError
from roboisf.frames import make_transform
from roboisf.parts import Cone
from roboisf.robot import SingularityWarning, ik_toolpath, load_robot, opw_ik
from roboisf.toolpath import step_down

TOOL = make_transform(None, [0.0, 0.0, 0.30])  # 300 mm straight tool + holder


@pytest.fixture(scope="module")
def cone_path():
    return step_down(Cone())


def test_cone_round_trip_and_orientation(cone_path):
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    r = ik_toolpath(m, cone_path, tool_rotation=0.3)
    T = m.fk(r.q)  # also checks the limits
    tip_base = (m.default_placement @ np.c_[cone_path.tip, np.ones(len(cone_path))].T).T[:, :3]
    assert np.abs(T[:, :3, 3] - tip_base).max() < 1e-9
    # tool z points down into the sheet (−z_work); tool x is work x turned by γ about the tool's
    # own (downward) axis, i.e. by −γ about work z (clockwise seen from above)
    Rw = m.default_placement[:3, :3].T @ T[:, :3, :3]
    np.testing.assert_allclose(Rw[:, :, 2], np.tile([0, 0, -1], (len(T), 1)), atol=1e-9)
    np.testing.assert_allclose(
        Rw[:, :, 0], np.tile([np.cos(0.3), -np.sin(0.3), 0], (len(T), 1)), atol=1e-9
    )
    # one continuous trajectory: joint steps stay small between neighbouring points
    assert np.abs(np.diff(r.q, axis=0)).max() < np.radians(2)
    # chosen branch: elbow up, no wrist flip (OPW θ5 > 0 for ABB)
    assert np.all(r.q[:, 4] > 0)
    assert not r.near_singular.any()


def test_all_branches_round_trip():
    m = load_robot("irb4600-60-2.05").with_tool(TOOL)
    rng = np.random.default_rng(0)
    q = rng.uniform(m.q_min, m.q_max, (300, 6))
    T = m.fk(q) @ np.linalg.inv(TOOL)
    for shoulder in ("front", "back"):
        for elbow in ("up", "down"):
            for wrist in ("noflip", "flip"):
                qs, ok = opw_ik(m, T, shoulder=shoulder, elbow=elbow, wrist=wrist)
                assert ok.any()
                np.testing.assert_allclose(
                    m.fk(qs[ok], check_limits=False) @ np.linalg.inv(TOOL), T[ok], atol=1e-9
                )


def test_tool_rotation_per_point(cone_path):
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    tip = cone_path.tip[:400]
    g = np.linspace(0, 0.5, len(tip))
    r = ik_toolpath(m, tip, tool_rotation=g)
    Rw = m.default_placement[:3, :3].T @ m.fk(r.q)[:, :3, :3]
    np.testing.assert_allclose(np.arctan2(Rw[:, 1, 0], Rw[:, 0, 0]), -g, atol=1e-9)


def test_unreachable_points_reported_by_index(cone_path):
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    tip = cone_path.tip[:50].copy()
    tip[[7, 31]] += [5.0, 0, 0]  # 5 m further away
    with pytest.raises(UnreachableError) as e:
        ik_toolpath(m, tip)
    assert e.value.indices == [7, 31]


def test_beyond_joint_limits_reported(cone_path):
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    # work frame behind-left of the robot at floor level: A1 would need > 180°… use a placement
    # that forces A5 beyond ±100°: work plane high above the robot, tool down
    T = make_transform(None, [0.8, 0.0, 2.6])
    with pytest.raises(UnreachableError) as e:
        ik_toolpath(m, cone_path.tip[:20], T)
    assert len(e.value.indices) > 0


def test_singularity_warning():
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    # a work frame placed so that the wrist centre is straight above the A1 axis-ish: choose
    # points where θ5 → 0 by asking for a flange pose aligned with the forearm
    q = np.radians([[0, 20, -10, 0, 0.3, 0]])
    T = m.fk(q)[0]
    # express the tool pose as a tool-down pose of some work frame: T_base_work = T · Rx(π)
    Rx = np.diag([1.0, -1.0, -1.0, 1.0])
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = ik_toolpath(m, np.zeros((1, 3)), T @ Rx)
    assert r.near_singular[0]
    assert any(issubclass(x.category, SingularityWarning) for x in w)


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_margin_test_by_elimination_agrees_with_eigvalsh(backend):
    """robot.singularity.margin_ok (the check of ik_toolpath and plan) says σ_min > thr exactly
    where the eigenvalues do, on real and on random nearly singular Jacobians."""
    from roboisf.robot import vjm_kernel
    from roboisf.robot.singularity import margin_ok, scaled_jacobian, sigma_min

    if backend == "numba" and not vjm_kernel.HAVE_NUMBA:
        pytest.skip("numba not installed")
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    rng = np.random.default_rng(21)
    q = rng.uniform(m.q_min, m.q_max, (3000, 6))
    q[:1000, 4] = rng.normal(0, 0.02, 1000)  # wrist near θ5 = 0
    J_real = scaled_jacobian(m.jacobian(q), m.opw.c2 + m.opw.c3)
    R = rng.normal(size=(3000, 6, 6))
    R[:800, :, 5] = R[:800, :, 4] + 1e-4 * rng.normal(size=(800, 6))
    for Js in (J_real, R):
        sig = sigma_min(Js)
        for thr in (*np.quantile(sig, [0.02, 0.3, 0.5, 0.9]), 0.0):
            ok = margin_ok(Js, thr, backend=backend)
            far = np.abs(sig - thr) > 1e-8 * max(1.0, thr)
            np.testing.assert_array_equal(ok[far], (sig > thr)[far])


def test_ik_flags_with_the_elimination_and_gives_sigma_on_demand(cone_path):
    from roboisf.robot.singularity import margin_ok, sigma_min

    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    r = ik_toolpath(m, cone_path)
    assert r.J_scaled is not None
    np.testing.assert_array_equal(r.near_singular, ~margin_ok(r.J_scaled, 0.02))
    J = m.jacobian(r.q)
    J[:, :3] /= m.opw.c2 + m.opw.c3
    np.testing.assert_array_equal(r.sigma_min, sigma_min(J))
    assert "sigma_min" in vars(r)  # computed once, then cached
    # a threshold between the path's σ values flags exactly the points below it
    thr = float(np.median(r.sigma_min))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SingularityWarning)
        r2 = ik_toolpath(m, cone_path, singular_threshold=thr)
    far = np.abs(r.sigma_min - thr) > 1e-8  # eigvalsh's own accuracy; the path repeats σ
    np.testing.assert_array_equal(r2.near_singular[far], (r.sigma_min < thr)[far])
    assert 0.3 < r2.near_singular.mean() < 0.7
    skip = ik_toolpath(m, cone_path, singular_threshold=None)
    assert skip.J_scaled is None and np.isnan(skip.sigma_min).all()
    assert not skip.near_singular.any()


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_fused_singularity_check_needs_no_stiffness(backend):
    """The IK check runs in the VJM kernel with unit stiffness: robots without a published
    stiffness are checked too, with the same answer as the eigenvalues."""
    from roboisf.robot import vjm_kernel
    from roboisf.robot.singularity import scaled_jacobian, sigma_min

    if backend == "numba" and not vjm_kernel.HAVE_NUMBA:
        pytest.skip("numba not installed")
    m = load_robot("irb4600-60-2.05").with_tool(TOOL)
    assert m.stiffness is None
    rng = np.random.default_rng(22)
    q = rng.uniform(m.q_min, m.q_max, (2000, 6))
    q[:700, 4] = rng.normal(0, 0.02, 700)
    L = m.opw.c2 + m.opw.c3
    sig = sigma_min(scaled_jacobian(m.jacobian(q), L))
    thr = float(np.quantile(sig, 0.3))
    ok = m.singularity_margin_ok(q, L, thr, backend=backend)
    far = np.abs(sig - thr) > 1e-8
    np.testing.assert_array_equal(ok[far], (sig > thr)[far])
    assert 0.2 < 1 - ok.mean() < 0.4
