"""The simulated cell on the pyramid (``online --simulate --virtual pyramid``): the force the
simulated sensor streams along the toolpath has no unloaded stretch after forming began, so
the loop's plausibility check never holds on it — while a force that truly drops still holds.

The walk is the simulated controller's: cycle ``c`` at toolpath point ``min(c·step, N − 1)``,
``step = ceil(N / cycles)`` (roboisf.cli.online's ``_run_simulated``), four sensor samples a
cycle; run through the core with the CLI's plausibility bounds (the expected peak force)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roboisf.online import Limits, OnlineCompensator, Plausibility
from roboisf.online import kernel as kn
from roboisf.online.replay import expected_peak_force
from roboisf.online.sim import virtual_setup


@pytest.fixture(scope="module")
def pyramid():
    from roboisf.virtual.builtin import make_builtin_cell

    return virtual_setup(make_builtin_cell("pyramid", field="--virtual", scan_points=1000))


def _walk(setup, seconds, *, reading=None, seed=0):
    """The simulated controller's walk for a run of ``seconds`` (4 ms cycles) through the core:
    (points k, status, correction (n, 3) m) per cycle."""
    lim = Limits()
    oc = OnlineCompensator.from_cell(
        setup.vc.cell,
        setup.sensor,
        lim,
        Plausibility.from_expected(expected_peak_force(setup.wrench)),
    )
    reading = setup.reading if reading is None else reading
    n_pts = len(setup.q)
    n = int(seconds / lim.cycle)
    step = max(1, math.ceil(n_pts / n))
    rng = np.random.default_rng(seed)
    ks = np.minimum(np.arange(n) * step, n_pts - 1)
    status = np.zeros(n, dtype=np.int64)
    corr = np.zeros((n, 3))
    for c, k in enumerate(ks):
        t = c * lim.cycle
        for i in range(4):
            noise = rng.normal(scale=setup.noise, size=6) * np.r_[1, 1, 1, 5e-3, 5e-3, 5e-3]
            oc.sample(t + (i + 0.5) * 1e-3, reading[k] + noise)
        corr[c] = oc.cycle(t + lim.cycle, setup.q[k])
        status[c] = oc.status
    return ks, status, corr


@pytest.mark.parametrize("seconds", [10.0, 100.0])  # point step 10, and every point
def test_the_simulated_pyramid_is_never_held_once_forming_began(pyramid, seconds):
    """A 10 s `online --simulate --virtual pyramid` held the correction mid-run (38 cycles,
    49 implausible samples; this walk: 36 cycles at step 10, 103 in 7 episodes at every
    point, all on the last lap): its force fell from 662 N to 0 and back six times between
    neighbouring points (48 unloaded points in the first stretch). Not the walk — the simulated
    controller walks the laps in order, going down, the unloaded depth-0 laps only before
    forming begins — but the toolpath: at the full depth the ball touches the flat bottom and
    the wall at once, and the contact fell on the bottom (wall angle 0, no forming force).
    The wall is the contact (roboisf.toolpath.slice); the last lap is loaded like the one
    above it."""
    tp = pyramid.toolpath
    F = np.linalg.norm(pyramid.wrench[:, :3], axis=1)
    ks, status, _ = _walk(pyramid, seconds)
    assert np.all(np.diff(ks) >= 0) and np.all(np.diff(tp.lap[ks]) >= 0)  # laps in order
    loaded = np.flatnonzero(F[ks] > 1.0)
    first = int(loaded[0])
    assert np.all(tp.depth[ks[first:]] > 0)  # no depth-0 point after forming began
    assert np.all(F[ks[first:]] > 0.05 * F.max())  # nor any unloaded one
    held = (status[first:] & (kn.STATUS_HOLD | kn.STATUS_IMPLAUSIBLE)) != 0
    assert not held.any(), np.flatnonzero(held)[:10] + first
    last = tp.lap == tp.n_laps - 1
    assert np.degrees(tp.wall_angle[last]).min() > 59.0  # the wall, not the bottom


def test_a_force_that_truly_drops_is_still_held(pyramid):
    """The same walk with the tool suddenly unloaded mid-run (the sensor reads the tool at
    rest from one cycle to the next, for 200 ms): the plausibility check holds the correction
    and the watchdog then ramps it at its rate — the safety behaviour, unchanged."""
    lim = Limits()
    k_drop = len(pyramid.q) // 2
    span = slice(k_drop, k_drop + 500)  # 50 cycles at step 10
    reading = pyramid.reading.copy()
    # the tool at rest at those points: the reading less the forming wrench in sensor axes
    from roboisf.online.sim import SIM_TARE, SIM_TOOL_COG, SIM_TOOL_MASS

    cell = pyramid.vc.cell
    R_bs = cell.robot.fk(pyramid.q[span])[:, :3, :3] @ pyramid.vc.T_tip_sensor[:3, :3]
    f = SIM_TOOL_MASS * np.einsum("nji,j->ni", R_bs, np.array([0.0, 0.0, -9.80665]))
    reading[span, :3] = f + np.array(SIM_TARE[:3])
    reading[span, 3:] = np.cross(np.array(SIM_TOOL_COG), f) + np.array(SIM_TARE[3:])
    ks, status, corr = _walk(pyramid, 10.0, reading=reading)
    during = (ks >= span.start) & (ks < span.stop)
    assert during.sum() >= 40
    held = (status & (kn.STATUS_HOLD | kn.STATUS_IMPLAUSIBLE)) != 0
    assert held[during].any() and (status[during] & kn.STATUS_IMPLAUSIBLE).any()
    outside = np.flatnonzero(held & ~during)
    assert outside.size == 0 or ks[outside].min() >= span.start  # held for the drop only
    steps = np.linalg.norm(np.diff(corr, axis=0), axis=1)
    assert steps.max() <= lim.max_rate * lim.cycle * (1 + 1e-9)  # never faster than the rate
