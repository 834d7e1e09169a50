"""Alignment by the force signature, for a run without a joint log.

A ball tool pressing a wall is pushed back along the wall's normal (plus a friction/feed share
along the path): in the work frame the *horizontal* direction of the forming force turns with
the tool around the part, one turn per lap. Its unwrapped azimuth ``φ(τ)`` is therefore a
progress variable of the log, like arc length, and the toolpath's own normals give the
expected one, ``Φ_i`` (unwrapped azimuth of the horizontal normal). The map is

1. contact: |F| (smoothed over half a toolpath point) above a quarter of its 90th percentile;
   onset = the toolpath's first point, release = its last;
2. ``ψ(τ) = φ(τ) − b``, the constant ``b`` (which side the load is on, the friction share)
   where the expected direction is surest (:func:`_bias_window`: the middle of the last flat
   side, else the end of the last stretch on a wall — not a flat floor the path ends on);
3. ``ψ`` made monotone (mean of its running maximum and its reversed running minimum);
4. each toolpath point's passage = the first time ``ψ`` reaches ``Φ_i``, at anchors: points
   where the azimuth turns (both neighbours differ by more than :data:`TURN_MIN`), at least a
   margin (four times the direction's scatter) from every flat side's azimuth and passed in
   contact (:func:`_anchors`); the other points are interpolated in nominal time between
   anchors, and those before the first anchor extrapolated on the first anchors' clock line.

Pauses show as a standing azimuth and are recovered wherever the path turns; a pause on a flat
wall of a pyramid is not observable (it is spread over the wall). The residual per point is the
scatter of the raw azimuth about the monotone map over the point's window, in equivalent
toolpath points (``"points"``). The map fails, with :class:`~roboisf.errors.InputError`, for a
path that does not turn around the part at least half a turn, a log in contact from its first
sample (no onset), a force direction running backwards, or a log that turns a different number
of laps than the toolpath.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.logs.forcelog import row_norms, window_average
from roboisf.sync.alignment import Alignment, clock_fit, first_passage
from roboisf.toolpath import Toolpath

__all__ = [
    "ANCHOR_MARGIN_MIN",
    "BACKWARD_MAX",
    "BIAS_RUN",
    "FORCE_RESIDUAL_MAX",
    "RELEASE_FRACTION",
    "TURN_MIN",
    "align_by_force",
    "expected_azimuth",
]

F64 = NDArray[np.float64]

#: Azimuth change [rad] between neighbouring toolpath points below which a point does not
#: anchor the map (flat wall, vertical step-down).
TURN_MIN = 1e-3
#: Smallest distance [rad] from a plateau's azimuth (flat wall, step-down) at which a turning
#: point anchors the map (:func:`_anchors`; the measured scatter raises it).
ANCHOR_MARGIN_MIN = 0.01
#: Contact ends where the force falls below this fraction of its 90th percentile (and five
#: times the log's rest), after its last sample above a quarter of it (:func:`_lighter_end`).
RELEASE_FRACTION = 0.05
#: Consecutive wall points that make the stretch the force direction's bias is read at.
BIAS_RUN = 5
#: Largest backward swing of the force azimuth [rad] accepted as noise.
BACKWARD_MAX = 0.3
#: Largest accepted RMS residual [equivalent toolpath points] of a force alignment.
FORCE_RESIDUAL_MAX = 3.0


def _smooth(x: F64, w: int) -> F64:
    if w <= 1:
        return x
    from scipy.ndimage import uniform_filter1d

    return np.asarray(uniform_filter1d(x, size=w, axis=0, mode="nearest"), dtype=float)


def _anchors(phi: F64, margin: float) -> NDArray[np.bool_]:
    """The entries of ``phi`` (non-decreasing expected azimuth) whose passage the force's own
    azimuth can time: where the path turns (both neighbours differ by more than
    :data:`TURN_MIN`) and at least ``margin`` [rad] away from the azimuth of every point where
    it does not (a flat wall, a step-down: a plateau of ``phi``).

    Near a plateau the first passage is ill-posed: along a flat wall the measured azimuth
    scatters about the wall's, and a corner's first points lie a hair above it — noise reaches
    them anywhere along the wall, up to a side of the part early (a pyramid's laps slipped by
    quarter turns so, and the clock fit turned them into dozens of pauses). Inside a turn the
    azimuth sweeps through at the tool's speed and the passage is sharp."""
    n = len(phi)
    d = np.diff(phi)
    turn = np.zeros(n, dtype=bool)
    turn[1:-1] = (d[:-1] > TURN_MIN) & (d[1:] > TURN_MIN)
    flat = d <= TURN_MIN  # segments that do not turn: both their ends lie on a plateau
    plateau = np.zeros(n, dtype=bool)
    plateau[:-1] |= flat
    plateau[1:] |= flat
    idx = np.arange(n)
    before = np.maximum.accumulate(np.where(plateau, idx, -1))  # last plateau point ≤ i
    after = np.minimum.accumulate(np.where(plateau, idx, n)[::-1])[::-1]  # first ≥ i
    low = np.where(before >= 0, phi[np.maximum(before, 0)], -np.inf)
    high = np.where(after < n, phi[np.minimum(after, n - 1)], np.inf)
    return turn & (phi - low > margin) & (high - phi > margin)


def _passages(
    tau: F64, psi: F64, t_nom: F64, phi: F64, margin: float, gap: float
) -> tuple[F64, NDArray[np.bool_]]:
    """Passage time of each entry of ``phi`` (non-decreasing), anchors inside its turns
    (:func:`_anchors`), the rest interpolated in nominal time between them (and the first and
    last entries at the first and last samples); and which entries are such anchors."""
    n = len(phi)
    anchor = _anchors(phi, margin)
    anchor[0] = anchor[-1] = False  # the onset and the release: timed, but not by a turn
    # a turn passed while the tool was off the sheet (a gap in the contact samples longer
    # than ``gap``: along a flat bottom the force drops to nothing) is not timed by it
    k = np.clip(np.searchsorted(psi, phi[anchor], side="left"), 1, len(psi) - 1)
    anchor[np.flatnonzero(anchor)[tau[k] - tau[k - 1] > gap]] = False
    turn = anchor.copy()
    turn[0] = turn[-1] = True
    out = np.empty(n)
    out[turn] = first_passage(tau, psi, np.clip(phi[turn], psi[0], psi[-1]))
    out[0], out[-1] = tau[0], tau[-1]
    out[~turn] = np.interp(t_nom[~turn], t_nom[turn], out[turn])
    return np.maximum.accumulate(out), anchor


def _margin(psi: F64, w: int) -> float:
    """How far [rad] from a plateau's azimuth a passage can be timed: four times the measured
    azimuth's scatter (robust, from its changes over one smoothing window ``w`` samples, the
    turning itself taken out by the median), at least :data:`ANCHOR_MARGIN_MIN`."""
    lag = max(1, w)
    if psi.size <= lag + 1:
        return ANCHOR_MARGIN_MIN
    dpsi = psi[lag:] - psi[:-lag]
    sigma = 1.4826 * float(np.median(np.abs(dpsi - np.median(dpsi)))) / math.sqrt(2)
    return max(ANCHOR_MARGIN_MIN, 4.0 * sigma)


def _bias_window(toolpath: Toolpath, Phi: F64, span: float) -> tuple[float, float]:
    """Nominal toolpath times [s] between which the force direction's bias is read.

    Where the path has a flat wall (a plateau of ``Phi``: a pyramid's side), the middle half of
    its last stretch of at least ``2 BIAS_RUN`` points on a wall: the expected direction is
    constant there, so the log's clock rate, unknown yet, cannot move the window off it (read
    from the release backwards, a 1 % clock over the last lap is a quarter second — across a
    corner, a wrong bias). Else (a cone turns everywhere) ``span`` before the end of the last
    run of :data:`BIAS_RUN` wall points (horizontal normal ≥ 0.5: the forming force's
    horizontal direction is the wall's): the release itself when the path ends on a wall, as
    a cone's does — not the floor of a path that ends along a flat bottom."""
    t = toolpath.time
    n = t.size
    wall = np.linalg.norm(toolpath.normal[:, :2], axis=1) >= 0.5
    still = (np.abs(np.diff(Phi)) <= TURN_MIN) & wall[1:] & wall[:-1]  # (n − 1,) segments
    # runs of still segments: [start, stop) in segment indices
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    long = np.flatnonzero(stops - starts >= 2 * BIAS_RUN - 1)  # ≥ 2 BIAS_RUN points
    if long.size:
        a, b = float(t[starts[long[-1]]]), float(t[stops[long[-1]]])
        return a + 0.25 * (b - a), b - 0.25 * (b - a)
    if n >= BIAS_RUN:
        full = np.convolve(wall.astype(np.int64), np.ones(BIAS_RUN, dtype=np.int64), "valid")
        ends = np.flatnonzero(full == BIAS_RUN) + BIAS_RUN - 1
        if ends.size:
            return float(t[ends[-1]]) - span, float(t[ends[-1]])
    return float(t[-1]) - span, float(t[-1])


def _lighter_end(mag: F64, raw_mag: F64, r1: int, ref: float) -> tuple[int, float]:
    """The last sample of contact and the force level it ends at [N], from ``r1`` (the last
    raw sample above a quarter of the run's force): carried on while the smoothed force
    ``mag`` stays above :data:`RELEASE_FRACTION` of ``ref`` and five times the log's rest (the
    median magnitude of the last half of what follows ``r1``), to the last raw sample above
    that level. A path whose last laps press lighter (the VWACF's small bottom circles: 500 →
    200 → 80 → 30 N over its last 1.4 s) was released at the quarter, 0.8 s — one and a half
    of those laps — early, and its whole map slipped by two turns."""
    n = mag.size
    tail = raw_mag[r1 + 1 + (n - r1 - 1) // 2 :]
    if tail.size < 10:
        return r1, 0.25 * ref
    low = max(RELEASE_FRACTION * ref, 5.0 * float(np.median(tail)))
    below = np.flatnonzero(mag[r1 + 1 :] <= low)
    stop = r1 + 1 + int(below[0]) if below.size else n  # the smoothed force's end of contact
    above = np.flatnonzero(raw_mag[r1:stop] > low)
    return (r1 + int(above[-1]) if above.size else r1), low


def expected_azimuth(toolpath: Toolpath, *, file: Path | None = None) -> tuple[F64, float]:
    """The toolpath's expected force azimuth per point, unwrapped, non-decreasing [rad], and the
    sense it turns (+1 counter-clockwise seen from above, −1 clockwise).

    Raises
    ------
    InputError
        when force alignment cannot work on this toolpath: nearly flat, turning less than half a
        turn, turning back, ending on a flat bottom.
    """
    n = len(toolpath)
    hn = toolpath.normal[:, :2]
    if n < 3 or float(np.median(np.linalg.norm(hn, axis=1))) < 0.05:
        raise InputError(
            "alignment by force needs walls (the horizontal force direction turns with the "
            'tool); this toolpath is nearly flat — use sync = "time" or a joint log',
            file=file,
            field="sync",
        )
    flat = np.linalg.norm(hn, axis=1) < 0.05  # a flat bottom: no horizontal direction
    if flat[-1]:
        raise InputError(
            "the toolpath ends on a flat bottom, where the forming force has no horizontal "
            "direction to time the end of the run by: alignment by force cannot anchor it; use "
            'sync = "position" (a joint log) or "time"',
            file=file,
            field="sync",
        )
    walls = np.flatnonzero(~flat)
    Phi = np.empty(n)
    Phi[walls] = np.unwrap(np.arctan2(hn[walls, 1], hn[walls, 0]))
    # flat points take the direction of the wall point before them (they do not turn)
    fill = np.maximum.accumulate(np.where(~flat, np.arange(n), walls[0]))
    Phi = Phi[fill]
    turns = (Phi[-1] - Phi[0]) / (2 * math.pi)
    if abs(turns) < 0.5:
        raise InputError(
            f"alignment by force needs a toolpath that turns around the part (this one turns "
            f'{turns:.2f} times): use sync = "time" or "position"',
            file=file,
            field="sync",
        )
    sign = 1.0 if turns > 0 else -1.0
    Phi = sign * Phi
    back_tp = np.maximum.accumulate(Phi) - Phi
    if float(np.max(back_tp)) > BACKWARD_MAX:
        i = int(np.argmax(back_tp > BACKWARD_MAX))
        raise InputError(
            "alignment by force needs a toolpath that turns one way around the part (this one "
            f"turns back at point {i}, lap {int(toolpath.lap[i])}, e.g. a lap run the other way): "
            'use sync = "position" (a joint log) or "time"',
            file=file,
            field="sync",
        )
    Phi = np.maximum.accumulate(Phi)
    return Phi, sign


def align_by_force(
    log_time: ArrayLike,
    force_work: ArrayLike,
    toolpath: Toolpath,
    *,
    file: Path | None = None,
    residual_max: float = FORCE_RESIDUAL_MAX,
) -> Alignment:
    """Map a force log onto the toolpath by the turning of the forming force, monotonically.

    Parameters
    ----------
    log_time : (M,) float, s — the log's clock, strictly increasing
    force_work : (M, 3) float, N — the force in **work axes** (the sensor's pose applied; its
        sign does not matter)
    toolpath : the toolpath the run followed (its normals give the expected direction)
    file : the log (for messages)
    residual_max : equivalent toolpath points — refuse above this RMS residual

    Returns
    -------
    Alignment
        ``method = "force"``, residual in equivalent toolpath points.
    """
    tau = np.asarray(log_time, dtype=float)
    F = np.asarray(force_work, dtype=float)
    if F.shape != (tau.size, 3) or tau.size < 10:
        raise InputError(f"expected (M, 3) forces for M ≥ 10 log times, got {F.shape}", file=file)
    n = len(toolpath)
    Phi, sign = expected_azimuth(toolpath, file=file)

    dt_log = float(np.median(np.diff(tau)))
    dt_pt = float(np.median(np.diff(toolpath.time)))
    w = max(1, round(0.5 * dt_pt / dt_log))
    Fs = _smooth(F, w)
    # |F| per sample in one pass, the bits of np.linalg.norm(…, axis=1) without its (M, 3)
    # temporaries (a 1 kHz log of the paper cone: 2.3 M samples, 55 MB each)
    mag = row_norms(Fs)
    ref = float(np.percentile(mag, 90))
    contact = mag > 0.25 * ref
    if not np.any(contact) or ref <= 0:
        raise InputError("the force log holds no forming force", file=file, field="Fz")
    i0, i1 = int(np.argmax(contact)), int(len(contact) - 1 - np.argmax(contact[::-1]))
    if i0 == 0:
        raise InputError(
            "the force log is in contact from its first sample: alignment by force needs the "
            "onset of contact (start the log before the tool touches the sheet)",
            file=file,
            field="time",
        )
    if i1 == len(contact) - 1:
        raise InputError(
            "the force log is in contact at its last sample: alignment by force needs the "
            "release at the end of the toolpath (stop the log after the tool lifts off)",
            file=file,
            field="time",
        )
    # the release from the raw magnitude (smoothing spreads the lift-off over its window)
    raw_mag = row_norms(F)
    raw = raw_mag > 0.25 * ref
    r1 = int(len(raw) - 1 - np.argmax(raw[::-1]))
    r_strict = r1
    r1, low = _lighter_end(mag, raw_mag, r1, ref)
    if r1 > r_strict:  # the lighter last laps are contact too (their direction is read)
        contact[r_strict : r1 + 1] |= mag[r_strict : r1 + 1] > low
        i1 = max(i1, r1)
    t_rel = float(tau[r1]) + 0.5 * dt_log
    sel = np.arange(i0, i1 + 1)
    sel = sel[contact[sel] & (tau[i0 : i1 + 1] <= t_rel)]
    tc = tau[sel]
    phi = sign * np.unwrap(np.arctan2(Fs[sel, 1], Fs[sel, 0]))
    # the bias, from the contact where the expected direction is surest (_bias_window: a flat
    # wall's middle, else the end of the last stretch on a wall — the release on a cone),
    # on the raw forces (a smoothed direction lags where the tool turns fastest): the tool
    # presses hardest at the end, while the first laps may carry too little force to read. A
    # path that ends along a flat bottom (a pyramid's last lap at its floor) has no wall
    # direction there: the bias taken there was off by ~0.4 rad and slipped the early laps'
    # corners by quarter turns.
    t_end = float(toolpath.time[-1])
    span = max(dt_pt, 3 * dt_log)
    b_lo, b_hi = (t_rel - (t_end - v) for v in _bias_window(toolpath, Phi, span))  # log time
    win = (tau[: r1 + 1] >= b_lo) & (tau[: r1 + 1] <= b_hi)
    if not np.any(win):  # no sample that close (a log slower than the toolpath)
        win = tau[: r1 + 1] >= t_rel - span
    t_win = tau[: r1 + 1][win]
    az = sign * np.arctan2(F[: r1 + 1][win, 1], F[: r1 + 1][win, 0])
    expect = np.interp(t_win - t_rel + t_end, toolpath.time, Phi)
    b = float(np.angle(np.mean(np.exp(1j * (az - expect)))))
    last = (tc >= t_win[0]) & (tc <= t_win[-1])
    if not np.any(last):
        last = tc >= t_rel - span
    ref_b = float(np.mean(phi[last] - np.interp(tc[last] - t_rel + t_end, toolpath.time, Phi)))
    b += 2 * math.pi * round((ref_b - b) / (2 * math.pi))
    psi = phi - b
    back = float(np.max(np.maximum.accumulate(psi) - psi))
    if back > BACKWARD_MAX:
        k = int(np.argmax(np.maximum.accumulate(psi) - psi))
        raise InputError(
            f"the force direction runs backwards by {math.degrees(back):.0f}° at log time "
            f"{tc[k]:.2f} s: not a log of this toolpath (or of a path run in reverse)",
            file=file,
        )
    mono = 0.5 * (np.maximum.accumulate(psi) + np.minimum.accumulate(psi[::-1])[::-1])
    if mono[0] < Phi[0] - 0.5 * math.pi:
        raise InputError(
            f"the force log's direction turns {(mono[-1] - mono[0]) / (2 * math.pi):.2f} times "
            f"but the toolpath only {(Phi[-1] - Phi[0]) / (2 * math.pi):.2f}: a log of another "
            "path",
            file=file,
        )
    mono = np.clip(mono, Phi[0], Phi[-1])
    # the last point is passed at the release
    tc = np.append(tc, max(t_rel, float(tc[-1]) + 1e-9))
    mono = np.append(mono, Phi[-1])
    psi = np.append(psi, Phi[-1])
    # points and the half-way marks between them, in one pass
    t2 = np.empty(2 * n - 1)
    t2[0::2] = toolpath.time
    t2[1::2] = 0.5 * (toolpath.time[1:] + toolpath.time[:-1])
    P2 = np.empty(2 * n - 1)
    P2[0::2] = Phi
    P2[1::2] = 0.5 * (Phi[1:] + Phi[:-1])
    seen = P2 >= mono[0]  # before the force onset the direction is not readable
    tau2 = np.empty(2 * n - 1)
    anchored = np.zeros(2 * n - 1, dtype=bool)
    tau2[seen], anchored[seen] = _passages(tc, mono, t2[seen], P2[seen], _margin(psi, w), span)
    anchors = np.flatnonzero(anchored)
    if anchors.size == 0:
        raise InputError(
            "the force direction turns nowhere the map can time (every turn of the path is "
            "within the force direction's scatter of a flat wall): use a joint log "
            '(sync = "position") or sync = "time"',
            file=file,
        )
    # before the first anchor — the points before the force is readable, and those between the
    # onset and the first turn (on a flat wall they were all put at the onset's time): the
    # clock line through the first anchors (up to 100 points on, at least 10 anchors)
    first = int(anchors[0])
    near = anchors[anchors <= first + 200]
    fit = near if near.size >= 10 else anchors[:10]
    if fit.size >= 2 and float(np.ptp(t2[fit])) > 0:
        scale, icpt = (float(v) for v in np.polyfit(t2[fit], tau2[fit], 1))
        tau2[:first] = np.minimum(icpt + scale * t2[:first], tau2[first])
    else:
        tau2[:first] = tau2[first] - (t2[first] - t2[:first])
    seen[:first] = False
    t_pt, mid = tau2[0::2], tau2[1::2]
    lo = np.concatenate([t_pt[:1], mid])
    hi = np.concatenate([mid, t_pt[-1:]])
    n_unseen = int(np.sum(~seen[0::2]))
    if n_unseen > n // 2:
        raise InputError(
            f"the force direction is readable only over the last {n - n_unseen} of {n} toolpath "
            "points: a log that stops half-way, or of another path",
            file=file,
        )
    # residual: the raw azimuth about the map, in toolpath points (per-point turn as the unit)
    step = np.gradient(Phi)
    unit = np.maximum(
        step, float(np.median(step[step > TURN_MIN])) if np.any(step > TURN_MIN) else 1.0
    )
    at = np.clip(np.searchsorted(Phi, mono), 0, n - 1)
    r2 = ((psi - mono) / unit[at]) ** 2
    res = np.sqrt(
        window_average(tc, r2[:, None], np.clip(lo, tc[0], tc[-1]), np.clip(hi, tc[0], tc[-1]))[
            :, 0
        ]
    )
    res[~seen[0::2]] = np.nan
    rms = float(np.sqrt(np.nanmean(res**2)))
    if rms > residual_max:
        raise InputError(
            f"force alignment failed: the force direction scatters {rms:.2g} toolpath points "
            f"(RMS) about the map (limit {residual_max:g}): too noisy, or not this toolpath; "
            'use a joint log (sync = "position")',
            file=file,
        )
    scale, offset, pauses = clock_fit(toolpath.time, t_pt)
    notes = []
    if n_unseen:
        notes.append(
            f"the first {n_unseen} toolpath points come before the first turn the force "
            "direction times (too little force to read it, or a flat side before the first "
            "corner): timed back from the first timed ones at their clock rate; a pause among "
            "them is not seen"
        )
    flat = int(np.sum(np.abs(np.diff(Phi)) <= TURN_MIN))
    if flat:
        notes.append(
            f"{flat} toolpath segment(s) do not turn (flat wall, step-down): their timing is "
            "interpolated, and a pause there is not observable"
        )
    return Alignment(
        "force",
        t_pt,
        lo,
        hi,
        res,
        "points",
        scale,
        offset,
        pauses,
        str(file) if file is not None else "",
        notes,
    )
