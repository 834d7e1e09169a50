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

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf import jit
from roboisf.errors import InputError
from roboisf.formats import FileFormat, file_formats, get_file_format
from roboisf.io.atomic import atomic_write
from roboisf.io.table import (
    LogTable,
    format_rows,
    read_log_table,
    read_table,
    split_name_unit,
)
from roboisf.io.timestamps import repair_time
from roboisf.io.units import log_unit_to_si, to_si
from roboisf.logs.logprofile import FORCES, MOMENTS, ForceLogSpec, study_formats
from roboisf.path.toolpath import Toolpath

__all__ = [
    "FORCE_COLUMNS",
    "ForceLog",
    "attach_to_toolpath",
    "detect_force_format",
    "force_formats",
    "force_profiles_written",
    "is_roboisf_force_log",
    "log_kernel",
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
    moments_known : bool — False for a log without (all three) moment channels (a 3-component
        dynamometer): its Mx, My, Mz are zeros standing for "not measured", and the analysis
        takes the load as a point force at the tool tip (``docs/study.md``, logs)
    profile : str — the format it was read as ("roboisf", "ati", "kistler", "dyno3", ...)
    notes : tuple of str — what reading changed (``timestamps = "repair"``: rows reordered,
        dropped, averaged; :mod:`roboisf.io.timestamps`)
    """

    time: F64
    wrench: F64
    frame: str
    path: Path | None = None
    position: F64 | None = None
    moments_known: bool = True
    profile: str = "roboisf"
    notes: tuple[str, ...] = ()

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

    @classmethod
    def checked(
        cls,
        time: F64,
        wrench: F64,
        frame: str,
        path: Path | None = None,
        position: F64 | None = None,
        *,
        moments_known: bool = True,
        profile: str = "roboisf",
        notes: tuple[str, ...] = (),
    ) -> ForceLog:
        """A log from arrays its reader has already checked — float64 ``time`` (N,) finite and
        strictly increasing, ``wrench`` (N, 6) and ``position`` (N, 3) finite — without
        :meth:`__post_init__`'s passes over them again (its finiteness and order checks: ~20 ms
        on a 2.3 M-sample paper log). Shapes, dtypes and frame are still checked (cheap)."""
        n = time.shape[0] if time.ndim == 1 else -1
        ok = (
            time.dtype == np.float64
            and wrench.dtype == np.float64
            and n >= 1
            and wrench.shape == (n, 6)
            and (position is None or (position.dtype == np.float64 and position.shape == (n, 3)))
            and isinstance(frame, str)
            and bool(frame)
        )
        if not ok:  # not what a reader makes: the full checks, with their messages
            return cls(time, wrench, frame, path, position, moments_known, profile, notes)
        values = {
            "time": time,
            "wrench": wrench,
            "frame": frame,
            "path": path,
            "position": position,
            "moments_known": moments_known,
            "profile": profile,
            "notes": notes,
        }
        # every field set: a field added to the class and not here fails at once, not later
        assert values.keys() == {f.name for f in dataclasses.fields(cls)}, "ForceLog.checked"
        log = object.__new__(cls)
        for k, v in values.items():
            object.__setattr__(log, k, v)
        return log

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


def _read_roboisf_csv(
    path: str | Path,
    *,
    frame: str | None = None,
    time_unit: str | None = None,
    force_unit: str | None = None,
    moment_unit: str | None = None,
    length_unit: str | None = None,
    timestamps: str = "refuse",
) -> ForceLog:
    """Read a roboisf force log CSV (see the module docstring) into SI.

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
    where = f"{path}:{units_line}" if units_line else path
    for q in needed:
        a, b = declared.get(q), given[q]
        # by what they mean, not how they are spelled ('Nm' in the file, 'N*m' in the study)
        if (
            a is not None
            and b is not None
            and log_unit_to_si(a, q, file=where, field="units") != log_unit_to_si(b, q)
        ):
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
    # the spellings instruments write (lbf, lbf-in, Nm …) as in every other log profile
    scale = {q: log_unit_to_si(u, q, file=where, field="units") for q, u in units.items()}
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
    # scaled straight into one (N, 6) array (six scaled columns stacked held the wrench twice)
    wrench = np.empty((t.data.shape[0], 6))
    for k, c in enumerate(("Fx", "Fy", "Fz", "Mx", "My", "Mz")):
        np.multiply(t.column(c), scale["force" if k < 3 else "moment"], out=wrench[:, k])
    position = (
        np.column_stack([t.column(c) for c in POSITION_COLUMNS]) * scale["length"]
        if has_pos
        else None
    )
    notes: tuple[str, ...] = ()
    if time.size > 1 and not bool(np.all(np.diff(time) > 0)):
        vals = wrench if position is None else np.hstack([wrench, position])
        time, vals, rep = repair_time(
            time, vals, timestamps, error=lambda m, r: t.error(m, r, "time")
        )
        wrench = vals[:, :6]
        position = vals[:, 6:] if position is not None else None
        notes = (rep.describe(),)
    return ForceLog(time, wrench, fr, path, position, notes=notes)


# -- logs as instruments write them: profiles ---------------------------------------------------
# Each profile is a force-log format of the registry (roboisf.formats, one module per profile in
# roboisf.logs.formats): its column matchers, fixed units and time axis are its ForceLogSpec.

_FORCES = FORCES
_MOMENTS = MOMENTS


def _profiles() -> tuple[FileFormat, ...]:
    """The registered force-log formats read as text tables (they carry a ``ForceLogSpec``)."""
    return tuple(f for f in file_formats("force_log") if isinstance(f.spec, ForceLogSpec))


def _spec(profile: str) -> ForceLogSpec | None:
    return next((f.spec for f in _profiles() if f.name == profile), None)


def force_formats() -> tuple[str, ...]:
    """``format`` values of a force log (study ``[runs.X.forces] format``): ``auto``, every
    registered text profile, and ``columns`` (header names given in the study)."""
    return study_formats("force_log")


def force_profiles_written() -> tuple[str, ...]:
    """The force-log profiles with a text writer (the virtual cell's ``--*-force-profile``)."""
    return tuple(f.name for f in file_formats("force_log") if f.writer and not f.binary)


def is_roboisf_force_log(path: Path) -> bool:
    """The roboisf layout: ``# key: value`` lines, then exactly ``time,Fx,...`` (case-sensitive)."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for line in fh:
                s = line.strip()
                if s and not s.startswith("#"):
                    cells = [c.strip() for c in s.split(",")]
                    return cells[:7] == list(FORCE_COLUMNS)
    except (OSError, UnicodeDecodeError):
        return False
    return False


def _columns_matcher(columns: dict[str, str]) -> dict[str, re.Pattern[str]]:
    known = ("time", *_FORCES, *_MOMENTS, "x", "y", "z")
    out = {}
    for k, v in columns.items():
        if k not in known:
            raise InputError(
                f"unknown column key {k!r}; expected {', '.join(known)}", field=f"columns.{k}"
            )
        out[k] = re.compile(re.escape(split_name_unit(v)[0]))
    return out


def _open(p: Path, fmt: str, columns: dict[str, str] | None) -> tuple[str, LogTable | None]:
    """(profile, parsed table); the roboisf CSV is left to its own reader (None)."""
    known = force_formats()
    if fmt not in known:
        raise InputError(f"format must be one of {', '.join(known)}, got {fmt!r}", file=p)
    if fmt == "columns" or columns:
        if not columns:
            raise InputError(
                "format 'columns' needs a columns = {time = ..., Fx = ...} table", file=p
            )
        match = _columns_matcher(columns)
        req = tuple(k for k in match if k in ("time", *_FORCES))
        missing = [k for k in ("time", *_FORCES) if k not in match]
        if missing:
            raise InputError(
                f"columns must name at least time, Fx, Fy, Fz (missing {', '.join(missing)})",
                file=p,
                field="columns",
            )
        return "columns", read_log_table(
            p, match, req, what="force log", expected=", ".join(columns.values())
        )
    if fmt in ("auto", "roboisf") and is_roboisf_force_log(p):
        return "roboisf", None
    if fmt == "roboisf":
        raise InputError(
            "not a roboisf force log: expected '# units:' / '# frame:' lines and the header "
            'time,Fx,Fy,Fz,Mx,My,Mz (or set format = "auto")',
            file=p,
        )
    profiles = _profiles()
    # automatic detection tries every profile that no other refines, in rank order
    order = [f for f in profiles if not f.spec.refines] if fmt == "auto" else []
    order += [f for f in profiles if f.name == fmt]
    last: InputError | None = None
    for f in order:
        spec: ForceLogSpec = f.spec
        try:
            t = read_log_table(p, spec.match, spec.required, what="force log")
        except InputError as e:
            if "no header line" not in e.message:
                raise
            last = e
            continue
        got = [m for m in _MOMENTS if m in t.data]
        if got and len(got) < 3:
            miss = [m for m in _MOMENTS if m not in t.data]
            raise InputError(
                f"missing column(s) {', '.join(miss)}: the header has {', '.join(got)} but a "
                "wrench needs all three moments (or none: a 3-component dynamometer); found "
                f"{', '.join(t.columns)}",
                file=p,
                line=t.header_line,
                field=miss[0],
            )
        if spec.moments == "none" and got:
            raise InputError(
                f"format {f.name!r} is a 3-component log but the file has moment columns", file=p
            )
        name = f.name
        if fmt == "auto":  # a profile found as another's table (DynoWare: a tab-separated table)
            name = next(
                (
                    g.name
                    for g in profiles
                    if name in g.spec.refines and g.spec.accept is not None and g.spec.accept(t)
                ),
                name,
            )
        return name, t
    if fmt == "auto" or last is None:
        near = _near_force_header(p)
        if near is not None:
            line, names, missing = near
            raise InputError(
                f"the header has {', '.join(names)} but no {', '.join(missing)}: a force log "
                "needs time, Fx, Fy and Fz (and Mx, My, Mz, or none of them)",
                file=p,
                line=line,
                field=missing[0],
            )
        labels = ", ".join(f.label for f in profiles)
        raise InputError(
            "no force-log format recognised: expected a header naming time, Fx, Fy, Fz (and "
            f"Mx, My, Mz or Tx, Ty, Tz), a roboisf log or one of: {labels}; for other names "
            'give columns = {time = "...", Fx = "...", ...} in the study',
            file=p,
        )
    raise last


_HEAD_SPLIT = re.compile(r"[,;\t]")
_UNIT_SUFFIX = re.compile(r"\s*[\[(].*$")


def _near_force_header(p: Path) -> tuple[int, list[str], list[str]] | None:
    """(line, its names, the missing ones) of a line among the file's first 64 kB that names
    time and two or more of Fx, Fy, Fz but not all: a header one column short (a dropped
    channel, a cut column), which the generic "no format recognised" would not name."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(65536).decode("utf-8-sig", errors="replace")
    except OSError:
        return None
    want = ("time", "Fx", "Fy", "Fz")
    for i, ln in enumerate(head.splitlines()[:200], start=1):
        names = [_UNIT_SUFFIX.sub("", c).strip().strip('"') for c in _HEAD_SPLIT.split(ln)]
        low = {n.lower() for n in names}
        have = [w for w in want if w.lower() in low]
        if "time" in have and 3 <= len(have) < 4:
            return i, [n for n in names if n], [w for w in want if w not in have]
    return None


def detect_force_format(
    path: str | Path, *, fmt: str = "auto", columns: dict[str, str] | None = None
) -> tuple[str, dict[str, str], dict[str, str]]:
    """Which profile reads a force log, and what it found.

    Returns
    -------
    profile : str — "roboisf", "parquet", "ati", "kistler", "dyno3", "generic" or "columns"
    columns : dict — canonical column ("time", "Fx" … "Mz", ATI's "rdt") → header cell as written
    units : dict — quantity ("time", "force", "moment", "length") → unit as declared in the file
        (``# units:`` line, header names, a units row, ATI's "Force Units:" lines); a quantity
        missing here is not declared by the file

    Raises
    ------
    InputError
        no profile recognises the file (naming the file and what each expects).
    """
    p = Path(path)
    if p.suffix.lower() == ".parquet":
        from roboisf.logs.logparquet import parquet_log_info

        cols, units = parquet_log_info(p, kind="force_log")
        return "parquet", cols, units
    profile, t = _open(p, fmt, columns)
    if t is None:
        line = _meta_line(p, "units")
        meta = _head_meta(p)
        return (
            "roboisf",
            {k: k for k in FORCE_COLUMNS},
            _parse_units(meta.get("units", ""), file=p, line=line),
        )
    return profile, _found(t), _declared_units(profile, t)


def _declared_units(profile: str, t: LogTable) -> dict[str, str]:
    """Units the profile's layout fixes, then those the file declares."""
    spec = _spec(profile)
    return {**((spec.units or {}) if spec else {}), **_file_units(t)}


def _head_meta(path: Path) -> dict[str, str]:
    out: dict[str, str] = {}
    with open(path, encoding="utf-8-sig") as fh:
        for ln in fh:
            s = ln.strip()
            if s and not s.startswith("#"):
                break
            body = s.lstrip("#").strip()
            if ":" in body:
                k, _, v = body.partition(":")
                out[k.strip().lower()] = v.strip()
    return out


def _found(t: LogTable) -> dict[str, str]:
    return {c: t.columns[j] for c, j in t.col_index.items()}


def _file_units(t: LogTable) -> dict[str, str]:
    """Quantity → unit declared by the file (header names/units row, '# units:', ATI lines)."""
    out: dict[str, str] = {}
    if "units" in t.meta:
        out.update(_parse_units(t.meta["units"], file=t.path, line=None))
    for q, cols in (("time", ("time",)), ("force", _FORCES), ("moment", _MOMENTS)):
        us = {t.units[c] for c in cols if c in t.units}
        if len(us) == 1:
            out.setdefault(q, us.pop())
    for q, key in (("force", "force units"), ("moment", "torque units")):
        if key in t.preamble:
            out.setdefault(q, t.preamble[key])
    return out


def read_force_log(
    path: str | Path,
    *,
    frame: str | None = None,
    time_unit: str | None = None,
    force_unit: str | None = None,
    moment_unit: str | None = None,
    length_unit: str | None = None,
    fmt: str = "auto",
    columns: dict[str, str] | None = None,
    timestamps: str = "refuse",
) -> ForceLog:
    """Read a force log into SI, as it comes from the instrument.

    ``fmt`` (study key ``format``): ``"auto"`` tries, in order, a ``.parquet`` log
    (:mod:`roboisf.logs.logparquet`), the roboisf CSV (module docstring), an ATI Net F/T CSV, a
    Universal Robots RTDE recording (``timestamp``, ``actual_TCP_force_0..5``), a 6-component
    table (time, Fx…Fz, Mx…Mz or Tx…Tz), a Kistler DynoWare text export and a
    3-component dynamometer (time, Fx, Fy, Fz: moments unknown, ``moments_known=False``).
    ``columns`` maps canonical names to the file's header cells for anything else.

    Units come from the file (``# units:`` line, ``Fx [N]`` / ``Fx (N)`` header names, a units
    row under the header, ATI's ``Force Units:`` / ``Torque Units:`` lines) or the arguments; a
    quantity declared in neither, or differently in both, is an error — never a guess.

    Raises
    ------
    InputError
        naming file and line: no recognised header, undeclared/conflicting/unknown units or
        frame, a cell that is not a number, NaN, time not strictly increasing.
    """
    p = Path(path)
    given = {"time": time_unit, "force": force_unit, "moment": moment_unit, "length": length_unit}
    if p.suffix.lower() == ".parquet":
        from roboisf.logs.logparquet import read_force_parquet

        return read_force_parquet(p, frame=frame, given=given)
    profile, t = _open(p, fmt, columns)
    if t is None:
        return _read_roboisf_csv(
            p,
            frame=frame,
            time_unit=time_unit,
            force_unit=force_unit,
            moment_unit=moment_unit,
            length_unit=length_unit,
            timestamps=timestamps,
        )
    declared = _declared_units(profile, t)
    spec = _spec(profile)
    units: dict[str, float] = {}
    has_m = all(m in t.data for m in _MOMENTS)
    timed = spec is not None and spec.time is not None  # the layout's own time axis (ATI)
    needed = ["force"] + (["moment"] if has_m else []) + ([] if timed else ["time"])
    qcols = {"time": ("time",), "force": _FORCES, "moment": _MOMENTS}
    for q in needed:
        b = given[q]
        per_col = [t.units[c] for c in qcols[q] if c in t.units]
        if len(per_col) == len(qcols[q]):  # every column says its unit in the header
            for c in qcols[q]:
                fc = log_unit_to_si(t.units[c], q, file=p, field=c)
                if b is not None and fc != log_unit_to_si(b, q):
                    raise InputError(
                        f"{q} unit declared as {t.units[c]!r} in the file but {b!r} was given "
                        "(study units for this log); remove one",
                        file=p,
                        line=t.header_line,
                        field=c,
                    )
            continue
        a = declared.get(q)
        if a is not None and b is not None and log_unit_to_si(a, q) != log_unit_to_si(b, q):
            raise InputError(
                f"{q} unit declared as {a!r} in the file but {b!r} was given (study [units] or "
                "the log's units); remove one",
                file=p,
                field="units",
            )
        u = a if a is not None else b
        if u is None:
            raise InputError(
                f"{q} unit not declared: put it in the header ('Fx [N]'), a '# units: time=s "
                f"force=N moment=N*m' line, or the study's units for this log",
                file=p,
                field="units",
            )
        units[q] = log_unit_to_si(u, q, file=p, field="units")

    # per-column units in the header override the file-wide one (each converts on its own)
    def col(c: str, q: str) -> F64:
        f = log_unit_to_si(t.units[c], q, file=p, field=c) if c in t.units else units[q]
        return t.data[c] * f

    time = spec.time(t) if spec is not None and spec.time is not None else col("time", "time")
    F = np.column_stack([col(c, "force") for c in _FORCES])
    M = np.column_stack([col(c, "moment") for c in _MOMENTS]) if has_m else np.zeros_like(F)
    W = np.hstack([F, M])
    notes: tuple[str, ...] = ()
    if time.size > 1 and not bool(np.all(np.diff(time) > 0)):
        tcol = spec.time_column if spec is not None else "time"
        time, W, rep = repair_time(time, W, timestamps, error=lambda m, r: t.error(m, r, tcol))
        notes = (rep.describe(),)
    fr = frame or t.meta.get("frame") or (spec.frame if spec and spec.frame else "sensor")
    notes += spec.notes if spec is not None else ()
    return ForceLog(time, W, fr, p, None, moments_known=has_m, profile=profile, notes=notes)


def write_force_log(
    log: ForceLog,
    path: str | Path,
    *,
    time_unit: str = "s",
    force_unit: str = "N",
    moment_unit: str = "N*m",
    length_unit: str = "mm",
    profile: str = "roboisf",
) -> None:
    """Write ``log`` as a force log (atomically): Parquet for a ``.parquet`` name (SI;
    :mod:`roboisf.logs.logparquet`), else a CSV in the given units.

    The CSV is written at 1e-9 of the time unit and 10 significant digits for wrenches, so
    reading back reproduces the log to ≈ 1e-9 relative.

    ``profile`` writes the text as an instrument would, with that force-log format's registered
    writer (:mod:`roboisf.formats`; each profile's module in :mod:`roboisf.logs.formats` states its
    layout, units and rounding): ``"ati"``, ``"kistler"``, ``"dyno3"``, ``"generic"``, …
    """
    if Path(path).suffix.lower() == ".parquet":
        from roboisf.logs.logparquet import write_force_parquet

        write_force_parquet(log, path)
        return
    if profile != "roboisf":
        fmt = get_file_format("force_log", profile, field="profile")
        if fmt.writer is None or fmt.binary:
            names = ", ".join(force_profiles_written())
            raise InputError(
                f"force-log profile {profile!r} has no text writer; expected one of {names}",
                field="profile",
            )
        fmt.writer(log, path)
        return
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
    """∫ y dt of the piecewise-linear interpolant from t[0] to each t[k]; (N, K).

    Computed in one (N, K) buffer (trapezoids, then their running sum in place): the same bits
    as ``concatenate([0, cumsum(0.5·(y[1:] + y[:-1])·Δt)])`` (0.5 scales exactly) with one
    array instead of four temporaries of the log's size — a 1 kHz log of a paper-scale part has
    2.3 M samples, 110 MB per (N, 6) array.
    """
    cum = np.empty(y.shape)
    cum[0] = 0.0
    seg = cum[1:]
    np.add(y[1:], y[:-1], out=seg)
    seg *= (0.5 * np.diff(t))[:, None]
    np.cumsum(seg, axis=0, out=seg)
    return cum


def _segment(t: F64, x: F64) -> NDArray[np.int64]:
    """Index k of the sample interval [t[k], t[k+1]] holding each x (clipped to the log)."""
    return np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)


def _integral_from(t: F64, y: F64, cum_k: F64, k: NDArray[np.int64], x: F64) -> F64:
    """∫ from t[0] to x given the running integral ``cum_k`` at the samples k below x:
    ``cum_k + u · y[k] + 0.5 · u · u · slope`` (u = x − t[k], slope = (y[k+1] − y[k]) / h), in
    that order, in two (M, K) arrays (y[k] gathered once; a product or sum is the same bits
    with its operands swapped)."""
    k1 = k + 1
    tk = t[k]
    h = t[k1] - tk
    u = x - tk
    term = y[k1]
    yk = y[k]
    term -= yk
    term /= h[:, None]  # the slope
    term *= (0.5 * u * u)[:, None]
    yk *= u[:, None]
    yk += cum_k
    yk += term
    return yk


def _integral_at(t: F64, y: F64, cum: F64, x: F64) -> F64:
    """∫ from t[0] to x of the piecewise-linear interpolant, for x ∈ [t[0], t[-1]]; (M, K)."""
    k = _segment(t, x)
    return _integral_from(t, y, cum[k], k, x)


def log_kernel() -> Any:
    """:mod:`roboisf.logs.forcelog_kernel` when its compiled kernels are ready
    (:func:`roboisf.jit.ready`; imported on first use), else None (the numpy forms run)."""
    global _KERNEL
    if _KERNEL is None and not jit.ready("forcelog"):  # not built yet: a background build
        _KERNEL = False
    if _KERNEL is None:
        try:
            from roboisf.logs import forcelog_kernel

            _KERNEL = forcelog_kernel
        except ImportError:  # pragma: no cover - numba is a test dependency
            _KERNEL = False
    return _KERNEL or None


_KERNEL: Any = None


def row_norms(X: F64, j: int = 0, centre: ArrayLike | None = None) -> F64:
    """``|X[:, j:j+3] − centre|`` per row (N,) of a log's wrench X (N, ≥ j + 3); ``centre``
    (3,) defaults to 0 — |F| (j = 0) or |M| (j = 3), or the distance from a force level. The
    compiled pass of :func:`roboisf.logs.forcelog_kernel.row_norms` when its kernels are ready,
    else :func:`row_norms_numpy`; both give the bits of ``np.linalg.norm(…, axis=1)`` without
    its (N, 3) temporaries (tests/test_forcelog_kernel.py)."""
    kern = log_kernel()
    if kern is None:
        return row_norms_numpy(X, j, centre)
    return np.asarray(kern.row_norms(X, j, centre))


def row_norms_numpy(X: F64, j: int = 0, centre: ArrayLike | None = None) -> F64:
    """:func:`row_norms` with numpy, column by column (a new install's first run, the plain
    install): squares summed x, y, z in that order, as ``np.linalg.norm(X[:, j:j+3] − centre,
    axis=1)`` does, without its (N, 3) temporaries and strided reduction — 3–4× faster on a
    2.3 M-sample log."""
    c = np.zeros(3) if centre is None else np.asarray(centre, dtype=float)
    out = np.subtract(X[:, j], c[0])
    out *= out
    d = np.subtract(X[:, j + 1], c[1])
    d *= d
    out += d
    np.subtract(X[:, j + 2], c[2], out=d)
    d *= d
    out += d
    return np.sqrt(out, out=out)


def _integrals(t: F64, y: F64, x: F64) -> F64:
    """∫ from t[0] to each x (M,) of the piecewise-linear interpolant of ``y`` (N, K): (M, K).
    With numba the running sum is read at the samples below the x in one pass over the log
    (:func:`roboisf.logs.forcelog_kernel.running_integral_at`); else the whole running sum."""
    kern = log_kernel()
    if kern is None:
        return _integral_at(t, y, _cumulative_integral(t, y), x)
    k = _segment(t, x)
    if k.size > 1 and bool(np.all(k[1:] >= k[:-1])):
        # ends in order (the windows of a path): np.unique's answer without its sort
        first = np.empty(k.size, dtype=bool)
        first[0] = True
        np.not_equal(k[1:], k[:-1], out=first[1:])
        ks, inv = k[first], np.cumsum(first) - 1
    else:
        ks, inv = np.unique(k, return_inverse=True)
    return _integral_from(t, y, kern.running_integral_at(t, y, ks)[inv], k, x)


def window_average(t: F64, y: F64, lo: F64, hi: F64) -> F64:
    """Mean of the piecewise-linear interpolant of ``y`` over each window [lo_i, hi_i].

    Exact for the interpolant (cumulative trapezoid sums, no loop over windows); a zero-width
    window returns the interpolated value. ``t`` (N,) increasing, ``y`` (N, K), windows within
    [t[0], t[-1]]. Returns (M, K). With numba the running sum is read at the windows' ends in
    one pass over the log (:func:`roboisf.logs.forcelog_kernel.running_integral_at`: the same bits
    without the (N, K) array).
    """
    y = np.asarray(y, dtype=float).reshape(len(t), -1)
    if len(t) == 1:
        return np.repeat(y, len(lo), axis=0)
    width = (hi - lo)[:, None]
    zero = width[:, 0] <= 0
    mean = np.empty((len(lo), y.shape[1]))
    nz = ~zero
    if np.any(nz):
        # windows that follow each other (each ends where the next begins: the half-way windows
        # of attach_to_toolpath and of roboisf.sync) share their ends: the integral is taken
        # once at each (the same numbers: each end's integral is its own row's arithmetic)
        chained = len(lo) > 1 and np.array_equal(lo[1:], hi[:-1])
        x = np.concatenate([lo[:1], hi]) if chained else np.concatenate([hi[nz], lo[nz]])
        both = _integrals(t, y, x)
        if chained:
            i_hi, i_lo = both[1:], both[:-1]
            if not nz.all():
                i_hi, i_lo = i_hi[nz], i_lo[nz]
        else:
            m = int(np.count_nonzero(nz))
            i_hi, i_lo = both[:m], both[m:]
        mean[nz] = (i_hi - i_lo) / width[nz]
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
