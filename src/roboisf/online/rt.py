"""Real-time settings of a process that must answer every 4 ms: scheduler, CPU, memory, GC.

On a general-purpose Linux kernel a Python loop that computes in 50 µs can still answer a cycle
late: the scheduler gives the core to another process for a time slice (milliseconds), a page
of a growing array is faulted in, or the cyclic garbage collector walks every tracked object.
:func:`apply` asks the operating system for what removes the first two; :class:`GcQuiet`
removes the third:

* ``priority`` — ``SCHED_FIFO`` at this priority (1–99, ``sched_setscheduler(2)``): the loop
  runs as soon as its packet arrives, ahead of every normal process. Needs ``CAP_SYS_NICE`` or
  an ``RLIMIT_RTPRIO`` (``ulimit -r``) at least that high; the kernel still keeps 5 % of each
  second for normal processes (``/proc/sys/kernel/sched_rt_runtime_us``).
* ``cpu`` — pin the process to this CPU (``sched_setaffinity(2)``); best on a core kept free of
  other work (``isolcpus=`` or a cpuset).
* ``mlock`` — ``mlockall(MCL_CURRENT | MCL_FUTURE)``: every page stays in RAM and is faulted in
  when mapped, not on first touch in the loop. Needs ``CAP_IPC_LOCK`` or an
  ``RLIMIT_MEMLOCK`` (``ulimit -l``) above the process's size.

What the process may not do is not an error: :func:`apply` returns one line per refused setting
naming the missing capability or limit (the loop still runs, without that guarantee). A value
that cannot be meant (priority 0, a CPU the process may not use) is an
:class:`~roboisf.errors.InputError`.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import gc
import os
import socket
import struct
import time
from dataclasses import dataclass
from typing import Any

from roboisf.errors import InputError

__all__ = [
    "Applied",
    "GcQuiet",
    "Pacer",
    "Realtime",
    "apply",
    "enable_stamps",
    "kernel_stamp",
    "other_cpus",
    "set_timer_slack",
    "sleep_until",
]

MCL_CURRENT = 1
MCL_FUTURE = 2


@dataclass(frozen=True)
class Realtime:
    """What to ask of the operating system (all off by default: they need privileges).

    Attributes
    ----------
    priority : int or None — ``SCHED_FIFO`` priority 1–99; None leaves the scheduler alone
    cpu : int or None — the one CPU to run on; None leaves the affinity alone
    mlock : bool — lock all current and future pages in RAM
    cpus : tuple of int or None — several CPUs to run on instead of one (e.g. the simulated
        devices on every CPU but the loop's, :func:`other_cpus`); not with ``cpu``
    """

    priority: int | None = None
    cpu: int | None = None
    mlock: bool = False
    cpus: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if self.priority is not None:
            lo = os.sched_get_priority_min(os.SCHED_FIFO)
            hi = os.sched_get_priority_max(os.SCHED_FIFO)
            if not lo <= self.priority <= hi:
                raise InputError(
                    f"SCHED_FIFO priority must be {lo}–{hi}, got {self.priority}",
                    field="--realtime",
                )
        if self.cpu is not None:
            allowed = sorted(os.sched_getaffinity(0))
            if self.cpu not in allowed:
                raise InputError(
                    f"CPU {self.cpu} is not one this process may use ({allowed})", field="--cpu"
                )
        if self.cpus is not None:
            allowed_set = os.sched_getaffinity(0)
            if self.cpu is not None or not self.cpus or not set(self.cpus) <= allowed_set:
                raise InputError(
                    f"cpus must be a non-empty set of the CPUs this process may use "
                    f"({sorted(allowed_set)}), without cpu; got {self.cpus}",
                    field="cpus",
                )

    @property
    def any(self) -> bool:
        return (
            self.priority is not None or self.cpu is not None or self.cpus is not None or self.mlock
        )

    @property
    def affinity(self) -> set[int] | None:
        """The CPUs to pin to (None: leave the affinity alone)."""
        if self.cpu is not None:
            return {self.cpu}
        return set(self.cpus) if self.cpus is not None else None


def other_cpus(cpu: int | None) -> tuple[int, ...] | None:
    """The CPUs this process may use except ``cpu`` (None when ``cpu`` is None or it is the
    only one): where the simulated devices go when the loop is pinned to ``cpu``."""
    if cpu is None:
        return None
    rest = tuple(sorted(os.sched_getaffinity(0) - {cpu}))
    return rest or None


def _libc() -> Any:
    return ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)


def _mlockall(flags: int) -> int:
    """``mlockall(flags)``; 0 or the errno."""
    libc = _libc()
    if libc.mlockall(flags) != 0:
        return ctypes.get_errno() or errno.EPERM
    return 0


class Applied:
    """What :func:`apply` did: ``warnings`` (one line per refused setting) and :meth:`restore`,
    which puts the thread's scheduler and CPUs back and unlocks memory it locked."""

    def __init__(self) -> None:
        self.warnings: list[str] = []
        self._policy: tuple[int, int] | None = None
        self._cpus: set[int] | None = None
        self._locked = False

    def restore(self) -> None:
        if self._policy is not None:
            try:
                os.sched_setscheduler(0, self._policy[0], os.sched_param(self._policy[1]))
            except OSError:
                pass
            self._policy = None
        if self._cpus is not None:
            try:
                os.sched_setaffinity(0, self._cpus)
            except OSError:
                pass
            self._cpus = None
        if self._locked:
            _libc().munlockall()
            self._locked = False


def apply(rt: Realtime, who: str = "the loop") -> Applied:
    """Apply ``rt`` to the calling thread (scheduler, CPU) and process (memory lock).

    Returns an :class:`Applied`: its ``warnings`` name each refused setting and what it needs
    (empty: all granted); its ``restore()`` undoes what was granted. ``who`` names the thread in
    the warnings.
    """
    done = Applied()
    w = done.warnings
    cpus = rt.affinity
    if cpus is not None:
        before = os.sched_getaffinity(0)
        try:
            os.sched_setaffinity(0, cpus)
            done._cpus = before
        except OSError as e:
            w.append(f"{who}: could not pin to CPU {sorted(cpus)} ({e.strerror}); not pinned")
    if rt.priority is not None:
        before_p = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt.priority))
            done._policy = before_p
        except PermissionError:
            w.append(
                f"{who}: real-time priority refused (SCHED_FIFO {rt.priority} needs CAP_SYS_NICE "
                f"or `ulimit -r` ≥ {rt.priority}); running at normal priority"
            )
        except OSError as e:
            w.append(
                f"{who}: real-time priority refused ({e.strerror}; in a container the cgroup "
                "may have no real-time budget, cpu.rt_runtime_us); running at normal priority"
            )
    if rt.mlock:
        err = _mlockall(MCL_CURRENT | MCL_FUTURE)
        if err:
            w.append(
                f"{who}: memory not locked (mlockall: {os.strerror(err)}; needs CAP_IPC_LOCK or "
                "`ulimit -l` above the process's size); pages may be faulted in during the loop"
            )
        else:
            done._locked = True
    return done


class GcQuiet:
    """The cyclic garbage collector kept out of the cycle (a context manager).

    On entry: one full collection, ``gc.freeze()`` (everything alive now — modules, the cell,
    numba's dispatchers — moves to the permanent generation and is never scanned again) and
    ``gc.disable()``. The loop then calls :meth:`slack` right after each reply, when it has the
    rest of the cycle to spare: it collects the young generation only if the allocation counts
    have reached the collector's own thresholds, so cyclic garbage still cannot accumulate. On
    exit the collector's previous state is restored. ``collections`` and ``max_pause`` (s)
    count every collection in the block, automatic or not (``gc.callbacks``).
    """

    def __init__(self) -> None:
        self.collections = 0
        self.max_pause = 0.0
        self._t = 0.0
        self._was_enabled = True

    def _cb(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._t = time.perf_counter()
        else:
            self.collections += 1
            self.max_pause = max(self.max_pause, time.perf_counter() - self._t)

    def __enter__(self) -> GcQuiet:
        self._was_enabled = gc.isenabled()
        gc.collect()
        gc.freeze()
        gc.disable()
        gc.callbacks.append(self._cb)
        return self

    def slack(self) -> None:
        """Collect the generation the collector would have collected by now (usually none)."""
        c0, c1, c2 = gc.get_count()
        t0, t1, t2 = gc.get_threshold()
        if t0 and c0 >= t0:
            gc.collect(2 if c2 >= t2 else 1 if c1 >= t1 else 0)

    def __exit__(self, *exc: object) -> None:
        gc.callbacks.remove(self._cb)
        gc.unfreeze()
        if self._was_enabled:
            gc.enable()


#: Linux's SO_TIMESTAMPNS (= SCM_TIMESTAMPNS; 35 on x86 and arm, not exported by Python 3.11)
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)
#: ancillary buffer size for one ``struct timespec``
STAMP_SPACE = socket.CMSG_SPACE(16)


def enable_stamps(s: socket.socket) -> bool:
    """Ask the kernel to stamp each datagram's arrival on ``s`` (``SO_TIMESTAMPNS``; read with
    ``recvmsg(n, STAMP_SPACE)`` and :func:`kernel_stamp`); False if refused."""
    try:
        s.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def kernel_stamp(ancdata: list[tuple[int, int, bytes]]) -> int | None:
    """The arrival stamp (``CLOCK_REALTIME``, ns) in ``recvmsg``'s ancillary data, or None."""
    for level, kind, d in ancdata:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(d) >= 16:
            sec, ns = struct.unpack("qq", d[:16])
            return int(sec * 1_000_000_000 + ns)
    return None


# ------------------------------------------------------------------------------- absolute time
CLOCK_MONOTONIC = 1  # Linux's clock id; time.perf_counter() reads this clock
TIMER_ABSTIME = 1
PR_SET_TIMERSLACK = 29


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


_nanosleep: Any = None  # libc's clock_nanosleep, looked up once (False: not available)


def _clock_nanosleep() -> Any:
    global _nanosleep
    if _nanosleep is None:
        try:
            f = _libc().clock_nanosleep
            f.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
            f.restype = ctypes.c_int
            ok = time.get_clock_info("perf_counter").implementation == (
                "clock_gettime(CLOCK_MONOTONIC)"
            )
            _nanosleep = f if ok else False
        except (AttributeError, OSError):
            _nanosleep = False
    return _nanosleep


def sleep_until(t: float) -> None:
    """Sleep until ``t`` (s, on the :func:`time.perf_counter` clock, ``CLOCK_MONOTONIC``).

    ``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)``: the wake-up is an absolute time, so a
    process preempted between computing the deadline and going to sleep does not sleep that
    long again (as a relative ``time.sleep(t − now)`` would). Returns at once when ``t`` has
    passed. Where the call is not available, a relative sleep.
    """
    f = _clock_nanosleep()
    if not f:
        d = t - time.perf_counter()
        if d > 0:
            time.sleep(d)
        return
    ts = _Timespec(int(t), round((t - int(t)) * 1e9))
    if ts.tv_nsec >= 1_000_000_000:
        ts.tv_sec += 1
        ts.tv_nsec -= 1_000_000_000
    while f(CLOCK_MONOTONIC, TIMER_ABSTIME, ctypes.byref(ts), None) == errno.EINTR:
        pass  # a signal: the deadline is absolute, sleep on to it


def set_timer_slack(ns: int) -> bool:
    """This thread's timer slack (``prctl(PR_SET_TIMERSLACK)``, ns; Linux's default is
    50,000): how much later than asked the kernel may end a sleep to batch wake-ups. False if
    refused. (``SCHED_FIFO`` threads have none.)"""
    try:
        return int(_libc().prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(max(1, int(ns))), 0, 0, 0)) == 0
    except (AttributeError, OSError):
        return False


class Pacer:
    """Events at absolute times, met to the microsecond without drift (a simulated controller's
    cycle: a hard-real-time controller sends on its clock, whatever happened the cycle before).

    :meth:`at` ``(k) = t0 + k·period`` — computed from the start, never by adding periods to
    the previous wake-up, so no error accumulates and a late cycle does not shift the ones
    after it. :meth:`wait` sleeps with :func:`sleep_until` to ``spin`` s before the time (the
    kernel's wake-up latency, µs to a few hundred µs, falls in that margin), then busy-waits
    the rest on the clock, and returns how late it returned (s, ≥ 0; the process's own
    lateness — a wake-up or a return from a preemption after the time).

    ``clock`` and ``sleep`` (the absolute sleep) are the real ones by default; tests pass fakes.
    """

    def __init__(
        self,
        t0: float,
        period: float,
        *,
        spin: float = 3e-4,
        clock: Any = time.perf_counter,
        sleep: Any = sleep_until,
    ) -> None:
        if not period > 0 or not spin >= 0:
            raise InputError(
                f"period must be > 0 and spin ≥ 0, got {period}, {spin}", field="period"
            )
        self.t0 = float(t0)
        self.period = float(period)
        self.spin = float(spin)
        self.clock = clock
        self.sleep = sleep

    def at(self, k: int) -> float:
        """The time of event ``k`` (s): ``t0 + k·period``."""
        return self.t0 + k * self.period

    def wait(self, t: float, spin: float | None = None) -> float:
        """Return at ``t`` (s, the clock's time): absolute sleep to ``t − spin``, busy-wait the
        tail. Returns the lateness ``clock() − t`` (≥ 0)."""
        s = self.spin if spin is None else spin
        clock = self.clock
        now = clock()
        if now < t - s:
            self.sleep(t - s)
        while (now := clock()) < t:
            pass
        return float(now - t)
