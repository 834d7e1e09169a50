"""``roboisf study init``: a ``study.toml`` drafted from the files a user has.

:func:`detect_files` tries every file of a folder with roboisf's public readers (:data:`READERS`,
in order; the first that accepts a file names its kind), so a reader added to roboisf is picked
up here by adding it to that list. :func:`draft_study` assigns the detected files to the
study's keys — the CNC and robot run by the words ``cnc`` and ``robot``/``rob`` in their names,
the joint log to the robot run, a compliance JSON with ``holder`` in its name to the tool
holder — and fills what no file says (robot model and placement, flange → tip, sensor poses,
the part when no part TOML is in the folder) from the caller's options, or with a ``"TODO: …"``
string that ``load_study`` refuses with the key's name and what it expects.

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

from roboisf.errors import InputError

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


def _toolpath(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.io.toolpath_csv import read_toolpath_csv

    tp = read_toolpath_csv(p)
    return "roboisf toolpath CSV", {
        "points": str(len(tp)),
        "laps": str(tp.n_laps),
        "ball": f"Ø{2 * tp.tool_radius * 1e3:.4g} mm",
        "feed": f"{tp.feed * 6e4:.4g} mm/min",
        "units": "mm, s (declared)",
    }


def _force_log(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.io.forcelog import read_force_log

    note = "declared in the file"
    try:
        log = read_force_log(p, frame=None)
    except InputError as e:
        msg = str(e)
        if "frame not declared" in msg or "unit not declared" in msg:
            try:
                log = read_force_log(p, frame="sensor")
            except InputError as e2:
                if "unit not declared" not in str(e2):
                    raise
                log = read_force_log(
                    p, frame="sensor", time_unit="s", force_unit="N", moment_unit="N*m"
                )
                note = "NOT declared: [units] of the study applies (s, N, N*m unless set)"
        else:
            raise
    return "force log (time, Fx..Mz)", {
        "samples": str(len(log)),
        "span": f"{log.time[0]:.3f} … {log.time[-1]:.3f} s",
        "peak |F|": f"{float((log.force**2).sum(axis=1).max() ** 0.5):.4g} N",
        "units": note,
        "x,y,z": "yes" if log.position is not None else "no",
    }


def _joint_log(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.io.jointlog import read_joint_log

    log = read_joint_log(p)
    return "joint log (time, q1..q6)", {
        "samples": str(len(log.time)),
        "span": f"{log.time[0]:.3f} … {log.time[-1]:.3f} s",
        "units": "declared in the file",
    }


def _thickness(p: Path) -> tuple[str, dict[str, str]]:
    from roboisf.io.thickness import read_thickness_csv

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
    return f"scan ({p.suffix.lower().lstrip('.')})", {
        "points": str(len(cloud.points)),
        "units": "mm assumed (scan_unit in study.toml)",
    }


#: ``(kind, reader)`` in the order they are tried; a reader returns ``(format, details)`` or
#: raises :class:`InputError`. Add a reader here and ``study init`` detects its files.
READERS: list[tuple[str, Callable[[Path], tuple[str, dict[str, str]]]]] = [
    ("part", _part),
    ("compliance", _compliance),
    ("toolpath", _toolpath),
    ("force_log", _force_log),
    ("joint_log", _joint_log),
    ("thickness", _thickness),
    ("scan", _scan),
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
                fmt, details = reader(p)
            except InputError as e:
                problems.append(f"{kind}: {e.message}")
                continue
            except Exception as e:  # a reader's bug must not stop the survey
                problems.append(f"{kind}: {type(e).__name__}")
                continue
            out.append(DetectedFile(p, kind, fmt, details))
            break
        else:
            out.append(DetectedFile(p, "unknown", "", {}, "; ".join(problems[:3])))
    return out


def _role(name: str) -> str | None:
    n = name.lower()
    if "cnc" in n:
        return "cnc"
    if "rob" in n:
        return "robot"
    return None


def _todo(what: str) -> str:
    return f"TODO: {what}"


@dataclass
class StudyDraft:
    """The drafted ``study.toml`` (``data``), its TODO keys and notes for the user."""

    data: dict[str, Any]
    todo: list[str]
    notes: list[str]


def _pose(values: list[float] | None, what: str) -> list[float] | str:
    return [float(v) for v in values] if values is not None else _todo(what)


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
) -> StudyDraft:
    """Assign detected files to a study (see the module docstring). Poses ``[x, y, z, roll,
    pitch, yaw]`` in mm and deg, ``holder_offset`` in mm, ``tool_rotation`` in deg, ``part`` a
    part TOML (instead of one in the folder)."""
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

    data: dict[str, Any] = {"study": {"name": root.name, "description": "drafted by study init"}}
    # part
    part_file = Path(part) if part is not None else None
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
    if tps:
        from roboisf.io.toolpath_csv import read_toolpath_csv

        tool["ball_diameter"] = round(2 * read_toolpath_csv(tps[0].path).tool_radius * 1e3, 6)
        notes.append(f"ball diameter {tool['ball_diameter']:g} mm from {tps[0].path.name}")
    else:
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
    # robot
    rb: dict[str, Any] = {
        "model": robot if robot is not None else _todo("a preset (roboisf robot list) or file"),
        "placement": _pose(placement, "[x, y, z, roll, pitch, yaw] of the work frame, mm/deg"),
    }
    if flange_to_tip is not None:
        rb["flange_to_tip"] = [float(v) for v in flange_to_tip]
    else:
        notes.append("robot.flange_to_tip: the preset's tool (give --flange-to-tip)")
    if tool_rotation is not None:
        rb["tool_rotation"] = float(tool_rotation)
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
            r[key] = rel(got.path) if got else _todo(f"the {run} run's {kind} file")
            if got is None:
                todo.append(f"runs.{run}.{key}")
        r["scan_unit"] = "mm"
        if run == "robot":
            j = pick("joint_log", run)
            if j is not None:
                r["joints"] = rel(j.path)
            th = pick("thickness", run)
            if th is not None:
                r["thickness"] = rel(th.path)
        r["sync"] = "position" if "joints" in r else "time"
        fl = pick("force_log", run)
        what = "T_work_sensor" if mount == "fixture" else "T_tip_sensor"
        r["forces"] = {
            "file": rel(fl.path) if fl else _todo(f"the {run} run's force log"),
            "mount": mount,
            "pose": _pose(pose, f"{what} [x, y, z, roll, pitch, yaw] in mm and deg"),
            "load_on": load_on,
        }
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
