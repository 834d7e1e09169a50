"""The simulated Net F/T and robot controller as processes: what a ``spawn``ed child runs.

:class:`roboisf.online.sim.Simulation` starts :func:`devices_process` (or
:func:`sensor_process` and :func:`controller_process`) in fresh interpreters. A spawned child
imports the module of its target before the devices can start, and the parent waits for them
(their ``ready`` events): this module imports only what the devices use — numpy, the protocol
codecs (:mod:`~roboisf.online.egm`, :mod:`~roboisf.online.rsi`, :mod:`~roboisf.online.netft`)
and :mod:`roboisf.online.rt` — not the virtual cell, the compensation or pandas that
:mod:`roboisf.online.sim` needs to prepare them (0.6 s of imports a child, twice per
simulation: docs/speed.md). Everything a device needs comes in its arguments (arrays, ports).
"""

from __future__ import annotations

import math
import os
import select
import socket
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.frames.rotations import quat_to_matrix
from roboisf.online import egm, netft, rsi
from roboisf.online.base import ProtocolError
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

__all__ = ["SENSOR_RATE", "SPIN", "controller_process", "devices_process", "sensor_process"]

F64 = NDArray[np.float64]

#: Hz — the simulated Net F/T's record rate
SENSOR_RATE = 1000.0


def _noise(rng: np.random.Generator, sigma: float) -> F64:
    n = rng.normal(scale=sigma, size=6)
    n[3:] *= 5e-3
    return n


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
