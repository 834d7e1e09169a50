"""The host's self-test (``roboisf online --selftest``): can this machine keep the cycle?

For ``seconds`` s, under the real-time settings asked for (:func:`roboisf.online.rt.apply`),
one iteration per controller cycle at the absolute times ``t0 + k·cycle``
(:func:`~roboisf.online.rt.sleep_until`, as the loop's wake-up on a controller message):

* **wake-up latency** — how late the thread runs after the time it asked for (what the
  scheduler, other processes, interrupts and power states add);
* **compute** — one cycle of the loop's work after the wake-up: the controller's message decoded,
  four force samples filtered, the correction computed and the reply encoded, with the real
  codec and the real core.

The verdict compares the worst response, wake-up latency + compute, with the **budget**: the
part of the cycle the loop may use (default half: the rest is the wire and the controller's own
margin). One response over it is a reply the controller would have counted late, so the verdict
is *pass* only when none was. On a general-purpose kernel a minute usually shows a few
milliseconds of wake-up latency somewhere; an RT host (PREEMPT_RT, an isolated core, the loop at
SCHED_FIFO with its memory locked) stays within tens of µs (docs/online.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.online.core import OnlineCompensator
from roboisf.online.rt import GcQuiet, Realtime, apply, sleep_until

__all__ = ["SelftestResult", "selftest"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class SelftestResult:
    """What :func:`selftest` measured (s).

    wake : (n,) wake-up latency per cycle; compute : (n,) the loop's work per cycle;
    cycle, budget : s; warnings : the real-time settings refused (one line each).
    """

    cycle: float
    budget: float
    wake: F64
    compute: F64
    warnings: list[str] = field(default_factory=list)

    @property
    def response(self) -> F64:
        """(n,) wake-up latency + compute per cycle."""
        return self.wake + self.compute

    @property
    def over(self) -> int:
        """Cycles whose response exceeded the budget."""
        return int(np.count_nonzero(self.response > self.budget))

    @property
    def passed(self) -> bool:
        return len(self.wake) > 0 and self.over == 0

    def lines(self) -> list[str]:
        """The report: the figures, then the verdict."""

        def stats(x: F64) -> str:
            p = np.percentile(x, [50, 99, 99.9]) * 1e6
            return f"p50 {p[0]:.0f}, p99 {p[1]:.0f}, p99.9 {p[2]:.0f}, max {x.max() * 1e6:.0f} µs"

        n = len(self.wake)
        worst = float(self.response.max()) if n else math.nan
        verdict = (
            f"PASS: every one of {n} cycles answered within the budget "
            f"{self.budget * 1e3:g} ms of the {self.cycle * 1e3:g} ms cycle "
            f"(worst {worst * 1e3:.3f} ms)"
            if self.passed
            else f"FAIL: {self.over} of {n} cycles over the budget {self.budget * 1e3:g} ms of "
            f"the {self.cycle * 1e3:g} ms cycle (worst {worst * 1e3:.3f} ms): the controller "
            "would count those replies late; see docs/online.md (PREEMPT_RT, an isolated core, "
            "--realtime, --cpu, --mlock)"
        )
        return [
            f"wake-up latency: {stats(self.wake)}",
            f"loop compute:    {stats(self.compute)}",
            verdict,
        ]


def selftest(
    oc: OnlineCompensator,
    adapter: Any,
    message: bytes,
    *,
    seconds: float = 10.0,
    budget: float | None = None,
    realtime: Realtime | None = None,
    clock: Callable[[], float] = time.perf_counter,
    sleep: Callable[[float], None] = sleep_until,
) -> SelftestResult:
    """Measure wake-up latency and the loop's compute for ``seconds`` s (module docstring).

    ``message``: a controller message the ``adapter`` decodes (its joints: a pose of the part);
    ``budget``: s, default half the cycle; ``clock``/``sleep``: the time source and the
    absolute sleep (injected by the tests). The compensator is reset afterwards.
    """
    cycle = float(oc.limits.cycle)
    if not (math.isfinite(seconds) and seconds > 0):
        raise InputError(f"must be > 0 s, got {seconds}", field="--selftest-seconds")
    b = cycle / 2 if budget is None else float(budget)
    if not 0 < b <= cycle:
        raise InputError(f"must be in (0, cycle], got {b}", field="budget")
    n = max(1, int(seconds / cycle))
    wake = np.empty(n)
    compute = np.empty(n)
    adapter.decode(message)  # a message the adapter takes (ProtocolError otherwise)
    W = np.array([20.0, -15.0, 600.0, 0.2, -0.1, 0.05])
    dt = cycle / 4
    applied = apply(realtime) if realtime is not None else None
    oc.reset()
    oc.warm_up()
    oc.set_joints(adapter.decode(message).q)  # as the loop, once the controller has spoken
    gcq = GcQuiet().__enter__()
    try:
        t0 = clock() + cycle
        for k in range(n):
            target = t0 + k * cycle
            sleep(target)
            woke = clock()
            st = adapter.decode(message)
            for i in range(4):
                oc.sample(k * cycle + i * dt, W)
            c = oc.cycle(k * cycle + cycle, st.q)
            adapter.encode(st, c)
            done = clock()
            wake[k] = max(0.0, woke - target)
            compute[k] = done - woke
            gcq.slack()
    finally:
        gcq.__exit__()
        if applied is not None:
            applied.restore()
        oc.reset()
    return SelftestResult(cycle, b, wake, compute, applied.warnings if applied else [])
