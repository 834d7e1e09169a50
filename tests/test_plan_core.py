"""Placement planning: scores against independent computations, γ physics, the lap schedule,
acceptance on the paper's cone, bad input."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from roboisf.cell import at_ball_centre
from roboisf.errors import InputError, UnreachableError
from roboisf.frames import make_transform, rpy_to_matrix
from roboisf.parts import Symmetry
from roboisf.plan import (
    PlanProblem,
    evaluate_placement,
    placement_grid,
    placement_transforms,
    plan_placements,
    problem_from_cell,
    smooth_schedule,
)
from roboisf.plan.evaluate import _realise, _solve
from roboisf.robot import ik_toolpath, load_robot
from roboisf.virtual.cell import PAPER_CELL_PLACEMENT, paper_cone_cell

CELL = paper_cone_cell(spacing=4e-3)


@pytest.fixture(scope="module")
def cone():
    return problem_from_cell(CELL.cell, **CELL.path_settings)


@pytest.fixture(scope="module")
def cone_robot_only():
    return problem_from_cell(CELL.cell, **CELL.path_settings, with_tool=False)[0]


def _angled_model():
    # an angled holder: tool axis 30° off the flange axis, 150 mm off to the side
    T_ft = make_transform(rpy_to_matrix([0.0, math.radians(30), 0.0]), [0.15, 0.0, 0.25])
    return load_robot("irb7600-500-2.55").with_tool(T_ft)


def test_score_equals_direct_vjm(cone_robot_only):
    """Robot-only score = IK + RobotModel.deflection in work axes, moved to the ball centre by the
    analysis's own function (a different code path)."""
    prob = cone_robot_only
    assert prob.ball_radius == CELL.cell.tool.radius > 0
    s = evaluate_placement(prob, PAPER_CELL_PLACEMENT)
    q = ik_toolpath(prob.model, prob.tip, PAPER_CELL_PLACEMENT).q
    d6 = prob.model.deflection(q, prob.wrench, T_base_work=PAPER_CELL_PLACEMENT)
    d = at_ball_centre(d6, prob.ball_radius)
    a = np.linalg.norm(d, axis=1)
    assert s.ok and s.status == "ok" and s.reason == ""
    assert s.mean_robot == pytest.approx(a.mean(), rel=1e-12)
    assert s.max_robot == pytest.approx(a.max(), rel=1e-12)
    assert s.mean_abs == pytest.approx(a.mean(), rel=1e-12)
    dn = np.abs(np.einsum("ij,ij->i", d, prob.normal))
    assert s.mean_abs_normal == pytest.approx(dn.mean(), rel=1e-12)
    # the tip's deflection differs, by ~0.6 % for the robot (cell.at_ball_centre's docstring)
    a_tip = np.linalg.norm(d6[:, :3], axis=1).mean()
    assert 1e-4 < abs(s.mean_robot / a_tip - 1.0) < 0.03
    # ball_radius = 0 scores the tip
    tip = evaluate_placement(replace(prob, ball_radius=0.0), PAPER_CELL_PLACEMENT)
    assert tip.mean_robot == pytest.approx(a_tip, rel=1e-12)
    # the paper-like cell's order of magnitude (virtual/cell.py: R_m ≈ 0.5 mm there)
    assert 0.2e-3 < s.mean_robot < 1.0e-3


def test_tool_compliance_added_as_in_the_virtual_cell(cone, cone_robot_only):
    prob, _ = cone
    s = evaluate_placement(prob, PAPER_CELL_PLACEMENT)
    ev = _solve(cone_robot_only, PAPER_CELL_PLACEMENT, 0.0)
    # γ = 0: tool axes = work; the ball centre as the virtual cell's tool_rob
    tool = at_ball_centre(prob.wrench @ prob.tool_compliance.T, prob.ball_radius)
    d = ev.d_robot + tool
    assert s.mean_abs == pytest.approx(np.linalg.norm(d, axis=1).mean(), rel=1e-12)
    assert s.mean_robot == pytest.approx(np.linalg.norm(ev.d_robot, axis=1).mean(), rel=1e-12)
    assert s.mean_abs > s.mean_robot


@pytest.mark.parametrize("radius", [0.0, 7.5e-3])
def test_ball_centre_compiled_equals_numpy_engine(radius):
    """The compiled path kernel and the numpy path, an angled tool with a full (rotational) tool
    compliance and a per-point γ, so every term of the ball-centre shift is non-zero."""
    from roboisf.robot import vjm_kernel

    if not vjm_kernel.use_numba("auto"):
        pytest.skip("numba not installed")
    base = problem_from_cell(CELL.cell, **CELL.path_settings, model=_angled_model())[0]
    rng = np.random.default_rng(3)
    C = rng.normal(size=(6, 6)) * 1e-7
    prob = replace(base, tool_compliance=C @ C.T, ball_radius=radius)
    prob_np = replace(prob, model=prob.model.with_backend("numpy"))
    T = placement_transforms([[1.6, 0.1, 0.6, 0.2]])[0]
    g = np.linspace(0.0, 0.6, prob.n_points)
    a, b = _solve(prob, T, g), _solve(prob_np, T, g)
    for f in ("d_robot", "d_total"):
        x, y = getattr(a, f), getattr(b, f)
        assert np.max(np.abs(x - y)) <= 1e-12 * np.max(np.abs(y)), f
    if radius:
        # the shift is really there: against the tip
        tip = _solve(replace(prob, ball_radius=0.0), T, g)
        assert np.max(np.abs(tip.d_total - a.d_total)) > 1e-3 * np.max(np.abs(a.d_total))


def test_tool_compliance_turns_with_gamma(cone_robot_only):
    """k = diag(a, b, …) in tool axes; γ = 90° puts x_tool along −y_work, so a force along
    x_work loads the tool's y axis: δx_work = b·Fx."""
    p = cone_robot_only
    k = np.diag([1e-6, 3e-6, 1e-8, 0.0, 0.0, 0.0])
    W = np.zeros_like(p.wrench)
    W[:, 0] = 100.0
    prob = PlanProblem(p.model, p.tip, p.normal, p.lap, W, tool_compliance=k)
    ev = _solve(prob, PAPER_CELL_PLACEMENT, math.pi / 2)
    dt = ev.d_total - ev.d_robot
    np.testing.assert_allclose(dt[:, 0], 3e-6 * 100.0, rtol=1e-12)
    np.testing.assert_allclose(dt[:, 1:], 0.0, atol=1e-18)
    ev0 = _solve(prob, PAPER_CELL_PLACEMENT, 0.0)
    np.testing.assert_allclose((ev0.d_total - ev0.d_robot)[:, 0], 1e-6 * 100.0, rtol=1e-12)
    assert not prob.tool_is_coaxial()


def test_gamma_cannot_matter_for_a_coaxial_tool(cone):
    """Tool along A6: γ only turns A6, so k_c and δ are the same for every γ."""
    prob, _ = cone
    assert prob.tool_is_coaxial()
    a = _solve(prob, PAPER_CELL_PLACEMENT, 0.0)
    b = _solve(prob, PAPER_CELL_PLACEMENT, 1.1)
    assert not np.allclose(a.q[:, 5], b.q[:, 5])
    np.testing.assert_allclose(a.q[:, :5], b.q[:, :5], atol=1e-9)
    np.testing.assert_allclose(b.d_total, a.d_total, rtol=1e-9, atol=1e-15)
    r = plan_placements(prob, [[1.6, 0.0, 0.6, 0.0]], [0.0, 0.5], scheduler="serial")
    assert r.tool_rotations.tolist() == [0.0] and "coaxial" in r.notes[0]


def test_gamma_matters_for_an_angled_tool_and_the_best_is_kept():
    prob, _ = problem_from_cell(CELL.cell, **CELL.path_settings, model=_angled_model())
    assert not prob.tool_is_coaxial()
    T = placement_transforms([[1.6, 0.0, 0.6, 0.0]])[0]
    gs = np.radians([0.0, 60.0, 120.0, 180.0])
    each = [evaluate_placement(prob, T, [g]) for g in gs]
    means = [s.mean_abs for s in each]
    assert max(means) > 1.1 * min(means)  # the wrist posture changes the compliance
    best = evaluate_placement(prob, T, gs)
    assert best.ok
    assert best.mean_abs <= min(m for m, s in zip(means, each, strict=True) if s.ok) + 1e-15
    r = plan_placements(prob, [[1.6, 0.0, 0.6, 0.0]], gs, scheduler="serial")
    assert r.best.mean_abs == best.mean_abs
    assert r.best_gamma0 is not None and r.best_gamma0.mean_abs == each[0].mean_abs


def _at(prob, x, yaw_deg, gammas_deg=(0.0,)):
    T = placement_transforms([[x, 0.0, 0.6, math.radians(yaw_deg)]])[0]
    return evaluate_placement(prob, T, np.radians(gammas_deg))


def test_a_round_parts_yaw_is_evaluated_once(cone):
    """The cone turned about its axis is the same part: yaws 0, 45 and 90° at one x, y, z were
    ranked as three placements with the same numbers. Now one row per x, y, z (its first yaw),
    and a note says why."""
    prob, _ = cone
    assert prob.symmetry.continuous and prob.tool_is_coaxial()
    P = placement_grid([1.4, 1.6], [0.0], [0.6], np.radians([0.0, 45.0, 90.0]))
    r = plan_placements(prob, P, scheduler="serial")
    assert r.placements.tolist() == [[1.4, 0.0, 0.6, 0.0], [1.6, 0.0, 0.6, 0.0]]
    assert len(r.scores) == 2 and len(r.table()) == 2
    assert "the part is round" in r.notes[-1] and "(6 → 2 placements)" in r.notes[-1]
    r0 = plan_placements(prob, P[P[:, 3] == 0.0], scheduler="serial")
    assert [s.mean_abs for s in r.scores] == [s.mean_abs for s in r0.scores]
    # why it is right: turned, the same points under the same forces, only the laps start
    # elsewhere — the means agree to round-off (≤ 3e-10 relative measured on this 4 mm path),
    # the max to the path's sampling (≤ 6e-4)
    a = r.scores[1]
    for yaw in (45.0, 90.0, 137.0):
        b = _at(prob, 1.6, yaw)
        for f in ("mean_robot", "mean_abs", "mean_abs_normal"):
            assert getattr(b, f) == pytest.approx(getattr(a, f), rel=1e-8), (yaw, f)
        assert b.max_abs == pytest.approx(a.max_abs, rel=2e-3)
    # a part with no declared symmetry keeps every yaw
    r1 = plan_placements(replace(prob, symmetry=Symmetry(1)), P, scheduler="serial")
    assert len(r1.scores) == 6 and not any("round" in n for n in r1.notes)


def test_a_round_parts_yaw_is_a_tool_rotation_for_an_angled_tool():
    """With a tool off axis 6, a yaw ψ of a round part turns only the tool, by −ψ about its own
    axis relative to the robot: the yaws are searched as tool rotations of one placement."""
    prob, _ = problem_from_cell(CELL.cell, **CELL.path_settings, model=_angled_model())
    assert prob.symmetry.continuous and not prob.tool_is_coaxial()
    turned, same = _at(prob, 1.6, 90.0), _at(prob, 1.6, 0.0, (-90.0,))
    assert turned.ok and same.ok
    for f in ("mean_robot", "mean_abs", "mean_abs_normal"):
        assert getattr(turned, f) == pytest.approx(getattr(same, f), rel=1e-8), f
    assert abs(turned.mean_abs / _at(prob, 1.6, 0.0).mean_abs - 1.0) > 0.01  # γ matters
    P = placement_grid([1.6], [0.0], [0.6], np.radians([0.0, 90.0]))
    r = plan_placements(prob, P, scheduler="serial")
    assert r.placements.tolist() == [[1.6, 0.0, 0.6, 0.0]]
    np.testing.assert_allclose(r.tool_rotations, np.radians([0.0, -90.0]), atol=1e-15)
    assert r.best.mean_abs == _at(prob, 1.6, 0.0, (0.0, -90.0)).mean_abs
    assert "(2 → 1 placements), the other yaws as tool rotations (γ = 0°, -90°)" in r.notes[-1]


def test_schedule_known_optimum_rate_limit_and_infeasible():
    g = np.radians([0.0, 30.0, 60.0])
    # lap costs: γ=60 best on laps 0-1, γ=0 best on laps 2-3
    C = np.array([[5, 5, 1, 1], [4, 4, 4, 4], [1, 1, 5, 5]], dtype=float)
    F = np.ones_like(C, dtype=bool)
    free = smooth_schedule(C, F, g, max_step=math.radians(90), penalty=0.0)
    assert free.tolist() == [2, 2, 0, 0]
    # rate limit 30°/lap: 60 → 0 takes two laps through 30
    lim = smooth_schedule(C, F, g, max_step=math.radians(30), penalty=0.0)
    assert lim.tolist() in ([2, 2, 1, 0], [2, 1, 0, 0])
    # a large penalty: stay constant
    stay = smooth_schedule(C, F, g, max_step=math.radians(90), penalty=100.0)
    assert len(set(stay.tolist())) == 1
    F2 = F.copy()
    F2[:, 1] = False
    assert smooth_schedule(C, F2, g, max_step=1.0, penalty=0.0) is None
    F3 = F.copy()
    F3[2, :] = False  # γ=60 forbidden: best is γ=0 except where 30 is cheaper (never)
    assert smooth_schedule(C, F3, g, max_step=1.0, penalty=0.0).tolist() == [1, 1, 0, 0]


def test_realised_schedule_is_continuous(cone):
    prob, _ = cone
    L = prob.n_laps
    gl = np.zeros(L)
    gl[L // 2 :] = math.radians(30)
    g = _realise(prob, gl)
    step = np.abs(np.diff(g)).max()
    n_lap = int(np.sum(prob.lap_id == L // 2))
    need = math.ceil(math.radians(30) / (prob.max_joint_step / 2))
    assert step == pytest.approx(math.radians(30) / min(max(prob.ramp_points, need), n_lap))
    lap = prob.lap_id
    assert np.all(g[lap < L // 2] == 0.0)
    last = lap == L - 1
    assert np.all(g[last] == math.radians(30))


def test_acceptance_chosen_placement_beats_the_paper_cell(cone):
    """On the paper's cone with an IRB 7600 the best candidate predicts a lower mean robot
    deflection than the paper-like placement (2.2 m in front, γ = 0)."""
    prob, _ = cone
    P = placement_grid([1.4, 1.8, 2.2], [0.0, 0.3], [0.2, 0.6], [0.0])
    r = plan_placements(prob, P, [0.0], baseline=PAPER_CELL_PLACEMENT, scheduler="serial")
    assert r.baseline is not None and r.baseline.ok
    assert r.best.mean_robot < r.baseline.mean_robot
    gain = r.improvement("mean_robot")
    assert 0.2 < gain < 1.0
    # ranking is by the objective and the table says so
    means = [r.scores[i].mean_abs for i in r.order]
    assert means == sorted(means)
    assert r.table()[0]["rank"] == 1


def test_unreachable_candidates_are_reported_and_none_feasible_is_an_error(cone):
    prob, _ = cone
    P = np.array([[1.6, 0.0, 0.6, 0.0], [6.0, 0.0, 0.6, 0.0]])
    r = plan_placements(prob, P, scheduler="serial")
    far = r.scores[1]
    assert far.status == "unreachable" and "out of reach" in far.reason
    assert r.rejected() == {"unreachable": 1}
    assert r.order.tolist() == [0]
    with pytest.raises(UnreachableError, match="none of the 1 candidate"):
        plan_placements(prob, [[6.0, 0.0, 0.6, 0.0]], scheduler="serial")


def test_singularity_margin_rejects(cone):
    prob, _ = cone
    import dataclasses

    strict = dataclasses.replace(prob, sigma_threshold=10.0)
    s = evaluate_placement(strict, PAPER_CELL_PLACEMENT)
    assert s.status == "singular" and "σ_min" in s.reason
    jumpy = dataclasses.replace(prob, max_joint_step=1e-9)
    s = evaluate_placement(jumpy, PAPER_CELL_PLACEMENT)
    assert s.status == "discontinuous" and "joint jump" in s.reason


def test_bad_input(cone):
    prob, _ = cone
    with pytest.raises(InputError, match="at least one value"):
        placement_grid([], [0.0], [0.0])
    with pytest.raises(InputError, match="NaN"):
        placement_grid([np.nan], [0.0], [0.0])
    with pytest.raises(InputError, match=r"\(M, 4\)"):
        placement_transforms(np.zeros((0, 4)))
    with pytest.raises(InputError, match=r"\(M, 4\)"):
        plan_placements(prob, np.zeros((3, 3)), scheduler="serial")
    with pytest.raises(InputError, match="tool rotation"):
        plan_placements(prob, [[1.6, 0, 0.6, 0]], [], scheduler="serial")
    with pytest.raises(InputError, match="≥ 1"):
        plan_placements(prob, [[1.6, 0, 0.6, 0]], n_workers=0)
    with pytest.raises(InputError, match="≥ 1"):
        plan_placements(prob, [[1.6, 0, 0.6, 0]], batch_size=0, scheduler="serial")
    with pytest.raises(InputError, match="non-decreasing"):
        PlanProblem(prob.model, prob.tip, prob.normal, prob.lap[::-1].copy(), prob.wrench)
    with pytest.raises(InputError, match="ramp_points"):
        PlanProblem(prob.model, prob.tip, prob.normal, prob.lap, prob.wrench, ramp_points=0)
    with pytest.raises(InputError, match="objective"):
        PlanProblem(prob.model, prob.tip, prob.normal, prob.lap, prob.wrench, objective="x")
    with pytest.raises(InputError, match="joint stiffness"):
        PlanProblem(load_robot("kr210-r2700-2"), prob.tip, prob.normal, prob.lap, prob.wrench)
    with pytest.raises(InputError, match="wrench"):
        PlanProblem(prob.model, prob.tip, prob.normal, prob.lap, prob.wrench[:-1])


def test_per_lap_schedule_beats_every_constant_rotation(cone_robot_only):
    """Force along x on the first half of the laps, along y on the second half, and a tool that is
    soft in its own y: the best is γ = 0 first (x_tool along the force), then γ = 90°, ramped."""
    import dataclasses

    p = cone_robot_only
    half = p.lap_id >= p.n_laps // 2
    W = np.zeros_like(p.wrench)
    W[~half, 0] = 200.0
    W[half, 1] = 200.0
    W[:, 2] = 400.0
    k = np.diag([1e-7, 2e-6, 1e-9, 0.0, 0.0, 0.0])
    prob = dataclasses.replace(
        PlanProblem(p.model, p.tip, p.normal, p.lap, W, tool_compliance=k),
        max_rotation_step=math.radians(90),
        ramp_points=5,
    )
    g = np.radians([0.0, 90.0])
    consts = [evaluate_placement(prob, PAPER_CELL_PLACEMENT, [x]) for x in g]
    s = evaluate_placement(prob, PAPER_CELL_PLACEMENT, g)
    assert s.ok
    L = prob.n_laps
    np.testing.assert_allclose(s.gamma[: L // 2], 0.0)
    np.testing.assert_allclose(s.gamma[L // 2 :], math.pi / 2)
    assert s.mean_abs < min(c.mean_abs for c in consts) * 0.9
    # the realised (ramped) path is what was scored: recompute it independently
    ev = _solve(prob, PAPER_CELL_PLACEMENT, _realise(prob, s.gamma))
    assert s.mean_abs == pytest.approx(np.linalg.norm(ev.d_total, axis=1).mean(), rel=1e-12)
    assert s.max_joint_step <= prob.max_joint_step


def test_margin_test_agrees_with_the_singular_values(cone_robot_only):
    """The LDLᵀ pivot test says σ_min > threshold exactly where eigvalsh does."""
    from roboisf.plan import margin_ok, sigma_min

    ev = _solve(cone_robot_only, PAPER_CELL_PLACEMENT, 0.0)
    rng = np.random.default_rng(3)
    R = rng.normal(size=(2000, 6, 6))
    R[:500, :, 5] = R[:500, :, 4] + 1e-4 * rng.normal(size=(500, 6))  # nearly singular
    for Js in (ev.J_scaled, R):
        sig = sigma_min(Js)
        for thr in np.quantile(sig, [0.05, 0.5, 0.95]):
            ok = margin_ok(Js, thr)
            far = np.abs(sig - thr) > 1e-9 * max(1.0, thr)
            assert np.array_equal(ok[far], (sig > thr)[far])
            assert 0 < ok.sum() < len(ok)
    # and the path value reported for a shortlisted placement is ik_toolpath's
    from roboisf.plan import path_sigma_min

    L = cone_robot_only.n_laps
    ref = ik_toolpath(cone_robot_only.model, cone_robot_only.tip, PAPER_CELL_PLACEMENT).sigma_min
    got = path_sigma_min(cone_robot_only, PAPER_CELL_PLACEMENT, np.zeros(L))
    assert got == pytest.approx(ref.min(), rel=1e-9)


def test_path_sigma_min_equals_every_points_eigenvalues():
    """The pruned search (every 64th point, then the elimination test) gives the minimum of all
    points' σ_min, bit for bit: on the paper cell, elsewhere and near a wrist singularity (the
    angled tool at γ = 180°, a sharp minimum the subsample misses)."""
    from roboisf.plan.evaluate import _path_sigma_min_all, path_sigma_min

    cone, _ = problem_from_cell(CELL.cell, **CELL.path_settings)
    angled = problem_from_cell(CELL.cell, **CELL.path_settings, model=_angled_model())[0]
    cases = [
        (cone, PAPER_CELL_PLACEMENT, 0.0),
        (cone, placement_transforms([[1.2, 0.0, 0.4, 0.0]])[0], 0.0),
        (angled, placement_transforms([[1.6, 0.0, 0.6, 0.0]])[0], math.pi),
        (angled, placement_transforms([[1.6, 0.0, 0.6, 0.0]])[0], 2.0),
    ]
    vals = []
    for prob, T, g in cases:
        gl = np.full(prob.n_laps, g)
        a, b = path_sigma_min(prob, T, gl), _path_sigma_min_all(prob, T, gl)
        assert a == b
        vals.append(a)
    assert min(vals) < 0.1  # a case near the singularity was really tested
