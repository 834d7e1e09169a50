"""The robot batch kernels' C form (``vjm_kernel.c``: fk_numba._rows and vjm_numba._rows with
vjm_chain's walk, sincos and tip Jacobian) against their numba form, bit for bit, and the
dispatch that runs it without numba."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from native_forms import c_library, numba_form, same_bits
from roboisf.frames.se3 import make_transform
from roboisf.robot import fk_numba, vjm_chain, vjm_kernel
from roboisf.robot.model import RobotModel
from roboisf.robot.presets import list_robots, load_robot

VK = "roboisf.robot.vjm_kernel"
SRC = Path(__file__).resolve().parents[1] / "src"
needs_numba = pytest.mark.skipif(not vjm_kernel.HAVE_NUMBA, reason="numba not installed")
pytestmark = needs_numba  # the oracle is the numba form
TOOL = make_transform(np.eye(3), [0.01, -0.02, 0.3])  # a spindle's offset (m)


def _same(a: Any, b: Any) -> None:
    """Same shape and the same bits (a NaN equals any NaN; -0.0 differs from 0.0)."""
    same_bits(a, b, nan_sign=False)


def _model(name: str) -> RobotModel:
    """A preset with a tool; the presets without a published stiffness get one (N·m/rad)."""
    m = replace(load_robot(name), T_flange_tip=TOOL)
    return m if m.stiffness is not None else m.with_stiffness(np.linspace(4e6, 4e5, 6))


def _q(m: RobotModel, n: int, seed: int) -> np.ndarray:
    """Joint angles uniform within the preset's limits (rad)."""
    return np.random.default_rng(seed).uniform(m.q_min, m.q_max, size=(n, 6))


def _wrench(n: int, seed: int) -> np.ndarray:
    """Process wrenches of incremental forming: forces of a few 100 N, moments of tens of N·m."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.normal(0, 400, (n, 3)), rng.normal(0, 30, (n, 3))])


def _chain(m: RobotModel) -> tuple[np.ndarray, ...]:
    F = m.chain.F.copy()
    F[6] = F[6] @ m.T_flange_tip
    return F, np.asarray(m.chain.sign, float), np.asarray(m.chain.offset, float)


def test_the_c_form_is_built() -> None:
    c_library(vjm_kernel)
    assert {"fk_rows", "vjm_rows"} <= set(vjm_kernel.SIGNATURES)


def test_presets_include_the_fanuc_coupling() -> None:
    """The FANUC J2/J3 coupling (its own branch in the walk and the Jacobian) is covered."""
    assert {load_robot(n).chain.couple23 != 0.0 for n in list_robots()} == {True, False}


# ---- tip positions (fk_numba.tip_positions) ---------------------------------------------


@pytest.mark.parametrize("name", list_robots())
def test_tip_positions_c_equals_numba(name: str) -> None:
    """Every preset with a tool, base and work frame; 8 195 poses: chunks of BLOCK poses on
    threads, the last one short."""
    c_library(vjm_kernel)
    m = _model(name)
    q = _q(m, 2 * fk_numba.BLOCK + 3, seed=1)
    c, s = np.cos(0.4), np.sin(0.4)
    T_bw = make_transform(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), [2.2, -0.5, 0.2])
    for T in (None, T_bw):
        got = m.tip_positions(q, check_limits=False, T_base_work=T)
        with numba_form(VK):
            want = m.tip_positions(q, check_limits=False, T_base_work=T, backend="numba")
        _same(got, want)
        # and not trivially: the positions are FK's to rounding
        ref = m.fk(q, check_limits=False, T_base_work=T)[:, :3, 3]
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("n", [0, 1, 7, 4097])
def test_tip_positions_sizes_and_a_worker_thread(n: int) -> None:
    """N = 0, 1, odd; from a thread other than the main one (one serial pass of chunks)."""
    c_library(vjm_kernel)
    m = _model("r2000ic-210f")  # FANUC: coupled J2/J3
    F, sign, offset = _chain(m)
    q = _q(m, n, seed=2)
    T = make_transform(np.eye(3), [1.0, 2.0, 3.0])
    args = (F, sign, offset, m.chain.couple23, T, q)
    got = fk_numba.tip_positions(*args)
    box: list[np.ndarray] = []
    th = threading.Thread(target=lambda: box.append(fk_numba.tip_positions(*args)))
    th.start()
    th.join()
    with numba_form(VK):
        want = fk_numba.tip_positions(*args)
    assert got.shape == (n, 3)
    _same(got, want)
    _same(box[0], want)


def _sincos_angles() -> np.ndarray:
    """Angles for vjm_chain.sincos' paths: every quadrant (n & 3 of negative n too), the
    quadrant boundaries, half-way points of the reduction's rounding (half to even), |x| ≥ 1e5
    (libm), NaN and ±inf."""
    rng = np.random.default_rng(3)
    k = np.arange(-16, 17)
    half = []  # x with x · (2/π) exactly k + 1/2: round() to even, not away from zero
    for kk in range(-40, 41):
        x = (kk + 0.5) / 0.636619772367581343
        for _ in range(8):
            p = x * 0.636619772367581343
            if p == kk + 0.5:
                half.append(x)
                break
            x = np.nextafter(x, np.inf if p < kk + 0.5 else -np.inf)
    return np.concatenate(
        [
            rng.uniform(-30, 30, 4000),
            k * np.pi / 2,
            np.nextafter(k * np.pi / 2, np.inf),
            k * np.pi / 4,
            half,
            [0.0, -0.0, 1e-300, 5e-324, 99_999.9, 1e5, -1e5, 2e5, -3e7, 1e300],
            [np.nan, np.inf, -np.inf],
        ]
    )


def test_sincos_c_equals_numba_and_python_on_every_path() -> None:
    """A chain whose tip is (cos q0, sin q0, 0): sign (1, 0, …) turns joint 1 only (the others
    by sincos(0) = (0, 1), exact), so the tip positions are sincos' bits."""
    c_library(vjm_kernel)
    x = _sincos_angles()
    n = np.array([round(v * 0.636619772367581343) if abs(v) < 1e5 else 0 for v in x])
    assert set(n[n < 0] & 3) == {0, 1, 2, 3} and set(n[n > 0] & 3) == {0, 1, 2, 3}
    half = np.array([abs(v) < 1e5 and (v * 0.636619772367581343) % 1.0 == 0.5 for v in x])
    # a half-way point k + 1/2 with k even and > 0 (half to even and half away from zero differ)
    assert any(v > 0 and math.floor(v * 0.636619772367581343) % 2 == 0 for v in x[half])
    assert np.isnan(x).any() and (np.abs(x) >= 1e5).sum() >= 6
    F = np.tile(np.eye(4), (7, 1, 1))
    F[6, 0, 3] = 1.0
    sign, offset = np.array([1.0, 0, 0, 0, 0, 0]), np.zeros(6)
    q = np.zeros((len(x), 6))
    q[:, 0] = x
    got = fk_numba.tip_positions(F, sign, offset, 0.0, np.eye(4), q)
    with numba_form(VK):
        want = fk_numba.tip_positions(F, sign, offset, 0.0, np.eye(4), q)
    _same(got, want)
    # the plain Python sincos; the tip adds signed zeros (-0.0 + 0.0 = 0.0): compared + 0.0
    # (finite x: Python's math.sin raises for ±inf where numba's gives NaN)
    fin = np.isfinite(x)
    py = np.array([vjm_chain.sincos.py_func(float(v)) for v in x[fin]])
    _same(got[fin, 0] + 0.0, py[:, 1] + 0.0)
    _same(got[fin, 1] + 0.0, py[:, 0] + 0.0)
    assert np.isnan(got[~fin]).all()


def test_tip_positions_general_chain_and_large_angles() -> None:
    """Random rotations in every fixed transform (no zero entries) and joint angles up to
    ±2e5 rad (the reduction and libm), the coupling on; signs and coupling not ±1 (gear
    ratios: the order of the products shows)."""
    c_library(vjm_kernel)
    rng = np.random.default_rng(4)
    F = np.empty((7, 4, 4))
    for j in range(7):
        Qm, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        F[j] = make_transform(Qm, rng.normal(0, 0.5, 3))
    sign = rng.choice([-1.0, 1.0], 6) * rng.uniform(0.5, 2.0, 6)
    offset = rng.uniform(-np.pi, np.pi, 6)
    q = rng.uniform(-2e5, 2e5, (3001, 6)) * rng.choice([1e-5, 1.0], (3001, 6))
    T = make_transform(np.linalg.qr(rng.normal(size=(3, 3)))[0], [0.3, 0.1, -0.2])
    for c23 in (0.0, -1.0, 0.7):
        got = fk_numba.tip_positions(F, sign, offset, c23, T, q)
        with numba_form(VK):
            want = fk_numba.tip_positions(F, sign, offset, c23, T, q)
        _same(got, want)


def test_tip_positions_refuses_wrong_shapes() -> None:
    c_library(vjm_kernel)
    m = _model("kr210-r2700-2")
    F, sign, offset = _chain(m)
    q = _q(m, 5, seed=5)
    with pytest.raises(ValueError, match="F_tip"):
        fk_numba.tip_positions(F[:6], sign, offset, 0.0, np.eye(4), q)
    with pytest.raises(ValueError, match="q"):
        fk_numba.tip_positions(F, sign, offset, 0.0, np.eye(4), q[:, :5])
    with pytest.raises(ValueError, match="T_out_base"):
        fk_numba.tip_positions(F, sign, offset, 0.0, np.eye(4)[:3], q)


# ---- the VJM pass (vjm_kernel.vjm_eval) ---------------------------------------------------


def _vjm_both(m: RobotModel, q: np.ndarray, W: np.ndarray, **kw: Any) -> tuple[Any, Any]:
    got = m.vjm(q, W, backend="numba", **kw)
    with numba_form(VK):
        want = m.vjm(q, W, backend="numba", **kw)
    return got, want


@pytest.mark.parametrize("name", list_robots())
def test_vjm_c_equals_numba(name: str) -> None:
    """Every preset: δ, k_c, J and the margin test, per-pose wrenches and one for all; 2 501
    poses (several chunks of 1 024 on threads, the last one short); the margin threshold set
    so that both answers occur."""
    c_library(vjm_kernel)
    m = _model(name)
    q = _q(m, 2501, seed=6)
    W = _wrench(len(q), seed=7)
    L = 2.0  # m: the length scale of the margin test
    Js = m.jacobian(q, check_limits=False).copy()
    Js[:, :3] /= L
    thr = float(np.median(np.linalg.svd(Js, compute_uv=False)[:, -1]))
    for w in (W, W[0]):
        got, want = _vjm_both(m, q, w, want_compliance=True, want_jacobian=True, margin=(L, thr))
        for a, b in zip(got, want, strict=True):
            _same(a, b)
        assert 0 < got.margin_ok.sum() < len(q)
    # δ alone (the analysis' call): no k, J, margin written
    got, want = _vjm_both(m, q, W)
    assert got.k is None and got.J is None and got.margin_ok is None
    _same(got.d, want.d)


@pytest.mark.parametrize("n", [0, 1, 7, 1025])
def test_vjm_sizes_layouts_and_a_worker_thread(n: int) -> None:
    """N = 0, 1, odd; angles in a Fortran-ordered array (copied to C order), and from a
    thread other than the main one (serial)."""
    c_library(vjm_kernel)
    m = _model("m900ib-700")  # FANUC: coupled J2/J3
    q = np.asfortranarray(_q(m, n, seed=8))
    W = _wrench(n, seed=9)
    kw: dict[str, Any] = {"want_compliance": True, "want_jacobian": True, "margin": (2.0, 0.05)}
    got, want = _vjm_both(m, q, W, **kw)
    box: list[Any] = []
    th = threading.Thread(target=lambda: box.append(m.vjm(q, W, backend="numba", **kw)))
    th.start()
    th.join()
    for a, b, c in zip(got, want, box[0], strict=True):
        assert a.shape[0] == n
        _same(a, b)
        _same(c, b)


def test_vjm_zero_wrench_keeps_the_signs_of_zero() -> None:
    """W = 0 and W = -0: every δ is a sum of signed zeros (0.0 + -0.0 = 0.0 from the
    accumulator's start), compared by bits."""
    c_library(vjm_kernel)
    m = _model("irb6700-200-2.60")
    q = _q(m, 50, seed=10)
    for W in (np.zeros((50, 6)), np.full((50, 6), -0.0)):
        got, want = _vjm_both(m, q, W)
        _same(got.d, want.d)
        assert not np.any(got.d)


def test_vjm_calls_in_pieces_give_the_same_bits(monkeypatch: pytest.MonkeyPatch) -> None:
    """Inputs longer than one kernel call (vjm_kernel._CALL) are cut into calls."""
    c_library(vjm_kernel)
    m = _model("kr210-r2700-2")
    q = _q(m, 2500, seed=11)
    W = _wrench(len(q), seed=12)
    whole = m.vjm(q, W, want_compliance=True, margin=(2.0, 0.05), backend="numba")
    monkeypatch.setattr(vjm_kernel, "_CALL", 999)
    pieces, want = _vjm_both(m, q, W, want_compliance=True, margin=(2.0, 0.05))
    for a, b, c in zip(whole, pieces, want, strict=True):
        _same(a, c)
        _same(b, c)


def test_singular_poses_and_the_margin_test() -> None:
    """Wrist and elbow singular poses (J4/J6 aligned, arm stretched): zero and negative pivots
    of the margin test's elimination, the same answers."""
    c_library(vjm_kernel)
    m = _model("irb7600-500-2.55")
    q = _q(m, 600, seed=13)
    q[:200, 4] = 0.0  # wrist singular
    q[200:400, 4] = np.random.default_rng(14).normal(0, 1e-3, 200)
    W = _wrench(len(q), seed=15)
    for thr in (0.0, 1e-6, 0.05, 0.3):
        got, want = _vjm_both(m, q, W, want_jacobian=True, margin=(2.5, thr))
        for a, b in zip(got, want, strict=True):
            _same(a, b)
    assert not got.margin_ok[:200].any()


# ---- the dispatch -------------------------------------------------------------------------


def test_analysis_calls_run_c_without_numba_or_the_robot_group(tmp_path: Path) -> None:
    """With the C form built, tip_positions and vjm ("auto") run it in a process that never
    imports numba, never asks jit.ready("robot") (whose numba cache is empty here) and starts
    no background builder."""
    c_library(vjm_kernel)
    env = dict(os.environ, ROBOISF_BACKGROUND_COMPILE="1", NUMBA_CACHE_DIR=str(tmp_path))
    env["PYTHONPATH"] = str(SRC)
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from roboisf import jit\n"
        "from roboisf.jit import background as bg\n"
        "bg._start = lambda: sys.exit('a builder was started')\n"
        "ready = jit.ready\n"
        "def asked(g):\n"
        "    if g == 'robot':\n"
        "        sys.exit('jit.ready(robot) was asked')\n"
        "    return ready(g)\n"
        "jit.ready = asked\n"
        "from roboisf.robot import load_robot\n"
        "m = load_robot('irb7600-500-2.55')\n"
        "q = 0.5 * (m.q_min + m.q_max) + np.linspace(-0.3, 0.3, 50)[:, None]\n"
        "p = m.tip_positions(q)\n"
        "d = m.vjm(q, np.ones(6), want_compliance=True).d\n"
        "assert p.shape == (50, 3) and d.shape == (50, 6)\n"
        "assert 'numba' not in sys.modules, 'numba was imported'\n"
        "print('ok')\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr


def test_numpy_backend_still_numpy() -> None:
    """backend="numpy" is not the C form: the numpy engine's FK (fk's own numbers)."""
    m = _model("kr240-r2900-2")
    q = _q(m, 100, seed=16)
    got = m.tip_positions(q, check_limits=False, backend="numpy")
    _same(got, m.fk(q, check_limits=False)[:, :3, 3])
    assert vjm_kernel.use_c("numpy") is False
    assert vjm_kernel.use_c("auto") is (vjm_kernel._c() is not None)
