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
def test_tip_positions_equal_fk(name: str) -> None:
    """Every preset, with a tool and a work placement: ≤ 1e-12 m from fk()[:, :3, 3] (the
    compiled sincos is ≤ 1 ulp from numpy's); the numpy backend is fk's own numbers."""
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
