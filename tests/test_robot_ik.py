"""IK along a forming toolpath: round trip, orientation convention, continuity, errors."""

from __future__ import annotations

import warnings
import zlib

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


@pytest.mark.parametrize("opw", [True, False])
def test_singularity_warning_points_at_the_callers_line(opw):
    """Closed-form and numerical IK share one singularity check; its warning names the line
    that called ik_toolpath (not roboisf's own code) on both paths."""
    from pathlib import Path

    from roboisf.robot import load_urdf

    urdf = Path(__file__).parent / "data" / "urdf" / "irb4600_60_205.urdf"
    m = load_urdf(urdf, opw=opw).with_tool(TOOL)
    assert (m.opw is not None) == opw
    q = np.radians([[0, 20, -10, 0, 0.3, 0]])
    T = m.fk(q)[0] @ np.diag([1.0, -1.0, -1.0, 1.0])
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = ik_toolpath(m, np.zeros((1, 3)), T, match_q=None if opw else q[0])
    assert r.near_singular[0]
    sw = [x for x in w if issubclass(x.category, SingularityWarning)]
    assert len(sw) == 1
    assert sw[0].filename == __file__


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


# --- the compiled IK engine (robot.ik_numba) against the numpy engine and py-opw-kinematics ---

PRESETS = ["irb7600-500-2.55", "kr210-r2700-2", "irb4600-60-2.05"]
BRANCHES = [
    (s, e, w) for s in ("front", "back") for e in ("up", "down") for w in ("noflip", "flip")
]


def _needs_numba():
    from roboisf.robot import vjm_kernel

    if not vjm_kernel.HAVE_NUMBA:
        pytest.skip("numba not installed")


def _wrapped(a):
    """Angles mapped to (−π, π] (to compare wrapped solutions that sit at ±π)."""
    return np.angle(np.exp(1j * a))


def _flange_poses(m, n, seed):
    """Random flange poses (n, 4, 4) from angles within the limits, a third of them with the wrist
    near (not at) θ5 = 0, plus 50 poses out of reach."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(m.q_min, m.q_max, (n, 6)) * 0.98
    k = n // 3
    q[:k, 4] = rng.choice([-1.0, 1.0], k) * rng.uniform(1e-4, 0.05, k)
    T = m.fk(q, check_limits=False) @ np.linalg.inv(m.T_flange_tip)
    far = T[:50].copy()
    far[:, 0, 3] += 10.0  # 10 m further out: beyond any of these arms
    return np.concatenate([T, far])


@pytest.mark.parametrize("name", PRESETS)
def test_numba_opw_matches_numpy_on_every_branch(name):
    """Same reachability and the same angles (≤ 1e-12 rad) on all 8 branches of every preset,
    near-singular wrists and unreachable poses included."""
    _needs_numba()
    m = load_robot(name).with_tool(TOOL)
    T = _flange_poses(m, 3000, seed=zlib.crc32(name.encode()) % 1000)  # hash() varies per run
    for s, e, w in BRANCHES:
        qn, okn = opw_ik(m, T, shoulder=s, elbow=e, wrist=w, backend="numba")
        qp, okp = opw_ik(m, T, shoulder=s, elbow=e, wrist=w, backend="numpy")
        np.testing.assert_array_equal(okn, okp)
        assert not okn[-50:].any() and okn[:-50].any()
        assert np.isnan(qn[~okn]).all()
        d = np.abs(_wrapped(qn[okn] - qp[okp]))
        assert d[:, :3].max() <= 1e-12 and d[:, 4].max() <= 1e-12
        # A4 and A6 are ill-conditioned at a small θ5 (alone, not their sum): a rounding δ of
        # the wrist matrix's entries moves them by ~δ / |sin θ5|. With δ ≈ 9 ulp (2e-15) the
        # bound is 2e-15 / |sin θ5| (1e-12 from |θ5| ≥ 2e-3 rad); the worst of 1,000 seeds × 3
        # presets × 8 branches was 1.1e-15 / |sin θ5| (θ5 ≈ 2.6e-4 rad, KR 210).
        s5 = np.abs(np.sin(qp[okp, 4]))
        assert np.all(d[:, [3, 5]] <= 1e-12 * np.maximum(1.0, 2e-3 / s5)[:, None])
        assert np.all(np.abs(qn[okn]) <= np.pi)  # wrapped to (−π, π] like numpy's


@pytest.mark.parametrize("name", PRESETS)
def test_numba_opw_branches_are_py_opw_kinematics_solutions(name):
    """Independent oracle: every branch solution of the compiled engine is one of the eight
    solutions py-opw-kinematics finds for the pose, and maps back to the pose (1e-9 m)."""
    _needs_numba()
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
    rng = np.random.default_rng(5)
    q = rng.uniform(m.q_min, m.q_max, (400, 6)) * 0.9
    q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.05)  # away from θ5 = 0
    T = m.fk(q, check_limits=False)
    from scipy.spatial.transform import RigidTransform

    ref = Robot(km, degrees=False).reach(RigidTransform.from_matrix(T)).joints  # (n, 8, 6)
    for sh, el, wr in BRANCHES:
        qs, ok = opw_ik(m, T, shoulder=sh, elbow=el, wrist=wr, backend="numba")
        assert ok.sum() > 100
        d = np.abs(_wrapped(qs[ok, None, :] - ref[ok])).max(axis=2)  # (n_ok, 8)
        assert np.nanmin(d, axis=1).max() < 1e-9
        np.testing.assert_allclose(m.fk(qs[ok], check_limits=False), T[ok], atol=1e-9)


def _both(m, tip, T=None, **kw):
    """ik_toolpath on both engines: the results, or the same UnreachableError on both."""
    out = []
    for backend in ("numba", "numpy"):
        try:
            out.append(ik_toolpath(m, tip, T, singular_threshold=None, backend=backend, **kw))
        except UnreachableError as e:
            out.append(e)
    rn, rp = out
    assert type(rn) is type(rp)
    if isinstance(rn, UnreachableError):
        assert rn.indices == rp.indices and str(rn) == str(rp)
        return None
    assert np.abs(rn.q - rp.q).max() <= 1e-12  # continuous: no wrapping to forgive
    assert np.abs(rn.T_base_tip - rp.T_base_tip).max() <= 1e-12
    return rn


@pytest.mark.parametrize("name", PRESETS)
def test_numba_path_matches_numpy_on_random_paths(name, cone_path):
    """Random placements and tool-rotation schedules along the cone: identical verdicts
    (reachable, within limits, the same indices) and angles ≤ 1e-12 rad; FK(IK) = T (1e-9 m)."""
    _needs_numba()
    m = load_robot(name).with_tool(TOOL)
    rng = np.random.default_rng(7)
    tip = cone_path.tip[::7]
    n_ok = 0
    for trial in range(12):
        T = m.default_placement.copy()
        T[:3, 3] += rng.normal(0, 0.25, 3)
        g = rng.uniform(-np.pi, np.pi) + np.cumsum(rng.normal(0, 0.01, len(tip)))
        branch = BRANCHES[trial % 8]
        r = _both(m, tip, T, tool_rotation=g, shoulder=branch[0], elbow=branch[1], wrist=branch[2])
        if r is None:
            continue
        n_ok += 1
        tip_base = (T @ np.c_[tip, np.ones(len(tip))].T).T[:, :3]
        assert np.abs(m.fk(r.q)[:, :3, 3] - tip_base).max() < 1e-9
    assert n_ok >= 3


@pytest.mark.parametrize("wrist", ["noflip", "flip"])
def test_numba_path_crossing_pi_on_q4_q6(wrist, cone_path):
    """A tool rotation sweeping one turn drives A6 through ±180° (and, on the flipped wrist, A4
    sits at ±180°): both engines unwrap alike into one continuous trajectory inside the limits."""
    _needs_numba()
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    tip = cone_path.tip[:2000]
    g = np.linspace(-np.pi, np.pi, len(tip))
    r = _both(m, tip, tool_rotation=g, wrist=wrist)
    assert r is not None
    q_wrapped, _ = opw_ik(m, r.T_base_tip @ np.linalg.inv(TOOL), wrist=wrist, backend="numpy")
    assert np.abs(np.diff(q_wrapped[:, 5])).max() > np.pi  # the wrapped A6 does jump
    assert np.abs(np.diff(r.q, axis=0)).max() < np.radians(2)  # the trajectory does not
    assert np.ptp(r.q[:, 5]) > 2 * np.pi - 0.1
    if wrist == "flip":
        assert np.abs(np.abs(_wrapped(r.q[:, 3])) - np.pi).min() < 0.5


def test_numba_path_unreachable_and_limit_points_by_index(cone_path):
    """Out-of-reach points and joint-limit violations: the same indices and message from both
    engines (the compiled one leaves the limit test's message to the numpy code)."""
    _needs_numba()
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    tip = cone_path.tip[:50].copy()
    tip[[3, 44]] += [5.0, 0, 0]
    assert _both(m, tip) is None
    assert _both(m, cone_path.tip[:20], make_transform(None, [0.8, 0.0, 2.6])) is None
    with pytest.raises(UnreachableError) as e:
        ik_toolpath(m, tip, backend="numba")
    assert e.value.indices == [3, 44]


def test_numba_path_near_singular_points():
    """A path through the wrist singularity's neighbourhood (θ5 → 1e-4 rad): same angles from
    both engines, and the near-singular flag from the fused margin test."""
    _needs_numba()
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    q = np.radians([[0, 20, -10, 0, 0.3, 0]])
    T = m.fk(q)[0] @ np.diag([1.0, -1.0, -1.0, 1.0])
    tip = np.c_[np.linspace(0, 0.3, 300) - 0.15, np.zeros(300), np.zeros(300)]
    r = _both(m, tip, T)
    assert r is not None and np.abs(r.q[:, 4]).min() < 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SingularityWarning)
        rs = ik_toolpath(m, tip, T, backend="numba")
    assert rs.near_singular.any()


def test_ik_bad_branch_and_tool_rotation_are_input_errors(cone_path):
    from roboisf.errors import InputError

    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    with pytest.raises(InputError, match="shoulder"):
        ik_toolpath(m, cone_path.tip[:5], shoulder="side")
    with pytest.raises(InputError, match="tool_rotation"):
        ik_toolpath(m, cone_path.tip[:5], tool_rotation=np.zeros(3))
    with pytest.raises(InputError, match="tool_rotation"):
        ik_toolpath(m, cone_path.tip[:5], tool_rotation=np.nan)


def test_numba_ik_from_a_worker_thread_is_bit_identical(cone_path):
    """The serial twin (non-main threads) gives the same bits as the prange kernel."""
    _needs_numba()
    from concurrent.futures import ThreadPoolExecutor

    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    tip = cone_path.tip[:5000]
    g = np.linspace(0, 1, len(tip))
    main = ik_toolpath(m, tip, tool_rotation=g, singular_threshold=None, backend="numba")
    with ThreadPoolExecutor(1) as ex:
        other = ex.submit(
            lambda: ik_toolpath(m, tip, tool_rotation=g, singular_threshold=None, backend="numba")
        ).result()
    np.testing.assert_array_equal(main.q, other.q)
    np.testing.assert_array_equal(main.T_base_tip, other.T_base_tip)


@pytest.fixture(scope="module")
def plan_problem():
    from roboisf.plan import problem_from_cell
    from roboisf.virtual.cell import paper_cone_cell

    vc = paper_cone_cell(spacing=34.8 / 3000)
    prob, _ = problem_from_cell(vc.cell, **vc.path_settings)
    return prob


@pytest.mark.parametrize("tool", [True, False])
def test_plan_path_kernel_matches_the_numpy_solve(plan_problem, tool):
    """roboisf.plan's fused per-path kernel (ik_numba.path_vjm) against the numpy pipeline
    (ik_toolpath + RobotModel.vjm + numpy post-processing): the same angles (≤ 1e-12 rad), δ
    (≤ 1e-15 m absolute on ~1e-3 m), margin verdicts and joint steps, for a constant and a
    per-point γ, with and without the tool's compliance; the same errors for placements out of
    reach and beyond the limits; the worker-thread twin gives the same bits."""
    _needs_numba()
    from concurrent.futures import ThreadPoolExecutor
    from dataclasses import replace

    from roboisf.plan import evaluate as E

    prob = plan_problem if tool else replace(plan_problem, tool_compliance=None)
    prob_np = replace(prob, model=prob.model.with_backend("numpy"))
    # a fixed placement (the paper-like cell's until it moved off the base's x-axis): the σ_min
    # range quoted below is this placement's
    T = make_transform(p=[2.2, 0.0, 0.2])
    for g in (0.3, np.linspace(-0.5, 1.0, prob.n_points)):
        a, b = E._solve(prob, T, g), E._solve(prob_np, T, g)
        assert np.abs(a.q - b.q).max() <= 1e-12
        assert np.abs(a.steps - b.steps).max() <= 1e-12
        np.testing.assert_array_equal(a.margin_ok, b.margin_ok)
        for k in ("d_total", "d_robot", "abs_total", "abs_robot", "abs_normal"):
            assert np.abs(getattr(a, k) - getattr(b, k)).max() <= 1e-15
        # the kernel's per-point |δ_robot| and |δ·n| are the numpy reductions of its own δ (what
        # the placement scores were computed from before they moved into the kernel): |δ_robot|
        # bit for bit, |δ·n| within 1 ulp (einsum's summation order may follow the CPU's SIMD)
        np.testing.assert_array_equal(a.abs_robot, np.linalg.norm(a.d_robot, axis=1))
        dn = np.abs(np.einsum("ij,ij->i", a.d_total, prob.normal))
        assert np.all(np.abs(a.abs_normal - dn) <= np.spacing(dn))
        if not tool:
            np.testing.assert_array_equal(a.d_total, a.d_robot)
        with ThreadPoolExecutor(1) as ex:
            c = ex.submit(E._solve, prob, T, g).result()
        np.testing.assert_array_equal(a.q, c.q)
        np.testing.assert_array_equal(a.d_total, c.d_total)
    # a margin threshold inside the path's σ_min range (0.20–0.22): a mix of verdicts
    mid = replace(prob, sigma_threshold=0.21)
    a = E._solve(mid, T, 0.3)
    b = E._solve(replace(mid, model=mid.model.with_backend("numpy")), T, 0.3)
    assert 0.05 < a.margin_ok.mean() < 0.95
    np.testing.assert_array_equal(a.margin_ok, b.margin_ok)
    # out of reach; beyond the limits (A5, and A1 for part of the path)
    far = T.copy()
    far[0, 3] += 5.0
    for Tb in (far, make_transform(None, [0.6, 0, 2.2]), make_transform(None, [-1.5, 0, 0.5])):
        errs = []
        for p in (prob, prob_np):
            with pytest.raises(UnreachableError) as e:
                E._solve(p, Tb, 0.3)
            errs.append((str(e.value), e.value.indices))
        assert errs[0] == errs[1]


def test_compiled_atan2_within_one_ulp_of_libm():
    """The IK kernel's fdlibm atan2 against libm's over 20 decades, signs, zeros and infinities."""
    _needs_numba()
    from roboisf.robot.ik_numba import _atan2_many

    rng = np.random.default_rng(3)
    n = 200_000
    y = rng.normal(size=n) * 10.0 ** rng.uniform(-20, 20, n)
    x = rng.normal(size=n) * 10.0 ** rng.uniform(-20, 20, n)
    y[:100], x[100:200], x[200:300], y[300:310], x[310:320] = 0.0, 0.0, -1e-300, np.inf, -np.inf
    y[320:330] = x[320:330] = -0.0
    a = _atan2_many(y, x)
    b = np.arctan2(y, x)
    assert np.all(np.abs(a - b) <= np.spacing(np.abs(b)))  # ≤ 1 ulp
    np.testing.assert_array_equal(np.signbit(a), np.signbit(b))


def test_compiled_wrap_is_numpys_modulo_bit_for_bit():
    """The IK kernel's branch-free-of-fmod wrap against ``np.mod(x + π, 2π) − π``: its fast
    ranges, their edges (±π, 3π, ±2π ± 1 ulp), far angles, zeros, infinities and NaN."""
    _needs_numba()
    from roboisf.robot.ik_numba import _wrap_many

    rng = np.random.default_rng(5)
    pi, tp = np.pi, 2 * np.pi
    edges = np.array([-pi, pi, 3 * pi, -3 * pi, tp, -tp, 0.0, -0.0, tp - pi, 1e-300, -1e-300])
    edges = np.concatenate([edges, np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf)])
    x = np.concatenate(
        [
            rng.uniform(-4 * pi, 4 * pi, 500_000),  # every fast range and beyond
            rng.normal(size=1000) * 1e6,
            edges,
            [np.inf, -np.inf, np.nan, -1e-18, 1e-18],
        ]
    )
    a = _wrap_many(x)
    with np.errstate(invalid="ignore"):  # ±inf in, NaN out, on purpose
        b = np.mod(x + pi, tp) - pi
    np.testing.assert_array_equal(a, b)  # NaN where NaN, same bits elsewhere
    np.testing.assert_array_equal(np.signbit(a), np.signbit(b))
