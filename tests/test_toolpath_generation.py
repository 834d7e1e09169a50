"""Acceptance tests of toolpath generation (roboisf.toolpath) against hand geometry.

Levels are tool-tip heights (CAM Z-level): lap k has its tip at −kΔz; at each height the ball is
tangent to the nominal surface without entering it (see roboisf.toolpath.generate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.parts import VWACF, Cone, ProfilePart
from roboisf.toolpath import spiral, step_down

R = 5e-3
TOL = 1e-9


def _dense_generatrix(part, n=5000):
    """(M, 2) meridian points sampled along every primitive (flange, wall, bottom)."""
    pts = []
    for p in part.generatrix.primitives:
        r, z, _ = p.at(np.linspace(0.0, p.length, n))
        pts.append(np.column_stack([r, z]))
    return np.concatenate(pts)


def _check_tangent_ball(part, tp):
    """Contact on the surface; ball at C of radius R touches at P and contains no surface point."""
    q = part.closest_point(tp.contact)
    assert np.abs(q.distance).max() <= TOL
    np.testing.assert_allclose(q.point, tp.contact, rtol=0, atol=TOL)
    # C = P + R n, T = C − R ẑ, |n| = 1
    np.testing.assert_allclose(np.linalg.norm(tp.normal, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(tp.center, tp.contact + R * tp.normal, rtol=0, atol=1e-15)
    np.testing.assert_allclose(tp.tip, tp.center - [0, 0, R], rtol=0, atol=1e-15)
    # the exact distance from C to the whole nominal surface is R (tangent, not gouging)
    qc = part.closest_point(tp.center)
    assert np.abs(qc.distance - R).max() <= TOL
    # independent check: no densely sampled surface point strictly inside the ball
    cr = np.hypot(tp.center[:, 0], tp.center[:, 1])
    cz = tp.center[:, 2]
    meridian = np.unique(np.round(np.column_stack([cr, cz]), 12), axis=0)
    if len(meridian) > 400:  # spirals: every point differs; check an even subset + the ends
        pick = np.unique(np.r_[np.linspace(0, len(meridian) - 1, 400).astype(int)])
        meridian = meridian[pick]
    samples = _dense_generatrix(part)
    for chunk in np.array_split(meridian, max(1, len(meridian) // 50)):
        d = np.hypot(
            chunk[:, None, 0] - samples[None, :, 0], chunk[:, None, 1] - samples[None, :, 1]
        )
        assert d.min() >= R - TOL
    # tool side: the centre is never across the axis
    assert cr.min() >= 0.0


@pytest.fixture(scope="module")
def paper_cone():
    return Cone(87e-3, math.radians(71.0), 102.97e-3)


@pytest.fixture(scope="module")
def cone_path(paper_cone):
    return step_down(paper_cone, R, 0.5e-3, spacing=1e-3)


def test_paper_cone_laps_and_levels(cone_path):
    tp = cone_path
    assert tp.n_laps == 206
    levels = np.array([tp.tip[tp.lap == k, 2] for k in range(206)], dtype=object)
    for k, z in enumerate(levels):
        expect = -0.5e-3 * (k + 1) if k < 205 else -102.97e-3
        assert np.abs(z - expect).max() <= TOL, k
    assert tp.meta.get("truncated") is None


def test_paper_cone_tangency(paper_cone, cone_path):
    _check_tangent_ball(paper_cone, cone_path)


def test_paper_cone_offsets_on_the_wall(cone_path):
    """On the 71° wall with R = 5 mm: C is R sin α = 4.73 mm inward of P, T is R(1 − cos α)
    = 3.37 mm below P."""
    tp = cone_path
    a = math.radians(71.0)
    on_wall = np.abs(tp.wall_angle - a) < 1e-9
    assert on_wall.sum() > 0.9 * len(tp)
    rp = np.hypot(tp.contact[on_wall, 0], tp.contact[on_wall, 1])
    rc = np.hypot(tp.center[on_wall, 0], tp.center[on_wall, 1])
    inward = rp - rc
    below = tp.contact[on_wall, 2] - tp.tip[on_wall, 2]
    np.testing.assert_allclose(inward, R * math.sin(a), atol=1e-12)
    np.testing.assert_allclose(below, R * (1 - math.cos(a)), atol=1e-12)
    assert round(inward[0] * 1e3, 2) == 4.73 and round(below[0] * 1e3, 2) == 3.37


def test_paper_cone_rim_and_bottom(paper_cone, cone_path):
    """Tips above −R(1 − cos α) = −3.37 mm roll over the rim edge; the last lap touches the wall
    and the flat bottom at once (its tip is exactly at the part depth)."""
    tp = cone_path
    a = math.radians(71.0)
    rim = tp.tip[:, 2] > -R * (1 - math.cos(a)) + 1e-9
    assert set(np.unique(tp.lap[rim])) == set(range(6))  # tips −0.5 … −3.0 mm
    np.testing.assert_allclose(np.hypot(tp.contact[rim, 0], tp.contact[rim, 1]), 43.5e-3, atol=TOL)
    np.testing.assert_allclose(tp.contact[rim, 2], 0.0, atol=TOL)
    last = tp.lap == 205
    # ball centre exactly R above the bottom plane, and R from the wall
    np.testing.assert_allclose(tp.center[last, 2] - (-102.97e-3), R, atol=TOL)
    np.testing.assert_allclose(tp.wall_angle[last], a, atol=1e-9)


def test_cone_spiral_tangency_and_ramp(paper_cone):
    part = Cone(87e-3, math.radians(71.0), 20e-3)
    tp = spiral(part, R, 0.5e-3, spacing=1e-3)
    _check_tangent_ball(part, tp)
    assert np.all(np.diff(tp.tip[:, 2]) <= 1e-15)  # never goes up
    assert tp.tip[0, 2] == pytest.approx(0.0, abs=TOL)
    assert tp.tip[-1, 2] == pytest.approx(-20e-3, abs=TOL)
    # within a lap the tip descends linearly by one step
    lap3 = tp.tip[tp.lap == 3, 2]
    assert np.allclose(np.diff(lap3), np.diff(lap3)[0], atol=1e-15)
    assert lap3[0] - lap3[-1] == pytest.approx(0.5e-3 * (1 - 1 / lap3.size), abs=1e-12)


def test_vwacf_tangency_and_truncation():
    part = VWACF(arc_radius=40e-3)  # Ø88.15, 40 mm arc, 0° → 90°: bottom Ø8.15 mm < Ø10 ball
    tp = step_down(part, R, 0.5e-3, spacing=2e-3)
    _check_tangent_ball(part, tp)
    assert tp.meta["truncated"] is True
    z_end = tp.meta["reachable_tip_z"]
    assert tp.tip[:, 2].min() == pytest.approx(z_end, abs=TOL)
    # at the deepest height the ball centre is on the axis: a little deeper and it would gouge
    assert np.hypot(*tp.center[tp.lap == tp.n_laps - 1, :2].T).max() < 1e-6
    # hand check of that height: the ball on the axis touches the arc where the arc normal points
    # at the axis: sin β = r0 / (ρ + R); tip = −(ρ + R)(1 − cos β) is then a lower bound on how
    # deep a ball centred on the axis may go (it may not touch the arc elsewhere first)
    beta = math.asin(44.075e-3 / 45e-3)
    assert z_end >= -(45e-3) * (1 - math.cos(beta)) - 1e-9
    # the wall angle grows from ~0 to the steepest contact
    assert tp.wall_angle[0] < math.radians(10) and tp.wall_angle[-1] > math.radians(75)


def test_default_vwacf_is_followed_to_the_bottom_by_a_10mm_ball():
    part = VWACF()  # 39 mm arc: the largest a Ø10 ball can follow to 90°
    tp = step_down(part, R, 0.5e-3, spacing=2e-3)
    _check_tangent_ball(part, tp)
    assert "truncated" not in tp.meta
    assert tp.tip[:, 2].min() == pytest.approx(-part.depth, abs=TOL)


def test_vwacf_fits_with_a_smaller_tool():
    part = VWACF(88.15e-3, 30e-3, math.radians(80.0))
    tp = spiral(part, 2e-3, 1e-3, spacing=3e-3)
    q = part.closest_point(tp.center)
    assert np.abs(q.distance - 2e-3).max() <= TOL
    assert "truncated" not in tp.meta
    assert tp.tip[:, 2].min() == pytest.approx(-part.depth, abs=TOL)


def test_max_wall_step_limits_along_wall_distance():
    part = VWACF()
    tp = step_down(part, R, 0.5e-3, spacing=5e-3, max_wall_step=0.4e-3)
    _check_tangent_ball(part, tp)
    s = np.array([part.closest_point(tp.contact[tp.lap == k][:1]).s[0] for k in range(tp.n_laps)])
    assert np.all(np.diff(s) <= 0.4e-3 + 1e-9)
    plain = step_down(part, R, 0.5e-3, spacing=5e-3)
    assert tp.n_laps > plain.n_laps


def test_profile_with_convex_and_concave_kinks():
    """30° → 60° (convex kink: the ball rolls over it) → 40° (concave kink: touches both)."""
    r = [40e-3, 40e-3 - 10e-3 / math.tan(math.radians(30))]
    z = [0.0, -10e-3]
    r.append(r[-1] - 10e-3 / math.tan(math.radians(60)))
    z.append(-20e-3)
    r.append(r[-1] - 5e-3 / math.tan(math.radians(40)))
    z.append(-25e-3)
    part = ProfilePart(r=tuple(r), z=tuple(z))
    for gen in (step_down, spiral):
        tp = gen(part, R, 0.25e-3, spacing=3e-3)
        _check_tangent_ball(part, tp)


def test_path_length_and_time_consistent_with_feed(cone_path):
    tp = cone_path
    seg = np.linalg.norm(np.diff(tp.tip, axis=0), axis=1)
    np.testing.assert_allclose(tp.path_length, np.concatenate([[0], np.cumsum(seg)]), atol=1e-12)
    np.testing.assert_allclose(tp.time * 750e-3 / 60, tp.path_length, rtol=1e-12, atol=1e-15)
    # a lap of the step-down path is a closed polygon of the ball-centre circle (+ the step)
    k = 100
    idx = np.flatnonzero(tp.lap == k)
    lap_len = tp.path_length[idx[-1]] - tp.path_length[idx[0]]
    rc = np.hypot(*tp.center[idx[0], :2])
    m = idx.size
    polygon = 2 * m * rc * math.sin(math.pi / m) * (m - 1) / m
    assert lap_len == pytest.approx(polygon, rel=1e-9)
    # point spacing ≤ 1 mm at the contact radius
    rp = np.hypot(*tp.contact[idx[0], :2])
    assert 2 * math.pi * rp / m <= 1e-3


def test_bad_generation_inputs():
    from roboisf.errors import InputError

    part = Cone(87e-3, math.radians(71.0), 10e-3)
    with pytest.raises(InputError, match="larger than the part depth"):
        step_down(part, R, 20e-3)
    with pytest.raises(InputError, match="tool_radius"):
        step_down(part, 0.0, 0.5e-3)
    narrow = Cone(4e-3, math.radians(80.0), 5e-3)  # Ø4 opening: a Ø20 ball cannot enter
    with pytest.raises(InputError, match="does not fit"):
        step_down(narrow, 10e-3, 0.5e-3)
