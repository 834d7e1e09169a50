"""Alignment by position: the logged tool path (FK of a joint log) tracked along the toolpath.

The toolpath is a polyline of tip positions with arc length ``S`` (its ``path_length``). Each log
sample's tip ``P_k`` is projected on the polyline within a window that follows the tool: from a
little behind the progress so far to as far ahead as the *logged* tip has travelled since
(plus a margin). The progress ``s_k`` is then made monotone (running maximum), so the map can
stretch (a clock that runs fast, a feed override), stand still (a pause: the tool does not move)
and resume, but never jump back to an earlier lap that passes a step-down away. Samples farther
than :data:`OFF_PATH` from the path (approach, retract) do not move the progress. A tool that
leaves and comes back further on (a restart from a later line) is re-acquired at the nearest
toolpath point ahead.

The result is :class:`~roboisf.sync.Alignment`; its residual per point is the distance between
the logged tip at the point's passage time and the toolpath's tip [m].

Assumption: the window (≈ :data:`BLOCK` + :data:`MARGIN` of arc length) is shorter than a lap,
so a lap is never confused with the next one (laps of a few mm, at the very bottom of a dome,
would need a finer block).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf import jit
from roboisf.errors import InputError
from roboisf.sync import position_kernel as _kernel
from roboisf.sync.alignment import Alignment, clock_fit, point_windows
from roboisf.toolpath import Toolpath

__all__ = ["BLOCK", "MARGIN", "OFF_PATH", "POSITION_RESIDUAL_MAX", "align_by_position"]

F64 = NDArray[np.float64]

#: Arc length of logged travel [m] processed per block.
BLOCK = 8e-3
#: Slack of the search window [m] behind and ahead of the logged travel.
MARGIN = 2e-3
#: A logged tip farther than this from the toolpath [m] is off the path (approach, retract).
OFF_PATH = 5e-3
#: Largest accepted residual [m] at any toolpath point: the logged tip (commanded joints through
#: FK) follows the toolpath to interpolation error; 2 mm means another path or a wrong placement.
POSITION_RESIDUAL_MAX = 2e-3
#: Clock rates [log s per nominal s] of a time-unit slip (ms read as s: 1000; s read as ms:
#: 0.001), each with the logged tip speed [m/s] that only the slip explains: a forming tool
#: faster than 2 m/s, or slower than 0.1 mm/s along the whole path. A joint log whose times were
#: in s but declared ms was tracked as a tool passing the path 1000× fast; with the force log on
#: its clock every force then came from the first half-second of the log, and analyze ended
#: with a robot term of 808 mm and exit 0.
TIME_SLIP_SCALE = (300.0, 3000.0)
TIME_SLIP_FAST = 2.0
TIME_SLIP_SLOW = 1e-4
#: A tip within this of the first/last point [m] stands there (IK/FK round-off, no motion).
_END_TOL = 1e-5
#: Most samples per block (memory of the distance matrix; a long pause is cut into blocks).
_MAX_BLOCK_SAMPLES = 4096
#: Run the tracking loop compiled (:func:`roboisf.sync.position_kernel.track_blocks`) when numba
#: is installed; False runs the Python loop below over the compiled projection (the reference the
#: tests compare the compiled loop with, bit for bit).
_COMPILED_LOOP = True


def _project(P: F64, A: F64, D: F64, L2: F64, S0: F64, seglen: F64) -> tuple[F64, F64]:
    """Nearest point of segments (A + u D) to each of P: (progress s, distance) per sample."""
    if jit.ready("sync") and len(A) > 0:
        return _kernel.project_segments(np.ascontiguousarray(P, dtype=float), A, D, L2, S0, seglen)
    return _project_numpy(P, A, D, L2, S0, seglen)


def _project_numpy(P: F64, A: F64, D: F64, L2: F64, S0: F64, seglen: F64) -> tuple[F64, F64]:
    """The numpy path of :func:`_project`: the compiled kernel's operations in its order
    (``u = (r₀D₀ + r₁D₁ + r₂D₂) / |D|²`` clipped to [0, 1], ``d² = e₀² + e₁² + e₂²``, the first
    nearest segment), so its numbers are the kernel's bit for bit (tests/test_sync_kernel.py).
    One (samples × segments) array per coordinate: no (b, w, 3) temporaries (2.5× the einsum
    form it replaced on a first run's paper-cone joint log)."""
    rel = [P[:, c, None] - A[None, :, c] for c in range(3)]
    t = rel[0] * D[:, 0]
    t += rel[1] * D[:, 1]
    t += rel[2] * D[:, 2]
    u = t / np.where(L2 > 0, L2, 1.0)
    np.clip(u, 0.0, 1.0, out=u)
    d2 = np.zeros_like(u)
    for c in range(3):
        e = rel[c] - u * D[:, c]
        e *= e
        d2 += e
    j = np.argmin(d2, axis=1)
    b = np.arange(len(P))
    return S0[j] + u[b, j] * seglen[j], np.sqrt(d2[b, j])


def _travel(P: F64) -> F64:
    """The logged tip's travel so far [m] at each sample (M,): 0, then the running sum of
    ``|P[k+1] − P[k]|`` — ``np.linalg.norm(np.diff(P, axis=0), axis=1)``'s bits (the three
    squares summed x, y, z in that order) built column by column in the result, without its
    (M − 1, 3) difference and square arrays (a 573 k-sample joint log: ~3× faster)."""
    out = np.empty(P.shape[0])
    if out.size == 0:
        return out
    out[0] = 0.0
    seg = out[1:]
    d = np.subtract(P[1:, 0], P[:-1, 0])
    np.multiply(d, d, out=seg)
    for c in (1, 2):
        np.subtract(P[1:, c], P[:-1, c], out=d)
        d *= d
        seg += d
    np.sqrt(seg, out=seg)
    np.cumsum(seg, out=seg)
    return out


def _track(P: F64, tip: F64, S: F64, tol: float) -> F64:
    """Monotone progress [m along the tip path] per log sample; NaN where off the path."""
    from scipy.spatial import cKDTree

    A, D = tip[:-1], np.diff(tip, axis=0)
    seglen = np.linalg.norm(D, axis=1)
    L2 = seglen**2
    S0 = S[:-1]
    travel = _travel(P)
    tree = cKDTree(tip)
    spacing = float(np.median(seglen[seglen > 0])) if np.any(seglen > 0) else tol
    M = len(P)
    s = np.full(M, np.nan)
    s_prev = -np.inf  # not yet on the path
    last_on = 0
    k = 0
    compiled = _COMPILED_LOOP and jit.ready("sync") and len(A) > 0
    if compiled:
        P = np.ascontiguousarray(P, dtype=float)
    while k < M:
        if compiled:
            # the tracking loop below, compiled; it stops where the tool has to be re-acquired
            k, s_prev, last_on = _kernel.track_blocks(
                P, travel, A, D, L2, S0, seglen, tol, BLOCK, MARGIN, _MAX_BLOCK_SAMPLES, s, k,
                s_prev, last_on,
            )  # fmt: skip
            if k >= M:
                break
        k2 = int(np.searchsorted(travel, travel[k] + BLOCK, side="right"))
        k2 = max(k + 1, min(k2, k + _MAX_BLOCK_SAMPLES, M))
        blk = P[k:k2]
        hit = None
        if np.isfinite(s_prev) and not compiled:
            ahead = travel[k2 - 1] - travel[last_on] + MARGIN
            j0 = max(int(np.searchsorted(S0, s_prev - MARGIN, side="right")) - 1, 0)
            j1 = min(int(np.searchsorted(S0, s_prev + ahead, side="right")), len(S0))
            j1 = max(j1, j0 + 1)
            sl = slice(j0, j1)
            sb, db = _project(blk, A[sl], D[sl], L2[sl], S0[sl], seglen[sl])
            if np.any(db <= tol):
                hit = (sb, db)
        if hit is None:
            # (re-)acquire: the nearest toolpath point ahead of the progress so far
            dist, idx = tree.query(blk, k=8, distance_upper_bound=tol + spacing)
            ok = np.isfinite(dist) & (S[np.minimum(idx, len(S) - 1)] >= max(s_prev, S[0]) - MARGIN)
            rows = np.flatnonzero(ok.any(axis=1))
            if rows.size == 0:
                k = k2  # off the path (approach, retract): progress unchanged
                continue
            r = int(rows[0])
            i0 = int(np.min(idx[r][ok[r]]))
            j0 = max(i0 - 2, 0)
            j1 = min(i0 + 2, len(S0))
            sb, db = _project(
                blk[r : r + 1], A[j0:j1], D[j0:j1], L2[j0:j1], S0[j0:j1], seglen[j0:j1]
            )
            if db[0] > tol:
                k = k2
                continue
            s[k + r] = sb[0]
            s_prev = float(sb[0]) if not np.isfinite(s_prev) else max(s_prev, float(sb[0]))
            last_on = k + r
            k = k + r + 1
            continue
        sb, db = hit
        on = db <= tol
        idx_on = np.flatnonzero(on)
        mono = np.maximum.accumulate(np.concatenate([[s_prev], sb[on]]))[1:]
        s[k + idx_on] = mono
        s_prev = float(mono[-1])
        last_on = k + int(idx_on[-1])
        k = k2
    return s


def _sharpen_ends(ts: F64, ss: F64, S: F64) -> tuple[F64, F64]:
    """Departure from the first point and arrival at the last one at the speed of the samples
    next to them (a linear map between a moving and a standing sample would put the arrival
    up to one sample late). ``ts`` and ``ss`` are not changed: a moved end is a new array."""
    k = int(np.searchsorted(ss, S[-1], side="left"))  # first sample at the end
    if 2 <= k < len(ss) and ss[k - 1] > ss[k - 2]:
        v = (ss[k - 1] - ss[k - 2]) / (ts[k - 1] - ts[k - 2])
        t_end = min(ts[k - 1] + (S[-1] - ss[k - 1]) / v, ts[k])
        ts = np.concatenate([ts[:k], [t_end], ts[k:]])
        ss = np.concatenate([ss[:k], [S[-1]], ss[k:]])
    k = int(np.searchsorted(ss, S[0], side="right"))  # first sample past the start
    if k == 1 and len(ss) > 2 and ss[2] > ss[1] > ss[0]:
        v = (ss[2] - ss[1]) / (ts[2] - ts[1])
        t_dep = max(ts[1] - (ss[1] - S[0]) / v, ts[0])
        ts = np.concatenate([[t_dep], ts[1:]])
    return ts, ss


def _check_time_unit(scale: float, toolpath: Toolpath, file: Path | None) -> None:
    """Refuse a clock ``scale`` (log s per nominal s, :func:`clock_fit`) that is a time unit
    slip of the log (:data:`TIME_SLIP_SCALE`) at a logged tip speed no forming run has."""
    span = float(toolpath.time[-1] - toolpath.time[0])
    length = float(toolpath.path_length[-1] - toolpath.path_length[0])
    if not (span > 0 and length > 0 and scale > 0):
        return
    v = length / (scale * span)  # m/s — the logged tip's mean speed outside pauses
    lo, hi = TIME_SLIP_SCALE
    if 1 / hi <= scale <= 1 / lo and v > TIME_SLIP_FAST:
        unit, fix, how = "s", "s", f"{1 / scale:.0f}× faster than"
    elif lo <= scale <= hi and v < TIME_SLIP_SLOW:
        unit, fix, how = "ms", "ms", f"{scale:.0f}× slower than"
    else:
        return
    read = "ms" if unit == "s" else "s"
    raise InputError(
        f"the logged tool tip passes the toolpath {how} its programmed feed (the path's "
        f"{span:.4g} s in {scale * span:.4g} s of log, {v * 1e3:.3g} mm/s): the log's time is "
        f"likely in {unit} read as {read}; declare time={fix} in its '# units:' line or header "
        f'(or units = {{time = "{fix}"}} in study.toml)',
        file=file,
        field="time",
    )


def align_by_position(
    log_time: ArrayLike,
    tip_log: ArrayLike,
    toolpath: Toolpath,
    *,
    file: Path | None = None,
    tol: float = OFF_PATH,
    residual_max: float = POSITION_RESIDUAL_MAX,
) -> Alignment:
    """Map a log of tool-tip positions onto the toolpath by position, monotonically.

    Parameters
    ----------
    log_time : (M,) float, s — the log's own clock, strictly increasing
    tip_log : (M, 3) float, m — logged tool tip in the work frame (FK of the logged joints with
        the study's robot, placement and tool)
    toolpath : the toolpath the run followed
    file : the log (for messages)
    tol : m — a sample farther from the path is off it (:data:`OFF_PATH`)
    residual_max : m — refuse when any toolpath point's residual exceeds this

    Returns
    -------
    Alignment
        ``method = "position"``, residual in m per point.

    Raises
    ------
    InputError
        the logged tip never comes near the toolpath, reaches only part of it (naming the last
        point reached), or passes a point farther than ``residual_max`` from it; a log whose
        clock runs ~1000× off the toolpath's at a tip speed no forming run has (its time unit
        slipped: s read as ms, or ms as s).
    """
    tau = np.asarray(log_time, dtype=float)
    P = np.asarray(tip_log, dtype=float)
    if P.shape != (tau.size, 3) or tau.size < 2:
        raise InputError(f"expected (M, 3) positions for M ≥ 2 log times, got {P.shape}", file=file)
    S = np.asarray(toolpath.path_length, dtype=float)
    tip = toolpath.tip
    if len(toolpath) < 2:
        raise InputError("alignment by position needs a toolpath of ≥ 2 points", file=file)
    s = _track(P, tip, S, tol)
    on = np.isfinite(s)
    if not np.any(on):
        d = float(
            np.min(
                np.linalg.norm(
                    P[:: max(1, P.shape[0] // 2000), None] - tip[None, :: max(1, len(tip) // 2000)],
                    axis=2,
                )
            )
        )
        raise InputError(
            "the logged tool tip (the robot's forward kinematics at the logged joint angles) "
            f"never comes within {tol * 1e3:g} mm of the toolpath (nearest {d * 1e3:.3g} mm): "
            "a joint log of another path, or a wrong [robot] placement, flange_to_tip or angle "
            "unit",
            file=file,
        )
    ts, ss = tau[on], s[on]
    reach_tol = min(tol, 0.5 * float(np.median(np.diff(S))) + 1e-4)
    if ss[0] > S[0] + reach_tol:
        i = int(np.searchsorted(S, ss[0]))
        raise InputError(
            f"the joint log starts with the tool at toolpath point {i} of {len(S)} "
            f"({ss[0] * 1e3:.1f} mm along the path): the log does not cover the start",
            file=file,
        )
    if ss[-1] < S[-1] - reach_tol:
        i = int(np.searchsorted(S, ss[-1]))
        raise InputError(
            f"the logged tool tip follows the toolpath only to point {i} of {len(S)} "
            f"({ss[-1] * 1e3:.1f} of {S[-1] * 1e3:.1f} mm): the log stops half-way, or leaves "
            "the path (farther than "
            f"{tol * 1e3:g} mm) and does not come back",
            file=file,
        )
    # the map must reach the ends exactly (the projection stops within a few µm of them)
    ss = np.clip(ss, S[0], S[-1])
    # a tool standing at the first point before the program starts (out of contact) has not
    # passed it yet: the passage is the departure, the last sample at the start
    at_start = np.flatnonzero(ss <= S[0] + _END_TOL)
    if at_start.size > 1 and at_start[-1] == at_start.size - 1:
        ts, ss = ts[at_start[-1] :], ss[at_start[-1] :]
    ss[ss >= S[-1] - _END_TOL] = S[-1]  # standing at the end (IK/FK round-off)
    ss[-1] = max(ss[-1], S[-1])
    ss[0] = min(ss[0], S[0])
    ts, ss = _sharpen_ends(ts, ss, S)
    t_pt, lo, hi = point_windows(ts, ss, S)
    P_pt = np.column_stack([np.interp(t_pt, tau, P[:, j]) for j in range(3)])
    res = np.linalg.norm(P_pt - tip, axis=1)
    if float(res.max()) > residual_max:
        i = int(np.argmax(res))
        raise InputError(
            f"position alignment failed: at toolpath point {i} the logged tool tip is "
            f"{res[i] * 1e3:.3g} mm from the toolpath (limit {residual_max * 1e3:g} mm): the "
            "log does not follow this path (wrong placement or tool, or a path that crosses "
            "itself)",
            file=file,
        )
    scale, offset, pauses = clock_fit(toolpath.time, t_pt)
    _check_time_unit(scale, toolpath, file)
    return Alignment(
        "position",
        t_pt,
        lo,
        hi,
        res,
        "mm",
        scale,
        offset,
        pauses,
        str(file) if file is not None else "",
    )
