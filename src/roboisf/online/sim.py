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
  the tool is); or both in one process (:func:`devices_process`). They live in
  :mod:`roboisf.online.devices` (re-exported here), a module a spawned child imports cheaply.
  The controller keeps its cycle on absolute times (:class:`~roboisf.online.rt.Pacer`) and
  reports its own lateness beside the loop's (:func:`missed_causes`).

:func:`evaluate` forms the part with the commanded path (``simulate(cell, commanded=…)``) and
compares its compliance error with the uncorrected part's and with offline pre-deflection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.cell import tip_compliances
from roboisf.compensate.compliance import DeflectionModel, precompensate
from roboisf.errors import InputError
from roboisf.frames import matrix_to_quat, vertical_tool
from roboisf.online import egm, netft, rsi
from roboisf.online import kernel as kn
from roboisf.online.core import Limits, OnlineCompensator, SensorSetup
from roboisf.online.devices import (  # the devices' processes: a module a spawned child imports
    SENSOR_RATE,
    SPIN,
    _bind,
    _noise,
    controller_process,
    devices_process,
    sensor_process,
)
from roboisf.online.rt import Realtime
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
