"""Joint-angle logs: what the robot controller recorded along the path.

Format (the roboisf numeric-CSV layout of :mod:`roboisf.io.table`)::

    # units: time=s angle=deg
    time,q1,q2,q3,q4,q5,q6
    0.000,0.0,12.5,20.1,0.0,50.2,-180.0

Angles in the **controller's convention** (as logged; see ``docs/robot.md``), degrees by default
(``angle=rad`` accepted); time in s (``ms``/``min`` accepted). Inside roboisf: rad and s.

Logs as controllers write them are read too (:func:`detect_joint_format`): any separator, decimal
comma, a free-text header block, names in any case — ABB ``J1..J6``, KUKA ``A1..A6`` (also as in
a KUKA trace's text export, ``AxisActPos A1 [°]``; FANUC ``J1..J6`` as ABB), Universal Robots'
RTDE recordings (``timestamp actual_q_0 … actual_q_5``, blank-separated, s and rad by the RTDE
specification), ``q1..q6``, ``joint 1``/``axis 1`` — a time
column ``time``/``t``/``timestamp``/``Zeit``, units in the header names (``[deg]``, ``(rad)``,
``[°]``, ``[ms]``), a ``# units:`` line or given by the study. Unknown units are an error.
A ``.parquet`` name is a Parquet joint log (:mod:`roboisf.logs.logparquet`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.formats import FileFormat, file_formats, get_file_format
from roboisf.io.atomic import atomic_write
from roboisf.io.table import LogTable, format_rows, read_log_table, read_table, split_name_unit
from roboisf.io.timestamps import repair_time
from roboisf.io.units import log_unit_to_si
from roboisf.logs.logprofile import JointLogSpec, study_formats

__all__ = [
    "JOINT_COLUMNS",
    "JointLog",
    "detect_joint_format",
    "is_roboisf_joint_log",
    "joint_formats",
    "joint_profiles_written",
    "joint_rows",
    "read_joint_log",
    "unstated_units",
    "write_joint_log",
]


def _profiles() -> tuple[FileFormat, ...]:
    """The registered joint-log formats read as text tables (they carry a ``JointLogSpec``)."""
    return tuple(f for f in file_formats("joint_log") if isinstance(f.spec, JointLogSpec))


def joint_formats() -> tuple[str, ...]:
    """``format`` values of a joint log (study ``[runs.X.joints] format``): ``auto``, every
    registered text profile, and ``columns`` (header names given in the study)."""
    return study_formats("joint_log")


def joint_profiles_written() -> tuple[str, ...]:
    """The joint-log profiles with a text writer (the virtual cell's ``--joint-profile``)."""
    return tuple(f.name for f in file_formats("joint_log") if f.writer and not f.binary)


def _fixed_units(profile: str) -> dict[str, str]:
    spec = next((f.spec for f in _profiles() if f.name == profile), None)
    return dict(spec.units or {}) if spec is not None else {}


def unstated_units(profile: str) -> dict[str, str]:
    """The units ``profile``'s writer writes in but its files do not state (quantity → unit);
    empty when the file says them (a study reading such a file must give them)."""
    spec = next((f.spec for f in _profiles() if f.name == profile), None)
    return dict(spec.unstated_units or {}) if spec is not None else {}


F64 = NDArray[np.float64]
JOINT_COLUMNS = ("time", "q1", "q2", "q3", "q4", "q5", "q6")


@dataclass(frozen=True, eq=False)
class JointLog:
    """time : (N,) s, strictly increasing; q : (N, 6) rad (controller convention); path;
    notes: what reading changed (``timestamps = "repair"``, :mod:`roboisf.io.timestamps`)."""

    time: F64
    q: F64
    path: Path | None = None
    notes: tuple[str, ...] = ()


def is_roboisf_joint_log(path: Path) -> bool:
    """The roboisf layout: ``# key: value`` lines, then exactly ``time,q1,…,q6``."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for line in fh:
                s = line.strip()
                if s and not s.startswith("#"):
                    return [c.strip() for c in s.split(",")] == list(JOINT_COLUMNS)
    except (OSError, UnicodeDecodeError):
        return False
    return False


def _file_units(t: LogTable) -> dict[str, str]:
    out: dict[str, str] = {}
    for tok in t.meta.get("units", "").split():
        k, _, v = tok.partition("=")
        if k in ("time", "angle") and v:
            out[k] = v
    if "time" in t.units:
        out.setdefault("time", t.units["time"])
    us = {t.units[f"q{i}"] for i in range(1, 7) if f"q{i}" in t.units}
    if len(us) == 1:
        out.setdefault("angle", us.pop())
    elif len(us) > 1:
        raise InputError(
            f"joint columns declare different angle units {sorted(us)}", file=t.path, field="units"
        )
    return out


def detect_joint_format(
    path: str | Path, *, fmt: str = "auto", columns: dict[str, str] | None = None
) -> tuple[str, dict[str, str], dict[str, str]]:
    """Which profile reads a joint log: (profile, canonical column → header cell, quantity →
    unit declared by the file). Profiles: "parquet", "roboisf", "abb" and "fanuc" (J1..J6; auto
    names a J1..J6 file "abb"), "kuka" (A1..A6,
    KUKA trace text export), "ur" (Universal Robots RTDE recording: ``timestamp``,
    ``actual_q_0..5``, s and rad), "generic" (q1..q6, joint/axis N), "columns" (``columns``
    given).

    Raises
    ------
    InputError
        no profile recognises the file.
    """
    p = Path(path)
    known = joint_formats()
    if fmt not in known:
        raise InputError(f"format must be one of {', '.join(known)}, got {fmt!r}", file=p)
    if p.suffix.lower() == ".parquet":
        from roboisf.logs.logparquet import parquet_log_info

        cols, units = parquet_log_info(p, kind="joint_log")
        return "parquet", cols, units
    t = _read_text_log(p, fmt, columns)
    profile = t[0]
    tab = t[1]
    units = {**_fixed_units(profile), **_file_units(tab)}
    return profile, {c: tab.columns[j] for c, j in tab.col_index.items()}, units


def _read_text_log(p: Path, fmt: str, columns: dict[str, str] | None) -> tuple[str, LogTable]:
    req = JOINT_COLUMNS
    if fmt == "columns" or columns:
        if not columns or set(columns) != set(JOINT_COLUMNS):
            raise InputError(
                f"columns must map each of {', '.join(JOINT_COLUMNS)} to a header cell",
                file=p,
                field="columns",
            )
        match = {k: re.compile(re.escape(split_name_unit(v)[0])) for k, v in columns.items()}
        return "columns", read_log_table(
            p, match, req, what="joint log", expected=", ".join(columns.values())
        )
    if fmt in ("auto", "roboisf") and is_roboisf_joint_log(p):
        match = {k: re.compile(k) for k in JOINT_COLUMNS}
        return "roboisf", read_log_table(p, match, req, what="joint log")
    if fmt == "roboisf":
        raise InputError(
            "not a roboisf joint log: expected '# units: time=s angle=deg' and the header "
            'time,q1,...,q6 (or set format = "auto")',
            file=p,
        )
    order = [f for f in _profiles() if (f.spec.auto if fmt == "auto" else f.name == fmt)]
    for f in order:
        try:
            return f.name, read_log_table(p, f.spec.match, req, what="joint log")
        except InputError as e:
            if "no header line" not in e.message:
                raise
    raise InputError(
        "no joint-log format recognised: expected a header naming a time column (time, t, "
        "timestamp, Zeit) and six joints (q1..q6, ABB/FANUC J1..J6, KUKA A1..A6, UR RTDE "
        "actual_q_0..5); for other names "
        'give columns = {time = "…", q1 = "…", …} in the study',
        file=p,
    )


def read_joint_log(
    path: str | Path,
    *,
    fmt: str = "auto",
    columns: dict[str, str] | None = None,
    time_unit: str | None = None,
    angle_unit: str | None = None,
    timestamps: str = "refuse",
) -> JointLog:
    """Read a joint log into SI (errors name the file line); see the module docstring.

    Units: the file's (``# units:`` line, header names such as ``A1 [°]``) or the arguments;
    neither, or both disagreeing, is an error. ``timestamps``: ``"refuse"`` a time that does not
    strictly increase, or ``"repair"`` it (:mod:`roboisf.io.timestamps`; counted in ``notes``).
    """
    p = Path(path)
    if p.suffix.lower() == ".parquet":
        from roboisf.logs.logparquet import _steps_back, read_joint_parquet

        t_si, q_si = read_joint_parquet(p, {"time": time_unit, "angle": angle_unit})
        back = _steps_back(t_si)
        if back is not None:
            raise InputError(f"time must increase strictly (row {back})", file=p, field="time")
        return JointLog(time=t_si, q=q_si, path=p)
    if not (fmt in ("auto", "roboisf") and not columns and is_roboisf_joint_log(p)):
        profile, tab = _read_text_log(p, fmt, columns)
        declared = {**_fixed_units(profile), **_file_units(tab)}
        given = {"time": time_unit, "angle": angle_unit}
        f = {}
        for qty in ("time", "angle"):
            a, b = declared.get(qty), given[qty]
            if a is not None and b is not None and log_unit_to_si(a, qty) != log_unit_to_si(b, qty):
                raise InputError(
                    f"{qty} unit declared as {a!r} in the file but {b!r} was given; remove one",
                    file=p,
                    field="units",
                )
            u = a if a is not None else b
            if u is None:
                raise InputError(
                    f"{qty} unit not declared: put it in the header ('A1 [deg]', 'time [s]'), a "
                    "'# units: time=s angle=deg' line, or the study's units for this log",
                    file=p,
                    field="units",
                )
            f[qty] = log_unit_to_si(u, qty, file=p, field="units")
        time = tab.data["time"] * f["time"]
        q = np.column_stack([tab.data[f"q{i}"] for i in range(1, 7)]) * f["angle"]
        return _checked(time, q, p, timestamps, lambda m, r: tab.error(m, r, "time"))
    t = read_table(p, JOINT_COLUMNS, what="joint log")
    units = {"time": "s", "angle": "deg"}
    if "units" not in t.meta and angle_unit is None:
        raise InputError(
            "missing '# units: time=s angle=deg' line (angles must declare deg or rad; the "
            "study's [units] are not taken for a joint log's angles): add the line, or give "
            f'them in study.toml: joints = {{file = "{p.name}", units = {{time = "s", '
            'angle = "deg"}}',
            file=p,
            field="units",
        )
    file_units: dict[str, str] = {}
    for tok in t.meta.get("units", "").split():
        k, _, v = tok.partition("=")
        if k not in units or not v:
            raise InputError(
                f"bad units entry {tok!r}; expected time=… angle=…", file=p, field="units"
            )
        file_units[k] = v
    for k, g_unit in (("time", time_unit), ("angle", angle_unit)):
        if g_unit is None:
            continue
        if k in file_units and log_unit_to_si(
            file_units[k], k, file=p, field="units"
        ) != log_unit_to_si(g_unit, k):
            raise InputError(
                f"{k} unit declared as {file_units[k]!r} in the file but {g_unit!r} was given "
                "(study units for this log); remove one",
                file=p,
                field="units",
            )
        file_units.setdefault(k, g_unit)
    units.update(file_units)
    ft = log_unit_to_si(units["time"], "time", file=p, field="units.time")
    fa = log_unit_to_si(units["angle"], "angle", file=p, field="units.angle")
    time = t.column("time") * ft
    q = np.stack([t.column(f"q{i}") for i in range(1, 7)], axis=1) * fa
    return _checked(time, q, p, timestamps, lambda m, r: t.error(m, r, "time"))


def _checked(
    time: F64, q: F64, p: Path, policy: str, error: Callable[[str, int], Exception]
) -> JointLog:
    """The joint log, its times under the timestamp ``policy``."""
    if time.size < 2 or bool(np.all(np.diff(time) > 0)):
        return JointLog(time=time, q=q, path=p)
    time, q, rep = repair_time(time, q, policy, error=error)
    return JointLog(time=time, q=q, path=p, notes=(rep.describe(),))


def joint_rows(time: ArrayLike, q: ArrayLike) -> tuple[F64, F64]:
    """(time (N,) s, q (N, 6) in degrees) for a writer; ``InputError`` (field ``q``) on a shape
    mismatch."""
    tt = np.asarray(time, dtype=float).reshape(-1)
    qq = np.asarray(q, dtype=float)
    if qq.shape != (tt.size, 6):
        raise InputError(f"expected q of shape ({tt.size}, 6), got {qq.shape}", field="q")
    return tt, np.degrees(qq)


def write_joint_log(
    path: str | Path, time: ArrayLike, q: ArrayLike, *, profile: str = "roboisf"
) -> None:
    """Write ``time`` (N,) s and ``q`` (N, 6) rad as a joint log, atomically: Parquet (SI) for a
    ``.parquet`` name, else the roboisf CSV in degrees — or, with ``profile``, as a controller
    would, with that joint-log format's registered writer (:mod:`roboisf.formats`; ``"abb"``,
    ``"kuka"``: their modules in :mod:`roboisf.logs.formats` state the layout and rounding)."""
    tt = np.asarray(time, dtype=float).reshape(-1)
    qq = np.asarray(q, dtype=float)
    if qq.shape != (tt.size, 6):
        raise InputError(f"expected q of shape ({tt.size}, 6), got {qq.shape}", field="q")
    if Path(path).suffix.lower() == ".parquet":
        from roboisf.logs.logparquet import write_joint_parquet

        write_joint_parquet(path, tt, qq)
        return
    if profile != "roboisf":
        fmt = get_file_format("joint_log", profile, field="profile")
        if fmt.writer is None or fmt.binary:
            raise InputError(
                f"joint-log profile {profile!r} has no text writer; expected one of "
                f"{', '.join(joint_profiles_written())}",
                field="profile",
            )
        fmt.writer(path, tt, qq)
        return
    data = np.column_stack([tt, np.degrees(qq)])
    body = "# units: time=s angle=deg\n" + ",".join(JOINT_COLUMNS) + "\n"
    body += format_rows(data, ["%.6f"] + ["%.9f"] * 6)
    with atomic_write(path) as f:
        f.write(body)
