"""The loop against the virtual cell: the part it forms, offline agreement, UDP end to end,
malformed and late packets, a sensor that stops, and a study's logs replayed."""

from __future__ import annotations

import math
import socket
import threading
import time

import numpy as np
import pandas as pd
import pytest

from roboisf.online import Limits, OnlineCompensator, egm, netft, rsi
from roboisf.online import kernel as kn
from roboisf.online.loop import RULES_OFF, CycleLog, Loop
from roboisf.online.replay import load_replay, replay_study
from roboisf.online.sim import (
    Simulation,
    evaluate,
    form_online,
    missed_causes,
    virtual_setup,
)
from roboisf.virtual.cell import build_study

#: loops at their real cycle: this module waits on the clock more than it computes (the
#: collection puts it beside a CPU-bound module, tests/conftest.py)
pytestmark = pytest.mark.realtime


@pytest.fixture(scope="module")
def setup(online_cone):
    return virtual_setup(online_cone(20e-3, scan_points=20_000))


@pytest.mark.parametrize("controller", ["egm", "rsi"])
def test_first_part_loses_most_of_its_compliance_error(setup, controller):
    lim = Limits()
    run = form_online(setup, controller, limits=lim)
    ev = evaluate(setup, run)
    assert ev.rms_before > 100e-6  # a real compliance error to remove (~0.3 mm)
    assert ev.removed >= 0.80, ev.removed
    # offline pre-deflection on the wrenches the loop used: the same model, so where no limit
    # acted it is the same answer; the dead band may leave up to its width
    assert np.nanmax(ev.offline_diff[ev.steady]) < 0.1e-6
    not_limited = np.isfinite(ev.offline_diff) & ((run.status & kn.STATUS_LIMITED) == 0)
    assert not_limited.mean() > 0.9
    assert np.nanmax(ev.offline_diff[not_limited]) <= lim.deadband + 1e-9
    # never beyond the limits
    norms = np.linalg.norm(run.applied, axis=1)
    assert norms.max() <= lim.max_correction


def _serve(loop: Loop, **kw):
    out = {}
    th = threading.Thread(target=lambda: out.setdefault("c", loop.run(**kw)))
    th.start()
    return th, out


def test_udp_end_to_end_with_the_simulated_processes(setup, tmp_path):
    lim = Limits(max_correction=0.3e-3, max_rate=10e-3)
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, lim)
    loop = Loop(oc, egm.EgmAdapter(), ("127.0.0.1", 0), ("127.0.0.1", 9), **RULES_OFF)
    step = max(1, len(setup.q) // 400)  # 400 cycles over the whole path
    with Simulation(setup, "egm", loop.listen[1], n_cycles=400, point_step=step) as sim:
        assert loop.ft is not None
        loop.ft.connect(("127.0.0.1", sim.sensor_port))
        th, _ = _serve(loop, duration=60)
        res = sim.result(timeout=60)
        loop.stop()
        th.join()
    c = loop.counters
    assert c.cycles > 100 and c.samples > 100  # timing on a loaded machine is not asserted
    mc = missed_causes(res)
    assert mc["missed"] == res["missed"] == mc["controller"] + mc["loop_late"] + mc["loop_lost"]
    assert np.all(res["send_late"][: res["ran"]] >= 0)
    assert c.bad_controller == c.bad_sensor == 0
    got = np.isfinite(res["rtt"])
    assert np.linalg.norm(res["applied"][got], axis=1).max() <= lim.max_correction + 1e-9
    assert np.linalg.norm(res["applied"][got], axis=1).max() > 0.1e-3  # it did correct
    loop.log.write(tmp_path / "log.parquet", {"controller": "egm"})
    df = pd.read_parquet(tmp_path / "log.parquet")
    assert len(df) == c.cycles
    corr = df[["corr_x_mm", "corr_y_mm", "corr_z_mm"]].to_numpy() * 1e-3
    assert np.linalg.norm(corr, axis=1).max() <= lim.max_correction * (1 + 1e-12)  # mm → m
    # the rate limit in the messages' own time (their kernel arrival: the log's t_s); a gap
    # of more than two cycles counts as two
    steps = np.linalg.norm(np.diff(corr, axis=0), axis=1)
    dt = np.minimum(np.diff(df["t_s"].to_numpy()), 2 * lim.cycle)
    assert np.all(steps <= lim.max_rate * dt * (1 + 1e-9) + 1e-12)
    # the run ended with the ramp to zero the controller's last messages carried, or said why
    assert c.stop_reason


@pytest.mark.parametrize(("controller", "end"), [("egm", "stop"), ("rsi", "cycles")])
def test_the_end_of_the_simulated_run_ramps_the_correction_to_zero(setup, controller, end):
    """The simulated controller's path ending (what ends ``online --simulate --duration``:
    ``sim.result()`` then ``loop.stop()``) or the loop's own cycle count (``--cycles``, the same
    count as the controller's path): the controller still answers after its path, holding its
    last point, so the stop ramps the correction to zero and the log ends at zero. Before, it
    fell silent after its last path cycle and every such stop said "NOT ramped"."""
    n = 100
    lim = Limits(ramp_rate=5e-3)
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, lim)
    adapter = egm.EgmAdapter() if controller == "egm" else rsi.RsiAdapter()
    loop = Loop(oc, adapter, ("127.0.0.1", 0), ("127.0.0.1", 9), **RULES_OFF)
    step = max(1, len(setup.q) // n)
    with Simulation(  # one process: half the start-up of two (the test's time)
        setup, controller, loop.listen[1], n_cycles=n, point_step=step, processes=1
    ) as sim:
        assert loop.ft is not None
        loop.ft.connect(("127.0.0.1", sim.sensor_port))
        if end == "stop":
            th, _ = _serve(loop, duration=60)
            res = sim.result(timeout=60)
            loop.stop()
        else:
            th, _ = _serve(loop, duration=60, cycles=n)
            res = sim.result(timeout=60)
        th.join(30)
        assert not th.is_alive()
    c = loop.counters
    assert res["ran"] == n
    assert c.stop_reason == ("stop requested" if end == "stop" else f"{n} cycles run")
    d = loop.log.data[: loop.log.n]
    corr = np.linalg.norm(d[:, 17:20], axis=1) * 1e-3  # mm → m
    assert corr.max() > 0.05e-3, corr.max()  # there was a correction to ramp out
    assert c.ramped, (c.stop_reason, c.left_mm)
    assert c.left_mm == 0.0 and corr[-1] == 0.0
    assert int(d[-1, 20]) & kn.STATUS_STOP  # the log ends in the stop's ramp


def _recv(s: socket.socket, timeout: float = 2.0) -> bytes | None:
    s.settimeout(timeout)
    try:
        return s.recv(65536)
    except TimeoutError:
        return None


def test_malformed_and_late_packets_are_dropped_never_answered(setup):
    lim = Limits(max_correction=0.1e-3, deadband=0.0, watchdog=2.0)  # a slow machine: no hold
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, lim)
    ft = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ft.bind(("127.0.0.1", 0))
    loop = Loop(oc, rsi.RsiAdapter(), ("127.0.0.1", 0), ft.getsockname())
    assert loop.ft is not None
    robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    robot.bind(("127.0.0.1", 0))
    th, _ = _serve(loop, duration=20)
    try:
        assert netft.decode_request(ft.recv(64)) == (netft.CMD_START_REALTIME, 0)
        for bad in (b"", b"<Rob/>", b"\xff" * 40, b'<Rob Type="KUKA"><IPOC>1</IPOC></Rob>'):
            robot.sendto(bad, loop.listen)
            assert _recv(robot, 0.3) is None
        dest = loop.ft.getsockname()
        big = setup.reading[len(setup.reading) // 2] * 5  # far beyond the size limit
        for seq in (10, 11, 12):
            ft.sendto(netft.encode_record(seq, seq, 0, big), dest)
        ft.sendto(netft.encode_record(5, 5, 0, np.zeros(6)), dest)  # late: older than 12
        ft.sendto(b"\0" * 35, dest)  # malformed
        ft.sendto(netft.encode_record(13, 13, 1, np.zeros(6)), dest)  # sensor status bit set
        time.sleep(0.02)  # the records arrive before the robot's message
        q = setup.q[len(setup.q) // 2]
        robot.sendto(rsi.encode_robot(4242, q), loop.listen)
        reply = _recv(robot)
        assert reply is not None
        ipoc, k = rsi.decode_reply(reply)
        assert ipoc == 4242
        assert 0 < np.linalg.norm(k) <= lim.max_correction + 1e-9  # limited, never beyond
    finally:
        loop.stop()
        th.join()
        robot.close()
        ft.close()
    c = loop.counters
    assert c.bad_controller == 4
    assert c.bad_sensor == 1
    assert c.late_sensor == 1
    assert c.sensor_status == 1
    assert c.samples == 3


def test_a_sensor_that_stops_trips_the_watchdog(setup):
    lim = Limits(watchdog=0.05, ramp_rate=5e-3)
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, lim)
    loop = Loop(oc, egm.EgmAdapter(), ("127.0.0.1", 0), ("127.0.0.1", 9), **RULES_OFF)
    mid = len(setup.q) // 2
    with Simulation(
        setup, "egm", loop.listen[1], n_cycles=700, point_step=0, sensor_silent_after=0.8
    ) as sim:
        sim.index.value = mid
        assert loop.ft is not None
        loop.ft.connect(("127.0.0.1", sim.sensor_port))
        th, _ = _serve(loop, duration=60)
        sim.result(timeout=60)
        loop.stop()
        th.join()
    d = loop.log.data[: loop.log.n]
    status = d[:, 20].astype(int)
    corr = np.linalg.norm(d[:, 17:20], axis=1) * 1e-3
    assert np.any(status & kn.STATUS_HOLD) and np.any(status & kn.STATUS_RAMP)
    # the ramp after the sensor stopped: the log's last stretch of ramping cycles (on a busy
    # machine the watchdog may also trip earlier — before the first sample, or on a sample late
    # by more than 50 ms — and the correction come back with the next sample: correct, and not
    # the ramp this test is about)
    ramping = (status & kn.STATUS_RAMP) != 0
    calm = np.flatnonzero(~ramping)
    final = int(calm[-1]) + 1 if calm.size else 0
    assert 0 < final < len(corr), "the log must end in the watchdog's ramp"
    assert corr[:final].max() > 0.1e-3, corr[:final].max()
    assert corr[-1] == 0.0  # ramped out
    ramp = np.diff(corr[final - 1 :])
    assert ramp.max() <= 1e-15 and ramp.min() >= -lim.ramp_rate * lim.cycle * (1 + 1e-9)


def test_replay_of_a_study_follows_its_truth(setup, tmp_path):
    build_study(setup.vc, tmp_path / "study")
    rep = load_replay(tmp_path / "study")
    oc, out = replay_study(rep, Limits(max_correction=5e-3, max_rate=1.0))
    truth = setup.truth
    tp = truth.toolpath
    d_true = truth.tool_robot + truth.holder_robot + truth.robot
    # the correction at each joint-log time against −δ of the truth at that time
    ref = np.column_stack([np.interp(out[:, 0], tp.time, -d_true[:, j]) for j in range(3)])
    err = np.linalg.norm(out[:, 1:4] - ref, axis=1)
    busy = np.linalg.norm(ref, axis=1) > 50e-6
    assert busy.mean() > 0.5
    assert np.median(err[busy]) < 10e-6, np.median(err[busy])
    assert math.isfinite(oc.correction.sum())


def test_cycle_log_grows_and_keeps_units():
    log = CycleLog(capacity=2)
    assert [n for n, _ in log.COLUMNS][:2] == ["t_s", "seq"]
    assert len(log.COLUMNS) == log.data.shape[1]


def _at_rest(setup, q):
    """What the simulated flange sensor reads at joints ``q`` with no forming load: the tool's
    weight (3 kg at its CoG, sensor axes) and the tare (as :func:`virtual_setup` adds them)."""
    from roboisf.online.sim import SIM_TARE, SIM_TOOL_COG, SIM_TOOL_MASS

    R_bs = setup.vc.cell.robot.fk(q[None])[0][:3, :3] @ setup.vc.T_tip_sensor[:3, :3]
    f = SIM_TOOL_MASS * R_bs.T @ np.array([0.0, 0.0, -9.80665])
    return np.concatenate([f, np.cross(SIM_TOOL_COG, f)]) + np.array(SIM_TARE)


def test_the_tool_at_rest_gets_no_correction_before_or_after_the_first_message(setup):
    """The sensor streams from the loop's start; the controller's first message comes later.
    The records read meanwhile had the tool's weight removed at joints 0 — the robot's zero
    pose — and the first replies corrected for a force the tool never felt (0.076 mm in the
    first cycle of a simulated pyramid run, in the air). Now they wait for the joint angles:
    at rest every reply is zero and the filtered force is the tool's nothing."""
    q = setup.q[len(setup.q) // 3]
    rest = _at_rest(setup, q)
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, Limits(watchdog=2.0))
    # the negative control: the weight removed at the zero pose leaves tens of newtons
    oc.set_joints(np.zeros(6))
    oc.sample(0.0, rest)
    assert np.linalg.norm(oc.filtered[:3]) > 10.0
    oc.reset()
    ft = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ft.bind(("127.0.0.1", 0))
    loop = Loop(oc, egm.EgmAdapter(), ("127.0.0.1", 0), ft.getsockname(), **RULES_OFF)
    assert loop.ft is not None
    robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    robot.bind(("127.0.0.1", 0))
    th, _ = _serve(loop, duration=30)
    seq = 0
    replies = []
    try:
        assert netft.decode_request(ft.recv(64))[0] == netft.CMD_START_REALTIME
        dest = loop.ft.getsockname()
        planned = setup.planned[len(setup.q) // 3]
        for burst in range(6):  # 0.15 s before the first message (idle drains), then cycles
            for _ in range(150 if burst == 0 else 4):
                ft.sendto(netft.encode_record(seq, seq, 0, rest), dest)
                seq += 1
                time.sleep(1e-3 if burst == 0 else 0.0)
            robot.sendto(egm.encode_robot(burst + 1, 0, q, planned), loop.listen)
            reply = _recv(robot)
            assert reply is not None
            replies.append(egm.decode_sensor(reply)[1][:3] - planned[:3])
    finally:
        loop.stop()
        th.join()
        robot.close()
        ft.close()
    assert np.abs(np.asarray(replies)).max() < 1e-9, replies  # m (the wire's rounding)
    d = loop.log.data[: loop.log.n]
    assert np.abs(d[:6, 8:11]).max() < 1.0  # N: the tip wrench of the first cycles
    assert loop.counters.samples >= 4 * 5


def test_an_unreachable_sensor_does_not_stop_the_loop(setup):
    """Nothing listens on the sensor's port: the loop keeps answering, with zero correction."""
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, Limits())
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    dead = probe.getsockname()
    probe.close()
    loop = Loop(oc, egm.EgmAdapter(), ("127.0.0.1", 0), dead)
    robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    robot.bind(("127.0.0.1", 0))
    th, _ = _serve(loop, duration=20)
    try:
        time.sleep(0.2)
        for seq in (1, 2, 3):
            robot.sendto(egm.encode_robot(seq, 0, setup.q[0], setup.planned[0]), loop.listen)
            reply = _recv(robot)
            assert reply is not None
            rseq, pose = egm.decode_sensor(reply)
            assert rseq == seq
            np.testing.assert_allclose(pose[:3], setup.planned[0, :3])  # no correction
    finally:
        loop.stop()
        th.join()
        robot.close()
    assert loop.counters.cycles == 3
    assert loop.counters.sensor_unreachable >= 1
    assert loop.oc.status & kn.STATUS_NO_SAMPLE


def test_replay_sensor_releases_each_sample_once_on_the_clock():
    from roboisf.online.replay import ReplaySensor

    t = np.arange(10) * 1e-3 + 5.0
    W = np.arange(60, dtype=float).reshape(10, 6)
    rs = ReplaySensor(t, W, speed=2.0)
    tt, ww = rs.samples_until(100.0)  # starts the clock at the first sample
    assert len(tt) == 1 and tt[0] == 100.0
    tt, ww = rs.samples_until(100.00275)  # 2.75 ms of loop time = 5.5 ms of log at speed 2
    np.testing.assert_array_equal(ww, W[1:6])
    np.testing.assert_allclose(tt, 100.0 + (t[1:6] - t[0]) / 2)
    assert len(rs.samples_until(100.00275)[0]) == 0  # nothing twice
    assert len(rs.samples_until(101.0)[0]) == 4


@pytest.mark.slow
def test_at_the_real_feed_the_loop_follows_the_true_forces(online_cone):
    """At the toolpath's own feed (40 cycles of 4 ms per 2 mm point at 12.5 mm/s) the lag of the
    filter and of the one-cycle delay spans little path: the correction is within a few µm of
    offline pre-deflection on the virtual cell's *true* wrench (the fast test above walks one
    point per cycle, 20–40× faster, where that lag reaches tens of µm)."""
    s = virtual_setup(online_cone(6e-3))
    cpp = round(2e-3 / (s.toolpath.feed * 4e-3))
    assert cpp == 40
    ev = evaluate(s, form_online(s, "rsi", cycles_per_point=cpp))
    assert ev.removed >= 0.95
    assert np.median(ev.offline_true_diff) < 2e-6
    assert np.percentile(ev.offline_true_diff, 99) < 10e-6


def test_missed_cycles_are_split_into_the_controllers_and_the_loops():
    nan = np.nan
    res = {
        "ran": 5,
        "missed": 3,
        # cycle 0 on time; 1 missed though sent on time, reply later; 2 sent 3 ms late (1 ms
        # left: the controller's own); 3 missed, never answered; 4 on time; 5 never ran
        "rtt": np.array([0.4e-3, nan, nan, nan, 0.5e-3, nan]),
        "send_late": np.array([0.1e-3, 0.2e-3, 3e-3, 0.1e-3, 0.1e-3, nan]),
        "rtt_late": np.array([nan, 5e-3, nan, nan, nan, nan]),
    }
    assert missed_causes(res, cycle=4e-3, budget=2e-3) == {
        "missed": 3,
        "controller": 1,
        "loop_late": 1,
        "loop_lost": 1,
    }


def test_a_status_display_that_fails_stops_neither_the_loop_nor_its_ramp(setup):
    """The status callback writes to a terminal or a pipe; once that is gone (a closed pipe:
    ``roboisf online -v | tee`` whose reader ended, a hung-up terminal) every write raises
    OSError. It used to end the loop from inside its reply path, the ramp to zero included:
    the display is now dropped and the run goes on to its stop and its ramp."""
    n = 100
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, Limits(ramp_rate=5e-3))
    loop = Loop(oc, egm.EgmAdapter(), ("127.0.0.1", 0), ("127.0.0.1", 9), **RULES_OFF)
    calls = [0]

    def status(lp: Loop) -> None:
        calls[0] += 1
        if calls[0] > 3:
            raise BrokenPipeError(32, "Broken pipe")

    step = max(1, len(setup.q) // n)
    with Simulation(setup, "egm", loop.listen[1], n_cycles=n, point_step=step, processes=1) as sim:
        assert loop.ft is not None
        loop.ft.connect(("127.0.0.1", sim.sensor_port))
        th, out = _serve(loop, duration=60, status=status, status_every=0.0)
        sim.result(timeout=60)
        loop.stop()
        th.join(30)
        assert not th.is_alive()
    c = out["c"]
    assert calls[0] == 4  # dropped at its first failure
    assert c.status_lost.startswith("BrokenPipeError")
    assert c.stop_reason == "stop requested"
    d = loop.log.data[: loop.log.n]
    assert np.linalg.norm(d[:, 17:20], axis=1).max() > 0.05  # mm: a correction to ramp out
    assert c.ramped and c.left_mm == 0.0
