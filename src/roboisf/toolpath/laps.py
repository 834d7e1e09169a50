"""Laps of a toolpath known only by its points (an imported CAM program): levels or turns.

A lap is what the part sees as one pass of the tool: one z level of a step-down (z-level) path,
or one turn of a spiral about the part's axis. The rule follows the part, not the program's
rounding (docs/toolpaths.md, "Laps of an imported program"):

1. **Turning.** The tip's polar angle φ about the part's axis (the vertical line through the
   centre of the part's bounding box, the work z axis for an axisymmetric part) is unwrapped;
   the *travel* is Σ|Δφ|. ``T`` = travel / 2π turns, ``H`` = the z range of the points and
   ``D = H / T`` the mean z drop per turn (the step-down or the pitch).
2. **Levels.** The points are cut greedily into runs whose z range stays within a band; a run is
   a *level* when it turns through at least half a turn (:data:`LEVEL_TURN`) and has no trend
   (the least-squares z drop along the run is at most half its z range: a helix's run is all
   trend, a level's wiggle none). Points at either end of a run further from its median z than
   twice its 80th-percentile deviation (+ :data:`Z_TOL`) are a ramp's, not the level's. Two
   bands are tried: :data:`Z_TOL` (exact levels, 1 µm rounding) and then ``D / 4`` (levels whose
   z wiggles, by less than a quarter of the step). Neighbouring levels whose median z differ by
   less than half the band are one level (a level split by a glitch).
3. **z-level** when the levels of a band cover at least half of the travel: lap k is level k, and
   the points between two levels (a ramp, a plunge) belong to the level below; points after the
   last level to the last lap.
4. **Spiral** otherwise: a new lap starts at each full turn about the axis from the first point;
   the final stretch whose z stays within :data:`Z_TOL` (a closing contour) stays in the lap the
   descent ended in.

A path that turns less than once about the axis (a line, a test snippet) has no turns to count:
a level is then any run of two or more points at one z (to :data:`Z_TOL`), and it is a z-level
path if at least half of its segments keep their z.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LEVEL_TURN", "Z_TOL", "LapRule", "detect_laps"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Two points are on one z level within this [m] (the 1 µm resolution of programs).
Z_TOL = 1.5e-6
#: A level turns through at least this fraction of a turn about the part's axis.
LEVEL_TURN = 0.5
#: The wiggly-level band as a fraction of the mean z drop per turn.
_WIGGLE_BAND = 0.25


@dataclass(frozen=True)
class LapRule:
    """The laps of a path and how they were found.

    Attributes
    ----------
    lap : (N,) int — 0-based lap of every point, non-decreasing
    rule : ``"z-level"`` or ``"spiral"``
    turns : float — turns about the axis (travel / 2π)
    drop_per_turn : float, m — mean z drop per turn ``D``
    wiggle : float, m — the largest z range inside a level (0 for a spiral)
    axis_xy : (2,) float, m — the axis the turns are counted about
    """

    lap: I64
    rule: str
    turns: float
    drop_per_turn: float
    wiggle: float
    axis_xy: tuple[float, float]

    def describe(self) -> str:
        """One line for the import notes."""
        n = int(self.lap.max()) + 1 if self.lap.size else 0
        if self.rule == "spiral":
            return (
                f"laps: {n} turn(s) about the part's axis (x = {self.axis_xy[0] * 1e3:g} mm, "
                f"y = {self.axis_xy[1] * 1e3:g} mm; {self.turns:.2f} turns, "
                f"{self.drop_per_turn * 1e3:.4g} mm per turn)"
            )
        return (
            f"laps: {n} z level(s) ({self.turns:.2f} turns about the part's axis; z within "
            f"{self.wiggle * 1e6:.3g} µm in a level; ramps belong to the level below)"
        )


def _band_runs(z: F64, band: float) -> I64:
    """Boundaries ``[0, s1, …, n]`` of greedy runs whose z range stays ≤ ``band``."""
    zs = z.tolist()
    starts = [0]
    lo = hi = zs[0]
    for i in range(1, len(zs)):
        v = zs[i]
        if v < lo:
            lo = v
        elif v > hi:
            hi = v
        if hi - lo > band:
            starts.append(i)
            lo = hi = v
    starts.append(len(zs))
    return np.asarray(starts, dtype=np.int64)


def _levels(z: F64, travel: F64, band: float) -> list[tuple[int, int, float]]:
    """Levels ``(start, stop, median z)`` of ``z`` for ``band`` (module docstring, step 2)."""
    b = _band_runs(z, band)
    out: list[tuple[int, int, float]] = []
    for a, e in zip(b[:-1].tolist(), b[1:].tolist(), strict=True):
        if e - a < 2 or travel[e - 1] - travel[a] < LEVEL_TURN * 2 * math.pi:
            continue
        zr = z[a:e]
        m = float(np.median(zr))
        dev = np.abs(zr - m)
        w = 2.0 * float(np.percentile(dev, 80)) + Z_TOL
        inside = np.flatnonzero(dev <= w)
        a2, e2 = a + int(inside[0]), a + int(inside[-1]) + 1
        if travel[e2 - 1] - travel[a2] < LEVEL_TURN * 2 * math.pi:
            continue
        zr, tr = z[a2:e2], travel[a2:e2]
        rng = float(zr.max() - zr.min())
        if rng > Z_TOL:
            slope = np.polyfit(tr - tr[0], zr, 1)[0]
            if abs(slope * (tr[-1] - tr[0])) > 0.5 * rng:
                continue  # a stretch of a helix: all trend, no wiggle
        if out and abs(out[-1][2] - m) < 0.5 * band:
            out[-1] = (out[-1][0], e2, float(np.median(z[out[-1][0] : e2])))
        else:
            out.append((a2, e2, m))
    return out


def _level_laps(n: int, levels: list[tuple[int, int, float]]) -> I64:
    """Lap k on level k; the points between two levels to the level below; after the last, the
    last."""
    lap = np.empty(n, dtype=np.int64)
    prev = 0
    for k, (_a, e, _) in enumerate(levels):
        lap[prev:e] = k  # the ramp before level k, and level k
        prev = e
    lap[prev:] = len(levels) - 1
    return lap


def _short_path_laps(z: F64) -> tuple[I64, str]:
    """Laps of a path that turns less than once: exact runs of ≥ 2 points at one z."""
    n = len(z)
    flat = np.abs(np.diff(z)) <= Z_TOL
    if flat.size == 0 or flat.mean() < 0.5:
        return np.zeros(n, dtype=np.int64), "spiral"
    run = np.cumsum(np.concatenate([[True], ~flat])) - 1  # runs of one z
    real = np.bincount(run) > 1  # a run of one point is a ramp point
    if not real.any():
        return np.zeros(n, dtype=np.int64), "z-level"
    lap_of_run: I64 = np.cumsum(real) - real
    lap = np.minimum(lap_of_run[run], int(real.sum()) - 1)
    return lap.astype(np.int64), "z-level"


def detect_laps(tip: F64, axis_xy: tuple[float, float] = (0.0, 0.0)) -> LapRule:
    """Laps of the tip path ``tip`` (module docstring).

    Parameters
    ----------
    tip : (N, 3) float, m — the forming points in order, work frame
    axis_xy : (2,) float, m — the part's axis (x, y); the centre of its bounding box

    Returns
    -------
    LapRule
    """
    tip = np.asarray(tip, dtype=float)
    n = len(tip)
    axis = (float(axis_xy[0]), float(axis_xy[1]))
    if n <= 1:
        return LapRule(np.zeros(n, dtype=np.int64), "z-level", 0.0, 0.0, 0.0, axis)
    z = tip[:, 2]
    phi = np.unwrap(np.arctan2(tip[:, 1] - axis[1], tip[:, 0] - axis[0]))
    travel = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(phi)))])
    turns = float(travel[-1] / (2 * math.pi))
    H = float(z.max() - z.min())
    D = H / turns if turns > 0 else 0.0
    if turns < 1.0:
        lap, rule = _short_path_laps(z)
        return LapRule(lap, rule, turns, D, 0.0, axis)
    for band in (Z_TOL, max(Z_TOL, _WIGGLE_BAND * D)):
        levels = _levels(z, travel, band)
        cover = sum(float(travel[e - 1] - travel[a]) for a, e, _ in levels)
        if levels and cover >= 0.5 * travel[-1]:
            wig = max(float(np.ptp(z[a:e])) for a, e, _ in levels)
            return LapRule(_level_laps(n, levels), "z-level", turns, D, wig, axis)
    turned = np.abs(phi - phi[0]) / (2 * math.pi)
    lap = np.maximum.accumulate(np.floor(turned + 1e-6).astype(np.int64))
    # the closing stretch: the longest end of the path whose z stays within Z_TOL (not the last
    # segment that changes z by more than Z_TOL — a fine helix moves less than that per block)
    lo = np.minimum.accumulate(z[::-1])[::-1]
    hi = np.maximum.accumulate(z[::-1])[::-1]
    k = int(np.argmax(hi - lo <= Z_TOL))  # the stretch starts where the descent ends, at k
    lap[k:] = np.minimum(lap[k:], lap[max(k - 1, 0)])
    return LapRule(lap, "spiral", turns, D, 0.0, axis)
