"""``roboisf study init``: a ``study.toml`` drafted from the files a user has.

:func:`detect_files` tries every file of a folder with roboisf's public readers (:data:`READERS`,
in order; the first that accepts a file names its kind), so a reader added to roboisf is picked
up here by adding it to that list. :func:`draft_study` assigns the detected files to the
study's keys — the CNC and robot run by the words ``cnc`` and ``robot``/``rob`` in their names,
the joint log to the robot run, a compliance JSON with ``holder`` in its name to the tool
holder — and fills what no file says (robot model and placement, flange → tip, sensor poses,
the part when no part TOML is in the folder) from the caller's options, or with a ``"TODO: …"``
string that ``load_study`` refuses with the key's name and what it expects.

Formats (issue #13): a force log's profile and a joint log's (``detect_force_format``,
``detect_joint_format``) are written as the log's ``format``, and each unit the file does not
declare as a ``"TODO: …"`` in its ``units`` table (never guessed; joint angles beyond 2π + 0.5
can only be degrees and are written so); a CAM program (tried last: a bare ``x,y,z`` list reads
most numeric tables) is a run's ``toolpath`` with ``toolpath_format`` and ``toolpath_point =
"tip"``, and leaves ``[tool] ball_diameter`` a TODO.

Alignment: the run with a joint log gets ``sync = "position"`` (a real run drifts against
nominal time; the joint log says where the tool was); a run without one ``sync = "time"``
(``"force"`` aligns by the force signature; asked for, not assumed, because it needs a part the
tool turns around).
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roboisf.errors import InputError
from roboisf.frames.pose import pose_numbers

__all__ = ["READERS", "DetectedFile", "StudyDraft", "detect_files", "draft_study", "render_toml"]

#: Files and folders never read (outputs of roboisf, a virtual cell's ground truth, hidden).
_SKIP = {"study.toml", "truth"}


@dataclass(frozen=True)
class DetectedFile:
    """What a file is: ``kind`` (``toolpath``, ``force_log``, ``joint_log``, ``scan``,
    ``thickness``, ``part``, ``compliance``, or ``unknown``), the reader's ``format``, details
    for the user to confirm (units, columns, size) and, for ``unknown``, why each reader refused
    it."""

    path: Path
    kind: str
    format: str
    details: dict[str, str] = field(default_factory=dict)
    problem: str = ""
    #: study keys written beside the file (a log's ``format``/``units``, a CAM program's
    #: ``toolpath_format``/``toolpath_point``); a ``"TODO: …"`` value is for the user to fill
    keys: dict[str, Any] = field(default_factory=dict)


#: What a reader returns: ``(format, details)`` or ``(format, details, study keys)``.
_Result = tuple[str, dict[str, str]] | tuple[str, dict[str, str], dict[str, Any]]


def _toolpath(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.cam.toolpath_csv import read_toolpath_csv

    tp = read_toolpath_csv(p)
    return "roboisf toolpath CSV", {
        "points": str(len(tp)),
        "laps": str(tp.n_laps),
        "ball": f"Ø{2 * tp.tool_radius * 1e3:.4g} mm",
        "feed": f"{tp.feed * 6e4:.4g} mm/min",
        "units": "mm, s (declared)",
    }


def _units_keys(
    needed: list[str], declared: dict[str, str], todo: dict[str, str]
) -> tuple[dict[str, str], str]:
    """``units`` to write for the quantities the file does not declare (a TODO each) and the
    line shown to the user."""
    missing = [q for q in needed if q not in declared]
    shown = ", ".join(f"{q} {declared[q]}" for q in needed if q in declared)
    if missing:
        shown += ("; " if shown else "") + "NOT declared: " + ", ".join(missing) + " (TODO)"
    return {q: _todo(todo[q]) for q in missing}, shown or "none needed"


_FORCE_TODO = {
    "time": "time unit of this log (s, ms)",
    "force": "force unit of this log (N, kN)",
    "moment": "moment unit of this log (N*m, N*mm)",
}


def _force_log(p: Path) -> _Result:
    from roboisf.logs.forcelog import detect_force_format, read_force_log

    profile, cols, declared = detect_force_format(p)
    has_m = all(m in cols for m in ("Mx", "My", "Mz"))
    needed = ["force"] + (["moment"] if has_m else []) + ([] if profile == "ati" else ["time"])
    if profile in ("roboisf", "parquet"):
        # roboisf's own logs take the study's [units] when they do not declare theirs
        units: dict[str, str] = {}
        shown = ", ".join(f"{q} {declared[q]}" for q in needed if q in declared)
        if any(q not in declared for q in needed):
            shown = "NOT declared: the study's [units] apply (s, N, N*m unless set)"
    else:
        units, shown = _units_keys(needed, declared, _FORCE_TODO)
    given = {"time": "s", "force": "N", "moment": "N*m"}  # placeholders to count samples only
    frame = None if profile == "roboisf" else "sensor"
    policy = "refuse"
    for _ in range(2):
        try:
            try:
                log = read_force_log(
                    p,
                    frame=frame,
                    fmt=profile if profile != "parquet" else "auto",
                    timestamps=policy,
                )
            except InputError as e:
                if "not declared" not in e.message:
                    raise
                # read it once with placeholder units to report its size; the study says the
                # real ones
                log = read_force_log(
                    p,
                    frame="sensor",
                    fmt=profile if profile != "parquet" else "auto",
                    time_unit=None if "time" in declared or profile == "ati" else given["time"],
                    force_unit=None if "force" in declared else given["force"],
                    moment_unit=None if "moment" in declared or not has_m else given["moment"],
                    timestamps=policy,
                )
            break
        except InputError as e:
            if policy == "repair" or not _dirty_clock(e):
                raise
            policy = "repair"  # drafted as such, said in the details and the notes
    details = {
        "profile": profile,
        "samples": str(len(log)),
        "span": f"{log.time[0]:.3f} … {log.time[-1]:.3f} s",
        "units": shown,
        "moments": "yes" if log.moments_known else "no (3-component: point force at the tip)",
        "x,y,z": "yes" if log.position is not None else "no",
    }
    if units:
        details["peak |F|"] = "? (units TODO)"
    else:
        details["peak |F|"] = f"{float((log.force**2).sum(axis=1).max() ** 0.5):.4g} N"
    keys: dict[str, Any] = {}
    if profile not in ("roboisf", "parquet"):
        keys["format"] = profile
    if units:
        keys["units"] = units
    if log.notes:
        details["notes"] = "; ".join(log.notes)
    if policy == "repair":
        keys["timestamps"] = "repair"
    return f"force log ({profile})", details, keys


def _dirty_clock(e: InputError) -> bool:
    """A log refused only for times that do not strictly increase (a few repairable rows)."""
    return e.message.startswith("time must strictly increase")


_JOINT_TODO = {
    "time": "time unit of this log (s, ms)",
    "angle": "angle unit of this log (deg, rad)",
}


def _joint_log(p: Path) -> _Result:
    from roboisf.logs.jointlog import detect_joint_format, read_joint_log

    profile, cols, declared = detect_joint_format(p)
    if profile == "roboisf" and "angle" not in declared:
        raise InputError("missing '# units: time=s angle=deg' line", file=p, field="units")
    units, shown = _units_keys(["time", "angle"], declared, _JOINT_TODO)
    policy = "refuse"
    for _ in range(2):
        try:
            log = read_joint_log(
                p,
                fmt=profile if profile != "parquet" else "auto",
                time_unit=None if "time" in declared else "s",
                angle_unit=None if "angle" in declared else "rad",
                timestamps=policy,
            )
            break
        except InputError as e:
            if policy == "repair" or not _dirty_clock(e):
                raise
            policy = "repair"
    if "angle" in units:
        # undeclared angles: values beyond 2π rad (with margin) can only be degrees
        big = float(np.abs(log.q).max())
        if big > 2 * np.pi + 0.5:
            units["angle"] = "deg"
            todo = [q for q in _todos(units)]
            shown = ", ".join(f"{q} {declared[q]}" for q in ("time", "angle") if q in declared)
            shown += f"{'; ' if shown else ''}angle deg (not declared; up to {big:.4g}: not rad)"
            if todo:
                shown += "; NOT declared: " + ", ".join(todo) + " (TODO)"
    details = {
        "profile": profile,
        "samples": str(len(log.time)),
        "span": f"{log.time[0]:.3f} … {log.time[-1]:.3f} s"
        + (" (if s)" if "time" in units else ""),
        "columns": " ".join(cols.get(f"q{i}", "?") for i in range(1, 7)),
        "units": shown,
    }
    keys: dict[str, Any] = {}
    if profile not in ("roboisf", "parquet"):
        keys["format"] = profile
    if units:
        keys["units"] = units
    if log.notes:
        details["notes"] = "; ".join(log.notes)
    if policy == "repair":
        keys["timestamps"] = "repair"
    return f"joint log ({profile})", details, keys


def _units_text(u: object) -> str:
    return "/".join(str(x) for x in u) if isinstance(u, list | tuple) else str(u)


def _cam_toolpath(p: Path) -> _Result:
    """A CAM program (G-code, Sinumerik, APT/CL, x,y,z list) as a run's toolpath."""
    from roboisf.toolpath.importer import ImportOptions, detect_toolpath_format, read_cam_moves

    fmt = detect_toolpath_format(p)
    if fmt == "csv":
        raise InputError("a roboisf toolpath CSV (read as such)", file=p)
    moves = read_cam_moves(p, ImportOptions(fmt=fmt))
    n = len(moves.point)
    details = {
        "program": fmt,
        "moves": str(n),
        "point": "tip (the CAM convention for a ball tool; center if it names the ball centre)",
        "units": _units_text(moves.meta.get("units", "mm")) + " (from the program)",
    }
    if moves.warnings:
        details["warnings"] = f"{len(moves.warnings)} (roboisf toolpath import shows them)"
    return f"CAM program ({fmt})", details, {"toolpath_format": fmt, "toolpath_point": "tip"}


def _thickness(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.logs.thickness import read_thickness_csv

    read_thickness_csv(p)
    return "thickness CSV (depth, thickness)", {"units": "declared in the file"}


def _part(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.parts import load_part

    part = load_part(p)
    return "part TOML", {"kind": str(part.to_dict().get("kind", "?"))}


def _compliance(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.fem.result import load_compliance_json

    c = load_compliance_json(p)
    return "compliance JSON", {"method": str(c.method), "lateral": f"{c.lateral:.3g} m/N"}


def _scan(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.scan import read_scan

    cloud = read_scan(p, unit="mm")
    unit = getattr(cloud, "unit", "mm")
    return f"scan ({p.suffix.lower().lstrip('.')})", {
        "points": str(len(cloud.points)),
        "units": "mm assumed (scan_unit in study.toml)"
        if unit == "mm"
        else f"{unit} (declared by the format)",
    }


#: ``(kind, reader)`` in the order they are tried; a reader returns ``(format, details)`` or
#: raises :class:`InputError`. Add a reader here and ``study init`` detects its files.
READERS: list[tuple[str, Callable[[Path], _Result]]] = [
    ("part", _part),
    ("compliance", _compliance),
    ("toolpath", _toolpath),
    ("force_log", _force_log),
    ("joint_log", _joint_log),
    ("thickness", _thickness),
    ("scan", _scan),
    ("toolpath", _cam_toolpath),  # last: a bare x,y,z list reads most numeric tables
]

_SUFFIXES = {
    "part": {".toml"},
    "compliance": {".json"},
}


def detect_files(folder: str | Path) -> list[DetectedFile]:
    """Every file of ``folder`` (not recursive; ``study.toml``, ``truth/`` and hidden files
    skipped), tried with :data:`READERS` in order: the first reader that accepts it names its
    kind. Sorted by name."""
    root = Path(folder)
    if not root.is_dir():
        raise InputError("not a folder", file=root)
    out = []
    for p in sorted(root.iterdir()):
        if p.name.startswith(".") or p.name in _SKIP or not p.is_file():
            continue
        problems = []
        for kind, reader in READERS:
            only = _SUFFIXES.get(kind)
            if only is not None and p.suffix.lower() not in only:
                continue
            if only is None and p.suffix.lower() in {".toml", ".json"}:
                continue
            try:
                res = reader(p)
            except InputError as e:
                problems.append(f"{kind}: {e.message}")
                continue
            except Exception as e:  # a reader's bug must not stop the survey
                problems.append(f"{kind}: {type(e).__name__}")
                continue
            fmt, details = res[0], res[1]
            keys: dict[str, Any] = res[2] if len(res) == 3 else {}
            out.append(DetectedFile(p, kind, fmt, details, keys=keys))
            break
        else:
            out.append(DetectedFile(p, "unknown", "", {}, "; ".join(problems[:3])))
    return out


def _repair_note(key: str, f: DetectedFile) -> str:
    return (
        f'{key}.timestamps = "repair": {f.path.name}\'s time does not strictly increase '
        f"({f.details.get('notes', '')}); check the logger's clock, or remove the key to refuse"
    )


def _role(name: str) -> str | None:
    n = name.lower()
    if "cnc" in n:
        return "cnc"
    if "rob" in n:
        return "robot"
    return None


def _todo(what: str) -> str:
    return f"TODO: {what}"


def _todos(table: dict[str, Any] | None) -> list[str]:
    return [k for k, v in (table or {}).items() if str(v).startswith("TODO")]


@dataclass
class StudyDraft:
    """The drafted ``study.toml`` (``data``), its TODO keys and notes for the user."""

    data: dict[str, Any]
    todo: list[str]
    notes: list[str]


def _pose(values: list[float] | None, what: str, field: str) -> list[float] | str:
    """The pose (mm, deg) as given (checked), or the TODO that asks for it."""
    return pose_numbers(values, field=field) if values is not None else _todo(what)


def draft_study(
    folder: str | Path,
    files: list[DetectedFile],
    *,
    robot: str | None = None,
    placement: list[float] | None = None,
    flange_to_tip: list[float] | None = None,
    tool_rotation: float | None = None,
    part: str | Path | None = None,
    cnc_sensor_pose: list[float] | None = None,
    robot_sensor_pose: list[float] | None = None,
    holder_offset: float | None = None,
    tip_link: str | None = None,
) -> StudyDraft:
    """Assign detected files to a study (see the module docstring). Poses ``[x, y, z, roll,
    pitch, yaw]`` in mm and deg, ``holder_offset`` in mm, ``tool_rotation`` in deg, ``part`` a
    part TOML (instead of one in the folder), ``tip_link`` a URDF robot's flange link (checked
    against the file, written as ``[robot] tip_link``)."""
    root = Path(folder).resolve()
    by: dict[str, list[DetectedFile]] = {}
    for f in files:
        by.setdefault(f.kind, []).append(f)
    todo: list[str] = []
    notes: list[str] = []

    def rel(p: Path) -> str:
        p = p.resolve()
        return str(p.relative_to(root)) if root in p.parents else str(p)

    def pick(kind: str, run: str) -> DetectedFile | None:
        cands = by.get(kind, [])
        if len(cands) == 1 and kind in ("toolpath", "joint_log", "thickness"):
            return cands[0]
        named = [f for f in cands if _role(f.path.name) == run]
        if len(named) == 1:
            return named[0]
        other = "robot" if run == "cnc" else "cnc"
        rest = [f for f in cands if _role(f.path.name) != other]
        if len(cands) == 2 and len(rest) == 1:
            return rest[0]
        return None

    def missing(kind: str, run: str, what: str) -> str:
        """The TODO for a file ``pick`` could not choose: the candidates it had, named."""
        other = "robot" if run == "cnc" else "cnc"
        cands = [rel(f.path) for f in by.get(kind, []) if _role(f.path.name) != other]
        if not cands:
            return _todo(what)
        return _todo(f"{what} — one of: {', '.join(cands)}")

    data: dict[str, Any] = {"study": {"name": root.name, "description": "drafted by study init"}}
    # part
    part_file = Path(part) if part is not None else None
    if part_file is not None and not part_file.is_file():
        raise InputError(
            f"no part file here (looked for {part_file.resolve()}; a path relative to the "
            "working folder, as typed)",
            file=part_file,
            field="--part",
        )
    if part_file is None and len(by.get("part", [])) == 1:
        part_file = by["part"][0].path
    if part_file is not None:
        raw = tomllib.loads(part_file.read_text(encoding="utf-8"))["part"]
        if "file" in raw:  # a mesh part's file, relative to the part TOML
            raw["file"] = rel(part_file.parent / str(raw["file"]))
        data["part"] = raw
    else:
        data["part"] = {"kind": _todo("a part TOML (roboisf part …) or --part PART.toml")}
        todo.append("part")
    # tool and holder
    tps = by.get("toolpath", [])
    comps = by.get("compliance", [])
    holder_c = [f for f in comps if "holder" in f.path.name.lower()]
    tool_c = [f for f in comps if f not in holder_c]
    tool: dict[str, Any] = {}
    csv_tps = [f for f in tps if "toolpath_format" not in f.keys]
    if csv_tps:
        from roboisf.cam.toolpath_csv import read_toolpath_csv

        tool["ball_diameter"] = round(2 * read_toolpath_csv(csv_tps[0].path).tool_radius * 1e3, 6)
        notes.append(f"ball diameter {tool['ball_diameter']:g} mm from {csv_tps[0].path.name}")
    else:
        # a CAM program does not say its ball (APT CUTTER/ may, but it is the user's to confirm)
        tool["ball_diameter"] = _todo("ball diameter in mm")
        todo.append("tool.ball_diameter")
    if len(tool_c) == 1:
        tool["compliance"] = rel(tool_c[0].path)
    else:
        tool["free_length"] = _todo("free length in mm, or compliance = a tool-stiffness JSON")
        todo.append("tool")
    data["tool"] = tool
    if len(holder_c) == 1:
        data["tool_holder"] = {"compliance": rel(holder_c[0].path)}
        if holder_offset is not None:
            data["tool_holder"]["offset"] = float(holder_offset)
        else:
            data["tool_holder"]["offset"] = 0.0
            notes.append("tool_holder.offset = 0 mm (holder nose at the tip): give --holder-offset")
    else:
        data["tool_holder"] = {"rigid": True}
        notes.append("no holder compliance JSON: the holder is taken as rigid")
    # robot: a preset by name, or a robot file — found where the user typed it (the working
    # folder) and written relative to the study, as every study path is
    model: str = _todo("a preset (roboisf robot list) or file")
    if robot is not None:
        from roboisf.robot import list_robots

        model = robot
        if robot not in list_robots():
            rp = Path(robot)
            if not rp.is_file():
                raise InputError(
                    f"{robot!r} is neither a preset ({', '.join(list_robots())}) nor a robot "
                    f"file (looked for {rp.resolve()}, relative to the working folder)",
                    field="--robot",
                )
            model = rel(rp)
            if model != robot:
                notes.append(f"robot.model = {model!r}: {robot} relative to the study folder")
    if tip_link is not None:
        if robot is None:
            raise InputError(
                "--tip-link names a link of the --robot URDF; give --robot", field="--tip-link"
            )
        from roboisf.robot import load_robot

        try:
            load_robot(robot, tip_link=tip_link)
        except InputError as e:
            raise InputError(e.message, file=e.file, line=e.line, field="--tip-link") from None
    rb: dict[str, Any] = {
        "model": model,
        "placement": _pose(
            placement, "[x, y, z, roll, pitch, yaw] of the work frame, mm/deg", "placement"
        ),
    }
    if flange_to_tip is not None:
        rb["flange_to_tip"] = pose_numbers(flange_to_tip, field="flange_to_tip")
    else:
        notes.append("robot.flange_to_tip: the preset's tool (give --flange-to-tip)")
    if tool_rotation is not None:
        rb["tool_rotation"] = float(tool_rotation)
    if tip_link is not None:
        rb["tip_link"] = tip_link
    todo += [f"robot.{k}" for k in ("model", "placement") if str(rb[k]).startswith("TODO")]
    data["robot"] = rb
    # runs
    runs: dict[str, Any] = {}
    for run, mount, load_on, pose in (
        ("cnc", "fixture", "workpiece", cnc_sensor_pose),
        ("robot", "flange", "tool", robot_sensor_pose),
    ):
        r: dict[str, Any] = {"machine": run}
        for key, kind in (("toolpath", "toolpath"), ("scan", "scan")):
            got = pick(kind, run)
            r[key] = rel(got.path) if got else missing(kind, run, f"the {run} run's {kind} file")
            if got is None:
                todo.append(f"runs.{run}.{key}")
            elif kind == "toolpath" and got.keys:
                r.update(got.keys)
                notes.append(
                    f'runs.{run}.toolpath_point = "tip": {got.path.name} names the ball tip '
                    '(CAM convention); "center" if it names the ball centre'
                )
        r["scan_unit"] = "mm"
        if run == "robot":
            j = pick("joint_log", run)
            if j is not None:
                r["joints"] = {"file": rel(j.path), **j.keys} if j.keys else rel(j.path)
                todo += [f"runs.{run}.joints.units.{q}" for q in _todos(j.keys.get("units"))]
                if j.keys.get("timestamps") == "repair":
                    notes.append(_repair_note(f"runs.{run}.joints", j))
            th = pick("thickness", run)
            if th is not None:
                r["thickness"] = rel(th.path)
        r["sync"] = "position" if "joints" in r else "time"
        fl = pick("force_log", run)
        what = "T_work_sensor" if mount == "fixture" else "T_tip_sensor"
        r["forces"] = {
            "file": rel(fl.path) if fl else missing("force_log", run, f"the {run} run's force log"),
            "mount": mount,
            "pose": _pose(
                pose, f"{what} [x, y, z, roll, pitch, yaw] in mm and deg", f"{run}_sensor_pose"
            ),
            "load_on": load_on,
        }
        if fl is not None and fl.keys:
            r["forces"].update(fl.keys)
            todo += [f"runs.{run}.forces.units.{q}" for q in _todos(fl.keys.get("units"))]
            if fl.keys.get("timestamps") == "repair":
                notes.append(_repair_note(f"runs.{run}.forces", fl))
        if fl is None:
            todo.append(f"runs.{run}.forces.file")
        if pose is None:
            todo.append(f"runs.{run}.forces.pose")
        runs[run] = r
    data["runs"] = runs
    unknown = [f.path.name for f in files if f.kind == "unknown"]
    if unknown:
        notes.append(f"not recognised (left out): {', '.join(unknown)}")
    return StudyDraft(data, todo, notes)


def render_toml(draft: StudyDraft) -> str:
    """The draft as TOML text, headed by what to check and the TODO keys."""
    import tomli_w

    head = [
        "# study.toml drafted by `roboisf study init` (docs/study.md): check every value.",
    ]
    if draft.todo:
        head.append("# TODO before `roboisf analyze`: " + ", ".join(draft.todo))
    head += [f"# note: {n}" for n in draft.notes]
    return "\n".join(head) + "\n\n" + tomli_w.dumps(draft.data)
