"""``roboisf analyze``: the paper's decomposition from a study folder's raw files.

1. Forces from the sensor frames to the tool tip, matched to the toolpath by time.
2. Tool and holder deflection per toolpath point (``k_t W``, ``J_th k_th J_thᵀ W``).
3. CNC scan → normal deviation per toolpath point → springback ``δs = δ_CNC − δt``.
4. Robot scan → deviation → ``δc,exp = δ_robot − δs − δt − δth``.
5. VJM prediction ``δc,VJM = k_c W`` at the logged joint angles (or IK), ``Δ = δc,exp − δc,VJM``,
   compliance statistics along the path and the force-component contributions (Table 4).
6. The contribution table (Table 5), per-axis and normal-projected.

Compliance files from the FE/beam model (``roboisf tool-stiffness``) have z along the tool axis
pointing up; with the tool vertical in the work frame their axes are the work axes (a tool whose
compliance is not axisymmetric is assumed to have its FE x-axis along work x).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from roboisf.cell import Cell, at_ball_centre, cell_from_study, tip_compliances
from roboisf.decompose.core import (
    FACTORS,
    Decomposition,
    contribution_rows,
    decompose,
    resultant_mean_deviation,
)
from roboisf.errors import InputError
from roboisf.fem import ComplianceResult
from roboisf.frames import vertical_tool
from roboisf.io.atomic import atomic_path, atomic_write, staged_directory
from roboisf.io.forcelog import attach_to_toolpath, read_force_log
from roboisf.io.jointlog import read_joint_log
from roboisf.io.thickness import read_thickness_csv
from roboisf.io.toolpath_csv import read_toolpath_csv
from roboisf.parts import sine_law_thickness
from roboisf.progress import Progress, task
from roboisf.robot import compliance_stats, deflection_contributions, ik_toolpath
from roboisf.scan import CompareOptions, ScanComparison, compare_scan, read_scan
from roboisf.study.checks import check_force_log, check_joint_log, check_tool_radius
from roboisf.study.sensors import sensor_to_tip
from roboisf.study.spec import RunSpec, Study, load_study
from roboisf.toolpath import Toolpath

__all__ = [
    "AnalysisResult",
    "analyze",
    "run_tip_wrench",
    "write_results",
]

F64 = NDArray[np.float64]
_AX = "xyz"
_WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


@dataclass(frozen=True)
class AnalysisResult:
    """Everything ``analyze`` found. Tables in mm, N, N·m, deg, s (the report's contract)."""

    study: Study
    cell: Cell
    decomposition: Decomposition
    per_point: pd.DataFrame
    contributions: pd.DataFrame
    contributions_normal: pd.DataFrame
    summary: dict[str, Any]
    scans: dict[str, ScanComparison]


def _declared(path: Path, key: str) -> bool:
    # a file that is not text is left to the log reader, which names it
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            s = line.strip()
            if not s.startswith("#"):
                return False
            if s[1:].strip().lower().startswith(key + ":"):
                return True
    return False


def run_tip_wrench(
    study: Study, run: RunSpec, tp: Toolpath, *, warnings: list[str] | None = None
) -> F64:
    """A run's force log at each toolpath point, moved to the tool tip: (N, 6) [N, N·m], work
    axes, the sheet's load on the tool (units from the log or the study's ``[units]``).

    The log is checked against the toolpath first (:func:`roboisf.study.checks.check_force_log`:
    forming-force magnitudes, logged positions on the path); its warnings are appended to
    ``warnings``."""
    f = run.forces
    kw: dict[str, str] = {}
    if not _declared(f.file, "units"):
        u = study.units
        kw = {"time_unit": u.time, "force_unit": u.force, "moment_unit": u.moment}
    frame = None if _declared(f.file, "frame") else "sensor"
    log = read_force_log(f.file, frame=frame, **kw)
    notes = check_force_log(log, tp, time_offset=f.time_offset)
    if warnings is not None:
        warnings.extend(notes)
    W_s = attach_to_toolpath(log, tp, by="time", time_offset=f.time_offset)
    rot = study.robot.tool_rotation if study.robot is not None else 0.0
    return sensor_to_tip(W_s, f, tp.tip, vertical_tool(rot))


def _joint_angles(cell: Cell, run: RunSpec, tp: Toolpath) -> tuple[F64, str]:
    if run.joints is None:
        q = ik_toolpath(cell.robot, tp.tip, cell.T_base_work, tool_rotation=cell.tool_rotation).q
        return q, "inverse kinematics of the toolpath"
    log = read_joint_log(run.joints)
    t0, t1 = float(tp.time[0]), float(tp.time[-1])
    if log.time[0] > t0 + 1e-6 or log.time[-1] < t1 - 1e-6:
        raise InputError(
            f"the joint log covers {log.time[0]:.3f} … {log.time[-1]:.3f} s but the toolpath runs "
            f"{t0:.3f} … {t1:.3f} s (a log that stops half-way?)",
            file=run.joints,
        )
    check_joint_log(cell.robot, cell.T_base_work, log, tp, file=run.joints)
    q = np.column_stack([np.interp(tp.time, log.time, log.q[:, j]) for j in range(6)])
    return q, f"joint log {run.joints.name}"


def _compare(
    study: Study, cell: Cell, run: RunSpec, tp: Toolpath, progress: Progress | None
) -> ScanComparison:
    a = study.analysis
    # per-point deviations over the whole wall (the paper's polar plot sits at z = −11 mm, inside
    # the rim band); the rim band leaves the statistics through the ``used`` mask
    opts = CompareOptions(
        register=a.registration,
        rim_band=0.0,
        radius=a.point_radius,
        contour_z=a.contour_z,
        max_distance=a.max_distance,
    )
    cloud = read_scan(run.scan, unit=run.scan_unit)
    return compare_scan(
        cloud,
        cell.part,
        toolpath=tp,
        toolpath_source=str(run.toolpath),
        options=opts,
        progress=progress,
    )


def analyze(study: Study | str | Path, *, progress: Progress | None = None) -> AnalysisResult:
    """Run the decomposition on a study (a :class:`Study` or a folder/``study.toml``)."""
    if not isinstance(study, Study):
        study = load_study(study)
    cell = cell_from_study(study)
    cnc, rob = study.cnc, study.robot_run
    with task(progress, "toolpath"):
        tp = read_toolpath_csv(cnc.toolpath)
        tp_r = tp if rob.toolpath == cnc.toolpath else read_toolpath_csv(rob.toolpath)
        if len(tp_r) != len(tp) or np.max(np.abs(tp_r.contact - tp.contact)) > 1e-6:
            raise InputError(
                "the CNC and robot runs must use the same toolpath (the method "
                "compares the two parts point by point)",
                file=rob.toolpath,
            )
        for path in (tp, tp_r):
            check_tool_radius(study.tool.ball_diameter, path, study_file=study.root / "study.toml")
        off = np.abs(cell.part.closest_point(tp.contact).distance)
        if off.max() > 0.1e-3:
            i = int(np.argmax(off))
            raise InputError(
                f"toolpath point {i} is {off[i] * 1e3:.2f} mm off the part: the contact points are "
                "not on the nominal surface of [part] (a toolpath of another part?)",
                file=cnc.toolpath,
            )
    truth_file = study.root / "truth" / "per_point.parquet"
    truth = _read_truth(truth_file) if truth_file.is_file() else None  # before the long work
    with task(progress, "robot joint angles"):
        q, q_source = _joint_angles(cell, rob, tp)
    input_warnings: list[str] = []
    with task(progress, "forces to the tool tip"):
        W_cnc = run_tip_wrench(study, cnc, tp, warnings=input_warnings)
        W_rob = run_tip_wrench(study, rob, tp, warnings=input_warnings)

    with task(progress, "tool and holder compliance"):
        k_tool, k_holder, k_t, k_th = tip_compliances(cell, progress=progress)
    # deflections of the ball centre (the paper's reference: its normal motion forms the part)
    R_ball = cell.tool.radius
    tool_cnc = at_ball_centre(W_cnc @ k_t.T, R_ball)
    tool_rob = at_ball_centre(W_rob @ k_t.T, R_ball)
    holder_rob = at_ball_centre(W_rob @ k_th.T, R_ball)

    scans = {}
    for run in (cnc, rob):
        with task(progress, f"scan {run.name}"):
            scans[run.name] = _compare(study, cell, run, tp, progress)
    dev_c, dev_r = scans[cnc.name].toolpath, scans[rob.name].toolpath
    assert dev_c is not None and dev_r is not None

    with task(progress, "robot VJM"):
        k_c = cell.robot.compliance(q, T_base_work=cell.T_base_work)
        vjm = at_ball_centre(np.einsum("nij,nj->ni", k_c, W_rob), R_ball)

    valid = dev_c.valid & dev_r.valid & (tp.depth > study.analysis.rim_band)
    d = decompose(tp.normal, dev_c.dn, dev_r.dn, tool_cnc, tool_rob, holder_rob, vjm, valid)

    per_point = _per_point(cell, tp, W_cnc, W_rob, dev_c, dev_r, d)
    thick = rob.thickness or cnc.thickness
    if thick is not None:
        per_point["thickness_measured"] = read_thickness_csv(thick).at(tp.depth) * 1e3
    contributions = pd.DataFrame(_mm_rows(contribution_rows(d, projected=False)))
    contributions_normal = pd.DataFrame(_mm_rows(contribution_rows(d, projected=True)))
    summary = _summary(study, cell, tp, d, k_c, W_rob, valid, k_tool, k_holder, q_source, scans)
    summary["warnings"].extend(input_warnings)
    if truth is not None:
        _attach_truth(truth_file, per_point, summary, d, truth)
    return AnalysisResult(
        study, cell, d, per_point, contributions, contributions_normal, summary, scans
    )


def _mm_rows(rows: list[dict[str, float | str]]) -> list[dict[str, float | str]]:
    out = []
    for r in rows:
        out.append({k: (v * 1e3 if k.startswith(("mean_abs", "R_m")) else v) for k, v in r.items()})  # type: ignore[operator]
    return out


def _per_point(
    cell: Cell, tp: Toolpath, W_cnc: F64, W_rob: F64, dev_c: Any, dev_r: Any, d: Decomposition
) -> pd.DataFrame:
    cols: dict[str, Any] = {
        "index": np.arange(len(tp)),
        "lap": tp.lap,
        "time": tp.time,
        "angle_deg": np.degrees(tp.angle),
        "depth": tp.depth * 1e3,
        "wall_angle_deg": np.degrees(tp.wall_angle),
    }
    for j, ax in enumerate(_AX):
        cols[f"contact_{ax}"] = tp.contact[:, j] * 1e3
    for j, ax in enumerate(_AX):
        cols[f"normal_{ax}"] = tp.normal[:, j]
    for run, W in (("cnc", W_cnc), ("robot", W_rob)):
        for j, name in enumerate(_WRENCH):
            cols[f"{run}_{name}"] = W[:, j]
    for run, dev in (("cnc", dev_c), ("robot", dev_r)):
        for j, ax in enumerate(_AX):
            cols[f"{run}_d{ax}"] = dev.delta[:, j] * 1e3
        cols[f"{run}_dn"] = dev.dn * 1e3
        cols[f"{run}_n_points"] = dev.n_points
        cols[f"{run}_valid"] = dev.valid
    names = {f: f for f in FACTORS} | {"vjm": "vjm", "delta": "delta"}
    for key, col in names.items():
        v = d.vectors[key]
        for j, ax in enumerate(_AX):
            cols[f"{col}_d{ax}"] = v[:, j] * 1e3
        cols[f"{col}_dn"] = d.normal[key] * 1e3
    cols["thickness_predicted"] = sine_law_thickness(tp.wall_angle, cell.part.sheet_thickness) * 1e3
    cols["used"] = d.valid
    return pd.DataFrame(cols)


def _summary(
    study: Study,
    cell: Cell,
    tp: Toolpath,
    d: Decomposition,
    k_c: F64,
    W: F64,
    valid: Any,
    k_tool: ComplianceResult,
    k_holder: ComplianceResult | None,
    q_source: str,
    scans: dict[str, ScanComparison],
) -> dict[str, Any]:
    st = compliance_stats(k_c[valid])
    stats = {
        f"k_{i + 1}{j + 1}": {
            "mean": float(st.mean[i, j]),
            "std": float(st.std[i, j]),
            "min": float(st.min[i, j]),
            "max": float(st.max[i, j]),
        }
        for i in range(6)
        for j in range(6)
    }
    contrib = deflection_contributions(k_c[valid], W[valid])
    table4 = {
        f"d{ax}": {w: float(contrib.mean_abs[i, j]) * 1e3 for j, w in enumerate(_WRENCH)}
        for i, ax in enumerate(_AX)
    }
    vjm_cmp = _vjm_vs_experiment(d, valid)
    warnings = []
    below_rim = tp.depth > study.analysis.rim_band
    for name, sc in scans.items():
        dev = sc.toolpath
        holes = 0 if dev is None else int(np.sum(~dev.valid & below_rim))
        if holes:
            warnings.append(
                f"{name} scan: {holes} toolpath points below the rim band fall in holes of the "
                "scan and are left out"
            )
    return {
        "study": study.name,
        "description": study.description,
        "part": cell.part.to_dict(),
        "part_symmetry": cell.part.symmetry.order,  # the report: polar plot only when 0
        "robot": {
            "model": cell.robot_name,
            "preset": cell.robot_name,
            "placement_T_base_work_m": cell.T_base_work.tolist(),
            "joint_angles_from": q_source,
        },
        "tool": {
            "ball_diameter_mm": cell.tool.ball_diameter * 1e3,
            "method": k_tool.method,
            "lateral_compliance_m_per_N": k_tool.lateral,
            "holder_lateral_compliance_m_per_N": None if k_holder is None else k_holder.lateral,
        },
        "units": {
            "length": "mm",
            "force": "N",
            "moment": "N*m",
            "angle": "deg",
            "time": "s",
            "compliance": "SI",
        },
        "n_points": len(tp),
        "n_points_used": int(np.sum(valid)),
        "rim_band_mm": study.analysis.rim_band * 1e3,
        "contour_z": study.analysis.contour_z * 1e3,
        "compliance_stats": stats,
        "force_contributions": table4,
        "vjm_vs_experiment": vjm_cmp["normal"],
        "vjm_vs_experiment_per_axis": vjm_cmp["per_axis"],
        "registration": {name: sc.registration.to_dict() for name, sc in scans.items()},
        "warnings": warnings,
    }


def _vjm_vs_experiment(d: Decomposition, valid: Any) -> dict[str, dict[str, float]]:
    """The paper's Δ_i = mean|δc,exp,i| − mean|δc,VJM,i| [mm] and its resultant, both books.

    (The paper's cone: Δ = (0.311, 0.5, −0.840), resultant 1.02 mm.) Per-axis vectors carry the
    VJM's tangential part, which no scan observes, so only the ``normal`` book can be ~0 when the
    model is right.
    """
    out = {}
    for book in ("per_axis", "normal"):
        if book == "per_axis":
            exp, vjm = d.vectors["robot_compliance"][valid], d.vectors["vjm"][valid]
        else:
            n = d.n[valid]
            exp = d.normal["robot_compliance"][valid, None] * n
            vjm = d.normal["vjm"][valid, None] * n
        delta = (np.abs(exp).mean(axis=0) - np.abs(vjm).mean(axis=0)) * 1e3
        out[book] = {
            "x": float(delta[0]),
            "y": float(delta[1]),
            "z": float(delta[2]),
            "resultant": float(np.linalg.norm(delta)),
        }
    return out


#: Columns of a virtual cell's ``truth/per_point.parquet`` that ``analyze`` reads (mm).
TRUTH_COLUMNS = (
    *(f"{f}_dn" for f in FACTORS),
    "dn_cnc",
    "dn_robot",
    *(f"{f}_d{ax}" for f in ("tool_cnc", *FACTORS) for ax in _AX),
)


def _read_truth(path: Path) -> pd.DataFrame:
    """A virtual cell's ground truth, validated: readable Parquet, the columns ``analyze`` uses
    (:data:`TRUTH_COLUMNS`), finite numbers. Read before the analysis so that a corrupt file
    fails in a second, not after the scans."""
    try:
        df = pd.read_parquet(path)
    except Exception as e:  # pyarrow raises many types for a damaged file
        raise InputError(
            f"not a readable Parquet file ({type(e).__name__}: {e}); delete the truth/ folder "
            "to analyze without ground truth, or regenerate the study (roboisf virtual-cell)",
            file=path,
        ) from None
    missing = [c for c in TRUTH_COLUMNS if c not in df.columns]
    if missing:
        raise InputError(
            f"missing column(s) {', '.join(missing)} (not a virtual-cell truth file?)",
            file=path,
            field=missing[0],
        )
    for c in TRUTH_COLUMNS:
        try:
            v = df[c].to_numpy(dtype=float)
        except (TypeError, ValueError):
            raise InputError("expected numbers (mm)", file=path, field=c) from None
        if not np.all(np.isfinite(v)):
            raise InputError(
                f"NaN or inf in row {int(np.argmax(~np.isfinite(v)))}", file=path, field=c
            )
    return df


def _attach_truth(
    path: Path,
    per_point: pd.DataFrame,
    summary: dict[str, Any],
    d: Decomposition,
    truth: pd.DataFrame | None = None,
) -> None:
    """Virtual-cell studies ship their ground truth: put it beside the recovered values.

    Two references. ``shares_normal`` — the physical truth projected on the normal (what a scan
    can observe), to compare with the normal book. ``shares_per_axis`` — the paper's recipe
    applied to the *noise-free* truth, to compare with the per-axis book: that book's robot
    term lacks the VJM's tangential part on any data, so only the recipe's own truth isolates
    the estimation error. ``R_m_physical`` gives the full-vector truth for the record.
    """
    truth = _read_truth(path) if truth is None else truth
    if len(truth) != len(per_point):
        summary["warnings"].append(f"truth file {path} does not match the toolpath; ignored")
        return
    used = d.valid

    def vec(name: str) -> F64:
        return truth[[f"{name}_d{ax}" for ax in _AX]].to_numpy() * 1e-3

    rms: dict[str, float] = {}
    for f in FACTORS:
        per_point[f"truth_{f}_dn"] = truth[f"{f}_dn"].to_numpy()
        err = per_point[f"{f}_dn"].to_numpy()[used] - per_point[f"truth_{f}_dn"].to_numpy()[used]
        rms[f] = float(np.sqrt(np.mean(err**2)))
    ideal = decompose(
        d.n,
        truth["dn_cnc"].to_numpy() * 1e-3,
        truth["dn_robot"].to_numpy() * 1e-3,
        vec("tool_cnc"),
        vec("tool"),
        vec("tool_holder"),
        vec("robot_compliance"),
        used,
    )
    shares = {}
    for book, projected in (("per_axis", False), ("normal", True)):
        rows = contribution_rows(ideal, projected=projected)
        shares[book] = {str(r["factor"]): float(r["share_percent"]) for r in rows[:-1]}
    physical = {f: resultant_mean_deviation(vec(f)[used]) * 1e3 for f in FACTORS}
    summary["truth"] = {
        "rms_error_dn_mm": rms,
        "shares_per_axis": shares["per_axis"],
        "shares_normal": shares["normal"],
        "R_m_physical_mm": physical,
        "source": str(path),
    }


def write_results(
    result: AnalysisResult,
    out_dir: str | Path,
    *,
    png: bool = True,
    progress: Progress | None = None,
) -> Path:
    """Write ``report.html``, ``contributions.csv``, ``contributions_normal.csv``,
    ``per_point.parquet``, ``summary.json`` and ``figures/*.png`` into ``out_dir`` (replaced only
    when everything is written)."""
    from roboisf.report import write_report

    out_dir = Path(out_dir)
    study_root = result.study.root.resolve()
    if out_dir.resolve() == study_root or study_root in out_dir.resolve().parents:
        raise InputError(
            "the output folder must not be the study folder or inside it (never "
            "overwrite an input)",
            file=out_dir,
        )
    with staged_directory(out_dir, "analyze") as stage:
        with task(progress, "tables"):
            with atomic_path(stage / "per_point.parquet") as tmp:
                result.per_point.to_parquet(tmp, index=False)
            for name, df in (
                ("contributions.csv", result.contributions),
                ("contributions_normal.csv", result.contributions_normal),
            ):
                with atomic_write(stage / name) as fh:  # mm and percent (docs/analyze.md)
                    df.to_csv(fh, index=False, float_format="%.6g")
            with atomic_write(stage / "summary.json") as fh:
                json.dump(_jsonable(result.summary), fh, indent=2)
        with task(progress, "report"):
            write_report(
                result.per_point,
                result.contributions,
                result.contributions_normal,
                result.summary,
                stage,
                png=png,
                progress=progress,
            )
    return out_dir


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
