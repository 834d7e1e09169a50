"""VJM: frames, serial assembly with a tool, complementary stiffness, statistics, contributions."""

from __future__ import annotations

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
    from roboisf.robot import vjm_batch

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


def test_docs_example_runs(capsys):
    """The first python example of docs/robot.md runs as written."""
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "robot.md").read_text(encoding="utf-8")
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(code, "docs/robot.md", "exec"), {})
    assert "k_11" in capsys.readouterr().out
