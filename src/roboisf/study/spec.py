"""The study folder: ``study.toml`` and the files it names.

A study is what a user hands ``roboisf analyze``: the part, the tool and tool holder, the robot,
the units of every file, and one or more runs (``cnc``, ``robot``) with their files. The whole
file is validated before anything is computed and **every** problem is reported at once, each
with its file and key (:class:`StudyError`). The full format, with a complete example, is in
``docs/study.md``.

Poses are written ``[x, y, z, roll, pitch, yaw]`` in mm and degrees, rotation
``Rz(yaw) Ry(pitch) Rx(roll)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames.pose import XYZ_RPY_MM_DEG, pose_numbers, pose_transform
from roboisf.io.units import ANGLE_UNITS, FORCE_UNITS, LENGTH_UNITS, MOMENT_UNITS, TIME_UNITS
from roboisf.parts import Part, part_from_dict
from roboisf.plausible import Bound, check_plausible, unit_slip
from roboisf.scan.deviation import default_rim_band
from roboisf.study.locate import read_study_toml

__all__ = [
    "AnalysisSpec",
    "ForceSensorSpec",
    "HolderSpec",
    "RobotSpec",
    "RunSpec",
    "Study",
    "StudyError",
    "ToolSpec",
    "UnitsSpec",
    "load_study",
    "pose_to_transform",
]

F64 = NDArray[np.float64]


class StudyError(InputError):
    """Every problem found in a study, listed one per line."""

    def __init__(self, problems: list[InputError], file: Path) -> None:
        self.problems = problems
        lines = "\n".join(f"  - {p}" for p in problems)
        super().__init__(f"{len(problems)} problem(s) in the study:\n{lines}", file=file)


def pose_to_transform(
    values: Any, *, field: str, file: Path | None = None, position: str | None = None
) -> F64:
    """``[x, y, z, roll, pitch, yaw]`` (mm, deg) → 4×4 transform (m).

    ``position`` names the :data:`roboisf.plausible.BOUNDS` entry x, y and z must lie in (the
    angles lie in ±720°): a position no real cell has (1e29 mm, a value in µm) is refused with
    the unit slip that explains it.
    """
    values = pose_numbers(values, XYZ_RPY_MM_DEG, field=field, file=file, strings=False)
    if position is not None:
        for i, axis in enumerate(("x", "y", "z", "roll", "pitch", "yaw")):
            check_plausible(
                values[i], position if i < 3 else "angle", file=file, field=f"{field}[{axis}]"
            )
    return pose_transform(values, XYZ_RPY_MM_DEG)


@dataclass(frozen=True)
class UnitsSpec:
    """Default units of files that do not declare their own (``[units]``)."""

    length: str = "mm"
    angle: str = "deg"
    force: str = "N"
    moment: str = "N*m"
    time: str = "s"


@dataclass(frozen=True)
class ToolSpec:
    """``[tool]``: the ball tool. Lengths in m.

    ``compliance`` is a compliance JSON (``roboisf tool-stiffness``) about the tool tip; without
    it the compliance is computed from ``free_length``/``shank_diameter`` by ``method``.
    """

    ball_diameter: float
    compliance: Path | None = None
    free_length: float | None = None
    shank_diameter: float | None = None
    method: Literal["beam", "fe"] = "beam"

    @property
    def radius(self) -> float:
        return self.ball_diameter / 2


@dataclass(frozen=True)
class HolderSpec:
    """``[tool_holder]``: compliance JSON about the holder's reference point (its nose), and the
    distance from that point down the tool axis to the tool tip (``offset``, m)."""

    compliance: Path | None = None
    offset: float = 0.0
    rigid: bool = False


@dataclass(frozen=True)
class RobotSpec:
    """``[robot]``: preset name or file, placement ``T_base_work``, flange → tip, stiffness."""

    model: str
    T_base_work: F64
    T_flange_tip: F64 | None = None
    joint_stiffness: tuple[float, ...] | None = None
    tool_rotation: float = 0.0
    #: a URDF robot's flange link (default: the URDF reader's choice; ``--tip-link``)
    tip_link: str | None = None


@dataclass(frozen=True)
class ForceSensorSpec:
    """A force log and where its sensor sits.

    ``mount = "fixture"``: fixed in the work frame at ``pose`` = ``T_work_sensor`` (CNC
    dynamometer under the fixture). ``mount = "flange"``: moves with the tool, ``pose`` =
    ``T_tip_sensor`` (robot F/T sensor). ``load_on`` says which body's load the sensor reports:
    ``"workpiece"`` (the tool pushing the sheet; a dynamometer) or ``"tool"``.
    """

    file: Path
    mount: Literal["fixture", "flange"]
    pose: F64
    load_on: Literal["tool", "workpiece"]
    time_offset: float = 0.0
    #: the log's format (``roboisf.logs.logprofile.study_formats``), header names for "columns",
    #: and its units (quantity → unit) when the file does not declare them
    format: str = "auto"
    columns: dict[str, str] | None = None
    units: dict[str, str] | None = None
    #: conditioning (``roboisf.sensor``): "none" | "auto" | (t0, t1) s on the log's clock;
    #: mass below a flange sensor (kg) and its centre of gravity in the sensor frame (m)
    tare: str | tuple[float, float] = "none"
    tool_mass: float | None = None
    tool_cog: tuple[float, float, float] | None = None
    #: ``"joint"``: the log's clock is the joint log's (one controller logs both); ``"own"``: a
    #: separate logger, aligned by its force signature against the joint-log timing
    clock: Literal["joint", "own"] = "joint"
    #: times that do not strictly increase: "refuse" or "repair" (``roboisf.io.timestamps``)
    timestamps: str = "refuse"


@dataclass(frozen=True)
class RunSpec:
    """``[runs.NAME]``: one formed part."""

    name: str
    machine: Literal["cnc", "robot"]
    toolpath: Path
    forces: ForceSensorSpec
    scan: Path
    scan_unit: str = "mm"
    joints: Path | None = None
    thickness: Path | None = None
    #: how a CAM-program toolpath is imported (roboisf.toolpath.importer): "auto" | "iso" | …
    toolpath_format: str = "auto"
    #: the point a CAM program names: "tip" | "center"
    toolpath_point: str = "tip"
    #: a joint log given as a table: its format, header names and units
    joints_format: str = "auto"
    joints_columns: dict[str, str] | None = None
    joints_units: dict[str, str] | None = None
    #: the joint log's timestamp policy: "refuse" | "repair" (``roboisf.io.timestamps``)
    joints_timestamps: str = "refuse"
    #: how the logs are matched to the toolpath (roboisf.sync): ``"time"``, ``"position"``
    #: (the default with a joint log) or ``"force"``
    sync: Literal["time", "position", "force"] = "time"
    #: a robot run formed with a compensated program: the ``per_point.csv`` of the ``roboisf
    #: compensate`` output that wrote it (its ``springback_offset_dn`` is the iteration's state)
    compensation: Path | None = None


@dataclass(frozen=True)
class AnalysisSpec:
    """``[analysis]``: rim band excluded (m), contour of the polar plot (m; None, the default:
    the report shows the lap nearest the middle of the analysed wall), scan registration, radius
    around a toolpath point's normal line within which scan points are averaged (m)."""

    rim_band: float = 20e-3
    contour_z: float | None = None
    registration: Literal["fixture", "flange", "axisymmetric", "icp", "none"] = "fixture"
    point_radius: float = 1.0e-3
    #: scan points farther than this from the nominal (m) are not the part (fixture, clamps)
    max_distance: float = 3e-3


@dataclass(frozen=True)
class Study:
    """A validated study. Paths are absolute."""

    root: Path
    name: str
    part: Part
    tool: ToolSpec
    holder: HolderSpec
    robot: RobotSpec | None
    runs: dict[str, RunSpec]
    analysis: AnalysisSpec = field(default_factory=AnalysisSpec)
    units: UnitsSpec = field(default_factory=UnitsSpec)
    description: str = ""

    @property
    def cnc(self) -> RunSpec:
        """The CNC run (:class:`InputError` when the study has none: see :attr:`has_cnc`)."""
        for r in self.runs.values():
            if r.machine == "cnc":
                return r
        raise InputError(
            "the study has no CNC run (machine = 'cnc')", file=self.root / "study.toml"
        )

    @property
    def has_cnc(self) -> bool:
        """A CNC twin is there: springback is measured; else it is model-based
        (:mod:`roboisf.decompose.robot_only`)."""
        return any(r.machine == "cnc" for r in self.runs.values())

    @property
    def robot_run(self) -> RunSpec:
        """The robot run analysed: the first in the file (see :meth:`for_run`)."""
        return next(r for r in self.runs.values() if r.machine == "robot")

    @property
    def robot_runs(self) -> list[RunSpec]:
        """Every robot run, in the file's order (successive commanded paths of an iteration:
        ``[runs.robot]``, ``[runs.robot_2]``, …; docs/study.md, "Several robot runs")."""
        return [r for r in self.runs.values() if r.machine == "robot"]

    def for_run(self, name: str) -> Study:
        """This study with its CNC run and the one robot run ``name`` (what ``analyze`` and
        ``compensate`` work on). Raises :class:`InputError` for an unknown robot run."""
        names = [r.name for r in self.robot_runs]
        if name not in names:
            raise InputError(
                f"no robot run {name!r}; the study has {', '.join(names)}",
                file=self.root / "study.toml",
                field="--run",
            )
        keep = {k: r for k, r in self.runs.items() if r.machine != "robot" or k == name}
        return replace(self, runs=keep)


# -- loading -----------------------------------------------------------------------------------

_TOP = {"study", "units", "part", "tool", "tool_holder", "robot", "analysis", "runs"}


class _Collector:
    def __init__(self, file: Path) -> None:
        self.file = file
        self.problems: list[InputError] = []

    def add(self, message: str, key: str) -> None:
        self.problems.append(InputError(message, file=self.file, field=key))

    def catch(self, err: InputError, key: str) -> None:
        f = err.file or self.file
        fld = (
            err.field
            if err.field and err.field.startswith(key)
            else (f"{key}.{err.field}" if err.field else key)
        )
        self.problems.append(InputError(err.message, file=f, line=err.line, field=fld))

    def table(
        self, data: dict[str, Any], key: str, allowed: set[str], required: bool = True
    ) -> dict[str, Any]:
        if key not in data:
            if required:
                self.add("missing table", key)
            return {}
        t = data[key]
        if not isinstance(t, dict):
            self.add("expected a table", key)
            return {}
        for k in sorted(set(t) - allowed):
            self.add(f"unknown key; expected one of {', '.join(sorted(allowed))}", f"{key}.{k}")
        return t

    def number(
        self,
        t: dict[str, Any],
        key: str,
        name: str,
        *,
        default: float | None = None,
        positive: bool = False,
        required: bool = True,
        bound: str | None = None,
    ) -> float | None:
        if name not in t:
            if default is None and required:
                self.add("missing key", f"{key}.{name}")
            return default
        v = t[name]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            self.add(f"expected a finite number, got {v!r}", f"{key}.{name}")
            return default
        if positive and v <= 0:
            self.add(f"must be > 0, got {v}", f"{key}.{name}")
            return default
        if bound is not None:  # the range a real cell has (roboisf.plausible)
            try:
                check_plausible(v, bound, file=self.file, field=f"{key}.{name}")
            except InputError as e:
                self.problems.append(e)
                return default
        return float(v)

    def path(
        self, root: Path, t: dict[str, Any], key: str, name: str, *, required: bool = True
    ) -> Path | None:
        if name not in t:
            if required:
                self.add("missing file", f"{key}.{name}")
            return None
        v = t[name]
        if not isinstance(v, str) or not v:
            self.add(f"expected a file name, got {v!r}", f"{key}.{name}")
            return None
        p = Path(v)
        p = p if p.is_absolute() else root / p
        try:
            found = p.is_file()
        except OSError as e:  # a name too long for the file system, a loop of links …
            what = e.strerror or str(e)
            self.add(
                f"{what[:1].lower()}{what[1:]}: {v[:40]}… ({len(v)} characters)", f"{key}.{name}"
            )
            return None
        if not found:
            self.add(f"file not found: {p}", f"{key}.{name}")
            return None
        return p

    def string(
        self, t: dict[str, Any], key: str, name: str, default: str | None = None
    ) -> str | None:
        """``t[name]`` as a TOML string; a problem (and ``default``) for any other type."""
        if name not in t:
            return default
        v = t[name]
        if not isinstance(v, str):
            self.add(f"expected a string, got {v!r}", f"{key}.{name}")
            return default
        return v

    def boolean(self, t: dict[str, Any], key: str, name: str, default: bool) -> bool:
        """``t[name]`` as a TOML boolean (``true``/``false``, unquoted): ``"no"`` is a string and
        would be truthy in Python, silently meaning the opposite."""
        if name not in t:
            return default
        v = t[name]
        if not isinstance(v, bool):
            self.add(
                f"expected true or false (a TOML boolean, unquoted), got {v!r}", f"{key}.{name}"
            )
            return default
        return v

    def choice(
        self,
        t: dict[str, Any],
        key: str,
        name: str,
        options: tuple[str, ...],
        default: str | None = None,
    ) -> str | None:
        if name not in t:
            if default is None:
                self.add(f"missing key; expected one of {', '.join(options)}", f"{key}.{name}")
            return default
        v = t[name]
        if not isinstance(v, str) or v not in options:
            self.add(f"expected one of {', '.join(options)}, got {v!r}", f"{key}.{name}")
            return default
        return str(v)


def _units(c: _Collector, data: dict[str, Any]) -> UnitsSpec:
    t = c.table(data, "units", {"length", "angle", "force", "moment", "time"}, required=False)
    tables = {
        "length": LENGTH_UNITS,
        "angle": ANGLE_UNITS,
        "force": FORCE_UNITS,
        "moment": MOMENT_UNITS,
        "time": TIME_UNITS,
    }
    out = {}
    for k, table in tables.items():
        if k in t:
            if not isinstance(t[k], str) or t[k] not in table:
                c.add(f"unknown unit {t[k]!r}; expected one of {', '.join(table)}", f"units.{k}")
            else:
                out[k] = t[k]
    return UnitsSpec(**out)


def _forces(c: _Collector, root: Path, t: Any, key: str, machine: str) -> ForceSensorSpec | None:
    if not isinstance(t, dict):
        c.add("expected a table {file, mount, pose, load_on}", key)
        return None
    allowed = {"file", "mount", "pose", "load_on", "time_offset", "clock", *_LOG_KEYS, *_COND_KEYS}
    for k in sorted(set(t) - allowed):
        c.add(f"unknown key; expected {', '.join(sorted(allowed))}", f"{key}.{k}")
    f = c.path(root, t, key, "file")
    mount = c.choice(
        t, key, "mount", ("fixture", "flange"), default="fixture" if machine == "cnc" else "flange"
    )
    load_on = c.choice(
        t,
        key,
        "load_on",
        ("tool", "workpiece"),
        default="workpiece" if mount == "fixture" else "tool",
    )
    pose = None
    if "pose" not in t:
        c.add(
            "missing key: the sensor pose [x, y, z, roll, pitch, yaw] (mm, deg): "
            "T_work_sensor for a fixture sensor, T_tip_sensor for a flange sensor",
            f"{key}.pose",
        )
    else:
        try:
            pose = pose_to_transform(
                t["pose"], field=f"{key}.pose", file=c.file, position="sensor_position"
            )
        except InputError as e:
            c.catch(e, f"{key}.pose")
    off = c.number(t, key, "time_offset", default=0.0, bound="time_offset")
    from roboisf.logs.logprofile import study_formats

    fmt, cols, units = _log_keys(
        c, t, key, study_formats("force_log"), ("time", "force", "moment", "length")
    )
    tare, mass, cog = _conditioning(c, t, key, mount)
    clock = c.choice(t, key, "clock", ("joint", "own"), default="joint")
    ts = _timestamps(c, t, key)
    if (
        f is None
        or pose is None
        or mount is None
        or load_on is None
        or off is None
        or clock is None
    ):
        return None
    return ForceSensorSpec(
        f,
        mount,  # type: ignore[arg-type]
        pose,
        load_on,  # type: ignore[arg-type]
        off,
        fmt,
        cols,
        units,
        tare,
        mass,
        cog,
        clock,  # type: ignore[arg-type]
        ts,
    )


def _timestamps(c: _Collector, t: dict[str, Any], key: str) -> str:
    """A log's ``timestamps`` policy (``roboisf.io.timestamps``)."""
    from roboisf.io.timestamps import TIME_POLICIES

    return c.choice(t, key, "timestamps", TIME_POLICIES, default="refuse") or "refuse"


_LOG_KEYS = ("format", "columns", "units", "timestamps")
_COND_KEYS = ("tare", "tool_mass", "tool_cog")


def _log_keys(
    c: _Collector,
    t: dict[str, Any],
    key: str,
    formats: tuple[str, ...],
    quantities: tuple[str, ...],
) -> tuple[str, dict[str, str] | None, dict[str, str] | None]:
    """``format``, ``columns`` and ``units`` of a log table (``docs/study.md``, logs)."""
    fmt = c.choice(t, key, "format", formats, default="auto") or "auto"
    cols = None
    if "columns" in t:
        v = t["columns"]
        if not isinstance(v, dict) or not all(isinstance(x, str) and x for x in v.values()):
            c.add(
                'expected a table of header names, e.g. {time = "t [s]", Fx = "Kraft X"}',
                f"{key}.columns",
            )
        else:
            cols = {str(k): str(x) for k, x in v.items()}
            if fmt not in ("auto", "columns"):
                c.add(
                    f"columns = {{...}} reads the file by its names; format {fmt!r} "
                    'conflicts (use format = "columns" or leave it out)',
                    f"{key}.format",
                )
            fmt = "columns"
    elif fmt == "columns":
        c.add('format "columns" needs a columns = {...} table', f"{key}.columns")
    units = None
    if "units" in t:
        v = t["units"]
        if not isinstance(v, dict):
            c.add(
                f"expected a table {{{', '.join(q + ' = ...' for q in quantities)}}}",
                f"{key}.units",
            )
        else:
            units = {}
            from roboisf.io.units import log_unit_to_si

            for q, u in v.items():
                if q not in quantities:
                    c.add(f"unknown quantity; expected {', '.join(quantities)}", f"{key}.units.{q}")
                    continue
                try:
                    log_unit_to_si(str(u), q)
                except InputError as e:
                    c.add(e.message, f"{key}.units.{q}")
                    continue
                units[q] = str(u)
    return fmt, cols, units


def _conditioning(
    c: _Collector, t: dict[str, Any], key: str, mount: str | None
) -> tuple[str | tuple[float, float], float | None, tuple[float, float, float] | None]:
    tare: str | tuple[float, float] = "none"
    if "tare" in t:
        v = t["tare"]
        if v in ("none", "auto"):
            tare = v
        elif (
            isinstance(v, list)
            and len(v) == 2
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
            and v[1] > v[0]
        ):
            tare = (float(v[0]), float(v[1]))
        else:
            c.add(f'expected "none", "auto" or [t0, t1] (s, t1 > t0), got {v!r}', f"{key}.tare")
    mass = c.number(t, key, "tool_mass", positive=True, required=False, bound="tool_mass")
    cog = None
    if "tool_cog" in t:
        v = t["tool_cog"]
        if not (
            isinstance(v, list)
            and len(v) == 3
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        ):
            c.add(f"expected [x, y, z] in mm (sensor frame), got {v!r}", f"{key}.tool_cog")
        else:
            for i, x in enumerate(v):
                try:
                    check_plausible(x, "tool_cog", file=c.file, field=f"{key}.tool_cog[{i}]")
                except InputError as e:
                    c.problems.append(e)
            cog = (float(v[0]) * 1e-3, float(v[1]) * 1e-3, float(v[2]) * 1e-3)
    if (mass is None) != (cog is None):
        c.add("give both tool_mass (kg) and tool_cog (mm) for gravity compensation", key)
    if mass is not None and mount == "fixture":
        c.add(
            "tool_mass is for a flange sensor (the tool hangs below it); a fixture sensor is "
            "tared instead",
            f"{key}.tool_mass",
        )
    return tare, mass, cog


def _sync(c: _Collector, r: dict[str, Any], key: str, fs: ForceSensorSpec | None) -> str | None:
    """``[runs.X] sync``: ``"position"`` by default when the run has a joint log (a real run
    drifts against nominal time; the joint log says where the tool was), else ``"time"`` (force
    alignment depends on the part turning the force, so it is asked for, not assumed)."""
    default = "position" if "joints" in r else "time"
    sync = c.choice(r, key, "sync", ("time", "position", "force"), default=default)
    if sync == "position" and "joints" not in r:
        c.add(
            'sync = "position" needs a joint log (joints = "…"); without one use "force" '
            '(the force signature) or "time" (nominal time + time_offset)',
            f"{key}.sync",
        )
        return None
    if fs is not None and fs.clock == "own" and sync != "position":
        c.add(
            'clock = "own" applies to sync = "position" (a force log aligned against the '
            f'timing of the joint log); with sync = "{sync}" remove it',
            f"{key}.forces.clock",
        )
        return None
    return sync


def _robot_model(c: _Collector, root: Path, model: str) -> str | None:
    """A preset name as is; anything else is a robot file (.toml/.urdf) resolved relative to
    the study folder (never the working directory) and returned as an absolute path."""
    from roboisf.robot import list_robots

    if model in list_robots():
        return model
    p = Path(model)
    p = p if p.is_absolute() else root / p
    if not p.is_file():
        c.add(
            f"{model!r} is neither a preset ({', '.join(list_robots())}) nor a robot file "
            f"(looked for {p}; relative paths are relative to the study folder)",
            "robot.model",
        )
        return None
    return str(p)


def _check_reach(
    c: _Collector,
    model: str,
    T_bw: F64,
    T_ft: F64 | None,
    part: Part | None,
    tip_link: str | None = None,
) -> None:
    """Refuse a placement that puts the part outside any pose the robot could reach.

    The bound is generous and cheap: no point is farther from the base origin than the sum of
    the chain's link offsets plus the flange → tip distance, and the part extends at most to the
    farthest corner of its bounding box (``part.bounds``, any part kind) from the work origin.
    A placement of 1e9 mm (metres typed as mm, or a stray digit) fails here instead of as an IK
    failure, or silently when the joints come from a log.
    """
    from roboisf.robot import load_robot

    try:
        robot = load_robot(model, tip_link=tip_link)
    except InputError as e:
        c.catch(e, "robot.model" if tip_link is None else "robot.tip_link")
        return
    tip = robot.T_flange_tip if T_ft is None else T_ft
    reach = float(
        np.linalg.norm(robot.chain.F[:, :3, 3], axis=1).sum() + np.linalg.norm(tip[:3, 3])
    )
    size = 0.0
    if part is not None:
        lo, hi = (np.asarray(b, dtype=float) for b in part.bounds)
        size = float(np.linalg.norm(np.maximum(np.abs(lo), np.abs(hi))))
    dist = float(np.linalg.norm(T_bw[:3, 3]))
    if dist - size > reach:
        c.add(
            f"puts the work origin {dist:.4g} m from the robot base, but {robot.name} reaches at "
            f"most {reach:.3g} m (links + tool) and the part spans {size * 1e3:.4g} mm: the part "
            "is out of reach (placement is [x, y, z, roll, pitch, yaw] in mm and deg)",
            "robot.placement",
        )


def _toolpath_import_keys(c: _Collector, r: dict[str, Any], key: str) -> tuple[str, str]:
    """``toolpath_format`` and ``toolpath_point`` of a run (a CAM program as its toolpath)."""
    from roboisf.toolpath.importer import cam_format_names

    fmt = c.choice(r, key, "toolpath_format", ("auto", "csv", *cam_format_names()), default="auto")
    point = c.choice(r, key, "toolpath_point", ("tip", "center"), default="tip")
    return fmt or "auto", point or "tip"


def load_study(path: str | Path) -> Study:
    """Load and validate ``study.toml`` (or a folder containing it).

    Raises
    ------
    StudyError
        listing every problem (file, key, what was expected).
    """
    file, data = read_study_toml(path)
    root = file.parent.resolve()
    c = _Collector(file)
    for k in sorted(set(data) - _TOP):
        c.add(f"unknown table; expected {', '.join(sorted(_TOP))}", k)

    st = c.table(data, "study", {"name", "description"}, required=False)
    name = c.string(st, "study", "name", root.name) or root.name
    description = c.string(st, "study", "description", "") or ""
    units = _units(c, data)
    part = _load_part(c, data, file)
    tool = _load_tool(c, data, root)
    holder = _load_holder(c, data, root)
    runs = _load_runs(c, data, root, units)
    robot = _load_robot(c, data, root, file, part)
    analysis = _load_analysis(c, data, part)
    if c.problems:
        raise StudyError(c.problems, file)
    assert part is not None and tool is not None
    return Study(root, name, part, tool, holder, robot, runs, analysis, units, description)


def _load_part(c: _Collector, data: dict[str, Any], file: Path) -> Part | None:
    """``[part]``: any registered part kind (None, with the problem collected, if it fails)."""
    part = None
    if "part" not in data:
        c.add("missing table", "part")
    else:
        try:
            part = part_from_dict(data["part"], where=file)  # any part kind
        except InputError as e:
            c.catch(e, "part")

    return part


def _load_tool(c: _Collector, data: dict[str, Any], root: Path) -> ToolSpec | None:
    """``[tool]``: the ball and the source of its compliance."""
    tt = c.table(
        data, "tool", {"ball_diameter", "compliance", "free_length", "shank_diameter", "method"}
    )
    # an empty [tool] table still needs its ball (c.table reported a missing or non-table one)
    has_tool = isinstance(data.get("tool"), dict)
    ball = (
        c.number(tt, "tool", "ball_diameter", positive=True, bound="ball_diameter")
        if has_tool
        else None
    )
    tool_c = c.path(root, tt, "tool", "compliance", required=False)
    free = c.number(tt, "tool", "free_length", positive=True, required=False, bound="free_length")
    shank = c.number(
        tt, "tool", "shank_diameter", positive=True, required=False, bound="shank_diameter"
    )
    method = c.choice(tt, "tool", "method", ("beam", "fe"), default="beam")
    if has_tool and tool_c is None and "compliance" not in tt and free is None:
        c.add("give either 'compliance' (a JSON file) or 'free_length' (mm) to compute it", "tool")
    tool = None
    if ball is not None:
        tool = ToolSpec(
            ball * 1e-3,
            tool_c,
            None if free is None else free * 1e-3,
            None if shank is None else shank * 1e-3,
            cast(Literal["beam", "fe"], method),
        )

    return tool


def _load_holder(c: _Collector, data: dict[str, Any], root: Path) -> HolderSpec:
    """``[tool_holder]``: its compliance file and offset, or rigid."""
    ht = c.table(data, "tool_holder", {"compliance", "offset", "rigid"}, required=False)
    rigid = c.boolean(ht, "tool_holder", "rigid", not ht)
    holder_c = c.path(root, ht, "tool_holder", "compliance", required=not rigid)
    offset = c.number(ht, "tool_holder", "offset", default=0.0, bound="holder_offset")
    return HolderSpec(holder_c, (offset or 0.0) * 1e-3, rigid)


def _load_runs(
    c: _Collector, data: dict[str, Any], root: Path, units: UnitsSpec
) -> dict[str, RunSpec]:
    """``[runs.NAME]``: every run (those with a problem are left out, the problem collected)."""
    runs: dict[str, RunSpec] = {}
    rt = data.get("runs")
    if not isinstance(rt, dict) or not rt:
        c.add(
            "missing: at least one [runs.NAME] table (a 'cnc' and a 'robot' run to decompose)",
            "runs",
        )
        rt = {}
    for rname, r in rt.items():
        run = _load_run(c, data, root, units, rname, r)
        if run is not None:
            runs[rname] = run
    machines = [r.get("machine") for r in rt.values() if isinstance(r, dict)]
    if rt and "robot" not in machines:
        c.add(
            "the analysis needs a run with machine = 'robot' (and one with 'cnc' of the same "
            "toolpath to measure springback; without it springback is model-based)",
            "runs",
        )

    return runs


def _load_run(
    c: _Collector, data: dict[str, Any], root: Path, units: UnitsSpec, rname: str, r: Any
) -> RunSpec | None:
    """One ``[runs.NAME]`` table: its machine, files, log formats, alignment and compensation."""
    key = f"runs.{rname}"
    if not isinstance(r, dict):
        c.add("expected a table", key)
        return None
    allowed = {"machine", "toolpath", "forces", "scan", "scan_unit", "joints", "thickness"}
    allowed |= {"toolpath_format", "toolpath_point"}  # CAM import (docs/toolpaths.md)
    allowed |= {"sync"}  # log alignment (docs/study.md, Alignment)
    allowed |= {"compensation"}  # the compensate output of its program (docs/study.md)
    for k in sorted(set(r) - allowed):
        c.add(f"unknown key; expected one of {', '.join(sorted(allowed))}", f"{key}.{k}")
    machine = c.choice(r, key, "machine", ("cnc", "robot"))
    tp = c.path(root, r, key, "toolpath")
    sc = c.path(root, r, key, "scan")
    su = r.get("scan_unit", units.length)
    if not isinstance(su, str) or su not in LENGTH_UNITS:
        c.add(
            f"unknown length unit {su!r}; expected one of {', '.join(LENGTH_UNITS)}",
            f"{key}.scan_unit",
        )
    fs = None
    if "forces" not in r:
        c.add("missing table", f"{key}.forces")
    else:
        fs = _forces(c, root, r["forces"], f"{key}.forces", machine or "cnc")
    j_fmt, j_cols, j_units, j_ts = "auto", None, None, "refuse"
    if isinstance(r.get("joints"), dict):
        jt = r["joints"]
        jkey = f"{key}.joints"
        for k in sorted(set(jt) - {"file", *_LOG_KEYS}):
            c.add(
                "unknown key; expected file, format, columns, units, timestamps",
                f"{jkey}.{k}",
            )
        j_ts = _timestamps(c, jt, jkey)
        from roboisf.logs.logprofile import study_formats

        joints = c.path(root, jt, jkey, "file")
        j_fmt, j_cols, j_units = _log_keys(
            c, jt, jkey, study_formats("joint_log"), ("time", "angle")
        )
    else:
        joints = c.path(root, r, key, "joints", required=False)
    thick = c.path(root, r, key, "thickness", required=False)
    if machine == "robot" and joints is None and "joints" not in r and "robot" not in data:
        c.add("a robot run needs 'joints' (a joint log) or a [robot] table to solve IK", key)
    tp_fmt, tp_point = _toolpath_import_keys(c, r, key)
    sync = _sync(c, r, key, fs)
    comp = c.path(root, r, key, "compensation", required=False)
    if None not in (machine, tp, sc, fs, sync):
        return RunSpec(
            rname,
            machine,  # type: ignore[arg-type]
            tp,  # type: ignore[arg-type]
            fs,  # type: ignore[arg-type]
            sc,  # type: ignore[arg-type]
            su,
            joints,
            thick,
            toolpath_format=tp_fmt,
            toolpath_point=tp_point,
            joints_format=j_fmt,
            joints_columns=j_cols,
            joints_units=j_units,
            joints_timestamps=j_ts,
            sync=sync,  # type: ignore[arg-type]
            compensation=comp,
        )
    return None


def _load_robot(
    c: _Collector, data: dict[str, Any], root: Path, file: Path, part: Part | None
) -> RobotSpec | None:
    """``[robot]``: the model, its placement, the tool and the joint stiffness (reach checked)."""
    robot = None
    if "robot" in data:
        rb = c.table(
            data,
            "robot",
            {"model", "placement", "flange_to_tip", "joint_stiffness", "tool_rotation", "tip_link"},
        )
        model = rb.get("model")
        if not isinstance(model, str) or not model:
            c.add("missing key: a preset name (roboisf robot list) or a robot file", "robot.model")
            model = None
        else:
            model = _robot_model(c, root, model)
        T_bw = T_ft = None
        try:
            T_bw = pose_to_transform(
                rb.get("placement"), field="robot.placement", file=file, position="placement"
            )
        except InputError as e:
            c.catch(e, "robot.placement")
        if "flange_to_tip" in rb:
            try:
                T_ft = pose_to_transform(
                    rb["flange_to_tip"],
                    field="robot.flange_to_tip",
                    file=file,
                    position="flange_to_tip",
                )
            except InputError as e:
                c.catch(e, "robot.flange_to_tip")
        K = rb.get("joint_stiffness")
        if K is not None and not (
            isinstance(K, list)
            and len(K) == 6
            and all(isinstance(k, int | float) and not isinstance(k, bool) and k > 0 for k in K)
        ):
            c.add(f"expected 6 positive numbers (N·m/rad), got {K!r}", "robot.joint_stiffness")
            K = None
        for i, k in enumerate(K or ()):
            try:
                check_plausible(
                    k, "joint_stiffness", file=file, field=f"robot.joint_stiffness[{i}]"
                )
            except InputError as e:
                c.problems.append(e)
                K = None
                break
        rot = c.number(rb, "robot", "tool_rotation", default=0.0, bound="angle")
        tip = rb.get("tip_link")
        if tip is not None and not (isinstance(tip, str) and tip):
            c.add(f"expected the name of a link of the URDF, got {tip!r}", "robot.tip_link")
            model = None
        if isinstance(model, str) and T_bw is not None:
            _check_reach(c, model, T_bw, T_ft, part, tip)
            robot = RobotSpec(
                model,
                T_bw,
                T_ft,
                None if K is None else tuple(float(k) for k in K),
                math.radians(rot or 0.0),
                tip,
            )

    return robot


def _load_analysis(c: _Collector, data: dict[str, Any], part: Part | None) -> AnalysisSpec:
    """``[analysis]``: rim band, contour, registration and the scan's point neighbourhoods."""
    at = c.table(
        data,
        "analysis",
        {"rim_band", "contour_z", "registration", "point_radius", "max_distance"},
        required=False,
    )
    rim = c.number(at, "analysis", "rim_band", required=False, bound="rim_band")
    cz = c.number(at, "analysis", "contour_z", required=False)
    if part is not None and cz is not None and "contour_z" in at:
        depth_mm = part.depth * 1e3
        if not -depth_mm <= cz < 0:  # the polar plot's contour cuts the formed wall
            slip = unit_slip(cz, Bound(-depth_mm, -1e-9, "mm", ""))
            c.add(
                f"{cz:.6g} mm is not on the part's wall: a contour lies below the sheet "
                f"(z < 0) and above the bottom (z ≥ −{depth_mm:.6g} mm)"
                + (f"; {slip}" if slip else ""),
                "analysis.contour_z",
            )
            cz = None
    reg = c.choice(
        at,
        "analysis",
        "registration",
        ("fixture", "flange", "axisymmetric", "icp", "none"),
        default="fixture",
    )
    prad = c.number(
        at, "analysis", "point_radius", default=1.0, positive=True, bound="point_radius"
    )
    maxd = c.number(
        at, "analysis", "max_distance", default=3.0, positive=True, bound="max_distance"
    )
    if rim is not None and rim < 0:
        c.add("must be ≥ 0 mm", "analysis.rim_band")
    if rim is None:  # scaled with the part's depth: min(20 mm, 0.6·depth)
        rim_band = default_rim_band(part.depth) if part is not None else 20e-3
    else:
        rim_band = rim * 1e-3
    return AnalysisSpec(
        rim_band,
        None if cz is None else cz * 1e-3,
        cast(Literal["fixture", "flange", "axisymmetric", "icp", "none"], reg or "fixture"),
        (prad or 1.0) * 1e-3,
        (maxd or 3.0) * 1e-3,
    )
