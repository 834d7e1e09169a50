"""A simulated robot controller and force sensor, and the part the online loop forms virtually.

:func:`virtual_setup` prepares, for a :class:`~roboisf.virtual.cell.VirtualCell`, what the two
simulated devices need per toolpath point: the robot run's forming wrench (the virtual cell's
force model, :func:`roboisf.virtual.cell.simulate`), the joint angles of the nominal path and
its Jacobian (a commanded correction ``c`` moves the joints by ``J⁻¹ [c; 0]``), the planned
pose (EGM), and what the flange F/T sensor reads there (the wrench in the sensor's frame —
:func:`roboisf.study.sensors.tip_to_sensor`, the study's own code — plus the tool's weight and a
tare offset).

Two ways to run the loop against them:

* :func:`form_online` — in one process, no sockets, deterministic: per toolpath point, the
  sensor's samples go through the RDT codec, the controller's message and the reply through the
  EGM or RSI codec, and the correction the controller decodes is applied at the next point.
  The path is walked at one point per control cycle (1 mm / 4 ms: a fast feed, so the low-pass
  filter's lag is seen over more path than at a real feed).
* :func:`sensor_process` / :func:`controller_process` — separate processes speaking the real
  protocols over localhost UDP (for the CLI's ``--simulate``, the benchmark and the tests),
  sharing only the index of the current toolpath point (the physics: the force depends on where
  the tool is); or both in one process (:func:`devices_process`). The controller keeps its
  cycle on absolute times (:class:`~roboisf.online.rt.Pacer`) and reports its own lateness
  beside the loop's (:func:`missed_causes`).

:func:`evaluate` forms the part with the commanded path (``simulate(cell, commanded=…)``) and
compares its compliance error with the uncorrected part's and with offline pre-deflection.
"""

from __future__ import annotations

import math
import os
import select
import socket
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import tip_compliances
from roboisf.compensate.compliance import DeflectionModel, precompensate
from roboisf.errors import InputError
from roboisf.frames import matrix_to_quat, quat_to_matrix, vertical_tool
from roboisf.online import egm, netft, rsi
from roboisf.online import kernel as kn
from roboisf.online.base import ProtocolError
from roboisf.online.core import Limits, OnlineCompensator, SensorSetup
from roboisf.online.rt import (
    STAMP_SPACE,
    GcQuiet,
    Pacer,
    Realtime,
    apply,
    enable_stamps,
    kernel_stamp,
    set_timer_slack,
)
from roboisf.study.sensors import tip_to_sensor
from roboisf.study.spec import ForceSensorSpec
from roboisf.toolpath import Toolpath
from roboisf.virtual.cell import CellTruth, VirtualCell, build_study, simulate

__all__ = [
    "OnlineForming",
    "VirtualSetup",
    "applied_per_point",
    "controller_process",
    "devices_process",
    "evaluate",
    "form_online",
    "form_study",
    "missed_causes",
    "sensor_process",
    "virtual_setup",
]

F64 = NDArray[np.float64]

#: the simulated sensor's tool below it: mass [kg], CoG in the sensor frame [m], tare [N; N·m]
SIM_TOOL_MASS = 3.0
SIM_TOOL_COG = (0.0, 0.002, 0.09)
SIM_TARE = (4.0, -2.5, 12.0, 0.15, -0.08, 0.02)
#: Hz — the simulated Net F/T's record rate
SENSOR_RATE = 1000.0


@dataclass(frozen=True, eq=False)
class VirtualSetup:
    """Per toolpath point (N points; work frame, SI): what the simulated devices need."""

    vc: VirtualCell
    toolpath: Toolpath
    truth: CellTruth  #: the uncorrected part
    wrench: F64  #: (N, 6) the robot run's tip wrench, work axes [N; N·m]
    q: F64  #: (N, 6) rad, nominal path
    dq_dp: F64  #: (N, 6, 3) rad/m, joint change per tip translation (work axes)
    planned: F64  #: (N, 7) planned tip pose: position m, quaternion (w, x, y, z)
    reading: F64  #: (N, 6) the sensor's noiseless reading [N; N·m]
    sensor: SensorSetup
    noise: float  #: N, the sensor's white noise (moments: × 5 mm)


def virtual_setup(vc: VirtualCell, *, cutoff: float = 20.0) -> VirtualSetup:
    """The simulated cell of ``vc`` (its flange sensor :attr:`VirtualCell.T_tip_sensor`, a
    3 kg tool below it and a tare offset)."""
    truth = simulate(vc)
    tp = truth.toolpath
    cell = vc.cell
    W = truth.wrench_robot
    q = truth.q
    J = cell.robot.jacobian(q, T_base_work=cell.T_base_work)
    dq_dp = np.asarray(np.linalg.solve(J, np.eye(6)[None, :, :3].repeat(len(q), 0)), dtype=float)
    R_wt = vertical_tool(vc.tool_rotation)
    planned = np.empty((len(tp), 7))
    planned[:, :3] = tp.tip
    planned[:, 3:] = matrix_to_quat(R_wt)
    T_tip_sensor = vc.T_tip_sensor
    spec = ForceSensorSpec(vc.name, "flange", T_tip_sensor, "tool")  # type: ignore[arg-type]
    reading = tip_to_sensor(W, spec, tp.tip, R_wt)
    sensor = SensorSetup(
        cell.T_flange_tip @ T_tip_sensor,
        load_on="tool",
        tare=np.array(SIM_TARE),
        tool_mass=SIM_TOOL_MASS,
        tool_cog=np.array(SIM_TOOL_COG),
        cutoff=cutoff,
    )
    # the weight, an external load m g at the CoG, in the sensor's axes at each pose
    T_bt = cell.robot.fk(q)
    R_bs = T_bt[:, :3, :3] @ T_tip_sensor[:3, :3]
    f_g = SIM_TOOL_MASS * np.einsum("nji,j->ni", R_bs, np.array([0.0, 0.0, -9.80665]))
    reading[:, :3] += f_g
    reading[:, 3:] += np.cross(np.array(SIM_TOOL_COG), f_g)
    reading += np.array(SIM_TARE)
    return VirtualSetup(vc, tp, truth, W, q, dq_dp, planned, reading, sensor, float(vc.force.noise))


def _noise(rng: np.random.Generator, sigma: float) -> F64:
    n = rng.normal(scale=sigma, size=6)
    n[3:] *= 5e-3
    return n


@dataclass(frozen=True, eq=False)
class OnlineForming:
    """What the loop did at each toolpath point (N points, work frame, SI).

    applied : (N, 3) m — the correction the controller applied when the tool reached the point:
        the one the loop computed in the cycle before, at ``target`` with ``wrench``
    target : (N, 3) m — the nominal tip of that cycle (NaN at the first point)
    wrench : (N, 6) — the filtered tip wrench that cycle used, work axes [N; N·m]
    status : (N,) int — that cycle's status bits (:mod:`roboisf.online.kernel`)
    steady : (N,) bool — that cycle and the one before it ran with no limit, dead band or
        watchdog acting (status 0)
    """

    applied: F64
    target: F64
    wrench: F64
    status: NDArray[np.int64]
    steady: NDArray[np.bool_]


def form_online(
    setup: VirtualSetup,
    controller: str = "egm",
    *,
    limits: Limits | None = None,
    samples_per_cycle: int = 4,
    cycles_per_point: int = 1,
    seed: int = 0,
) -> OnlineForming:
    """Run the loop in-process over the whole toolpath (codecs included, no sockets).

    The tool moves from one toolpath point to the next in ``cycles_per_point`` control cycles
    (joints, planned pose and the sensor's reading interpolated linearly in between); at the
    toolpath's own feed that is ``spacing / (feed · cycle)`` (≈ 20 for 1 mm at 12.5 mm/s). The
    default, 1, walks the path 20× faster than real: the filter's and the one-cycle delay's lag
    then span 20× more path (a harder test of the lag, an easier one of the run time).
    """
    lim = limits or Limits()
    if cycles_per_point < 1 or samples_per_cycle < 1:
        raise InputError("cycles_per_point and samples_per_cycle must be ≥ 1", field="cycles")
    oc = OnlineCompensator.from_cell(setup.vc.cell, setup.sensor, lim)
    adapter: Any = egm.EgmAdapter() if controller == "egm" else rsi.RsiAdapter(lim.cycle)
    rng = np.random.default_rng(seed)
    n = len(setup.toolpath)
    applied = np.zeros((n, 3))
    target = np.full((n, 3), np.nan)
    wrench = np.zeros((n, 6))
    status = np.zeros(n, dtype=np.int64)
    steady = np.zeros(n, dtype=bool)
    rx = np.zeros(3)
    last_w = np.zeros(6)
    last_p = np.full(3, np.nan)
    last_st = prev_st = kn.STATUS_NO_SAMPLE
    R_bw = setup.vc.cell.T_base_work[:3, :3]
    dt = lim.cycle / samples_per_cycle
    cyc = 0
    for k in range(n):
        k1 = min(k + 1, n - 1)
        applied[k] = rx
        target[k] = last_p
        wrench[k] = last_w
        status[k] = last_st
        steady[k] = last_st == 0 and prev_st == 0
        for j in range(cycles_per_point):
            f = j / cycles_per_point
            q = (1 - f) * setup.q[k] + f * setup.q[k1] + setup.dq_dp[k] @ rx
            planned = (1 - f) * setup.planned[k] + f * setup.planned[k1]
            reading = (1 - f) * setup.reading[k] + f * setup.reading[k1]
            oc.set_joints(q)
            for i in range(samples_per_cycle):
                rec = netft.encode_record(cyc, i, 0, reading + _noise(rng, setup.noise))
                (r,) = netft.decode_records(rec)
                oc.sample((cyc * samples_per_cycle + i) * dt, r.wrench)
            t = (cyc + 1) * lim.cycle - 0.25 * dt
            if controller == "egm":
                msg = egm.encode_robot(cyc, int(t * 1e3), q, planned)
            else:
                msg = rsi.encode_robot(cyc, q)
            state = adapter.decode(msg)
            c = oc.cycle(t, state.q)
            reply = adapter.encode(state, c)
            if controller == "egm":
                rx = egm.decode_sensor(reply)[1][:3] - planned[:3]
            else:
                rx = rsi.decode_reply(reply)[1]
            cyc += 1
            last_p = planned[:3]
            last_w[:3] = R_bw.T @ oc.tip_wrench[:3]
            last_w[3:] = R_bw.T @ oc.tip_wrench[3:]
            prev_st, last_st = last_st, oc.status
    return OnlineForming(applied, target, wrench, status, steady)


@dataclass(frozen=True)
class Evaluation:
    """The virtually formed part (lengths m).

    rms_before, rms_after : RMS of the compliance error along the normal (tool + holder + robot,
        and the applied correction) without and with the loop
    removed : 1 − rms_after / rms_before
    offline_diff : (N,) ‖online applied − offline pre-deflection‖ on the loop's own wrenches
        (the one computed at the cycle's own target; NaN at the first point)
    offline_true_diff : (N,) the same against offline pre-deflection of the point with the
        virtual cell's true wrench there (adds the filter's and the one-cycle delay's lag)
    steady : (N,) bool — :attr:`OnlineForming.steady`
    """

    rms_before: float
    rms_after: float
    removed: float
    offline_diff: F64
    offline_true_diff: F64
    steady: NDArray[np.bool_]
    truth: CellTruth


def evaluate(setup: VirtualSetup, run: OnlineForming) -> Evaluation:
    """Form the part with the loop's commanded path and compare (see :class:`Evaluation`)."""
    vc = setup.vc
    tp = setup.toolpath
    truth = simulate(vc, commanded=tp.with_tip(tp.tip + run.applied))
    n = tp.normal
    before = np.einsum(
        "ij,ij->i", setup.truth.tool_robot + setup.truth.holder_robot + setup.truth.robot, n
    )
    after = np.einsum(
        "ij,ij->i",
        truth.tool_robot + truth.holder_robot + truth.robot + run.applied,
        n,
    )
    rb = float(np.sqrt(np.mean(before**2)))
    ra = float(np.sqrt(np.mean(after**2)))
    _, _, k_t, k_th = tip_compliances(vc.cell)
    model = DeflectionModel(
        vc.cell.robot, vc.cell.T_base_work, k_t + k_th, tool_rotation=vc.tool_rotation
    )
    ok = np.all(np.isfinite(run.target), axis=1)
    off = precompensate(run.target[ok], run.wrench[ok], model, tol=1e-9, max_iter=100)
    diff = np.full(len(tp), np.nan)
    diff[ok] = np.linalg.norm(run.applied[ok] - (off.commanded - off.target), axis=1)
    off_true = precompensate(tp.tip, setup.wrench, model, tol=1e-9, max_iter=100)
    true_diff = np.linalg.norm(run.applied - (off_true.commanded - tp.tip), axis=1)
    steady = run.steady & ok
    return Evaluation(rb, ra, 1.0 - ra / rb, diff, true_diff, steady, truth)


def applied_per_point(setup: VirtualSetup, k: NDArray[np.int64], applied: F64) -> F64:
    """The correction (N, 3) m the controller applied at each toolpath point, from its per-cycle
    report (``k`` (n,) the point of each cycle, ``applied`` (n, 3) m the correction it applied
    there; :func:`controller_process`). Points the controller skipped (``point_step`` > 1) take
    the linear interpolation of the cycles around them; points it never reached (a run stopped
    early) get 0: the robot formed them uncorrected.
    """
    k = np.asarray(k, dtype=np.int64)
    applied = np.asarray(applied, dtype=float)
    n = len(setup.toolpath)
    if k.ndim != 1 or applied.shape != (len(k), 3) or np.any(np.diff(k) < 0):
        raise InputError(
            "expected the controller's report: k (n,) non-decreasing, applied (n, 3)",
            field="applied",
        )
    out = np.zeros((n, 3))
    if len(k) == 0:
        return out
    first = np.concatenate([[True], np.diff(k) > 0])  # a point held at the path's end: its first
    ks, a = k[first], applied[first]
    reached = np.arange(n) <= ks[-1]
    for j in range(3):
        out[reached, j] = np.interp(np.arange(n)[reached], ks, a[:, j])
    return out


def form_study(setup: VirtualSetup, applied: F64, out_dir: Any, *, progress: Any = None) -> Any:
    """The study of the part the loop formed: the virtual cell's study
    (:func:`roboisf.virtual.cell.build_study`) with the robot run commanded along the nominal
    tip plus ``applied`` (N, 3) m, work axes (:attr:`OnlineForming.applied` or
    :func:`applied_per_point`). ``roboisf analyze`` then measures what the loop removed: the
    robot-compliance term of the scan is ``n · (applied + δ)``. Returns the study folder."""
    applied = np.asarray(applied, dtype=float)
    tp = setup.toolpath
    if applied.shape != tp.tip.shape or not np.all(np.isfinite(applied)):
        raise InputError(
            f"expected ({len(tp)}, 3) finite corrections, got shape {applied.shape}",
            field="applied",
        )
    return build_study(
        setup.vc, out_dir, progress=progress, commanded=tp.with_tip(tp.tip + applied)
    )


# ---------------------------------------------------------------------------------- processes
#: the simulated controller sleeps (absolute time) to this long before a send, then busy-waits
#: the rest (s): the kernel's wake-up latency falls in the margin, not into the cycle
SPIN = 3e-4


def _bind(port: int) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", port))
    return s


class _SensorSim:
    """The simulated Net F/T: its socket (non-blocking) and its stream's state. Records are due
    at absolute times ``start + n / rate`` from the start request (a stall is caught up, as the
    sensor's own clock keeps running); after ``silent_after`` s it falls silent for good (a
    sensor that dies: start requests are then ignored too)."""

    def __init__(
        self,
        port: int,
        reading: F64,
        index: Any,
        *,
        rate: float,
        noise: float,
        seed: int,
        silent_after: float,
    ) -> None:
        self.sock = _bind(port)
        self.sock.setblocking(False)
        self.reading = reading
        self.index = index
        self.period = 1.0 / rate
        self.noise = noise
        self.rng = np.random.default_rng(seed)
        self.silent_after = silent_after
        self.peer: Any = None
        self.left = 0
        self.seq = 0
        self.n = 0  # records since the start request
        self.t_start = 0.0
        self.dead = False

    def next_time(self) -> float:
        """When the next record is due (perf_counter s; inf: not streaming)."""
        if self.peer is None or self.dead:
            return math.inf
        return self.t_start + self.n * self.period

    def requests(self, now: float) -> None:
        """Handle the start / stop requests queued in the socket."""
        while True:
            try:
                data, addr = self.sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue
            try:
                cmd, count = netft.decode_request(data)
            except ProtocolError:
                continue
            if self.dead:
                continue
            if cmd in (netft.CMD_START_REALTIME, netft.CMD_START_BUFFERED) and self.peer is None:
                self.peer, self.left, self.t_start, self.n = addr, count, now, 0
            elif cmd == netft.CMD_STOP:
                self.peer = None

    def send_due(self, now: float) -> None:
        """Send every record due by ``now``."""
        while self.peer is not None and not self.dead and self.next_time() <= now:
            if self.n * self.period > self.silent_after:
                self.dead = True
                return
            k = min(int(self.index.value), len(self.reading) - 1)
            w = self.reading[k] + _noise(self.rng, self.noise)
            try:
                self.sock.sendto(netft.encode_record(self.seq, self.seq, 0, w), self.peer)
            except OSError:
                pass  # the loop's port closed (ICMP): it asks again if it comes back
            self.seq += 1
            self.n += 1
            if self.left:
                self.left -= 1
                if self.left == 0:
                    self.peer = None


class _ControllerSim:
    """The simulated controller (see :func:`controller_process`): cycle ``c``'s message is due
    at ``t0 + c·cycle``; at that time the previous cycle is settled first (replies in the
    socket read, judged by their kernel arrival stamps), then the message is sent.

    After its ``n_cycles`` (``path_done``: the report is due) it goes on streaming, holding the
    path's last point and applying the replies, as a real controller streams while its program
    waits at the end of the motion: the loop's stop then ramps the correction to zero through
    these messages. The hold ends (``done``) when no reply came for ``hold_quiet`` s (the loop
    has ended) or after ``hold_max`` s; :func:`devices_process` also ends it on ``stop``. Its
    cycles are not part of the report (neither counted nor timed)."""

    def __init__(
        self,
        loop_port: int,
        protocol: str,
        setup_arrays: tuple[F64, F64, F64],
        index: Any,
        *,
        cycle: float,
        n_cycles: int,
        point_step: int,
        relative: bool = False,
        hold_quiet: float = 1.0,
        hold_max: float = 10.0,
    ) -> None:
        self.q_nom, self.dq_dp, self.planned = setup_arrays
        self.relative = relative and protocol == "rsi"
        self.ipoc_step = max(1, round(cycle * 1e3))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.stamped = enable_stamps(self.sock)
        self.dest = ("127.0.0.1", loop_port)
        self.protocol = protocol
        self.index = index
        self.cycle = cycle
        self.n = n_cycles
        self.point_step = point_step
        self.rx = np.zeros(3)
        self.rtt = np.full(n_cycles, np.nan)
        self.applied = np.zeros((n_cycles, 3))
        self.ks = np.zeros(n_cycles, dtype=np.int64)
        self.missed = 0
        self.ran = 0  # cycles settled
        self.send_late = np.full(n_cycles, np.nan)
        self.wake_late = np.full(n_cycles, np.nan)
        self.read_late = np.full(n_cycles, np.nan)
        self.rtt_late = np.full(n_cycles, np.nan)
        self.sent = np.full(n_cycles, np.nan)
        self.sent_ns = np.zeros(n_cycles, dtype=np.int64)
        self.c = 0  # the next cycle to send
        self.t0 = math.inf
        self.awaiting = False  # the last message sent has no in-time reply yet
        self.path_done = False  # the n cycles run and settled: the report is due
        self.done = False  # the hold after the path ended too: nothing more to send
        self.hold_quiet = hold_quiet
        self.hold_max = hold_max
        self.hold_start = math.inf  # when the hold began (perf_counter s)
        self.hold_reply = math.inf  # when the hold's last reply was read
        self.k_last = 0  # the point of the last path message

    def next_time(self) -> float:
        """When the next event (settle the last cycle, send the next) is due (inf: done)."""
        return math.inf if self.done else self.t0 + self.c * self.cycle

    def drain(self) -> None:
        """Read every reply queued in the socket."""
        while True:
            try:
                data, anc, _, _ = self.sock.recvmsg(65536, STAMP_SPACE)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue
            self._reply(data, kernel_stamp(anc), time.perf_counter())

    def _reply(self, data: bytes, arrival_ns: int | None, read_at: float) -> None:
        try:
            if self.protocol == "egm":
                rseq, pose = egm.decode_sensor(data)
            else:
                rseq, corr = rsi.decode_reply(data)
        except ProtocolError:
            return
        if self.protocol == "rsi":  # IPOC: the cycle's time stamp in ms
            if rseq % self.ipoc_step:
                return
            rseq //= self.ipoc_step
        if self.path_done:  # the hold: the reply to its latest message, else nothing
            if rseq != self.c or not self.awaiting:
                return
            j, k = -1, self.k_last  # its point: the path's last
        elif not 1 <= rseq <= self.c:
            return
        else:
            j = rseq - 1
            k = int(self.ks[j])
        if self.protocol == "egm":
            pl = self.planned[k]
            if np.isnan(pose[3]):  # path correction: in the TCP frame of the planned pose
                corr = quat_to_matrix(pl[3:]) @ pose[:3]
            else:  # position guidance: the pose sent, less the program's path
                corr = pose[:3] - pl[:3]
        if self.path_done:  # taken (settled when the next is due), neither counted nor timed
            self.rx = self.rx + corr if self.relative else corr
            self.awaiting = False
            self.hold_reply = read_at
            return
        # the arrival on this process's perf_counter clock: kernel stamp, else the read
        if arrival_ns is not None:
            arrived = float(self.sent[j] + (arrival_ns - self.sent_ns[j]) * 1e-9)
        else:
            arrived = read_at
        deadline = self.t0 + (j + 1) * self.cycle
        if j == self.c - 1 and self.awaiting and arrived < deadline:
            self.rtt[j] = arrived - self.sent[j]
            self.read_late[j] = read_at - arrived
            # RSI_ON(#RELATIVE) adds each reply taken to the sum; #ABSOLUTE replaces it
            self.rx = self.rx + corr if self.relative else corr
            self.awaiting = False
        elif np.isnan(self.rtt[j]) and np.isnan(self.rtt_late[j]):
            self.rtt_late[j] = arrived - self.sent[j]  # after its next cycle was due: dropped

    def step(self, wake_late: float) -> None:
        """The event due now: settle the cycle before, then send the next (after the path:
        the hold's next, or finish)."""
        c = self.c
        if self.path_done:
            self._hold_step()
            return
        if c > 0:
            self.drain()
            if self.awaiting:
                self.missed += 1
                self.awaiting = False
            self.ran = c
        if c >= self.n:
            self.path_done = True
            self.hold_start = self.hold_reply = time.perf_counter()
            self._hold_step()
            return
        k = min(c * self.point_step, len(self.q_nom) - 1)
        self.index.value = k
        self.ks[c] = k
        self.k_last = k
        self.applied[c] = self.rx
        msg = self._message(c, k)
        self.wake_late[c] = wake_late
        self.sent[c] = time.perf_counter()  # the round trip from before the send (an upper
        self.sent_ns[c] = time.time_ns()  # bound) …
        self._send(msg)
        # … the lateness from after it: a stall inside the send is this process's own
        self.send_late[c] = time.perf_counter() - (self.t0 + c * self.cycle)
        self.awaiting = True
        self.c = c + 1

    def _hold_step(self) -> None:
        """After the path: settle the hold's last message, then send the next one at the
        path's last point — until the loop no longer answers or ``hold_max``."""
        self.drain()
        self.awaiting = False  # a reply that did not come: not counted (the report is out)
        now = time.perf_counter()
        if now - self.hold_reply > self.hold_quiet or now - self.hold_start > self.hold_max:
            self.done = True
            return
        self._send(self._message(self.c, self.k_last))
        self.awaiting = True
        self.c += 1

    def _message(self, c: int, k: int) -> bytes:
        """Cycle ``c``'s message: the joints of point ``k`` moved by the correction taken."""
        q = self.q_nom[k] + self.dq_dp[k] @ self.rx
        seq = c + 1
        if self.protocol == "egm":
            return egm.encode_robot(seq, int((c * self.cycle) * 1e3), q, self.planned[k])
        # Delay: the replies that missed their cycle so far (DEF_Delay)
        return rsi.encode_robot(seq * self.ipoc_step, q, delay=self.missed)

    def _send(self, msg: bytes) -> None:
        try:
            self.sock.sendto(msg, self.dest)  # (on loopback, in the loop's socket on return)
        except OSError:
            pass  # nothing listens (ICMP): the cycle is missed

    def report(self, warnings: list[str], processes: int, spin: float) -> dict[str, Any]:
        return {
            "rtt": self.rtt,
            "missed": self.missed,
            "applied": self.applied,
            "k": self.ks,
            "ran": self.ran,
            "send_late": self.send_late,
            "wake_late": self.wake_late,
            "read_late": self.read_late,
            "rtt_late": self.rtt_late,
            "sent": self.sent,
            "stamped": self.stamped,
            "warnings": warnings,
            "processes": processes,
            "spin": spin,
        }


def devices_process(
    sensor: dict[str, Any] | None,
    controller: dict[str, Any] | None,
    index: Any,
    stop: Any,
    result: Any,
    ready: Any,
    *,
    start_delay: float = 0.3,
    realtime: Realtime | None = None,
    spin: float = SPIN,
    processes: int = 1,
) -> None:
    """The simulated sensor and/or controller in one thread of one process (``sensor`` and
    ``controller``: the keyword arguments of the devices, None for one not simulated here).

    One schedule of absolute times: the controller's cycles (``t0 + c·cycle``, ``t0`` =
    ``start_delay`` s after ``ready`` is set; met with :class:`~roboisf.online.rt.Pacer`:
    ``clock_nanosleep(TIMER_ABSTIME)`` to ``spin`` s before, then a busy-wait) and the sensor's
    records (``start + n / rate``, an absolute sleep, no busy-wait: the loop times samples by
    their arrival). While a reply or a start request is awaited the thread sleeps in
    ``select`` on those sockets, up to the same margin before the next event, and reads what
    comes at once (the reply's own arrival is the kernel's stamp either way). When both
    devices are due at once the controller goes first. One process instead of two is one
    fewer runnable process beside the loop (:class:`Simulation` ``processes=1``).

    The controller's report goes on ``result`` (:func:`controller_process`) when it has run its
    cycles or ``stop`` is set; it then streams on holding the path's last point until ``stop``
    or the loop falls silent (so the loop's stop can ramp the correction to zero:
    :class:`_ControllerSim`); the sensor streams on until ``stop``.

    The devices also end when the process that started them has (``os.getppid`` changes: it
    was killed — SIGKILL, or a SIGTERM that ran no cleanup — and this one was handed to init):
    they never outlive it, and the controller then sends no report (its queue's pipe, full and
    unread, would hold the process at exit). Before, a simulated sensor streamed on for good
    (one was found half an hour later, from a killed test run).
    """
    parent = os.getppid()
    warnings = apply(realtime, "the simulated devices").warnings if realtime is not None else []
    set_timer_slack(1000)  # 1 µs instead of 50: the absolute sleeps end when asked
    sen = _SensorSim(index=index, **sensor) if sensor is not None else None
    ctl = _ControllerSim(index=index, **controller) if controller is not None else None
    gcq = GcQuiet().__enter__()
    clock = time.perf_counter
    pacer = Pacer(clock() + start_delay, ctl.cycle if ctl is not None else 1.0, spin=spin)
    if ctl is not None:
        ctl.t0 = pacer.t0
    ready.set()
    reported = ctl is None
    try:
        while not stop.is_set() and (sen is not None or (ctl is not None and not ctl.done)):
            if os.getppid() != parent:  # orphaned (~0.1 µs a call: once a cycle is nothing)
                reported = True  # nobody reads it: a report in a full pipe would hold the exit
                break
            now = clock()
            if sen is not None:
                sen.requests(now)
            t_c = ctl.next_time() if ctl is not None else math.inf
            t_s = sen.next_time() if sen is not None else math.inf
            t = min(t_c, t_s, now + 0.05)
            margin = spin if t == t_c else 0.0
            watch: list[socket.socket] = []
            if sen is not None and sen.peer is None and not sen.dead:
                watch.append(sen.sock)  # a start request
            if ctl is not None and ctl.awaiting:
                watch.append(ctl.sock)  # the reply
            if watch:
                timeout = t - margin - clock()
                if timeout > 0:
                    ready_socks, _, _ = select.select(watch, [], [], timeout)
                    if ready_socks:
                        if ctl is not None and ctl.sock in ready_socks:
                            ctl.drain()
                        continue
            late = pacer.wait(t, margin)
            if ctl is not None and t == t_c:
                ctl.step(late)
                if ctl.path_done and not reported:
                    result.put(ctl.report(warnings, processes, spin))
                    reported = True
                gcq.slack()
            if sen is not None:
                sen.send_due(clock())
    finally:
        gcq.__exit__()
        if ctl is not None and not reported:
            result.put(ctl.report(warnings, processes, spin))
        for dev in (sen, ctl):
            if dev is not None:
                dev.sock.close()


def sensor_process(
    port: int,
    reading: F64,
    index: Any,
    stop: Any,
    ready: Any,
    *,
    rate: float = SENSOR_RATE,
    noise: float = 2.0,
    seed: int = 1,
    silent_after: float = math.inf,
    realtime: Realtime | None = None,
) -> None:
    """A Net F/T speaking RDT on 127.0.0.1:``port``, alone in its process: on a start request,
    streams a record of ``reading[index.value]`` (+ white noise) every ``1/rate`` s to the
    requester until a stop request, the sample count, ``stop`` is set, or ``silent_after`` s (a
    sensor that dies). ``realtime``: this process's scheduler, CPU and memory lock
    (:mod:`roboisf.online.rt`). :func:`devices_process` runs it beside the controller."""
    kw = {
        "port": port,
        "reading": reading,
        "rate": rate,
        "noise": noise,
        "seed": seed,
        "silent_after": silent_after,
    }
    devices_process(kw, None, index, stop, None, ready, realtime=realtime, processes=2)


def controller_process(
    loop_port: int,
    protocol: str,
    setup_arrays: tuple[F64, F64, F64],
    index: Any,
    stop: Any,
    result: Any,
    *,
    cycle: float = 0.004,
    n_cycles: int = 1000,
    start_delay: float = 0.3,
    point_step: int = 1,
    realtime: Realtime | None = None,
    ready: Any = None,
    spin: float = SPIN,
) -> None:
    """A robot controller speaking EGM or RSI to the loop at 127.0.0.1:``loop_port``, alone in
    its process (:func:`devices_process` runs it beside the sensor).

    Every ``cycle`` s, at the absolute time ``t0 + c·cycle`` (:class:`~roboisf.online.rt.Pacer`:
    no drift, a late cycle does not shift the next), it sends its state (joints of toolpath
    point ``k·point_step`` moved by the last correction it received; ``index`` tells the sensor
    the point) and waits for the reply. After its ``n_cycles`` it reports and goes on
    streaming, holding the last point and applying the replies, until ``stop`` or the loop falls
    silent for 1 s (at most 10 s): the loop's stop ramps the correction to zero through these
    messages, as through a real controller's while its program waits at the end of the
    motion. **Missed cycle**, as EGM and RSI define it: the reply
    carrying the cycle's sequence number (EGM ``seqno``, RSI ``IPOC``) has not arrived when the
    next cycle's message is due, ``t0 + (c + 1)·cycle``. Arrival is the kernel's receive stamp
    (``SO_TIMESTAMPNS``), not the moment this process got round to reading it: a reply that
    arrived in time counts even when the scheduler woke this process late (as a real-time
    controller would have read it).

    Puts on ``result`` a dict: ``rtt (n,) s`` (send → kernel arrival, NaN when missed),
    ``missed``, ``applied (n, 3) m``, ``k (n,)``, ``ran`` (the cycles it ran and settled, a
    prefix of the n), and what separates its own scheduling from the loop's latency
    (:func:`missed_causes`): ``send_late (n,) s`` — how late, after the cycle's start, its send
    returned (its own jitter); ``wake_late (n,) s`` — of that, how late it woke for the cycle;
    ``read_late (n,) s`` — how long an in-time reply waited in the socket before this process
    read it (its own wake-up delay); ``rtt_late (n,) s`` — for a missed cycle, when its reply
    came after all (NaN: never); ``stamped`` (kernel stamps in use); ``warnings`` (the
    real-time settings refused, :func:`roboisf.online.rt.apply`); ``sent (n,)`` — when each
    message was sent (``time.perf_counter``, CLOCK_MONOTONIC: comparable with the loop's);
    ``processes`` (1: beside the sensor, 2: alone) and ``spin`` (s).
    """
    kw = {
        "loop_port": loop_port,
        "protocol": protocol,
        "setup_arrays": setup_arrays,
        "cycle": cycle,
        "n_cycles": n_cycles,
        "point_step": point_step,
    }
    if ready is None:
        ready = _NoEvent()
    devices_process(
        None,
        kw,
        index,
        stop,
        result,
        ready,
        start_delay=start_delay,
        realtime=realtime,
        spin=spin,
        processes=2,
    )


class _NoEvent:
    def set(self) -> None:
        pass


def _stamping(s: socket.socket) -> bool:
    return enable_stamps(s)


def _recv_stamped(s: socket.socket, timeout: float) -> tuple[bytes, int | None, float] | None:
    """One datagram within ``timeout`` s (0: only one already queued): ``(data, arrival
    (CLOCK_REALTIME ns, the kernel's stamp; None without one), read (perf_counter s))``, or
    None."""
    s.settimeout(timeout if timeout > 0 else 0.0)
    try:
        data, anc, _, _ = s.recvmsg(65536, STAMP_SPACE)
    except (TimeoutError, BlockingIOError):
        return None
    return data, kernel_stamp(anc), time.perf_counter()


def missed_causes(
    result: dict[str, Any], *, cycle: float = 0.004, budget: float = 2e-3
) -> dict[str, int]:
    """Split the simulated controller's missed cycles by cause (its report, ``Simulation.result``).

    A missed cycle (:func:`controller_process`: no reply by the time the next cycle's message is
    due) is the **controller's own** when it sent its message so late that less than ``budget``
    s (the round-trip target) was left of the cycle: no loop meeting the target could have
    answered in time. The others are the **loop's**: the controller left it at least ``budget``
    and the reply came later (``late``, timed in ``rtt_late``) or never (``lost``).
    Returns ``dict(missed, controller, loop_late, loop_lost)`` (the last three sum to missed).
    """
    ran = int(result["ran"])
    rtt = np.asarray(result["rtt"])[:ran]
    late = np.asarray(result["send_late"])[:ran]
    rtt_late = np.asarray(result["rtt_late"])[:ran]
    miss = np.isnan(rtt)
    own = miss & (cycle - late < budget)
    loop = miss & ~own
    return {
        "missed": int(miss.sum()),
        "controller": int(own.sum()),
        "loop_late": int((loop & np.isfinite(rtt_late)).sum()),
        "loop_lost": int((loop & np.isnan(rtt_late)).sum()),
    }


class Simulation:
    """The simulated sensor and controller (``spawn``ed daemons): each in its own process
    (``processes=2``, the default) or both in one process and thread (``processes=1``,
    :func:`devices_process`). One process is one fewer runnable process beside the loop, but
    its one thread wakes five times a cycle (four records, one message): on the contended
    2-core machine the controller then woke for its cycle p50 1.6–2.1 ms late against
    0.0–0.07 ms alone (docs/online.md), so two stay the default.

    ``with Simulation(setup, "egm", loop_port, n_cycles=…) as sim:`` starts the sensor on
    127.0.0.1:``sim.sensor_port`` and, ``start_delay`` s after the devices are set up, the
    controller towards the loop (with ``realtime``'s scheduler, CPU and memory lock, when
    given — for the simulators, not the loop: on a machine without a spare core, give the loop
    the real-time priority and the simulators the other CPUs, :func:`roboisf.online.rt.other_cpus`);
    :meth:`result` waits for the controller's report (``rtt``, ``missed``, ``applied``, ``k``,
    :func:`controller_process`). Leaving the block stops them.
    """

    def __init__(
        self,
        setup: VirtualSetup,
        protocol: str,
        loop_port: int,
        *,
        n_cycles: int = 1000,
        cycle: float = 0.004,
        sensor_rate: float = SENSOR_RATE,
        point_step: int = 1,
        sensor_silent_after: float = math.inf,
        start_delay: float = 0.3,
        realtime: Realtime | None = None,
        processes: int = 2,
        spin: float = SPIN,
        relative: bool = False,
    ) -> None:
        import multiprocessing as mp

        if protocol not in ("egm", "rsi"):
            raise InputError(f"must be 'egm' or 'rsi', got {protocol!r}", field="controller")
        if processes not in (1, 2):
            raise InputError(f"must be 1 or 2, got {processes!r}", field="processes")
        ctx = mp.get_context("spawn")
        self._ctx = ctx
        self.index = ctx.Value("l", 0)
        self.stop = ctx.Event()
        self._queue: Any = ctx.Queue()
        probe = _bind(0)
        self.sensor_port = int(probe.getsockname()[1])
        probe.close()
        self._ready = [ctx.Event() for _ in range(processes)]
        sensor: dict[str, Any] = {
            "port": self.sensor_port,
            "reading": setup.reading,
            "rate": sensor_rate,
            "noise": setup.noise,
            "seed": 1,
            "silent_after": sensor_silent_after,
        }
        controller: dict[str, Any] = {
            "loop_port": loop_port,
            "protocol": protocol,
            "setup_arrays": (setup.q, setup.dq_dp, setup.planned),
            "cycle": cycle,
            "n_cycles": n_cycles,
            "point_step": point_step,
            "relative": relative,
        }
        common: dict[str, Any] = {"realtime": realtime, "spin": spin, "processes": processes}
        idx, stop, q = self.index, self.stop, self._queue
        jobs: list[tuple[Any, Any, Any, dict[str, Any]]]
        if processes == 1:
            jobs = [(sensor, controller, q, {"start_delay": start_delay, **common})]
        else:  # the sensor first: it is streaming when the controller starts
            jobs = [
                (sensor, None, None, common),
                (None, controller, q, {"start_delay": start_delay, **common}),
            ]
        self._procs = [
            ctx.Process(
                target=devices_process, args=(sen, ctl, idx, stop, res, ev), kwargs=kw, daemon=True
            )
            for (sen, ctl, res, kw), ev in zip(jobs, self._ready, strict=True)
        ]
        self._result: dict[str, Any] | None = None

    def __enter__(self) -> Simulation:
        import signal

        # the devices never see Ctrl-C (a signal mask survives fork and exec): a Ctrl-C while
        # they start would break the unpickling of their arguments (a child's traceback); this
        # process stops them (``stop``, then SIGTERM) whatever ends it. Nor a closed terminal's
        # SIGHUP: a real controller is not on the operator's terminal, and the loop's ramp to
        # zero on a hang-up needs the simulated one answering (parent gone: devices_process)
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGHUP})
        try:
            for p in self._procs:
                p.start()
        except BaseException:
            self.close()
            raise
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)  # a Ctrl-C held meanwhile: now
        try:
            for ev in self._ready:
                if not ev.wait(60):  # imported and set up (seconds on a busy machine)
                    raise InputError(
                        "the simulated devices did not start within 60 s (a heavily loaded "
                        "machine?)",
                        field="--simulate",
                    )
        except BaseException:
            self.close()
            raise
        return self

    def result(self, timeout: float | None = None) -> dict[str, Any]:
        """The controller's report (waits for it)."""
        if self._result is None:
            self._result = self._queue.get(timeout=timeout)
        return self._result

    def close(self) -> None:
        self.stop.set()
        for p in reversed(self._procs):
            if p.pid is not None:
                p.join(5)
                if p.is_alive():
                    p.terminate()
                    p.join(5)

    def __exit__(self, *exc: object) -> None:
        self.close()
