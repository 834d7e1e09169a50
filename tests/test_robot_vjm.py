"""VJM: frames, serial assembly with a tool, complementary stiffness, statistics, contributions."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames import make_transform, rot_z
from roboisf.parts import Cone
from roboisf.robot import (
    compliance_stats,
    deflection_contributions,
    geometric_stiffness,
    ik_toolpath,
    load_robot,
    loaded_deflection,
    rotate_6,
    tip_compliance,
    vjm_batch,
    vjm_kernel,
)
from roboisf.toolpath import step_down

TOOL = make_transform(None, [0.02, 0.0, 0.30])


@pytest.fixture(scope="module")
def setup():
    m = load_robot("irb7600-500-2.55").with_tool(TOOL)
    tp = step_down(Cone())
    q = ik_toolpath(m, tp).q[::50]
    return m, q


def test_work_frame_compliance_is_rotation_of_base(setup):
    m, q = setup
    Tbw = make_transform(rot_z(0.7), [1.6, 0.2, 0.8])
    kw = tip_compliance(m, q, T_base_work=Tbw)
    kb = m.compliance(q)
    W_work = np.random.default_rng(0).normal(size=(len(q), 6)) * 400
    d_work = np.einsum("nij,nj->ni", kw, W_work)
    d_base = m.deflection(q, rotate_6(W_work, Tbw[:3, :3]))
    np.testing.assert_allclose(rotate_6(d_work, Tbw[:3, :3]), d_base, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(
        np.trace(kw[:, :3, :3], axis1=1, axis2=2), np.trace(kb[:, :3, :3], axis1=1, axis2=2)
    )


def test_tool_compliance_added_at_the_tip(setup):
    """A lateral tool compliance (tip axes) adds k_lat to the two in-plane tip directions."""
    m, q = setup
    k_tool = np.diag([9.34e-7, 9.34e-7, 4.45e-9, 0, 0, 0])
    k = tip_compliance(m, q, [(k_tool, np.zeros(3))])
    R = m.fk(q)[:, :3, :3]
    added = np.swapaxes(R, 1, 2) @ (k - m.compliance(q))[:, :3, :3] @ R
    np.testing.assert_allclose(added, np.broadcast_to(k_tool[:3, :3], added.shape), atol=1e-18)


def test_geometric_stiffness_vs_finite_differences(setup):
    m, q = setup
    W = np.random.default_rng(1).normal(size=(len(q), 6)) * [400, 400, 600, 20, 20, 20]
    KG = geometric_stiffness(m, q, W)
    h = 1e-6
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        tp = np.einsum("nji,nj->ni", m.jacobian(q + dq, check_limits=False), W)
        tm = np.einsum("nji,nj->ni", m.jacobian(q - dq, check_limits=False), W)
        np.testing.assert_allclose(KG[:, :, j], (tp - tm) / (2 * h), atol=1e-6 * np.abs(KG).max())


def test_loaded_deflection_solves_nonlinear_equilibrium(setup):
    """K Δθ = J(q + Δθ)ᵀ W solved by fixed point: the linearised K_G answer agrees to O(W²)."""
    m, q = setup
    q = q[:5]
    W = np.tile([300.0, -200.0, 5000.0, 0, 0, 0], (len(q), 1))  # large load to see K_G
    K = m.joint_stiffness
    dth = np.zeros_like(q)
    for _ in range(50):
        dth = np.einsum("nji,nj->ni", m.jacobian(q + dth, check_limits=False), W) / K
    # tip displacement of the exact equilibrium (first order in Δθ: J Δθ)
    exact = np.einsum("nij,nj->ni", m.jacobian(q), dth)
    lin = loaded_deflection(m, q, W)
    plain = m.deflection(q, W)
    err_lin = np.abs(lin - exact).max()
    err_plain = np.abs(plain - exact).max()
    assert err_lin < 0.05 * err_plain
    assert err_plain > 0


def test_stats_and_contributions(setup):
    m, q = setup
    k = m.compliance(q)
    s = compliance_stats(k)
    np.testing.assert_allclose(s.mean, k.mean(0))
    assert np.all(s.min <= s.mean) and np.all(s.mean <= s.max)
    rows = s.diagonal_table()
    assert rows[0]["component"] == "k_11" and rows[0]["mean"] == pytest.approx(k[:, 0, 0].mean())
    W = np.tile([100.0, 50.0, 500.0, 1.0, 2.0, 3.0], (len(q), 1))
    c = deflection_contributions(k, W)
    np.testing.assert_allclose(c.deflection, m.deflection(q, W), rtol=1e-10, atol=1e-16)
    np.testing.assert_allclose(c.per_point[:, 1, 2], k[:, 1, 2] * 500.0)  # F_z on y through k_23


def test_bad_wrench_and_compliance_shapes(setup):
    m, q = setup
    with pytest.raises(InputError, match="wrench"):
        m.deflection(q, np.zeros((len(q), 3)))
    W = np.zeros((len(q), 6))
    W[0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        m.deflection(q, W)
    with pytest.raises(InputError):
        compliance_stats(np.zeros((3, 5, 5)))


def test_vjm_batch_matches_model_methods(setup):
    m, q = setup
    W = np.random.default_rng(5).normal(size=(len(q), 6)) * 300
    k, d = vjm_batch(m, q, W, chunk=7)
    np.testing.assert_allclose(k, m.compliance(q), rtol=1e-12, atol=1e-22)
    np.testing.assert_allclose(d, m.deflection(q, W), rtol=1e-12, atol=1e-18)
    k2, d2 = vjm_batch(m, q, W, want_compliance=False)
    assert k2 is None and np.allclose(d2, d, rtol=1e-12, atol=1e-18)


def test_work_frame_options_of_the_model(setup):
    m, q = setup
    Tbw = make_transform(rot_z(-0.4), [1.5, -0.3, 0.7])
    Rwb = Tbw[:3, :3].T
    np.testing.assert_allclose(m.fk(q, T_base_work=Tbw), np.linalg.inv(Tbw) @ m.fk(q), atol=1e-14)
    J, Jw = m.jacobian(q), m.jacobian(q, T_base_work=Tbw)
    np.testing.assert_allclose(Jw[:, :3], Rwb @ J[:, :3], atol=1e-14)
    np.testing.assert_allclose(Jw[:, 3:], Rwb @ J[:, 3:], atol=1e-14)
    kw = m.compliance(q, T_base_work=Tbw)
    np.testing.assert_allclose(kw, tip_compliance(m, q, T_base_work=Tbw), rtol=1e-12, atol=1e-22)
    W_work = np.tile([100.0, -50.0, 450.0, 0.0, 0.0, 0.0], (len(q), 1))
    np.testing.assert_allclose(
        m.deflection(q, W_work, T_base_work=Tbw),
        np.einsum("nij,nj->ni", kw, W_work),
        rtol=1e-10,
        atol=1e-16,
    )
    with pytest.raises(InputError, match="rigid"):
        m.compliance(q, T_base_work=np.diag([2.0, 1, 1, 1]))


def test_stiffness_map_values(setup):
    from roboisf.robot import stiffness_map
    from roboisf.robot.ik import ik_toolpath as ik

    m, _ = setup
    smap = stiffness_map(m, half_width=0.3, n=5)
    assert smap.reachable.all()
    # the centre point equals the compliance of the tool-down pose at the work origin
    q0 = ik(m, np.zeros((1, 3))).q
    k0 = m.compliance(q0, T_base_work=m.default_placement)[0]
    np.testing.assert_allclose(smap.compliance[2, 2], np.diag(k0)[:3], rtol=1e-12)


def test_a_small_map_runs_on_numpy_with_the_compiled_numbers(setup, monkeypatch):
    # an "auto" model's map of ≤ MAP_NUMPY_POSES poses is computed with numpy (starting numba
    # for it cost 0.48 s against 6 ms); an explicit backend, or a bigger grid, is left alone
    import roboisf.robot.maps as maps
    from roboisf.robot import stiffness_map

    m, _ = setup
    seen: list[str | None] = []
    real = maps.opw_ik
    monkeypatch.setattr(maps, "opw_ik", lambda *a, **k: seen.append(k["backend"]) or real(*a, **k))
    small = stiffness_map(m, half_width=0.3, n=7)
    explicit = stiffness_map(m, half_width=0.3, n=7, backend="auto")
    monkeypatch.setattr(maps, "MAP_NUMPY_POSES", 48)
    stiffness_map(m, half_width=0.3, n=7)  # 49 poses: above the (lowered) limit
    assert seen == ["numpy", "auto", "auto"]
    np.testing.assert_array_equal(small.reachable, explicit.reachable)
    # the two engines: the same arithmetic to rounding (test_robot_vjm's fused-path tests)
    np.testing.assert_allclose(small.compliance, explicit.compliance, rtol=1e-12, atol=0)


def test_docs_example_runs(capsys):
    """The first python example of docs/robot.md runs as written."""
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "robot.md").read_text(encoding="utf-8")
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(code, "docs/robot.md", "exec"), {})
    assert "k_11" in capsys.readouterr().out


# ---------------------------------------------------------------- the fused VJM path (issue #16)
needs_numba = pytest.mark.skipif(not vjm_kernel.HAVE_NUMBA, reason="numba not installed")
ENGINES = [pytest.param("numba", marks=needs_numba), "numpy"]
PRESETS = ["irb7600-500-2.55", "kr210-r2700-2", "irb4600-60-2.05"]
K_ANY = [3.0e6, 4.0e6, 3.5e6, 6.0e5, 7.0e5, 4.5e5]  # for presets without published stiffness


def _robot(name):
    m = load_robot(name).with_tool(make_transform(rot_z(0.3), [0.02, -0.01, 0.30]))
    return m if m.stiffness is not None else m.with_stiffness(K_ANY)


def _poses(m, n, seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform(m.q_min, m.q_max, (n, 6))
    W = rng.normal(size=(n, 6)) * [300, 300, 500, 10, 10, 10]
    return q, W


def _reference(m, q, W):
    """The numpy formulas as they were before the fused path (per pose, from the Jacobian)."""
    J = m.jacobian(q)
    kinv = 1.0 / m.joint_stiffness
    k = (J * kinv) @ np.swapaxes(J, 1, 2)
    tau = np.einsum("nji,nj->ni", J, W)
    return k, np.einsum("nij,nj->ni", J, tau * kinv)


def _rel_k(k, k_ref):
    """|Δk_ij| / √(k_ii k_jj): the natural scale of a PSD matrix's entries (|k_ij| ≤ it)."""
    s = np.sqrt(np.einsum("nii->ni", k_ref))
    return np.abs(k - k_ref) / (s[:, :, None] * s[:, None, :])


def _rel_d(d, d_ref, k_ref, W):
    """|Δδ_i| / (√k_ii · √(Wᵀk W)): the Cauchy–Schwarz bound of |δ_i|."""
    s = (
        np.sqrt(np.einsum("nii->ni", k_ref))
        * np.sqrt(np.einsum("ni,nij,nj->n", W, k_ref, W))[:, None]
    )
    return np.abs(d - d_ref) / s


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", PRESETS)
def test_engines_equal_the_numpy_formulas_on_every_preset(name, engine):
    """Both engines give the numbers of the per-pose numpy formulas to ≤ 1e-14 relative."""
    m = _robot(name)
    q, W = _poses(m, 3000, seed=11)
    k_ref, d_ref = _reference(m, q, W)
    d = m.deflection(q, W, backend=engine)
    k = m.compliance(q, backend=engine)
    assert _rel_k(k, k_ref).max() <= 1e-14
    assert _rel_d(d, d_ref, k_ref, W).max() <= 1e-14
    np.testing.assert_array_equal(k, np.swapaxes(k, 1, 2))  # symmetric by construction


@needs_numba
def test_numba_engine_on_a_general_dh_chain():
    """Not only OPW presets: a DH chain with skewed twists, signs and offsets (generic walk)."""
    from roboisf.robot import RobotModel, chain_from_dh

    rng = np.random.default_rng(2)
    chain = chain_from_dh(
        d=rng.uniform(-0.5, 0.5, 6),
        a=rng.uniform(-0.5, 0.5, 6),
        alpha=rng.uniform(-np.pi, np.pi, 6),
        offset=rng.uniform(-np.pi, np.pi, 6),
        sign=[1, -1, 1, -1, -1, 1],
    )
    m = RobotModel("dh", chain, -np.full(6, 3.0), np.full(6, 3.0), stiffness=K_ANY)
    m = m.with_tool(make_transform(rot_z(0.4), [0.05, 0.02, 0.2]))
    q, W = _poses(m, 2000, seed=3)
    k_ref, d_ref = _reference(m, q, W)
    assert _rel_d(m.deflection(q, W, backend="numba"), d_ref, k_ref, W).max() <= 1e-14
    assert _rel_k(m.compliance(q, backend="numba"), k_ref).max() <= 1e-14


@needs_numba
def test_numba_parallel_serial_and_threaded_calls_give_the_same_bits():
    import threading

    m = _robot("irb7600-500-2.55")
    q, W = _poses(m, 5000, seed=4)  # several blocks, one partial
    d_main = m.deflection(q, W, backend="numba")  # main thread: the prange kernel
    out = {}

    def run():
        out["d"] = m.deflection(q, W, backend="numba")  # other thread: the serial kernel

    t = threading.Thread(target=run)
    t.start()
    t.join()
    np.testing.assert_array_equal(out["d"], d_main)
    # the pose order and the block boundaries do not matter either
    perm = np.random.default_rng(0).permutation(len(q))
    np.testing.assert_array_equal(m.deflection(q[perm], W[perm], backend="numba"), d_main[perm])


@pytest.mark.parametrize("engine", ENGINES)
def test_broadcast_wrench_chunks_and_empty_input(engine):
    m = _robot("irb7600-500-2.55")
    q, W = _poses(m, 1001, seed=5)
    w = W[0]
    np.testing.assert_array_equal(
        m.deflection(q, w, backend=engine), m.deflection(q, np.tile(w, (len(q), 1)), backend=engine)
    )
    k7, d7 = vjm_batch(m, q, W, chunk=7, backend=engine)
    k_, d_ = vjm_batch(m, q, W, backend=engine)
    np.testing.assert_allclose(d7, d_, rtol=1e-15, atol=1e-20)
    np.testing.assert_allclose(k7, k_, rtol=1e-15, atol=1e-25)
    assert m.deflection(np.zeros((0, 6)), w, backend=engine).shape == (0, 6)
    assert m.compliance(np.zeros((0, 6)), backend=engine).shape == (0, 6, 6)
    with pytest.raises(InputError, match="chunk"):
        vjm_batch(m, q, W, chunk=0, backend=engine)


def test_backend_choice_and_errors(monkeypatch):
    m = _robot("irb7600-500-2.55")
    q, W = _poses(m, 10, seed=6)
    with pytest.raises(InputError, match="backend"):
        m.deflection(q, W, backend="fortran")
    with pytest.raises(InputError, match="backend"):
        m.with_backend("gpu")
    assert m.with_backend("numpy").backend == "numpy"
    monkeypatch.setattr(vjm_kernel, "HAVE_NUMBA", False)
    with pytest.raises(InputError, match=r"ROBOISF_NUMBA=0\) or does not import"):
        m.compliance(q, backend="numba")
    # "auto" without numba is the numpy engine, with the same numbers
    k_ref, d_ref = _reference(m, q, W)
    assert _rel_d(m.deflection(q, W), d_ref, k_ref, W).max() <= 1e-14


@pytest.mark.parametrize("engine", ENGINES)
def test_deflection_memory_is_the_result(engine):
    """Chunked: peak memory of a call ≈ its result, not N × (6×6) temporaries."""
    import tracemalloc

    m = _robot("irb7600-500-2.55")
    q, W = _poses(m, 200_000, seed=7)
    m.deflection(q[:10], W[:10], backend=engine)  # compile / load outside the measurement
    tracemalloc.start()
    d = m.deflection(q, W, backend=engine)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # the unchunked formulas held J (N, 6, 6) and two (N, 6) temporaries: 76.8 MB here
    assert peak < d.nbytes + 8e6, peak


@needs_numba
def test_sincos_within_one_ulp_of_numpy():
    import numba

    from roboisf.robot.vjm_numba import sincos

    @numba.njit
    def run(x, s, c):
        for i in range(x.shape[0]):
            s[i], c[i] = sincos(x[i])

    rng = np.random.default_rng(8)
    k = np.arange(-16, 17)
    x = np.concatenate(
        [
            rng.uniform(-30, 30, 200_000),
            k * np.pi / 2,  # the quadrant boundaries, where the reduction cancels
            np.nextafter(k * np.pi / 2, np.inf),
            k * np.pi / 4,  # the polynomial's interval ends
            [0.0, -0.0, 1e-300, 5e-324, 2e5, -3e7, 1e300],  # beyond 1e5: libm
        ]
    )
    s, c = np.empty_like(x), np.empty_like(x)
    run(x, s, c)
    for got, ref in ((s, np.sin(x)), (c, np.cos(x))):
        ulp = np.spacing(np.maximum(np.abs(ref), np.finfo(float).tiny))
        assert np.max(np.abs(got - ref) / ulp) <= 1.0


def test_single_blas_thread_pins_and_restores():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from roboisf.robot.vjm_kernel import single_blas_thread

    def blas():
        return [
            i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"
        ]

    # from 2 threads, whatever the session runs with (tests/conftest.py pins 1 under xdist)
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = blas()
        assert before and all(n == 2 for n in before)  # numpy's wheels bring OpenBLAS
        with single_blas_thread():
            assert all(n == 1 for n in blas())
        assert blas() == before


@pytest.mark.parametrize("engine", ENGINES)
def test_fused_margin_test_is_the_singularity_check(engine):
    """RobotModel.vjm(margin=…) runs the margin test of robot.singularity inside the VJM pass."""
    from roboisf.robot.singularity import scaled_jacobian, sigma_min

    m = _robot("irb7600-500-2.55")
    q, W = _poses(m, 4000, seed=9)
    q[:1500, 4] = np.random.default_rng(1).normal(0, 0.03, 1500)  # wrist near singular
    L = m.opw.c2 + m.opw.c3
    sig = sigma_min(scaled_jacobian(m.jacobian(q), L))
    for thr in np.quantile(sig, [0.1, 0.5]):
        r = m.vjm(q, W, margin=(L, thr), backend=engine)
        assert r.k is None and r.J is None
        far = np.abs(sig - thr) > 1e-8
        np.testing.assert_array_equal(r.margin_ok[far], (sig > thr)[far])
        assert _rel_d(r.d, *_reference(m, q, W)[::-1], W).max() <= 1e-14


@needs_numba
def test_numba_calls_in_pieces_give_the_same_bits(monkeypatch):
    """Inputs longer than one kernel call are cut into calls (progress between them)."""
    m = _robot("kr210-r2700-2")
    q, W = _poses(m, 2500, seed=10)
    r = m.vjm(q, W, want_compliance=True, margin=(2.0, 0.05), backend="numba")
    seen = []

    class P:
        @contextlib.contextmanager
        def task(self, description, total=None):
            seen.append(total)
            yield seen.append

    monkeypatch.setattr(vjm_kernel, "_CALL", 1000)
    r2 = m.vjm(q, W[0], want_compliance=True, margin=(2.0, 0.05), backend="numba", progress=P())
    np.testing.assert_array_equal(r2.k, r.k)
    np.testing.assert_array_equal(r2.margin_ok, r.margin_ok)
    np.testing.assert_array_equal(r2.d, m.vjm(q, np.tile(W[0], (len(q), 1)), backend="numba").d)
    assert seen == [2500, 1000, 1000, 500]


def test_bad_margin_is_an_input_error():
    m = _robot("irb7600-500-2.55")
    q, W = _poses(m, 5, seed=12)
    for bad in ((0.0, 0.02), (2.0, -1.0), (np.nan, 0.02)):
        with pytest.raises(InputError, match="margin"):
            m.vjm(q, W, margin=bad)


def test_single_blas_thread_pins_a_blas_loaded_after_its_first_use():
    """MKL comes in with pypardiso (the FE) after an analysis may have pinned BLAS once: the
    controller made then did not know MKL, which kept all its threads (seen in the suite once the
    test extra brought pypardiso). In a fresh interpreter, so that MKL really loads second."""
    pytest.importorskip("threadpoolctl")
    pytest.importorskip("pypardiso", reason="pypardiso (the pardiso extra) not installed")
    import subprocess
    import sys

    code = (
        "import threadpoolctl\n"
        "from roboisf.robot.vjm_kernel import single_blas_thread\n"
        "with single_blas_thread():\n"
        "    pass\n"
        "import pypardiso  # loads MKL\n"
        "assert any(i['internal_api'] == 'mkl' for i in threadpoolctl.threadpool_info())\n"
        "with threadpoolctl.threadpool_limits(limits=2, user_api='blas'):\n"
        "    with single_blas_thread():\n"
        "        got = [i['num_threads'] for i in threadpoolctl.threadpool_info()\n"
        "               if i['user_api'] == 'blas']\n"
        "assert got and all(n == 1 for n in got), got\n"
        "print('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
