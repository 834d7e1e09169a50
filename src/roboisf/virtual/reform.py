"""Re-form a commanded path in the same virtual cell: the loop's next part, before the robot.

``roboisf virtual-cell … --toolpath PROGRAM [--from STUDY] -o NEXT`` forms the part the program
commands (:func:`roboisf.toolpath.commanded.read_commanded`: a toolpath CSV, RAPID, KRL, FANUC or
CAM program with one forming move per toolpath point) in the cell the options describe — the
same options, truth and seed as the study the program was computed from:

* without ``--from``: a new study, CNC run and one robot run formed with the program
  (:func:`roboisf.virtual.cell.build_study` with ``robot_toolpath``);
* with ``--from STUDY``: a copy of STUDY (every run, its truth) plus the new robot run
  ``robot_<k>`` (k = the number of robot runs + 1): its toolpath (the commanded path as a
  toolpath CSV), force and joint logs (at the commanded path's times), scan and, when the program
  came from ``roboisf compensate`` (``compensation.json`` beside it), that output's
  ``per_point.csv`` as ``compensation``. Its truth is ``truth/runs/robot_<k>/``.

The cell must be the one that made STUDY: the nominal toolpath and ``truth/truth.json``'s cell
settings are compared and any difference is an :class:`InputError` naming it. The new run's
noise (force, joints, scan) is a new draw from the seed and the run number, as a second part
formed in a real cell is measured with new noise.
"""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from roboisf.cam.toolpath_csv import read_toolpath_csv, write_toolpath_csv
from roboisf.errors import InputError
from roboisf.frames.pose import format_pose
from roboisf.io.atomic import atomic_write, staged_directory
from roboisf.io.outdir import MARKER
from roboisf.logs.forcelog import write_force_log
from roboisf.logs.jointlog import write_joint_log
from roboisf.path.toolpath import Toolpath
from roboisf.progress import Progress, task
from roboisf.study.spec import ForceSensorSpec
from roboisf.toolpath.commanded import read_commanded
from roboisf.virtual.cell import (
    LOG_FORMATS,
    VirtualCell,
    _force_log,
    _log_times,
    _max_distance,
    _scan,
    _write_truth,
    build_study,
    cell_settings,
    cell_toolpath,
    scan_misregistration,
    simulate,
)

__all__ = ["commanded_path", "program_compensation", "reform_study"]


def program_compensation(program: Path) -> Path | None:
    """The ``per_point.csv`` of the ``roboisf compensate`` output that wrote ``program`` (a
    ``compensation.json`` beside it), else None."""
    folder = Path(program).parent
    f = folder / "per_point.csv"
    return f if (folder / "compensation.json").is_file() and f.is_file() else None


def commanded_path(cell: VirtualCell, program: str | Path) -> Toolpath:
    """The cell's nominal toolpath with the tips ``program`` commands (checked against the
    cell's work object and tool)."""
    return read_commanded(
        program,
        cell_toolpath(cell),
        T_base_work=cell.cell.T_base_work,
        tool_length=float(cell.T_flange_tip[2, 3]),
    )


def _check_same_cell(cell: VirtualCell, previous: Path, nominal: Toolpath) -> None:
    """``previous`` was written by ``roboisf virtual-cell`` for this very cell."""
    meta_file = previous / "truth" / "truth.json"
    try:
        meta = json.loads(meta_file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise InputError(
            "not a virtual-cell study (no readable truth/truth.json): --from takes a study "
            "`roboisf virtual-cell` wrote",
            file=previous,
            field="--from",
        ) from None
    ours = cell_settings(cell)
    theirs = meta.get("cell_settings") if isinstance(meta, dict) else None
    if not isinstance(theirs, dict):
        raise InputError(
            "truth/truth.json has no cell_settings (written by an older roboisf): make the "
            "study again",
            file=meta_file,
            field="--from",
        )
    for k, v in ours.items():
        if theirs.get(k) != v:
            raise InputError(
                f"the study was made with {k} = {theirs.get(k)!r}, this cell has {v!r}: give "
                "the same virtual-cell options as the study's",
                file=meta_file,
                field="--from",
            )
    tp_file = previous / "toolpath.csv"
    tp = read_toolpath_csv(tp_file)
    if len(tp) != len(nominal) or np.max(np.abs(tp.contact - nominal.contact)) > 1e-8:
        raise InputError(
            "the study's toolpath is not this cell's (another part, step-down or spacing)",
            file=tp_file,
            field="--from",
        )


def _copy_study(previous: Path, stage: Path) -> dict[str, Any]:
    """Every file of ``previous`` into ``stage`` (not roboisf's output marker); its study.toml."""
    for src in sorted(previous.rglob("*")):
        rel = src.relative_to(previous)
        if rel.name == MARKER or src.is_dir():
            continue
        (stage / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, stage / rel)
    with open(previous / "study.toml", "rb") as fh:
        return tomllib.load(fh)


def reform_study(
    cell: VirtualCell,
    program: str | Path,
    out_dir: str | Path,
    *,
    previous: str | Path | None = None,
    log_format: str = "parquet",
    progress: Progress | None = None,
) -> tuple[Path, str]:
    """Form ``program`` in ``cell``; write the study into ``out_dir``. Returns (folder, run name).

    See the module docstring. Raises :class:`InputError` for a program that is not a command of
    the cell's toolpath, or a ``previous`` study of another cell.
    """
    program = Path(program)
    commanded = commanded_path(cell, program)
    comp = program_compensation(program)
    if previous is None:
        build_study(
            cell,
            out_dir,
            progress=progress,
            log_format=log_format,
            commanded=commanded,
            robot_toolpath="robot_toolpath.csv",
            compensation=comp,
        )
        return Path(out_dir), "robot"
    previous = Path(previous)
    if log_format not in LOG_FORMATS:
        raise InputError(
            f"log format must be one of {', '.join(LOG_FORMATS)}, got {log_format!r}",
            field="log_format",
        )
    ext = LOG_FORMATS[log_format]
    _check_same_cell(cell, previous, commanded)
    with open(previous / "study.toml", "rb") as fh:
        runs = tomllib.load(fh).get("runs", {})
    k = 1 + sum(1 for r in runs.values() if isinstance(r, dict) and r.get("machine") == "robot")
    name = f"robot_{k}"
    rng = np.random.default_rng([cell.seed, k])
    truth = simulate(cell, commanded=commanded, progress=progress)
    tp = truth.toolpath  # nominal contacts, the commanded tips and their times
    sensor = ForceSensorSpec(Path(f"{name}_forces{ext}"), "flange", cell.T_tip_sensor, "tool")
    with staged_directory(out_dir, "virtual-cell") as d:
        data = _copy_study(previous, d)
        with task(progress, f"{name}: toolpath, logs and scan"):
            write_toolpath_csv(tp, d / f"{name}_toolpath.csv", generator=f"{program.name}")
            write_force_log(
                _force_log(cell, tp, truth.wrench_robot, sensor, rng, cell.truth), d / sensor.file
            )
            t = _log_times(tp, cell.joint_rate)
            q = np.column_stack([np.interp(t, tp.time, truth.q[:, j]) for j in range(6)])
            write_joint_log(d / f"{name}_joints{ext}", t, q)
            _scan(
                cell,
                truth,
                truth.dn_robot,
                d / f"{name}_scan.ply",
                rng,
                cell.seed + 2 + 1000 * (k - 1),
                scan_misregistration(cell.truth),
            )
        run: dict[str, Any] = {
            "machine": "robot",
            "toolpath": f"{name}_toolpath.csv",
            "joints": f"{name}_joints{ext}",
            "scan": f"{name}_scan.ply",
            "scan_unit": "mm",
            "forces": {
                "file": str(sensor.file),
                "mount": sensor.mount,
                "pose": format_pose(sensor.pose),
                "load_on": sensor.load_on,
            },
        }
        if comp is not None:
            run["compensation"] = f"{name}_compensation.csv"
            shutil.copyfile(comp, d / run["compensation"])
        data.setdefault("runs", {})[name] = run
        wider = _max_distance(truth).get("max_distance")
        analysis = data.setdefault("analysis", {})
        if wider is not None and wider > analysis.get("max_distance", 3.0):
            analysis["max_distance"] = wider
        with atomic_write(d / "study.toml", "wb") as fh:
            fh.write(tomli_w.dumps(data).encode())
        (d / "truth" / "runs" / name).mkdir(parents=True)
        _write_truth(cell, truth, d / "truth" / "runs" / name)
    return Path(out_dir), name
