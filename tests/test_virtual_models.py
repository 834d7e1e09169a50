"""Virtual-cell force and springback models against the paper's numbers (Bharti et al. 2024)."""

import math

import numpy as np
import pytest

from roboisf.cell.forces import ForceModel, aerens_axial_force, tip_wrench
from roboisf.errors import InputError
from roboisf.parts import VWACF, Cone
from roboisf.toolpath import step_down
from roboisf.virtual.springback import SpringbackModel


@pytest.fixture(scope="module")
def cone_path():
    return step_down(Cone(), spacing=2e-3)


@pytest.fixture(scope="module")
def vwacf_path():
    return step_down(VWACF(), spacing=2e-3, max_wall_step=0.5e-3)


def test_aerens_formula_by_hand():
    # 0.0716 · 90 · 1.22^1.57 · 10^0.41 · 0.5^0.09 · 71 · cos 71°
    hand = 0.0716 * 90 * 1.22**1.57 * 10**0.41 * 0.5**0.09 * 71 * math.cos(math.radians(71))
    got = aerens_axial_force(90e6, 1.22e-3, 10e-3, 0.5e-3, math.radians(71))
    assert got == pytest.approx(hand, rel=1e-12)
    assert 400 < got < 590  # the paper's force range for this sheet and tool


def test_cone_force_rises_then_saturates(cone_path):
    W = tip_wrench(cone_path, ForceModel(), thickness=1.22e-3, step_down=0.5e-3)
    fz = W[:, 2]
    assert fz[0] < 0.2 * fz.max()
    deep = cone_path.depth > 0.03
    assert np.ptp(fz[deep]) < 1e-3 * fz.max()


def test_wrench_directions_and_moment_arm(cone_path):
    W = tip_wrench(cone_path, ForceModel(), thickness=1.22e-3, step_down=0.5e-3)
    P = cone_path.contact
    r_hat = P[:, :2] / np.linalg.norm(P[:, :2], axis=1, keepdims=True)
    radial = np.einsum("ij,ij->i", W[:, :2], r_hat)
    assert np.all(radial <= 0)  # the sheet pushes the tool towards the axis
    # friction opposes travel: the path is counter-clockwise, so the tangential force is −φ̂
    phi_hat = np.stack([-r_hat[:, 1], r_hat[:, 0]], axis=1)
    assert np.all(np.einsum("ij,ij->i", W[:, :2], phi_hat) <= 0)
    # moment about the tip equals (P − T) × F
    np.testing.assert_allclose(W[:, 3:], np.cross(P - cone_path.tip, W[:, :3]), atol=1e-12)


def test_tool_deflection_scale_matches_paper(cone_path):
    # in-plane force × paper's lateral tool compliance ≈ the paper's 0.136 mm mean
    W = tip_wrench(cone_path, ForceModel(), thickness=1.22e-3, step_down=0.5e-3)
    deep = cone_path.depth > 0.02
    inplane = np.hypot(W[deep, 0], W[deep, 1]).mean()
    assert inplane * 9.34e-7 == pytest.approx(0.136e-3, rel=0.05)


def test_vwacf_force_peaks_near_475_and_drops_at_fracture(vwacf_path):
    fm = ForceModel(mode="variable")
    fz = fm.axial(vwacf_path, 1.22e-3, 0.5e-3)
    frac = fm.fracture_depth(vwacf_path)
    assert 0.028 < frac < 0.036  # paper: springback changes at z = 30–35 mm, near fracture
    assert fz.max() == pytest.approx(475.0, rel=0.01)
    assert fz[vwacf_path.depth > frac + 3e-3].max() < 0.01 * fz.max()


def analysed_rm(path, model, sel):
    v = model.normal(path.depth, path.wall_angle)[:, None] * path.normal
    m = np.abs(v[sel]).mean(axis=0)
    return m, float(np.sqrt((m**2).sum()))


def test_springback_tuned_to_paper_cone(cone_path):
    m, rm = analysed_rm(cone_path, SpringbackModel(), cone_path.depth > 0.02)
    assert rm == pytest.approx(1.132e-3, rel=0.02)
    assert m[0] == pytest.approx(0.72e-3, rel=0.06)


def test_springback_tuned_to_paper_vwacf(vwacf_path):
    frac = ForceModel(mode="variable").fracture_depth(vwacf_path)
    sb = SpringbackModel(amplitude=0.96e-3, fracture_depth=frac)
    sel = (vwacf_path.depth > 0.02) & (vwacf_path.depth <= frac)
    _, rm = analysed_rm(vwacf_path, sb, sel)
    assert rm == pytest.approx(0.53e-3, rel=0.03)


def test_bad_model_parameters():
    with pytest.raises(InputError, match=r"force\.radial_ratio"):
        ForceModel(radial_ratio=-1)
    with pytest.raises(InputError, match=r"springback\.amplitude"):
        SpringbackModel(amplitude=float("nan"))


def test_normal_field_reproduces_a_smooth_field_at_the_toolpath_points(cone_path):
    from roboisf.virtual.formed import NormalField

    part = Cone()
    q = part.closest_point(cone_path.contact)
    truth = 3e-4 + 2e-4 * np.cos(cone_path.angle) + 4e-3 * q.s  # smooth in φ, linear in s
    field = NormalField.from_toolpath(part, cone_path, truth)
    # laps rolling over the rim edge touch it at s = 0, where the field is pinned to 0: skip them
    on_wall = q.s > 1e-9
    q_s, ang, truth = q.s[on_wall], cone_path.angle[on_wall], truth[on_wall]
    got = field(q_s, ang)
    # lap points → 0.5° grid → back: near a lap point the grid interpolates the lap's piecewise-
    # linear curve across its kink, error ≤ Δφ_grid · Δφ_lap · |f''| / 4 with |f''| ≤ 2e-4 m
    r = np.hypot(cone_path.contact[on_wall, 0], cone_path.contact[on_wall, 1])
    dphi_lap = np.max(2e-3 / r) * 1.01  # the path's 2 mm spacing, at the smallest radius
    bound = (2 * np.pi / 720) * dphi_lap * 2e-4 / 4
    np.testing.assert_allclose(got, truth, rtol=0, atol=bound)
    assert np.max(np.abs(got - truth)) > bound / 20  # the bound is not vacuous
    # the rim is pinned at 0, and so is the flange (z = 0) through offset(z, φ)
    assert field(np.array([0.0]), np.array([0.3]))[0] == 0.0
    offset = field.offset(part)
    assert offset(np.array([0.0]), np.array([1.0]))[0] == 0.0
    np.testing.assert_allclose(offset(cone_path.contact[on_wall, 2], ang), got, atol=1e-12)
