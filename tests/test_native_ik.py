"""The robot IK's C form (``vjm_kernel.c``: ik_numba's _flange_rows, _tip_rows, _continuous,
_vjm_rows with its atan2 and _wrap, and vjm_numba._margin_rows) against the numba form, bit for
bit. ``roboisf compensate`` / ``roboisf plan`` with each form: tests/test_install_kernels.py."""

from __future__ import annotations

import math
import threading
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf.frames import invert
from roboisf.frames.se3 import make_transform
from roboisf.robot import ik_numba, vjm_kernel
from roboisf.robot.model import RobotModel
from roboisf.robot.presets import list_robots, load_robot
from roboisf.robot.singularity import margin_ok, scaled_jacobian, sigma_min
from test_native_robot import _model  # the same presets with the same tool

VK = "roboisf.robot.vjm_kernel"
pytestmark = pytest.mark.skipif(not vjm_kernel.HAVE_NUMBA, reason="numba not installed")
BRANCHES = [
    (s, e, w) for s in ("front", "back") for e in ("up", "down") for w in ("noflip", "flip")
]
PRESETS = [n for n in list_robots() if load_robot(n).opw is not None]


def _same(a: Any, b: Any) -> None:
    """Same shape, dtype and bits (a NaN equals any NaN; -0.0 differs from 0.0)."""
    same_bits(a, b, nan_sign=False)


def _flange_poses(m: RobotModel, n: int, seed: int) -> np.ndarray:
    """Flange poses (as tests/test_robot_ik.py's): from angles within the limits, a third with
    the wrist near θ5 = 0 (1e-4 … 0.05 rad), a tenth exactly at it, and a tenth out of reach
    (10 m further out)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(m.q_min, m.q_max, (n, 6)) * 0.98
    k = n // 3
    q[:k, 4] = rng.choice([-1.0, 1.0], k) * rng.uniform(1e-4, 0.05, k)
    q[k : k + n // 10, 4] = 0.0
    T = m.fk(q, check_limits=False) @ invert(m.T_flange_tip)
    T[-(n // 10) :, 0, 3] += 10.0
    return np.ascontiguousarray(T)


def _axis_poses(m: RobotModel) -> np.ndarray:
    """Flange poses whose wrist centre is on the A1 axis (b = 0 on every preset: the OPW's
    ``h2 = 0`` branch, θ1 from atan2(0, 0)), the tool straight down or up, at heights some of
    which are reachable."""
    out = []
    for R in (np.diag([1.0, -1.0, -1.0]), np.eye(3)):
        for z in np.linspace(0.2, 3.5, 12):
            out.append(make_transform(R, [0.0, 0.0, z]))
    return np.array(out)


def _stretched_poses(m: RobotModel, n: int, seed: int) -> np.ndarray:
    """Flange poses with the arm stretched or folded (θ3 = −φ or π − φ: |D| = 1 to rounding,
    the reach test's 1e-12 tolerance), the wrist random."""
    rng = np.random.default_rng(seed)
    g = m.opw
    q = rng.uniform(m.q_min, m.q_max, (n, 6)) * 0.9
    th3 = -math.atan2(g.a2, g.c3) + np.pi * (np.arange(n) % 2)
    s, o, c23 = m.chain.sign, m.chain.offset, m.chain.couple23
    q[:, 2] = (th3 - o[2]) / s[2] - c23 * q[:, 1]
    return np.ascontiguousarray(m.fk(q, check_limits=False) @ invert(m.T_flange_tip))


@pytest.fixture(autouse=True)
def _built() -> None:
    c_library(vjm_kernel)


def test_the_ik_functions_are_in_the_c_form() -> None:
    names = {"flange_rows", "tip_rows", "continuous", "path_vjm_rows", "margin_rows"}
    assert names <= set(vjm_kernel.SIGNATURES)
    assert {load_robot(n).chain.couple23 != 0.0 for n in PRESETS} == {True, False}


# ---- atan2 and _wrap ---------------------------------------------------------------------


def _c_many(name: str, *xs: np.ndarray) -> np.ndarray:
    lib = vjm_kernel._c()
    xs = tuple(np.ascontiguousarray(x, dtype=np.float64) for x in xs)
    out = np.empty(xs[0].shape[0])
    getattr(lib, name)(*(x.ctypes.data for x in xs), out.ctypes.data, out.shape[0])
    return out


def test_atan2_c_equals_numba_on_every_path() -> None:
    """Every branch of the fdlibm atan2: the reduction intervals and their boundaries (7/16,
    11/16, 19/16, 39/16), |y/x| < 2**-27, > 2**60, ≥ 2**66, x < 0 with |y/x| < 2**-60, the four
    quadrants, and libm's zeros, infinities and NaN."""
    rng = np.random.default_rng(1)
    r = np.concatenate(
        [
            rng.uniform(0, 3, 3000),
            10.0 ** rng.uniform(-30, 30, 3000),
            [0.4375, 0.6875, 1.1875, 2.4375, 2.0**-27, 2.0**-28, 2.0**60, 2.0**61, 2.0**66],
            [2.0**-61, 2.0**-59, 1.0, 7.3786976294838206464e19 * 2],
        ]
    )
    r = np.concatenate([r, np.nextafter(r, 0), np.nextafter(r, np.inf)])
    x = rng.choice([-1.0, 1.0], r.size) * 10.0 ** rng.uniform(-3, 3, r.size)
    y = r * x * rng.choice([-1.0, 1.0], r.size)
    sp = [0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan]
    ys, xs = np.meshgrid(sp, sp)
    y = np.concatenate([y, ys.ravel()])
    x = np.concatenate([x, xs.ravel()])
    got = _c_many("atan2_many", y, x)
    _same(got, ik_numba._atan2_many(y, x))
    # and not trivially: within 2 ulp of libm's
    fin = np.isfinite(got)
    assert np.all(np.abs(got[fin] - np.arctan2(y, x)[fin]) <= 4.5e-16 * np.abs(got[fin]) + 1e-300)


def test_wrap_c_equals_numba_on_every_path() -> None:
    """_wrap's three shortcut intervals of x + π, their boundaries (0, 2π, 4π, −2π: the
    modulo's signed zeros), and the modulo beyond them, NaN and ±inf."""
    rng = np.random.default_rng(2)
    pi, tau = np.pi, 2 * np.pi
    b = np.array([-pi, pi, 3 * pi, -3 * pi, -pi - tau, 0.0, -0.0])
    x = np.concatenate(
        [
            rng.uniform(-3 * pi, 3 * pi, 4000),
            rng.uniform(-1e4, 1e4, 500),
            b,
            np.nextafter(b, np.inf),
            np.nextafter(b, -np.inf),
            [tau - pi, 2 * tau - pi, -tau - pi, 1e300, -1e300, np.nan, np.inf, -np.inf],
        ]
    )
    y = x + pi
    assert ((y > 0) & (y < tau)).any() and ((y >= tau) & (y < 2 * tau)).any()
    assert ((y > -tau) & (y < 0)).any() and (y == 0).any() and (np.abs(y) > 2 * tau).any()
    _same(_c_many("wrap_many", x), ik_numba._wrap_many(x))


# ---- flange_ik -----------------------------------------------------------------------------


def _flange_both(m: RobotModel, T: np.ndarray, br: tuple[str, str, str]) -> tuple[Any, Any]:
    got = ik_numba.flange_ik(m, T, *br)
    with numba_form(VK):
        want = ik_numba.flange_ik(m, T, *br)
    return got, want


@pytest.mark.parametrize("name", PRESETS)
def test_flange_ik_c_equals_numba_on_every_branch(name: str) -> None:
    """Every preset (the FANUC J2/J3 coupling too) and all 8 branches; 2 311 poses (chunks of
    1 024, the last short): reachable, near- and exactly singular wrists, out of reach, and
    wrist centres on the A1 axis."""
    m = _model(name)
    seed = sum(map(ord, name))
    T = np.concatenate(
        [_flange_poses(m, 2300, seed), _axis_poses(m), _stretched_poses(m, 400, seed)]
    )
    for br in BRANCHES:
        (q, ok), (qn, okn) = _flange_both(m, T, br)
        _same(q, qn)
        _same(ok, okn)
        assert ok[:2000].sum() > 200 and not ok[2070:2300].any()  # both answers occur
        assert ok[-424:-400].any()  # an A1-axis pose is solved (the h2 = 0 branch)


@pytest.mark.parametrize("n", [0, 1, 7, 1025])
def test_flange_ik_sizes_layouts_and_a_worker_thread(n: int) -> None:
    """N = 0, 1, odd; a Fortran-ordered input (copied to C order); from a thread other than
    the main one (one serial pass of chunks)."""
    m = _model("m900ib-700")
    T = np.asfortranarray(_flange_poses(m, max(n, 10), seed=3)[:n])
    (q, ok), (qn, okn) = _flange_both(m, T, ("front", "up", "flip"))
    box: list[Any] = []
    th = threading.Thread(
        target=lambda: box.append(ik_numba.flange_ik(m, T, "front", "up", "flip"))
    )
    th.start()
    th.join()
    assert q.shape == (n, 6)
    for a, b in ((q, qn), (ok, okn), (box[0][0], qn), (box[0][1], okn)):
        _same(a, b)


def test_opw_ik_dispatches_to_c_without_numba_form() -> None:
    """opw_ik (the public entry) runs the C form when it is built: its answers are C's."""
    from roboisf.robot import opw_ik

    m = _model("kr210-r2700-2")
    T = _flange_poses(m, 300, seed=4)
    q, ok = opw_ik(m, T, backend="auto")
    qc, okc = ik_numba.flange_ik(m, T, "front", "up", "noflip")
    _same(q, qc)
    _same(ok, okc)


# ---- path_ik (tool poses, OPW, continuity, limits) ----------------------------------------


def _spiral(n: int, turns: float = 3.0) -> np.ndarray:
    """A cone's spiral toolpath (work axes, m): radius 0.1 → 0.03, 40 mm deep."""
    t = np.linspace(0.0, 1.0, n)
    r = 0.1 - 0.07 * t
    a = 2 * np.pi * turns * t
    return np.column_stack([r * np.cos(a), r * np.sin(a), -0.04 * t])


def _path_both(m: RobotModel, tip: np.ndarray, T: np.ndarray, g: np.ndarray, br: Any, **kw: Any):
    B = invert(m.T_flange_tip)
    got = ik_numba.path_ik(m, tip, T, B, g, *br, **kw)
    with numba_form(VK):
        want = ik_numba.path_ik(m, tip, T, B, g, *br, **kw)
    return got, want


def _check_path(got: Any, want: Any) -> None:
    (q, ok, within, Tt), (qn, okn, withinn, Ttn) = got, want
    _same(q, qn)
    _same(ok, okn)
    assert within == withinn
    assert (Tt is None) == (Ttn is None)
    if Tt is not None:
        _same(Tt, Ttn)


@pytest.mark.parametrize("name", PRESETS)
def test_path_ik_c_equals_numba(name: str) -> None:
    """Every preset: random placements around the default one, every branch, γ one for the
    path or per point (sweeping whole turns: A6 crosses ±π and is unwrapped), with and
    without the tip poses; the verdicts (out of reach, beyond limits, within) all occur."""
    m = _model(name)
    rng = np.random.default_rng(sum(map(ord, name)) + 5)
    tip = _spiral(1501)
    verdicts = set()
    for trial in range(16):
        T = m.default_placement.copy()
        T[:3, 3] += rng.normal(0, 0.3, 3)
        br = BRANCHES[trial % 8]
        g = (
            np.array([rng.uniform(-np.pi, np.pi)])
            if trial % 2
            else np.linspace(0.0, rng.uniform(-4, 4) * np.pi, len(tip))
        )
        got, want = _path_both(m, tip, T, g, br, want_tip_poses=bool(trial % 3))
        _check_path(got, want)
        verdicts.add("out" if not got[1].all() else ("in" if got[2] else "beyond"))
    assert "in" in verdicts and len(verdicts) >= 2, verdicts


def test_path_ik_continuity_shifts_and_limits() -> None:
    """Narrow limits that force the whole-turn shift (k ≠ 0, then dk = ±1) and limits no shift
    satisfies; per-point γ sweeping five turns (A6 unwrapped many times)."""
    m0 = _model("irb7600-500-2.55")
    tip = _spiral(800, turns=1.0)
    g = np.linspace(-5 * np.pi, 5 * np.pi, len(tip))
    (q, ok, _, _), _ = _path_both(m0, tip, m0.default_placement, g, BRANCHES[0])
    assert ok.all() and np.ptp(q[:, 5]) > 8 * np.pi
    lo, hi = q.min(axis=0), q.max(axis=0)
    cases = [
        (lo - 0.01 + 2 * np.pi, hi + 0.01 + 2 * np.pi),  # a whole turn up
        (lo - 0.01 - 4 * np.pi, hi + 0.01 - 4 * np.pi),  # two down
        (lo - 0.01 - np.pi, hi + 0.01 + np.pi),  # mid-way: k rounds, dk tries ±1
        (lo + 0.01, hi + 0.02),  # fits no shift
        (lo - 1e-10, hi + 1e-10),  # the ± 1e-9 rad tolerance
    ]
    seen = set()
    for q_min, q_max in cases:
        m = replace(m0, q_min=q_min, q_max=q_max)
        got, want = _path_both(m, tip, m.default_placement, g, BRANCHES[0])
        _check_path(got, want)
        seen.add(got[2])
    assert seen == {True, False}


def _cont_both(q: np.ndarray, q_min: np.ndarray, q_max: np.ndarray) -> None:
    """The C ``continuous`` and numba's _continuous on copies of ``q`` (n, 6)."""
    lib = vjm_kernel._c()
    a, b = np.array(q, order="C"), np.array(q, order="C")
    qmin, qmax = np.array(q_min, dtype=float), np.array(q_max, dtype=float)
    r = bool(lib.continuous(a.ctypes.data, a.shape[0], qmin.ctypes.data, qmax.ctypes.data))
    rn = bool(ik_numba._continuous(b, qmin, qmax))
    assert r == rn
    _same(a, b)
    return r


def test_continuous_edge_cases() -> None:
    """_continuous directly: steps of exactly ±π (np.unwrap's boundary), steps over π both
    ways, one row, a column whose shift ratio is exactly ½ (round half to even) and −½, wide
    and narrow limits."""
    pi = np.pi
    rng = np.random.default_rng(6)
    lim = np.full(6, 3 * pi)
    outcomes = []
    walk = np.cumsum(rng.uniform(-1.3 * pi, 1.3 * pi, (500, 6)), axis=0)
    walk = (walk + pi) % (2 * pi) - pi  # wrapped, as the OPW gives them
    outcomes.append(_cont_both(walk, -lim, lim))
    outcomes.append(_cont_both(walk, -lim / 30, lim / 30))
    exact = np.zeros((6, 6))
    exact[1::2] = pi  # 0, π, 0, π, …: steps of +π and −π exactly
    exact[:, 1] = [0.0, -pi, 0.0, -pi, 0.0, -pi]
    outcomes.append(_cont_both(exact, -lim, lim))
    one = rng.uniform(-pi, pi, (1, 6))
    outcomes.append(_cont_both(one, -lim, lim))
    half = np.full((4, 6), -pi)  # (mid − mean) / 2π = 0.5 exactly with mid = 0
    half[:, 1] = pi  # −0.5
    outcomes.append(_cont_both(half, -lim, lim))
    outcomes.append(_cont_both(half, np.full(6, -pi - 0.5), np.full(6, pi - 2.0)))
    assert set(outcomes) == {True, False}
    assert (walk[1:] - walk[:-1] > pi).any() and (walk[1:] - walk[:-1] < -pi).any()


@pytest.mark.parametrize("n", [0, 1, 3, 1027])
def test_path_ik_sizes_and_a_worker_thread(n: int) -> None:
    """N = 0 (no angle: within), 1, odd; from a worker thread: the same bits."""
    m = _model("r2000ic-210f")
    tip = _spiral(max(n, 2))[:n]
    g = np.linspace(0, 1, n)
    args = (m, tip, m.default_placement, invert(m.T_flange_tip), g, "front", "up", "noflip")
    got, want = _path_both(m, tip, m.default_placement, g, ("front", "up", "noflip"))
    _check_path(got, want)
    box: list[Any] = []
    th = threading.Thread(target=lambda: box.append(ik_numba.path_ik(*args)))
    th.start()
    th.join()
    _check_path(box[0], want)
    if n == 0:
        assert got[2] is True


def test_path_ik_refuses_wrong_shapes() -> None:
    m = _model("kr210-r2700-2")
    tip = _spiral(10)
    B = invert(m.T_flange_tip)
    with pytest.raises(ValueError, match="gamma"):
        ik_numba.path_ik(m, tip, m.default_placement, B, np.zeros(3), "front", "up", "noflip")
    with pytest.raises(ValueError, match="T_base_work"):
        ik_numba.path_ik(m, tip, np.eye(3), B, np.zeros(1), "front", "up", "noflip")
    with pytest.raises(ValueError, match="tip"):
        ik_numba.path_ik(
            m, tip[:, :2], m.default_placement, B, np.zeros(1), "front", "up", "noflip"
        )


# ---- path_vjm (roboisf.plan's pass) and the margin test ------------------------------------


@pytest.fixture(scope="module")
def plan_problem() -> Any:
    """The paper cone's plan problem (tests/test_robot_ik.py's), a coarse path."""
    from roboisf.plan import problem_from_cell
    from roboisf.virtual.cell import paper_cone_cell

    vc = paper_cone_cell(spacing=34.8 / 600)
    prob, _ = problem_from_cell(vc.cell, **vc.path_settings)
    return prob


def _vjm_both(*args: Any, **kw: Any) -> tuple[Any, Any]:
    got = ik_numba.path_vjm(*args, **kw)
    with numba_form(VK):
        want = ik_numba.path_vjm(*args, **kw)
    assert got.status == want.status
    for a, b in zip(got, want, strict=True):
        if isinstance(a, np.ndarray):
            _same(a, b)
        else:
            assert a == b
    return got, want


def test_path_vjm_c_equals_numba(plan_problem: Any) -> None:
    """With and without the tool's compliance, the ball centre (0 and the problem's radius),
    the normals; γ one or per point, one wrench for all or per point; the margin threshold
    set so that both answers occur; placements out of reach and beyond the limits."""
    p = plan_problem
    m = p.model
    n = p.tip.shape[0]
    tip, W, nrm = (np.array(a, order="C", dtype=float) for a in (p.tip, p.wrench, p.normal))
    C = p.tool_compliance if p.tool_compliance is not None else np.diag(np.full(6, 1e-7))
    rng = np.random.default_rng(7)
    # the margin threshold: the median σ_min of the path's scaled Jacobians (both answers)
    q0 = ik_numba.path_vjm(m, tip, m.default_placement, np.zeros(1), W, None, (1.5, 0.0)).q
    thr = float(np.median(sigma_min(scaled_jacobian(m.jacobian(q0, check_limits=False), 1.5))))
    runs = 0
    oks = []
    for tool in (None, C):
        for rb in (0.0, p.ball_radius or 0.005):
            for g in (np.array([0.4]), np.linspace(-0.5, 2.5, n)):
                for w in (W, W[:1].copy()):
                    for normal in (nrm, None):
                        got, _ = _vjm_both(
                            m, tip, m.default_placement, g, w, tool, (1.5, thr),
                            normal=normal, ball_radius=rb,
                        )  # fmt: skip
                        assert got.status == 0
                        oks.append(got.margin_ok)
                        runs += 1
    assert runs == 32
    ok = np.concatenate(oks)
    assert 0 < ok.sum() < ok.size  # both margin answers
    statuses = set()
    for _ in range(8):
        T = m.default_placement.copy()
        T[:3, 3] += rng.normal(0, 0.8, 3)
        got, _ = _vjm_both(m, tip, T, np.array([0.0]), W, C, (1.5, thr), normal=nrm)
        statuses.add(got.status)
    assert statuses - {0}, statuses  # out of reach or beyond the limits: q compared only


@pytest.mark.parametrize("n", [1, 2, 7])
def test_path_vjm_small_paths(plan_problem: Any, n: int) -> None:
    """N = 1 (its wrench row is also 'one wrench'), 2, odd."""
    p = plan_problem
    m = p.model
    tip = np.array(p.tip[:n], order="C")
    W = np.array(p.wrench[:n], order="C")
    got, _ = _vjm_both(
        m, tip, m.default_placement, np.zeros(1), W, p.tool_compliance, (1.5, 0.05),
        normal=np.array(p.normal[:n], order="C"), ball_radius=0.005,
    )  # fmt: skip
    assert got.status == 0 and got.steps[0] == 0.0


def test_plan_solve_runs_the_c_form(plan_problem: Any) -> None:
    """roboisf.plan's per-placement solve takes the compiled path with the C form (and gives
    the numba form's numbers)."""
    from roboisf.plan import evaluate

    p = plan_problem
    ev = evaluate._solve(p, p.model.default_placement, 0.3)
    with numba_form(VK):
        evn = evaluate._solve(p, p.model.default_placement, 0.3)
    for f in ("q", "margin_ok", "d_total", "d_robot", "steps", "abs_total", "abs_normal"):
        _same(getattr(ev, f), getattr(evn, f))


def test_margin_ok_c_equals_numba() -> None:
    """singularity.margin_ok (vjm_numba.margin_numba's C form): Jacobians of random and
    wrist-singular poses, thresholds where both answers occur; N = 0, 1."""
    m = _model("irb7600-500-2.55")
    rng = np.random.default_rng(8)
    q = rng.uniform(m.q_min, m.q_max, (1500, 6))
    q[:300, 4] = 0.0
    Js = m.jacobian(q, check_limits=False).copy()
    Js[:, :3] /= 2.5
    for thr in (0.0, 0.05, 0.2, 0.5):
        got = margin_ok(Js, thr, backend="numba")
        with numba_form(VK):
            want = margin_ok(Js, thr, backend="numba")
        _same(got, want)
    assert 0 < got.sum() < len(got) or thr == 0.5
    for k in (0, 1):
        got = margin_ok(Js[:k], 0.05)
        with numba_form(VK):
            want = margin_ok(Js[:k], 0.05, backend="numba")
        _same(got, want)


# ---- the commands without numba: tests/test_install_kernels.py (the C forms import no numba;
# the numba forms compile nothing and write the same bytes) ----------------------------


def test_numpy_backend_is_not_the_c_form() -> None:
    """backend="numpy" still runs the numpy IK (its own rounding: not C's bits everywhere)."""
    from roboisf.robot import opw_ik

    m = _model("kr210-r2700-2")
    T = _flange_poses(m, 400, seed=9)
    q, ok = opw_ik(m, T, backend="numpy")
    qc, okc = opw_ik(m, T, backend="auto")
    _same(ok, okc)
    assert not np.array_equal(q[ok], qc[ok])
    away = ok & (np.abs(q[:, 4]) > 0.05)  # A4, A6 ill-conditioned near θ5 = 0
    assert away.sum() > 100
    assert np.abs(np.angle(np.exp(1j * (q[away] - qc[away])))).max() <= 1e-9
