"""Link compliance of the virtual robot against beam theory's known answers."""

from dataclasses import replace

import numpy as np
import pytest

from roboisf.virtual.links import (
    IRB7600_LINKS,
    BeamSection,
    LinkBeam,
    beam_chain_deflection,
    link_deflection,
)

E1, E2 = 169e9, 200e9
S1 = BeamSection.hollow_box(0.30, 0.20, 0.015, E1, 65e9)
S2 = BeamSection.tube(0.24, 0.014, E2, 77e9)


def _straight(L1: float, L2: float, e: float, F: np.ndarray, sections):
    starts = np.array([[[0, 0, 0], [L1, 0, 0]]], dtype=float)
    ends = np.array([[[L1, 0, 0], [L1 + L2, 0, 0]]], dtype=float)
    axes = np.array([[[0, 1, 0], [0, 1, 0]]], dtype=float)
    tip = np.array([[L1 + L2 + e, 0, 0]])
    return beam_chain_deflection(starts, ends, axes, sections, tip, F[None, :])[0]


def test_stepped_cantilever_matches_the_unit_load_integral():
    # Euler–Bernoulli (no shear) stepped cantilever, tip load F beyond a rigid extension e:
    # δ = F/3 [(L³ − (L − L1)³)/EI1 + ((L − L1)³ − e³)/EI2], θ = −F/2 [...]², L = L1 + L2 + e
    eb = [replace(S1, shear_factor=1e12), replace(S2, shear_factor=1e12)]
    L1, L2, e, F = 1.075, 1.069, 0.3, 500.0
    L = L1 + L2 + e
    EI1, EI2 = E1 * S1.I_bend, E2 * S2.I_bend
    d = _straight(L1, L2, e, np.array([0, 0, F, 0, 0, 0.0]), eb)
    dz = F / 3 * ((L**3 - (L - L1) ** 3) / EI1 + ((L - L1) ** 3 - e**3) / EI2)
    th = -F / 2 * ((L**2 - (L - L1) ** 2) / EI1 + ((L - L1) ** 2 - e**2) / EI2)
    assert d[2] == pytest.approx(dz, rel=1e-9)
    assert d[4] == pytest.approx(th, rel=1e-9)
    np.testing.assert_allclose(d[[0, 1, 3, 5]], 0.0, atol=1e-15)
    # out of the plane: the other second moment
    d_out = _straight(L1, L2, e, np.array([0, F, 0, 0, 0, 0.0]), eb)
    dy = (
        F
        / 3
        * ((L**3 - (L - L1) ** 3) / (E1 * S1.I_out) + ((L - L1) ** 3 - e**3) / (E2 * S2.I_out))
    )
    assert d_out[1] == pytest.approx(dy, rel=1e-9)


def test_timoshenko_shear_and_axial_terms():
    L1, L2, F = 1.0, 0.8, 400.0
    d_t = _straight(L1, L2, 0.0, np.array([0, 0, F, 0, 0, 0.0]), [S1, S2])
    eb = [replace(S1, shear_factor=1e12), replace(S2, shear_factor=1e12)]
    d_e = _straight(L1, L2, 0.0, np.array([0, 0, F, 0, 0, 0.0]), eb)
    shear = F * (L1 / (0.5 * S1.G * S1.area) + L2 / (0.5 * S2.G * S2.area))
    assert d_t[2] - d_e[2] == pytest.approx(shear, rel=1e-9)
    d_ax = _straight(L1, L2, 0.0, np.array([F, 0, 0, 0, 0, 0.0]), [S1, S2])
    assert d_ax[0] == pytest.approx(F * (L1 / (E1 * S1.area) + L2 / (E2 * S2.area)), rel=1e-12)


def test_robot_links_linear_in_the_wrench_and_inverse_in_E():
    from roboisf.virtual.cell import paper_cone_cell

    cell = paper_cone_cell()
    model, T = cell.cell.robot, cell.cell.T_base_work
    q = np.radians([[2.0, 30.0, 10.0, 0.0, 45.0, 0.0], [-5.0, 40.0, 0.0, 10.0, 50.0, 30.0]])
    W = np.array([[30.0, -120.0, 480.0, 1.0, -2.0, 0.5]] * 2)
    d = link_deflection(model, q, W, T)
    np.testing.assert_allclose(link_deflection(model, q, 2 * W, T), 2 * d, rtol=1e-12)
    stiff = tuple(
        LinkBeam(
            lk.name,
            lk.start,
            lk.end,
            replace(lk.section, E=2 * lk.section.E, G=2 * lk.section.G),
        )
        for lk in IRB7600_LINKS
    )
    np.testing.assert_allclose(link_deflection(model, q, W, T, stiff), d / 2, rtol=1e-12)
    # links add a fraction of the joints' deflection, not a multiple (heavy cast arms)
    joints = model.deflection(q, W, T_base_work=T)
    ratio = np.linalg.norm(d[:, :3], axis=1) / np.linalg.norm(joints[:, :3], axis=1)
    assert np.all((0.02 < ratio) & (ratio < 0.5))


def test_ball_centre_is_the_reference_a_rigid_ball_rotation_moves_no_contact_normally():
    from roboisf.cell import at_ball_centre

    rng = np.random.default_rng(4)
    R = 5e-3
    d = rng.normal(size=(50, 6)) * np.array([1e-4, 1e-4, 1e-4, 1e-3, 1e-3, 1e-3])
    c = at_ball_centre(d, R)
    # the centre moves δ_tip + θ × (0, 0, R) (rigid ball)
    np.testing.assert_allclose(c, d[:, :3] + np.cross(d[:, 3:], [0, 0, R]), rtol=1e-14)
    # any contact point P = C − R n on the ball: its normal motion n · (δ_C + θ × (P − C)) is
    # n · δ_C exactly, whatever the rotation; the tip's n · δ_tip is not
    n = rng.normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    moved = c + np.cross(d[:, 3:], -R * n)
    np.testing.assert_allclose(
        np.einsum("ij,ij->i", moved, n), np.einsum("ij,ij->i", c, n), atol=1e-18
    )
    assert np.max(np.abs(np.einsum("ij,ij->i", d[:, :3] - c, n))) > 1e-7
