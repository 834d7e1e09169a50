"""The online loop: a force stream and a robot controller over UDP, the core in between.

One thread, woken only by the controller:

* the **controller** socket — the robot's messages (EGM or RSI), read by one blocking
  ``recvmsg`` (a 50 ms ``SO_RCVTIMEO`` lets it check its clock when no robot talks): each
  message is answered at once with the correction of :meth:`OnlineCompensator.cycle` to the
  address it came from;
* the **sensor** socket — Net F/T RDT records (:mod:`roboisf.online.netft`) from the sensor the
  loop started streaming — is drained (non-blocking) when a controller message has arrived,
  before the cycle is computed: every record that came since the last cycle goes through the
  filter, each at its own arrival time (the kernel's receive stamp, ``SO_TIMESTAMPNS``), so the
  filter is the same as if each had been read when it arrived. The loop does not wake for each
  of the 1,000 (up to 7,000) records a second — one wake-up per cycle instead of five or more,
  and never busy with a sample when the controller's message comes. With a
  :class:`~roboisf.online.replay.ReplaySensor` the samples are fed by the clock.

A malformed packet is dropped and counted (the loop never answers it); the sensor's
``rdt_sequence`` is followed by :class:`~roboisf.online.netft.SequenceTracker` (lost,
out-of-order and duplicate records counted, a restarted stream followed at once); a record with a
non-zero status word is not used (its bits counted); a sensor that stops trips the core's
watchdog. The cycle's time is the kernel's arrival stamp of the controller's message, so the
core's rate limits act per unit of the messages' own time.

**Every stop ramps the correction to zero first** (:meth:`Loop.run`): the end of ``duration``
or ``cycles``, :meth:`Loop.stop`, Ctrl-C / SIGTERM (``KeyboardInterrupt`` or
:class:`roboisf.io.outdir.Interrupted`), an error inside the loop, a controller silent for
``controller_timeout`` s, a Net F/T silent for ``sensor_timeout`` s (after the watchdog's
ramp), or too many late replies (``late_limit`` in ``late_window`` s: the host cannot keep the
cycle). The loop then answers the controller's messages with the correction
ramping at ``ramp_rate`` until it is zero, and :attr:`Counters.stop_reason` /
:attr:`Counters.ramped` say why it stopped and whether the ramp finished (it cannot when the
controller is silent: nothing to send it to).

Every cycle is logged (time, sequence, joints, tip wrench, correction, status,
compute time, and the latency from the kernel's arrival of the message to the reply sent) in
preallocated chunks and written to Parquet (atomically) at the end: nothing is written, printed
or collected between a message's arrival and its reply.
"""

from __future__ import annotations

import gc
import math
import signal
import socket
import struct
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.io.outdir import SIGNAL_OUTCOMES, Interrupted
from roboisf.online import netft
from roboisf.online.base import ProtocolError, RobotState
from roboisf.online.core import OnlineCompensator
from roboisf.online.rt import STAMP_SPACE, GcQuiet, Realtime, apply, enable_stamps, kernel_stamp

__all__ = ["IDLE", "RULES_OFF", "SENSOR_TIMEOUT", "Counters", "CycleLog", "Loop", "parse_address"]

F64 = NDArray[np.float64]

#: s — how long the loop waits for a controller message before it looks at its clock (stop,
#: duration, status, a silent sensor) and drains the sensor socket
IDLE = 0.05


#: s — a Net F/T that streamed and then sent nothing for this long stops the loop (the default
#: ``sensor_timeout``); the watchdog's ramp to zero, at twice ``Limits.watchdog``, must begin
#: before it (``roboisf online`` refuses a ``--watchdog`` of half this or more)
SENSOR_TIMEOUT = 2.0

#: :class:`Loop` keywords that switch its runtime stop rules off (a silent controller or sensor,
#: late replies) — for simulated devices that share the loop's CPUs (``--simulate``, the tests,
#: the benchmark), whose stalls on a loaded machine are no verdict on a real cell's host
RULES_OFF: dict[str, Any] = {
    "controller_timeout": 3600.0,
    "sensor_timeout": 3600.0,
    "late_limit": 1 << 30,
}


def _clock_offset() -> float:
    """CLOCK_REALTIME − perf_counter, s (what turns a kernel's arrival stamp into perf_counter
    time): of five paired reads, the one bracketed tightest by perf_counter — a thread stalled
    between two bare reads (100 ms on a loaded host) shifted every arrival stamp by as much."""
    best, offset = math.inf, 0.0
    for _ in range(5):
        a = time.perf_counter()
        w = time.time()
        b = time.perf_counter()
        if b - a < best:
            best, offset = b - a, w - 0.5 * (a + b)
    return offset


def _timeval(seconds: float) -> bytes:
    """``struct timeval`` for ``SO_RCVTIMEO``."""
    sec = int(seconds)
    return struct.pack("ll", sec, round((seconds - sec) * 1e6))


class Adapter(Protocol):
    name: str

    def decode(self, data: bytes) -> RobotState: ...

    def encode(self, state: RobotState, correction: F64) -> bytes: ...


class SampleSource(Protocol):
    def samples_until(self, t: float) -> tuple[F64, F64]: ...


def parse_address(
    text: str, default_port: int, what: str, *, resolve: bool = False
) -> tuple[str, int]:
    """``HOST`` or ``HOST:PORT`` → (host, port); :class:`InputError` naming ``what`` (and,
    with ``resolve``, for a host name that does not resolve to an IPv4 address)."""
    host, _, port = text.rpartition(":") if ":" in text else (text, "", "")
    if not host:
        raise InputError(f"expected HOST or HOST:PORT, got {text!r}", field=what)
    try:
        p = int(port) if port else default_port
    except ValueError:
        raise InputError(f"port must be a number, got {port!r}", field=what) from None
    if not 0 <= p < 65536:
        raise InputError(f"port must be 0–65535, got {p}", field=what)
    if resolve:
        try:
            socket.getaddrinfo(host, p, socket.AF_INET, socket.SOCK_DGRAM)
        except (OSError, UnicodeError) as e:
            raise InputError(
                f"host {host!r} is not an IPv4 address or a name that resolves ({e})", field=what
            ) from None
    return host, p


@dataclass
class Counters:
    """What the loop saw."""

    cycles: int = 0
    samples: int = 0
    bad_controller: int = 0
    bad_sensor: int = 0
    late_sensor: int = 0  # records out of order or duplicated (behind the last): dropped
    lost_sensor: int = 0  # records missing from the sequence
    sensor_resyncs: int = 0  # the sensor's stream restarted (power cycle, RDT restart, wrap)
    sensor_status: int = 0  # records with a non-zero RDT status (saturation, fault)
    sensor_status_bits: int = 0  # every status bit seen (netft.status_text names them)
    implausible: int = 0  # force samples rejected as implausible (core.Plausibility)
    unoriented: int = 0  # samples before the first joint angles, not used (a weighed tool)
    late_replies: int = 0  # replies the loop sent more than a cycle after the message arrived
    stop_reason: str = ""  # why the loop stopped
    ramped: bool = False  # the correction was ramped to zero before the loop ended
    ramp_time: float = 0.0  # s, the ramp to zero at the stop
    left_mm: float = 0.0  # mm, the correction when the loop ended (0 when ramped)
    sensor_unreachable: int = 0  # the sensor's host answered "port unreachable"
    send_errors: int = 0  # replies the operating system refused to send
    max_compute: float = 0.0  # s, per cycle
    max_latency: float = 0.0  # s, kernel arrival of a message → its reply sent
    gc_collections: int = 0  # garbage collections while the loop ran (quiet_gc: in the slack)
    gc_max_pause: float = 0.0  # s, the longest of them
    status_lost: str = ""  # the status display's failure, after which it was dropped


class CycleLog:
    """Per-cycle log in preallocated chunks of ``capacity`` rows.

    A full chunk is never copied: the next one is the spare that :meth:`prepare` allocated in
    the slack after a reply (or, without that, allocated at once), so a long run never pays
    for growing one big array inside a cycle.
    """

    #: columns of the Parquet log and their units
    COLUMNS = (
        ("t_s", "s"),
        ("seq", "1"),
        *((f"q{i}_deg", "deg") for i in range(1, 7)),
        *((f"{c}_N", "N") for c in ("fx", "fy", "fz")),
        *((f"{c}_Nm", "N·m") for c in ("mx", "my", "mz")),
        *((f"d{c}_mm", "mm") for c in "xyz"),
        *((f"corr_{c}_mm", "mm") for c in "xyz"),
        ("status", "1"),
        ("compute_us", "µs"),
        ("latency_us", "µs"),
    )

    def __init__(self, capacity: int = 1 << 12) -> None:
        self.capacity = max(1, int(capacity))
        self._chunks: list[F64] = [self._new()]
        self._spare: F64 | None = None
        self._i = 0  # rows used in the last chunk

    def _new(self) -> F64:
        return np.zeros((self.capacity, len(self.COLUMNS)))

    @property
    def n(self) -> int:
        """Rows logged."""
        return (len(self._chunks) - 1) * self.capacity + self._i

    @property
    def data(self) -> F64:
        """(n, len(COLUMNS)) the rows logged (a copy when the log spans several chunks)."""
        if len(self._chunks) == 1:
            return self._chunks[0][: self._i]
        return np.concatenate([*self._chunks[:-1], self._chunks[-1][: self._i]])

    def prepare(self) -> None:
        """Allocate the next chunk ahead of need (call when there is time to spare)."""
        if self._spare is None and self._i >= self.capacity // 2:
            self._spare = self._new()

    def add(
        self,
        t: float,
        state: RobotState,
        oc: OnlineCompensator,
        compute: float,
        latency: float = math.nan,
    ) -> None:
        if self._i == self.capacity:
            self._chunks.append(self._spare if self._spare is not None else self._new())
            self._spare = None
            self._i = 0
        row = self._chunks[-1][self._i]
        row[0] = t
        row[1] = state.seq
        row[2:8] = state.q
        row[2:8] *= 180.0 / math.pi
        row[8:14] = oc.tip_wrench
        row[14:17] = oc.deflection[:3]
        row[14:17] *= 1e3
        row[17:20] = oc.correction
        row[17:20] *= 1e3
        row[20] = oc.status
        row[21] = compute * 1e6
        row[22] = latency * 1e6
        self._i += 1

    def write(self, path: str | Path, meta: dict[str, str]) -> None:
        """The log as Parquet (atomic): one row per cycle, units in the column names and in
        the file's metadata; wrench and deflection in base axes, corrections in work axes."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from roboisf.io.atomic import atomic_path

        d = self.data
        cols = {name: d[:, i] for i, (name, _) in enumerate(self.COLUMNS)}
        cols["seq"] = d[:, 1].astype(np.int64)
        cols["status"] = d[:, 20].astype(np.int64)
        table = pa.table(cols)
        units = {name: unit for name, unit in self.COLUMNS}
        md = {
            b"roboisf": repr({"units": units, **meta}).encode(),
        }
        table = table.replace_schema_metadata(md)
        with atomic_path(Path(path)) as tmp:
            pq.write_table(table, tmp)


class Loop:
    """Run ``oc`` between a force source and a controller (see the module docstring).

    Parameters
    ----------
    oc : OnlineCompensator
    adapter : EgmAdapter or RsiAdapter
    listen : (host, port) — where the controller's messages arrive
    sensor : (host, port) of a Net F/T, or a replay source with ``samples_until(t)``
    counts : (counts per N, counts per N·m) of the Net F/T
    realtime : :class:`~roboisf.online.rt.Realtime` — scheduler, CPU and memory lock asked for
        the thread that calls :meth:`run` (refused settings: one line each in ``warnings``)
    controller_timeout : float, s — no controller message for this long (after the first):
        the controller is lost; the loop stops (default 0.5 s)
    sensor_timeout : float, s — a Net F/T that streamed and then sent nothing for this long
        (the loop asks it to start again after 1 s: a restart within this time is followed)
        is lost; the loop stops (default :data:`SENSOR_TIMEOUT`, 2 s; the watchdog's ramp has
        begun by then: ``roboisf online`` refuses a watchdog of half this or more)
    ramp_timeout : float, s — while a stop ramps the correction down, no controller message
        for this long ends the ramp unfinished (nothing to send it to; default 0.5 s)
    late_limit, late_window : int, float s — this many replies later than a cycle after their
        message's arrival within ``late_window`` s: the host cannot keep the cycle; the loop
        ramps down and stops (default 25 in 1 s)
    quiet_gc : bool — keep the garbage collector out of the cycle
        (:class:`~roboisf.online.rt.GcQuiet`; default True). The full collection it needs is
        done here, with ``gc.freeze()``, so that :meth:`run` starts at once (the objects alive
        now stay frozen until :meth:`run` ends)

    Housekeeping — the status callback, the collector, the log's next chunk — runs right after
    a reply is sent, in the slack before the controller's next message, never between a
    message's arrival and its reply.
    """

    def __init__(
        self,
        oc: OnlineCompensator,
        adapter: Adapter,
        listen: tuple[str, int],
        sensor: tuple[str, int] | SampleSource,
        *,
        counts: tuple[float, float] = (netft.DEFAULT_COUNTS, netft.DEFAULT_COUNTS),
        log: CycleLog | None = None,
        realtime: Realtime | None = None,
        quiet_gc: bool = True,
        controller_timeout: float = 0.5,
        sensor_timeout: float = SENSOR_TIMEOUT,
        ramp_timeout: float = 0.5,
        late_limit: int = 25,
        late_window: float = 1.0,
    ) -> None:
        for name, v in (
            ("controller_timeout", controller_timeout),
            ("sensor_timeout", sensor_timeout),
            ("ramp_timeout", ramp_timeout),
            ("late_window", late_window),
        ):
            if not v > 0:
                raise InputError(f"must be > 0 s, got {v}", field=name)
        if late_limit < 1:
            raise InputError(f"must be ≥ 1, got {late_limit}", field="late_limit")
        self.oc = oc
        self.controller_timeout = float(controller_timeout)
        self.sensor_timeout = float(sensor_timeout)
        self.ramp_timeout = float(ramp_timeout)
        self._last_record_at = math.nan  # perf_counter of the last sensor packet (none yet)
        self.late_limit = int(late_limit)
        self.late_window = float(late_window)
        # the last late_limit late replies' times — a deque, grown as they come: a preallocated
        # ring of late_limit floats was 8 GB for RULES_OFF's 2**30 (filled in seconds to
        # minutes on a loaded host before the first cycle, then held for the whole run)
        self._late_times: deque[float] = deque(maxlen=self.late_limit)
        self._last_msg = math.nan  # perf_counter of the last controller message answered
        self.seq = netft.SequenceTracker()
        self.realtime = realtime or Realtime()
        self.quiet_gc = quiet_gc
        self.warnings: list[str] = []
        self.adapter = adapter
        self.counts = counts
        self.log = log if log is not None else CycleLog()
        self.counters = Counters()
        self.ctl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.ctl.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.ctl.bind(listen)
        except OSError as e:
            self.ctl.close()
            raise InputError(
                f"cannot listen on {listen[0]}:{listen[1]} ({e})", field="listen"
            ) from None
        self.listen = self.ctl.getsockname()
        # arrival stamps from the start: a record stamped and one not could be out of order
        self._ctl_stamped = enable_stamps(self.ctl)
        self._ft_stamped = False
        self.ft: socket.socket | None = None
        self.replay: SampleSource | None = None
        if isinstance(sensor, tuple):
            self.ft = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._ft_stamped = enable_stamps(self.ft)
            try:
                self.ft.connect(sensor)
            except (OSError, UnicodeError) as e:
                self.ft.close()
                self.ctl.close()
                raise InputError(
                    f"cannot reach the sensor at {sensor[0]}:{sensor[1]} ({e})", field="sensor"
                ) from None
        else:
            self.replay = sensor
        self._last_sample_at = -math.inf
        self._stop = False
        self._stop_reason = ""
        self.t0 = math.nan
        self._status: Callable[[Loop], None] | None = None
        self._status_every = 0.25
        self._next_status = 0.0
        self._gc: GcQuiet | None = None
        self._rt_offset = _clock_offset()
        oc.warm_up()  # compile before the first packet can arrive
        if quiet_gc:  # the one long collection now, before a controller is pointed at us:
            gc.collect()  # run()'s own (GcQuiet) then only walks what was made since
            gc.freeze()

    def stop(self, reason: str = "") -> None:
        """End :meth:`run` after the current packet (e.g. from a signal handler); ``reason``
        is the stop reason it reports (default "stop requested")."""
        self._stop_reason = reason
        self._stop = True

    def close(self) -> None:
        if self.quiet_gc:
            gc.unfreeze()  # what __init__ froze, when run() did not (it unfreezes on its way out)
        if self.ft is not None:
            try:
                self.ft.send(netft.encode_request(netft.CMD_STOP))
            except OSError:
                pass
            self.ft.close()
        self.ctl.close()

    def run(
        self,
        *,
        duration: float = math.inf,
        cycles: int | None = None,
        status: Callable[[Loop], None] | None = None,
        status_every: float = 0.25,
        warn: Callable[[str], None] | None = None,
    ) -> Counters:
        """Serve until ``duration`` s, ``cycles`` cycles, :meth:`stop`, Ctrl-C or SIGTERM
        (``KeyboardInterrupt`` / :class:`~roboisf.io.outdir.Interrupted`, caught here), a lost
        controller, too many late replies or an error — then ramp the correction to zero
        (module docstring) and return the counters (an error is raised again after the ramp).
        ``status(loop)`` is called every ``status_every`` s; ``warn(line)`` once per real-time
        setting refused (also kept in ``warnings``)."""
        rt = apply(self.realtime)  # before the sensor streams: a collection takes its time
        self.warnings = rt.warnings
        if warn is not None:
            for w in rt.warnings:
                warn(w)
        gcq = GcQuiet() if self.quiet_gc else None
        self._gc = gcq
        if gcq is not None:
            gcq.__enter__()
        self._start_sensor()
        t0 = time.perf_counter()
        self.t0 = t0  # the log's t_s is from here (perf_counter: CLOCK_MONOTONIC, system-wide)
        self._status = status
        self._status_every = status_every
        self._next_status = t0 + status_every
        ctl = self.ctl
        self._rt_offset = _clock_offset()  # CLOCK_REALTIME − perf_counter, s
        ctl.settimeout(None)  # blocking in Python: one recvmsg system call per message …
        ctl.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, _timeval(IDLE))  # … or a timeout
        error: BaseException | None = None
        try:
            try:
                reason = self._serve(t0, duration, cycles)
            except KeyboardInterrupt:
                reason = "interrupted (Ctrl-C)"
            except Interrupted as e:  # the command's handlers (SIGINT, SIGTERM, SIGHUP)
                reason = (
                    "interrupted (Ctrl-C)"
                    if e.signum == signal.SIGINT
                    else SIGNAL_OUTCOMES.get(e.exit_code, e.args[0])
                )
            except Exception as e:  # an error in the loop: the ramp first, then the error
                reason, error = f"error ({type(e).__name__}: {e})", e
            self._ramp_down(t0, reason)
        except (KeyboardInterrupt, Interrupted):  # a second signal: the ramp is cut short
            self.counters.stop_reason += "; the ramp to zero cut short by a second signal"
        finally:
            self.counters.left_mm = float(np.linalg.norm(self.oc.correction)) * 1e3
            self.counters.implausible = self.oc.implausible
            self.counters.unoriented = self.oc.unoriented
            if gcq is not None:
                gcq.__exit__(None, None, None)
                self.counters.gc_collections = gcq.collections
                self.counters.gc_max_pause = gcq.max_pause
            rt.restore()
            self.close()
        if error is not None:
            raise error
        return self.counters

    def _receive(self, t0: float) -> tuple[bytes, Any, float, float] | None:
        """One controller message (``data, addr, read time, arrival time``, perf_counter s)
        or None after ``IDLE`` s (the sensor socket drained meanwhile)."""
        try:
            data, anc, _, addr = self.ctl.recvmsg(65536, STAMP_SPACE)
        except (BlockingIOError, TimeoutError):  # no message for IDLE s
            self._drain_sensor(t0)  # samples keep the watchdog fed, the socket empty
            return None
        except OSError:
            return None
        now = time.perf_counter()
        return data, addr, now, self._arrival(anc, self._ctl_stamped, now)

    def _arrival(self, anc: Any, stamped: bool, read: float) -> float:
        """A datagram's arrival on the perf_counter clock: the kernel's stamp (``anc``), or
        the ``read`` time without one."""
        ns = kernel_stamp(anc) if stamped else None
        t = read if ns is None else ns * 1e-9 - self._rt_offset
        if not read - 1.0 < t <= read + 1e-3:  # the wall clock was stepped: follow it
            self._rt_offset = _clock_offset()
            t = read
        return t

    def _serve(self, t0: float, duration: float, cycles: int | None) -> str:
        """Answer the controller until a reason to stop; returns it."""
        status = self._status
        status_every = self._status_every
        while not self._stop:
            now = time.perf_counter()
            if now - t0 >= duration:
                return f"--duration {duration:g} s reached"
            if cycles is not None and self.counters.cycles >= cycles:
                return f"{cycles} cycles run"
            if now - self._last_msg > self.controller_timeout:
                return f"controller silent for {self.controller_timeout:g} s"
            if now - self._last_record_at > self.sensor_timeout:
                return f"sensor silent for {self.sensor_timeout:g} s"
            if status is not None and now >= self._next_status + status_every:
                self._housekeeping(now)  # no controller: the status still shows it
            if self.ft is not None and now - self._last_sample_at > 1.0:
                self._start_sensor()  # no data for a second: ask again (sensor restarted)
            got = self._receive(t0)
            if got is None:
                continue
            data, addr, now, arrived = got
            self._orient(data)  # the first message's joints orient the records before it
            self._drain_sensor(t0)  # every sample since the last cycle, at its arrival
            if self._on_controller(data, addr, arrived - t0, arrived, started=now):
                self._last_msg = now
                late = self._late_times
                if len(late) == self.late_limit and late[0] >= now - self.late_window:  # oldest
                    return (
                        f"{self.late_limit} late replies within {self.late_window:g} s "
                        "(the host cannot keep the cycle: docs/online.md, --selftest)"
                    )
                self._housekeeping(time.perf_counter())
        return self._stop_reason or "stop requested"

    def _ramp_down(self, t0: float, reason: str) -> None:
        """Ramp the correction to zero at ``ramp_rate``, answering the controller, then end."""
        c = self.counters
        c.stop_reason = reason
        self.oc.begin_stop()
        start = time.perf_counter()
        last = self._last_msg if math.isfinite(self._last_msg) else start
        lim = self.oc.limits  # the ramp's own length, twice, and a silent controller's wait
        give_up = start + 2.0 * lim.max_correction / lim.ramp_rate + self.ramp_timeout
        while np.any(self.oc.correction != 0.0):
            got = self._receive(t0)
            now = time.perf_counter()
            if now > give_up:
                break  # the messages' clock did not advance: never wait on it for ever
            if got is None:
                if now - max(last, start) > self.ramp_timeout:
                    break  # nobody to send the ramp to
                continue
            data, addr, now, arrived = got
            self._orient(data)
            self._drain_sensor(t0)
            if self._on_controller(data, addr, arrived - t0, arrived, started=now):
                last = now
        c.ramped = not np.any(self.oc.correction != 0.0)
        c.ramp_time = time.perf_counter() - start

    def _orient(self, data: bytes) -> None:
        """Before the first joint angles a weighed tool's samples are not used (the core cannot
        remove its weight): the first controller message gives them, before the records that
        arrived ahead of it are drained (a few ms of them; those drained while no controller
        spoke are not used)."""
        if self.oc.joints_known:
            return
        try:
            self.oc.set_joints(self.adapter.decode(data).q)
        except ProtocolError:
            pass  # a malformed message: dropped and counted by _on_controller

    def _drain_sensor(self, t0: float) -> None:
        """Every record queued in the sensor socket through :meth:`_on_sensor`, each timed by
        its kernel arrival stamp (the read time without one)."""
        ft = self.ft
        if ft is None:
            return
        while True:
            try:
                data, anc, _, _ = ft.recvmsg(65536, STAMP_SPACE, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # ICMP port unreachable from the sensor's host
                self.counters.sensor_unreachable += 1
                continue
            t = self._arrival(anc, self._ft_stamped, time.perf_counter())
            self._on_sensor(data, t - t0)

    def _housekeeping(self, now: float) -> None:
        """After a reply: the status, the collector, the log's next chunk."""
        if self._status is not None and now >= self._next_status:
            try:
                self._status(self)
            except OSError as e:
                # the display is gone (a closed pipe, a hung-up terminal): the loop, and above
                # all its ramp to zero, go on without it
                self._status = None
                self.counters.status_lost = f"{type(e).__name__}: {e}"
            self._next_status = now + self._status_every
        if self._gc is not None:
            self._gc.slack()
        self.log.prepare()

    def _start_sensor(self) -> None:
        self._last_sample_at = time.perf_counter()
        if self.ft is None:
            return
        try:
            self.ft.send(netft.encode_request(netft.CMD_START_REALTIME, 0))
        except OSError:
            self.counters.sensor_unreachable += 1

    def _on_sensor(self, data: bytes, t: float) -> None:
        self._last_sample_at = self._last_record_at = time.perf_counter()
        try:
            recs = netft.decode_records(data, *self.counts)
        except ProtocolError:
            self.counters.bad_sensor += 1
            return
        seq = self.seq
        c = self.counters
        for r in recs:
            if not seq.accept(r.rdt_sequence):
                continue
            if r.status:
                c.sensor_status += 1
                c.sensor_status_bits |= r.status
                continue
            if self.oc.sample(t, r.wrench):
                c.samples += 1
        c.late_sensor, c.lost_sensor, c.sensor_resyncs = seq.out_of_order, seq.lost, seq.resyncs

    def _on_controller(
        self,
        data: bytes,
        addr: Any,
        t: float,
        arrived: float | None = None,
        started: float | None = None,
    ) -> bool:
        """Answer one controller message (``arrived``: when the kernel received it,
        perf_counter s; ``started``: when the loop read it, the start of the compute time —
        the sensor drain included; default now); True when a reply was sent."""
        c0 = time.perf_counter() if started is None else started
        try:
            state = self.adapter.decode(data)
        except ProtocolError:
            self.counters.bad_controller += 1
            return False
        if self.replay is not None:
            tt, W = self.replay.samples_until(t)
            self.oc.set_joints(state.q)
            for i in range(len(tt)):
                if self.oc.sample(float(tt[i]), W[i]):
                    self.counters.samples += 1
        corr = self.oc.cycle(t, state.q)
        try:
            reply = self.adapter.encode(state, corr)
        except ProtocolError:
            self.counters.bad_controller += 1
            return False
        try:
            self.ctl.sendto(reply, addr)
        except OSError:
            self.counters.send_errors += 1
            return False
        done = time.perf_counter()
        compute = done - c0
        latency = done - (c0 if arrived is None else arrived)
        self.oc.set_joints(state.q)
        self.counters.cycles += 1
        self.counters.max_compute = max(self.counters.max_compute, compute)
        self.counters.max_latency = max(self.counters.max_latency, latency)
        if latency > self.oc.limits.cycle:  # the controller had its next message due
            self.counters.late_replies += 1
            self._late_times.append(done)
        self.log.add(t, state, self.oc, compute, latency)
        return True
