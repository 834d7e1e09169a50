"""Force logs: time series of a measured wrench (6-axis F/T sensor, dynamometer), and how to
attach them to toolpath points.

File format (CSV)::

    # units: time=s force=N moment=N*m     ← required here or as read_force_log(...) arguments
    # frame: sensor                        ← the frame the wrench is expressed in (required)
    time,Fx,Fy,Fz,Mx,My,Mz
    0.000,1.2,-0.4,-310.5,0.01,0.02,0.0
    ...

Optional columns ``x,y,z`` give the tool-tip position at each sample (work frame, ``length=``
unit in the units line), used by :func:`attach_to_toolpath` ``by="position"``. Time must
strictly increase. Units accepted: time ``s ms min``; force ``N kN``; moment ``N*m Nm N.m N*mm
Nmm``; length ``m mm um cm in`` (see :mod:`roboisf.io.units`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.io.table import format_rows, read_table
from roboisf.io.units import to_si
from roboisf.toolpath.toolpath import Toolpath

__all__ = [
    "FORCE_COLUMNS",
    "ForceLog",
    "attach_to_toolpath",
    "read_force_log",
    "window_average",
    "write_force_log",
]

F64 = NDArray[np.float64]

FORCE_COLUMNS = ("time", "Fx", "Fy", "Fz", "Mx", "My", "Mz")
POSITION_COLUMNS = ("x", "y", "z")


@dataclass(frozen=True)
class ForceLog:
    """A measured wrench time series (SI).

    Attributes
    ----------
    time : (N,) float, s — strictly increasing
    wrench : (N, 6) float — [Fx, Fy, Fz, Mx, My, Mz] in N and N·m, expressed in ``frame``
    frame : str — name of the frame the wrench is expressed in (e.g. "sensor", "dynamometer")
    path : Path | None — the file it was read from
    position : (N, 3) float, m, optional — tool-tip position per sample (work frame)
    """

    time: F64
    wrench: F64
    frame: str
    path: Path | None = None
    position: F64 | None = None

    def __post_init__(self) -> None:
        t = np.asarray(self.time, dtype=float)
        w = np.asarray(self.wrench, dtype=float)
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "wrench", w)
        n = t.shape[0] if t.ndim == 1 else -1
        if t.ndim != 1 or n < 1:
            raise InputError(f"time must have shape (N,), got {t.shape}", field="time")
        if w.shape != (n, 6):
            raise InputError(f"wrench must have shape ({n}, 6), got {w.shape}", field="wrench")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(w))):
            raise InputError("time and wrench must be finite", field="wrench")
        if n > 1 and np.any(np.diff(t) <= 0):
            i = int(np.argmax(np.diff(t) <= 0)) + 1
            raise InputError(f"time must strictly increase (sample {i})", field="time")
        if not self.frame or not isinstance(self.frame, str):
            raise InputError("frame must be a non-empty name", field="frame")
        if self.position is not None:
            p = np.asarray(self.position, dtype=float)
            if p.shape != (n, 3):
                raise InputError(
                    f"position must have shape ({n}, 3), got {p.shape}", field="position"
                )
            object.__setattr__(self, "position", p)

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def force(self) -> F64:
        """(N, 3) N."""
        return self.wrench[:, :3]

    @property
    def moment(self) -> F64:
        """(N, 3) N·m."""
        return self.wrench[:, 3:]


def _parse_units(text: str, *, file: Path, line: int | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in text.split():
        if "=" not in item:
            raise InputError(
                f"units must read 'time=s force=N moment=N*m', got item {item!r}",
                file=file,
                line=line,
                field="units",
            )
        k, v = item.split("=", 1)
        k = k.strip().lower()
        if k not in ("time", "force", "moment", "length"):
            raise InputError(
                f"unknown quantity {k!r} in units; expected time, force, moment, length",
                file=file,
                line=line,
                field="units",
            )
        out[k] = v.strip()
    return out


def _meta_line(path: Path, key: str) -> int | None:
    """1-based line of the ``# key:`` metadata line (for messages)."""
    with open(path, encoding="utf-8-sig") as fh:
        for i, ln in enumerate(fh, start=1):
            s = ln.strip()
            if s and not s.startswith("#"):
                return None
            if s.lstrip("#").strip().lower().startswith(key + ":"):
                return i
    return None


def read_force_log(
    path: str | Path,
    *,
    frame: str | None = None,
    time_unit: str | None = None,
    force_unit: str | None = None,
    moment_unit: str | None = None,
    length_unit: str | None = None,
) -> ForceLog:
    """Read a force log CSV (see the module docstring) into SI.

    Units and frame come from the ``# units:`` / ``# frame:`` lines or from the arguments. A
    quantity declared in neither place, or declared differently in both, is an error: a force log
    in unknown units silently read as N would corrupt every deflection computed from it.

    Raises
    ------
    InputError
        naming file and line: undeclared or conflicting or unknown units/frame, missing columns,
        non-numeric or NaN cells, wrong number of cells, time not strictly increasing.
    """
    path = Path(path)
    t = read_table(path, FORCE_COLUMNS, optional=POSITION_COLUMNS, what="force log")
    units_line = _meta_line(path, "units") if "units" in t.meta else None
    declared = _parse_units(t.meta.get("units", ""), file=path, line=units_line)
    given = {"time": time_unit, "force": force_unit, "moment": moment_unit, "length": length_unit}
    has_pos = t.has(*POSITION_COLUMNS)
    if any(c in t.columns for c in POSITION_COLUMNS) and not has_pos:
        raise InputError("position needs all three columns x,y,z", file=path, line=t.header_line)
    needed = ["time", "force", "moment"] + (["length"] if has_pos else [])
    units: dict[str, str] = {}
    for q in needed:
        a, b = declared.get(q), given[q]
        if a is not None and b is not None and a != b:
            raise InputError(
                f"{q} unit declared as {a!r} in the file but {b!r} was given; remove one",
                file=path,
                line=units_line,
                field="units",
            )
        u = a if a is not None else b
        if u is None:
            raise InputError(
                f"{q} unit not declared; add a line '# units: time=s force=N moment=N*m"
                + (" length=mm" if has_pos else "")
                + f"' before the header or pass --{q}-unit",
                file=path,
                field="units",
            )
        units[q] = u
    scale = {
        q: to_si(u, q, file=f"{path}:{units_line}" if units_line else path, field="units")
        for q, u in units.items()
    }
    file_frame = t.meta.get("frame")
    if file_frame is not None and frame is not None and file_frame != frame:
        raise InputError(
            f"frame declared as {file_frame!r} in the file but {frame!r} was given",
            file=path,
            line=_meta_line(path, "frame"),
            field="frame",
        )
    fr = file_frame or frame
    if not fr:
        raise InputError(
            "frame not declared; add a line '# frame: sensor' (the frame the wrench is expressed "
            "in) or pass frame=...",
            file=path,
            field="frame",
        )
    time = t.column("time") * scale["time"]
    if time.size > 1 and np.any(np.diff(time) <= 0):
        r = int(np.argmax(np.diff(time) <= 0)) + 1
        raise t.error(
            f"time must strictly increase; {t.column('time')[r]:g} follows "
            f"{t.column('time')[r - 1]:g}",
            r,
            "time",
        )
    wrench = np.column_stack(
        [t.column(c) * scale["force"] for c in ("Fx", "Fy", "Fz")]
        + [t.column(c) * scale["moment"] for c in ("Mx", "My", "Mz")]
    )
    position = (
        np.column_stack([t.column(c) for c in POSITION_COLUMNS]) * scale["length"]
        if has_pos
        else None
    )
    return ForceLog(time, wrench, fr, path, position)


def write_force_log(
    log: ForceLog,
    path: str | Path,
    *,
    time_unit: str = "s",
    force_unit: str = "N",
    moment_unit: str = "N*m",
    length_unit: str = "mm",
) -> None:
    """Write ``log`` as a force-log CSV in the given units (atomically).

    Written at 1e-9 of the time unit and 10 significant digits for wrenches, so reading back
    reproduces the log to ≈ 1e-9 relative.
    """
    s = {
        "time": to_si(time_unit, "time"),
        "force": to_si(force_unit, "force"),
        "moment": to_si(moment_unit, "moment"),
        "length": to_si(length_unit, "length"),
    }
    units = f"time={time_unit} force={force_unit} moment={moment_unit}"
    cols = list(FORCE_COLUMNS)
    data = [log.time[:, None] / s["time"], log.force / s["force"], log.moment / s["moment"]]
    fmts = ["%.9f"] + ["%.10g"] * 6
    if log.position is not None:
        units += f" length={length_unit}"
        cols += list(POSITION_COLUMNS)
        data.append(log.position / s["length"])
        fmts += ["%.10g"] * 3
    with atomic_write(path) as fh:
        fh.write(f"# units: {units}\n# frame: {log.frame}\n")
        fh.write(",".join(cols) + "\n")
        fh.write(format_rows(np.column_stack(data), fmts))


# -- attaching a log to toolpath points ---------------------------------------------------------


def _cumulative_integral(t: F64, y: F64) -> F64:
    """∫ y dt of the piecewise-linear interpolant from t[0] to each t[k]; (N, K)."""
    dt = np.diff(t)[:, None]
    seg = 0.5 * (y[1:] + y[:-1]) * dt
    return np.concatenate([np.zeros((1, y.shape[1])), np.cumsum(seg, axis=0)])


def _integral_at(t: F64, y: F64, cum: F64, x: F64) -> F64:
    """∫ from t[0] to x of the piecewise-linear interpolant, for x ∈ [t[0], t[-1]]; (M, K)."""
    k = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
    h = (t[k + 1] - t[k])[:, None]
    u = (x - t[k])[:, None]
    slope = (y[k + 1] - y[k]) / h
    return cum[k] + u * y[k] + 0.5 * u * u * slope


def window_average(t: F64, y: F64, lo: F64, hi: F64) -> F64:
    """Mean of the piecewise-linear interpolant of ``y`` over each window [lo_i, hi_i].

    Exact for the interpolant (cumulative trapezoid sums, no loop over windows); a zero-width
    window returns the interpolated value. ``t`` (N,) increasing, ``y`` (N, K), windows within
    [t[0], t[-1]]. Returns (M, K).
    """
    y = np.asarray(y, dtype=float).reshape(len(t), -1)
    if len(t) == 1:
        return np.repeat(y, len(lo), axis=0)
    cum = _cumulative_integral(t, y)
    width = (hi - lo)[:, None]
    zero = width[:, 0] <= 0
    mean = np.empty((len(lo), y.shape[1]))
    nz = ~zero
    if np.any(nz):
        mean[nz] = (_integral_at(t, y, cum, hi[nz]) - _integral_at(t, y, cum, lo[nz])) / width[nz]
    if np.any(zero):
        mean[zero] = np.column_stack([np.interp(lo[zero], t, y[:, j]) for j in range(y.shape[1])])
    return mean


def attach_to_toolpath(
    log: ForceLog,
    toolpath: Toolpath,
    by: Literal["time", "position"] = "time",
    positions: ArrayLike | None = None,
    window: float | None = None,
    *,
    time_offset: float = 0.0,
    max_distance: float | None = None,
) -> F64:
    """The logged wrench at each toolpath point, (N_tp, 6) [N, N·m] in ``log.frame``.

    Parameters
    ----------
    log : the force log
    toolpath : the toolpath the log was recorded along
    by : ``"time"`` — toolpath point i was passed at log time ``toolpath.time[i] + time_offset``;
        the wrench is the mean of the (linearly interpolated) log over the point's window:
        by default from half-way to the previous point to half-way to the next one (so every
        logged sample counts once), or ``[t_i − window/2, t_i + window/2]`` if ``window`` [s] is
        given (``window=0``: plain interpolation). Windows are clipped to the toolpath's time span.
        ``"position"`` — the sample whose logged tool-tip position is nearest to ``toolpath.tip``.
    positions : (N_log, 3) float, m, optional — tip position of each log sample (overrides
        ``log.position``); required for ``by="position"`` if the log has no x,y,z columns
    window : float, s, optional — see ``by``
    time_offset : float, s — log time at which the toolpath started (toolpath time 0)
    max_distance : float, m, optional — for ``by="position"``: error if a toolpath point has no
        logged position within this distance

    Raises
    ------
    InputError
        toolpath times outside the logged time span (naming the first and last offending points),
        missing or mis-shaped positions, points farther than ``max_distance``.
    """
    n = len(toolpath)
    if by == "time":
        tt = toolpath.time + time_offset
        if window is None:
            mid = 0.5 * (tt[1:] + tt[:-1])
            lo = np.concatenate([[tt[0]], mid])
            hi = np.concatenate([mid, [tt[-1]]])
        else:
            if not (np.isfinite(window) and window >= 0):
                raise InputError(f"window must be ≥ 0 s, got {window}", field="window")
            lo = np.maximum(tt - 0.5 * window, tt[0])
            hi = np.minimum(tt + 0.5 * window, tt[-1])
        t0, t1 = log.time[0], log.time[-1]
        tol = 1e-9 * max(1.0, abs(t1))
        out = (lo < t0 - tol) | (hi > t1 + tol)
        if np.any(out):
            bad = np.flatnonzero(out)
            raise InputError(
                f"{bad.size} toolpath point(s) (indices {bad[0]}..{bad[-1]}, toolpath time "
                f"{toolpath.time[bad[0]]:.3f}..{toolpath.time[bad[-1]]:.3f} s) fall outside the "
                f"logged time span {t0:.3f}..{t1:.3f} s (time_offset {time_offset:g} s); the log "
                "must cover the whole toolpath — check the time offset and units",
                file=log.path,
                field="time",
            )
        return window_average(log.time, log.wrench, np.clip(lo, t0, t1), np.clip(hi, t0, t1))
    if by == "position":
        pos = log.position if positions is None else np.asarray(positions, dtype=float)
        if pos is None:
            raise InputError(
                "attaching by position needs the tip position of each log sample: columns x,y,z "
                "in the log or positions=(N_log, 3)",
                file=log.path,
                field="positions",
            )
        if pos.shape != (len(log), 3):
            raise InputError(
                f"positions must have shape ({len(log)}, 3), got {pos.shape}", field="positions"
            )
        from scipy.spatial import cKDTree

        dist, idx = cKDTree(pos).query(toolpath.tip)
        if max_distance is not None and np.any(dist > max_distance):
            bad = np.flatnonzero(dist > max_distance)
            raise InputError(
                f"{bad.size} toolpath point(s) (first index {bad[0]}) have no logged position "
                f"within {max_distance * 1e3:g} mm (nearest {dist[bad[0]] * 1e3:.3f} mm)",
                file=log.path,
                field="positions",
            )
        return log.wrench[idx].reshape(n, 6)
    raise InputError(f"by must be 'time' or 'position', got {by!r}", field="by")
