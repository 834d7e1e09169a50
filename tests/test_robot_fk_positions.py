"""Compiled tool-tip positions (the position alignment's FK) equal RobotModel.fk (issue #16)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from roboisf.errors import InputError
from roboisf.frames.se3 import make_transform
from roboisf.robot import vjm_kernel
from roboisf.robot.presets import list_robots, load_robot

pytestmark = pytest.mark.skipif(not vjm_kernel.HAVE_NUMBA, reason="numba not installed")


def _q(model: object, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = model.q_min, model.q_max  # type: ignore[attr-defined]
    return rng.uniform(np.maximum(lo, -3.0), np.minimum(hi, 3.0), size=(n, 6))


@pytest.mark.parametrize("name", list_robots())
def test_tip_positions_equal_fk(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every preset, with a tool and a work placement: ≤ 1e-12 m from fk()[:, :3, 3] (the
    compiled sincos is ≤ 1 ulp from numpy's); the numpy backend is fk's own numbers, also
    when it runs in blocks (here of 3 000 rows, the last one short)."""
    import roboisf.robot.model as model_module

    monkeypatch.setattr(model_module, "_FK_BLOCK", 3_000)
    tool = make_transform(np.eye(3), [0.01, -0.02, 0.3])
    model = replace(load_robot(name), T_flange_tip=tool)
    q = _q(model, 20_000, 5)  # several parallel blocks
    c, s = np.cos(0.4), np.sin(0.4)
    T_bw = make_transform(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), [2.2, -0.5, 0.2])
    for T in (None, T_bw):
        ref = model.fk(q, check_limits=False, T_base_work=T)[:, :3, 3]
        got = model.tip_positions(q, check_limits=False, T_base_work=T)
        assert got.shape == (len(q), 3)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
        num = model.tip_positions(q, check_limits=False, T_base_work=T, backend="numpy")
        np.testing.assert_array_equal(num, ref)


def test_tip_positions_fanuc_coupling_and_checks() -> None:
    """The J2/J3 coupling of a FANUC chain is applied, and bad angles are refused as by fk."""
    fanuc = [n for n in list_robots() if load_robot(n).chain.couple23 != 0.0]
    assert fanuc  # the presets include FANUC robots
    m = load_robot(fanuc[0])
    q = _q(m, 1000, 2)
    np.testing.assert_allclose(
        m.tip_positions(q, check_limits=False), m.fk(q, check_limits=False)[:, :3, 3],
        rtol=0, atol=1e-12,
    )  # fmt: skip
    m = load_robot(list_robots()[0])
    q = _q(m, 10, 1)
    q[3, 2] = np.nan
    with pytest.raises(InputError, match="NaN"):
        m.tip_positions(q)


@pytest.mark.parametrize("name", ["irb6700-200-2.60", "r2000ic-210f"])
def test_compiled_kernels_are_the_plain_python_walk_bit_for_bit(name: str, monkeypatch) -> None:
    """tip_positions (fk_numba), the batch VJM kernel (δ and J) and the online kernel all run
    vjm_chain.chain_walk: each equals that walk run as plain Python (sincos too), bit for bit,
    on an ABB and a FANUC (J2/J3 coupling) preset."""
    from roboisf.online import kernel as kn
    from roboisf.robot import vjm_chain

    tool = make_transform(np.eye(3), [0.01, -0.02, 0.3])
    m = replace(load_robot(name), T_flange_tip=tool).with_stiffness(np.linspace(4e6, 4e5, 6))
    q = _q(m, 300, 7)  # several poses per parallel block of the VJM kernel (BLOCK poses)
    rng = np.random.default_rng(8)
    W = np.column_stack([rng.normal(0, 400, (len(q), 3)), rng.normal(0, 30, (len(q), 3))])
    F = m.chain.F.copy()
    F[6] = F[6] @ m.T_flange_tip
    sign = np.ascontiguousarray(m.chain.sign, dtype=float)
    offset = np.ascontiguousarray(m.chain.offset, dtype=float)
    c23, kinv = float(m.chain.couple23), 1.0 / m.joint_stiffness
    assert (c23 != 0.0) == name.startswith("r2000")
    # compiled first (a kernel compiled after the patch below would see a Python sincos)
    p = m.tip_positions(q, check_limits=False, backend="numba")
    r = m.vjm(q, W, want_jacobian=True, backend="numba")
    d_on = np.zeros((len(q), 6))
    for n in range(len(q)):
        kn.fk_deflection(F, sign, offset, c23, kinv, q[n], W[n], d_on[n], np.zeros((3, 3)),
                         np.zeros((20, 6)))  # fmt: skip
    monkeypatch.setattr(vjm_chain, "sincos", vjm_chain.sincos.py_func)
    walk, jac = vjm_chain.chain_walk.py_func, vjm_chain.tip_jacobian.py_func
    oz, Jl = np.empty((6, 6)), np.empty((6, 6))
    p_py, d_py, J_py = np.empty((len(q), 3)), np.empty((len(q), 6)), np.empty((len(q), 6, 6))
    for n in range(len(q)):
        p_py[n] = walk(F, sign, offset, c23, q[n], None)[9:]
        px, py, pz = walk(F, sign, offset, c23, q[n], oz)[9:]
        assert (px, py, pz) == tuple(p_py[n])  # recording the joint axes changes nothing
        jac(sign, c23, oz, px, py, pz, Jl)
        J_py[n] = Jl
        a = [sum((Jl[i, j] * W[n, i] for i in range(6)), 0.0) * kinv[j] for j in range(6)]
        d_py[n] = [sum((Jl[i, j] * a[j] for j in range(6)), 0.0) for i in range(6)]
    np.testing.assert_array_equal(p, p_py)
    np.testing.assert_array_equal(r.J, J_py)
    np.testing.assert_array_equal(r.d, d_py)
    np.testing.assert_array_equal(d_on, d_py)
