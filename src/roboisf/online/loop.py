"""The online loop: a force stream and a robot controller over UDP, the core in between.

One thread, one ``select`` over two sockets:

* the **sensor** socket — Net F/T RDT records (:mod:`roboisf.online.netft`) from the sensor the
  loop started streaming, or none with a :class:`~roboisf.online.replay.ReplaySensor`, whose
  samples are fed by the clock;
* the **controller** socket — the robot's messages (EGM or RSI): each is answered at once with
  the correction of :meth:`OnlineCompensator.cycle` to the address it came from.

A malformed packet is dropped and counted (the loop never answers it); a sensor record older
than the last one (its ``rdt_sequence``) is dropped as late; a sensor that stops trips the
core's watchdog. Every cycle is logged (time, sequence, joints, tip wrench, correction, status,
compute time) in preallocated arrays and written to Parquet (atomically) at the end.
"""

from __future__ import annotations

import math
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.online import netft
from roboisf.online.base import ProtocolError, RobotState
from roboisf.online.core import OnlineCompensator

__all__ = ["Counters", "CycleLog", "Loop", "parse_address"]

F64 = NDArray[np.float64]


class Adapter(Protocol):
    name: str

    def decode(self, data: bytes) -> RobotState: ...

    def encode(self, state: RobotState, correction: F64) -> bytes: ...


class SampleSource(Protocol):
    def samples_until(self, t: float) -> tuple[F64, F64]: ...


def parse_address(text: str, default_port: int, what: str) -> tuple[str, int]:
    """``HOST`` or ``HOST:PORT`` → (host, port); :class:`InputError` naming ``what``."""
    host, _, port = text.rpartition(":") if ":" in text else (text, "", "")
    if not host:
        raise InputError(f"expected HOST or HOST:PORT, got {text!r}", field=what)
    try:
        p = int(port) if port else default_port
    except ValueError:
        raise InputError(f"port must be a number, got {port!r}", field=what) from None
    if not 0 <= p < 65536:
        raise InputError(f"port must be 0–65535, got {p}", field=what)
    return host, p


@dataclass
class Counters:
    """What the loop saw."""

    cycles: int = 0
    samples: int = 0
    bad_controller: int = 0
    bad_sensor: int = 0
    late_sensor: int = 0
    sensor_status: int = 0  # records with a non-zero RDT status (saturation, fault)
    sensor_unreachable: int = 0  # the sensor's host answered "port unreachable"
    send_errors: int = 0  # replies the operating system refused to send
    max_compute: float = 0.0  # s, per cycle


@dataclass
class CycleLog:
    """Preallocated per-cycle log (grows by doubling only when full)."""

    capacity: int = 1 << 16
    n: int = 0
    data: F64 = field(init=False)

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
    )

    def __post_init__(self) -> None:
        self.data = np.zeros((self.capacity, len(self.COLUMNS)))

    def add(self, t: float, state: RobotState, oc: OnlineCompensator, compute: float) -> None:
        if self.n == len(self.data):
            self.data = np.concatenate([self.data, np.zeros_like(self.data)])
        row = self.data[self.n]
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
        self.n += 1

    def write(self, path: str | Path, meta: dict[str, str]) -> None:
        """The log as Parquet (atomic): one row per cycle, units in the column names and in
        the file's metadata; wrench and deflection in base axes, corrections in work axes."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        from roboisf.io.atomic import atomic_path

        d = self.data[: self.n]
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
    ) -> None:
        self.oc = oc
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
        self.ft: socket.socket | None = None
        self.replay: SampleSource | None = None
        if isinstance(sensor, tuple):
            self.ft = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.ft.connect(sensor)
        else:
            self.replay = sensor
        self._last_rdt = -1
        self._last_sample_at = -math.inf
        self._stop = False
        oc.warm_up()  # compile before the first packet can arrive

    def stop(self) -> None:
        """End :meth:`run` after the current packet (e.g. from a signal handler)."""
        self._stop = True

    def close(self) -> None:
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
    ) -> Counters:
        """Serve until ``duration`` s, ``cycles`` cycles, :meth:`stop` or Ctrl-C (which ends
        the loop cleanly: KeyboardInterrupt is caught here). ``status(loop)`` is called every
        ``status_every`` s."""
        self._start_sensor()
        socks = [self.ctl] + ([self.ft] if self.ft is not None else [])
        t0 = time.perf_counter()
        next_status = t0 + status_every
        ctl_fd = self.ctl.fileno()
        try:
            while not self._stop:
                now = time.perf_counter()
                if now - t0 >= duration or (cycles is not None and self.counters.cycles >= cycles):
                    break
                if status is not None and now >= next_status:
                    status(self)
                    next_status = now + status_every
                if self.ft is not None and now - self._last_sample_at > 1.0:
                    self._start_sensor()  # no data for a second: ask again (sensor restarted)
                ready, _, _ = select.select(socks, [], [], 0.05)
                for s in ready:
                    try:
                        data, addr = s.recvfrom(65536)
                    except OSError:  # ICMP port unreachable from the sensor's host
                        self.counters.sensor_unreachable += 1
                        continue
                    t = time.perf_counter() - t0
                    if s.fileno() == ctl_fd:
                        self._on_controller(data, addr, t)
                    else:
                        self._on_sensor(data, t)
        except KeyboardInterrupt:
            pass
        finally:
            self.close()
        return self.counters

    def _start_sensor(self) -> None:
        self._last_sample_at = time.perf_counter()
        if self.ft is None:
            return
        try:
            self.ft.send(netft.encode_request(netft.CMD_START_REALTIME, 0))
        except OSError:
            self.counters.sensor_unreachable += 1

    def _on_sensor(self, data: bytes, t: float) -> None:
        self._last_sample_at = time.perf_counter()
        try:
            recs = netft.decode_records(data, *self.counts)
        except ProtocolError:
            self.counters.bad_sensor += 1
            return
        for r in recs:
            if self._last_rdt >= 0 and ((r.rdt_sequence - self._last_rdt) & 0xFFFFFFFF) >= 1 << 31:
                self.counters.late_sensor += 1  # older than the last: dropped
                continue
            if r.rdt_sequence == self._last_rdt:
                self.counters.late_sensor += 1
                continue
            self._last_rdt = r.rdt_sequence
            if r.status:
                self.counters.sensor_status += 1
                continue
            if self.oc.sample(t, r.wrench):
                self.counters.samples += 1

    def _on_controller(self, data: bytes, addr: Any, t: float) -> None:
        c0 = time.perf_counter()
        try:
            state = self.adapter.decode(data)
        except ProtocolError:
            self.counters.bad_controller += 1
            return
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
            return
        try:
            self.ctl.sendto(reply, addr)
        except OSError:
            self.counters.send_errors += 1
            return
        compute = time.perf_counter() - c0
        self.oc.set_joints(state.q)
        self.counters.cycles += 1
        self.counters.max_compute = max(self.counters.max_compute, compute)
        self.log.add(t, state, self.oc, compute)
