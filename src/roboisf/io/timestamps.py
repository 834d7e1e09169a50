"""Timestamps of a log that do not strictly increase: refuse (default) or repair, counted.

A logger's clock is not always clean: a sample written twice (the same row again), two samples
stamped with one tick of a coarse clock, a few rows out of order (buffered writes). The study
chooses per log (``timestamps = "refuse" | "repair"``, docs/study.md):

* ``"refuse"`` (default): the first time that does not exceed its predecessor is an error
  naming its line — a log whose clock is wrong is not silently bent into shape.
* ``"repair"``, in this order, every step counted in :class:`TimeRepair`:

  1. **reorder a few**: rows whose time is below the latest time before them are out of order;
     up to :data:`MAX_REORDERED` of the rows (at least one) are put back in time order (a stable
     sort). More than that is a log whose clock jumps back, refused.
  2. **drop exact duplicates**: a row equal to the previous one in time and every value.
  3. **average equal stamps**: the rows left that share a time become one sample, their mean.

The result strictly increases. Nothing else is changed: the values of the other rows are the
file's.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError

__all__ = ["MAX_REORDERED", "TIME_POLICIES", "TimeRepair", "repair_time"]

F64 = NDArray[np.float64]

#: ``timestamps`` values of a study log.
TIME_POLICIES = ("refuse", "repair")
#: "repair" puts at most this fraction of the rows back in order (at least one row).
MAX_REORDERED = 0.01


@dataclass(frozen=True)
class TimeRepair:
    """What ``timestamps = "repair"`` changed in a log (counts of rows)."""

    rows: int
    reordered: int = 0
    duplicates: int = 0
    averaged: int = 0  # rows merged into an earlier sample of the same time

    @property
    def changed(self) -> bool:
        return bool(self.reordered or self.duplicates or self.averaged)

    def describe(self) -> str:
        """One line for the log's notes."""
        return (
            f"timestamps repaired: {self.reordered} row(s) put back in time order, "
            f"{self.duplicates} exact duplicate row(s) dropped, {self.averaged} row(s) with a "
            f"repeated time averaged into their sample ({self.rows} rows read)"
        )


def repair_time(
    time: F64,
    values: F64,
    policy: str,
    *,
    error: Callable[[str, int], Exception],
) -> tuple[F64, F64, TimeRepair]:
    """Apply the timestamp ``policy`` to a log (module docstring).

    Parameters
    ----------
    time : (N,) float, s — as read
    values : (N, K) float — the other columns of each row (SI)
    policy : ``"refuse"`` | ``"repair"``
    error : ``error(message, row)`` → the exception naming the file line of 0-based ``row``

    Returns
    -------
    time : (M,) float, s — strictly increasing; values : (M, K); the :class:`TimeRepair`

    Raises
    ------
    InputError (from ``error``)
        under "refuse" at the first time not above its predecessor; under "repair" when more
        than :data:`MAX_REORDERED` of the rows are out of order.
    """
    n = int(time.size)
    if n < 2 or bool(np.all(np.diff(time) > 0)):
        return time, values, TimeRepair(n)
    if policy not in TIME_POLICIES:
        raise InputError(
            f"must be one of {', '.join(TIME_POLICIES)}, got {policy!r}", field="timestamps"
        )
    d = np.diff(time)
    if policy == "refuse":
        r = int(np.argmax(d <= 0)) + 1
        what = "repeats" if d[r - 1] == 0 else "goes back from"
        n_eq, n_back = int((d == 0).sum()), int((d < 0).sum())
        raise error(
            f"time must strictly increase: {time[r]:g} s {what} {time[r - 1]:g} s "
            f"({n_eq} repeated and {n_back} decreasing time(s) in the log); set "
            'timestamps = "repair" for this log to drop duplicates, average equal stamps and '
            "reorder a few rows",
            r,
        )
    # 1. a few rows out of order
    late = time[1:] < np.maximum.accumulate(time)[:-1]
    n_late = int(late.sum())
    limit = max(1, int(MAX_REORDERED * n))
    if n_late > limit:
        r = int(np.argmax(late)) + 1
        raise error(
            f"{n_late} rows have a time below an earlier row's (first {time[r]:g} s after "
            f"{float(np.max(time[:r])):g} s): more than {limit} ({MAX_REORDERED:.0%}) is a clock "
            "that jumps back, not a few rows written late; fix the log or split it",
            r,
        )
    if n_late:
        order = np.argsort(time, kind="stable")
        time, values = time[order], values[order]
    # 2. exact duplicate rows
    same_t = np.concatenate([[False], time[1:] == time[:-1]])
    same_v = np.concatenate([[False], np.all(values[1:] == values[:-1], axis=1)])
    dup = same_t & same_v
    n_dup = int(dup.sum())
    time, values = time[~dup], values[~dup]
    # 3. equal stamps: one sample, the mean
    start = np.concatenate([[True], time[1:] != time[:-1]])
    n_avg = int((~start).sum())
    if n_avg:
        group = np.cumsum(start) - 1
        count = np.bincount(group).astype(float)
        mean = np.empty((int(start.sum()), values.shape[1]))
        for k in range(values.shape[1]):
            mean[:, k] = np.bincount(group, weights=values[:, k]) / count
        time, values = time[start], mean
    return time, values, TimeRepair(n, n_late, n_dup, n_avg)
