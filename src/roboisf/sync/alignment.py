"""The result of aligning a log to a toolpath: a monotone map log clock → toolpath point.

Every method (:func:`~roboisf.sync.align_by_position`, :func:`~roboisf.sync.align_by_force`,
:func:`~roboisf.sync.align_by_time`) ends in an :class:`Alignment`: the log time at which the
tool passed each toolpath point and, for averaging a log over a point, the log-time window from
half-way to the previous point to half-way to the next one (so that every logged sample counts
once, a pause counts towards the point the tool stood at).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.logs.forcelog import window_average

__all__ = ["PAUSE_MIN", "Alignment", "first_passage", "point_windows"]

F64 = NDArray[np.float64]

#: Shortest stop [s of log time] reported as a pause (longer than any acceleration transient).
PAUSE_MIN = 1.0


def first_passage(tau: F64, s: F64, x: F64) -> F64:
    """Log time at which the monotone progress ``s(tau)`` first reaches each ``x``.

    ``tau`` (M,) increasing, ``s`` (M,) non-decreasing, ``x`` (K,) within ``[s[0], s[-1]]``.
    Linear between samples; during a plateau (a pause) the *first* time is returned, so a
    pause at ``x`` falls after it.
    """
    k = np.searchsorted(s, x, side="left")
    k = np.clip(k, 1, len(s) - 1)
    s0, s1 = s[k - 1], s[k]
    t0, t1 = tau[k - 1], tau[k]
    ds = s1 - s0
    u = np.where(ds > 0, (x - s0) / np.where(ds > 0, ds, 1.0), 1.0)
    out = t0 + np.clip(u, 0.0, 1.0) * (t1 - t0)
    out[x <= s[0]] = tau[0]
    return np.asarray(out, dtype=float)


def point_windows(tau: F64, s: F64, S: F64) -> tuple[F64, F64, F64]:
    """Passage times and averaging windows of toolpath points at progress ``S`` (N,).

    Returns ``(point_time, lo, hi)``, each (N,) in the log's clock: the window of point i runs
    from the first passage of half-way to the previous point to that of half-way to the next
    (the ends at the first and last point), as ``attach_to_toolpath(by="time")`` does on the
    nominal clock.
    """
    mid = 0.5 * (S[1:] + S[:-1])
    t_pt = first_passage(tau, s, S)
    t_mid = first_passage(tau, s, mid)
    lo = np.concatenate([t_pt[:1], t_mid])
    hi = np.concatenate([t_mid, t_pt[-1:]])
    return t_pt, lo, hi


@dataclass(frozen=True)
class Alignment:
    """How one run's log maps onto the toolpath (log clock, s).

    Attributes
    ----------
    method : ``"time"``, ``"position"`` or ``"force"``
    point_time : (N,) float, s — log time at which the tool passed each toolpath point
    lo, hi : (N,) float, s — each point's averaging window in log time (``lo ≤ hi``)
    residual : (N,) float — per point misfit: metres for ``position`` (logged tip, FK of the
        joints, against the toolpath's tip at the passage), equivalent toolpath points for
        ``force`` (the force direction's scatter about the fitted map), NaN for ``time``
    residual_unit : ``"mm"`` or ``"points"`` (the unit of :meth:`to_dict`'s figures)
    clock_scale : log seconds per nominal toolpath second outside pauses (1.02: the log's
        clock runs 2 % fast or the robot moves 2 % slow — the two are the same to a log)
    offset : s — log time at which the toolpath started
    pauses : list of (nominal toolpath time [s], duration [s of log]) — stops longer than
        :data:`PAUSE_MIN`
    source : the log the map was found from
    notes : assumptions and warnings (for the report)
    """

    method: str
    point_time: F64
    lo: F64
    hi: F64
    residual: F64
    residual_unit: str
    clock_scale: float
    offset: float
    pauses: list[tuple[float, float]] = field(default_factory=list)
    source: str = ""
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.point_time.shape[0])

    @property
    def residual_rms(self) -> float:
        r = self.residual[np.isfinite(self.residual)]
        return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")

    @property
    def residual_max(self) -> float:
        r = self.residual[np.isfinite(self.residual)]
        return float(np.max(np.abs(r))) if r.size else float("nan")

    def average(self, tau: F64, values: F64, *, file: Path | None = None) -> F64:
        """Mean of a log ``values`` (M, K) sampled at ``tau`` (M,) over each point's window;
        (N, K). The log must cover every window (else :class:`InputError` naming ``file``)."""
        t0, t1 = float(tau[0]), float(tau[-1])
        tol = 1e-9 * max(1.0, abs(t1))
        out = (self.lo < t0 - tol) | (self.hi > t1 + tol)
        if np.any(out):
            bad = np.flatnonzero(out)
            why = "the log must cover the whole toolpath"
            if self.method == "force" and not np.any(np.isfinite(self.residual[bad])):
                # points before the force direction was readable, timed by extrapolation
                why = (
                    "they come before the first turn the force direction times (too little "
                    "force to read it) and were timed back from the first timed points at their "
                    "clock rate — a pause or a clock "
                    "change among them cannot be seen that way (the log itself may well cover "
                    'them): give this run a joint log (sync = "position"), or its logs\' time '
                    'offset (sync = "time")'
                )
            raise InputError(
                f"{bad.size} toolpath point(s) (indices {bad[0]}..{bad[-1]}) were passed at log "
                f"time {self.lo[bad[0]]:.3f}..{self.hi[bad[-1]]:.3f} s, outside the log's span "
                f"{t0:.3f}..{t1:.3f} s ({self.method} alignment): {why}",
                file=file,
                field="time",
            )
        return window_average(tau, values, np.clip(self.lo, t0, t1), np.clip(self.hi, t0, t1))

    def mapped(self, scale: float, offset: float, *, method: str, source: str) -> Alignment:
        """This map seen through another clock ``tau' = offset + scale · tau`` (a second logger)."""
        return Alignment(
            method,
            offset + scale * self.point_time,
            offset + scale * self.lo,
            offset + scale * self.hi,
            self.residual,
            self.residual_unit,
            self.clock_scale * scale,
            offset + scale * self.offset,
            [(t, d * scale) for t, d in self.pauses],
            source,
            list(self.notes),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: method, residual_rms/max (mm or points), clock_scale, offset (s), pauses."""
        k = 1e3 if self.residual_unit == "mm" else 1.0
        return {
            "method": self.method,
            "residual_rms": None if not np.isfinite(self.residual_rms) else self.residual_rms * k,
            "residual_max": None if not np.isfinite(self.residual_max) else self.residual_max * k,
            "residual_unit": self.residual_unit,
            "clock_scale": self.clock_scale,
            "offset": self.offset,
            "pauses": [[float(t), float(d)] for t, d in self.pauses],
            "source": self.source,
            "notes": list(self.notes),
        }


def clock_fit(t_nominal: F64, point_time: F64) -> tuple[float, float, list[tuple[float, float]]]:
    """Clock scale, offset and pauses of a per-point time map.

    ``scale`` is the median ratio of log to nominal time over segments (robust to the few that
    hold a pause); a pause is a segment whose log duration exceeds ``scale · Δt`` by
    :data:`PAUSE_MIN`; ``offset`` is the log time of the first point.
    """
    dt = np.diff(t_nominal)
    dtau = np.diff(point_time)
    ok = dt > 0
    scale = float(np.median(dtau[ok] / dt[ok])) if np.any(ok) else 1.0
    extra = dtau - scale * dt
    pauses = [(float(t_nominal[i]), float(extra[i])) for i in np.flatnonzero(extra > PAUSE_MIN)]
    # a pause spread over two segments (the tool stood half-way) is one pause
    merged: list[tuple[float, float]] = []
    for t, d in pauses:
        if (
            merged
            and np.searchsorted(t_nominal, t) - np.searchsorted(t_nominal, merged[-1][0]) <= 1
        ):
            merged[-1] = (merged[-1][0], merged[-1][1] + d)
        else:
            merged.append((t, d))
    return scale, float(point_time[0] - scale * t_nominal[0]), merged
