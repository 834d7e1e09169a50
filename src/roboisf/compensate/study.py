"""Compensation from a study folder: the measured robot part and its forces (``analyze``).

The robot run of the study is the part to correct. Its toolpath is the command that formed it
(``formed``; its contacts define the nominal), its tip wrench per point (measured, brought to the
tip by ``analyze``) loads the deflection model, and its normal deviation ``robot_dn`` with the
scan's ``robot_valid`` flags is ``D``. Points in the analysis' rim band (sheet bending, excluded by
the method) are not springback-compensated: they keep the previous offset (0) and only get the
compliance pre-deflection — except the last ``rim_blend`` of the band, where the offset of the
first lap below the band ramps in (:func:`roboisf.compensate.pipeline.rim_blend`), so the
command has no step at the band's edge.
The "after" of the comparison is predicted by superposition::

    dn_after = dn_before + n · ((p_new + δ(p_new)) − (p_formed + δ(p_formed)))

(springback unchanged: the model's assumption); it is labelled ``predicted``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from roboisf.cam.program import RobotTool
from roboisf.cell import Cell, cell_from_study
from roboisf.compensate.cell import cell_deflection_model
from roboisf.compensate.compliance import DeflectionModel
from roboisf.compensate.pipeline import (
    Compensation,
    CompensationOptions,
    compensate,
    edge_source,
    rim_blend,
)
from roboisf.decompose.pipeline import analyze
from roboisf.errors import InputError
from roboisf.progress import Progress, task
from roboisf.robot.model import RobotModel
from roboisf.study.fingerprint import check_results
from roboisf.study.spec import Study, load_study
from roboisf.study.toolpaths import study_toolpath
from roboisf.summary import AnalysisSummary, read_summary

__all__ = [
    "DEFAULT_TARGET",
    "OFFSET_READINGS",
    "STALL_RATIO",
    "StudyCompensation",
    "compensate_study",
    "stopping_rule",
    "study_deflection_model",
]

F64 = NDArray[np.float64]
#: The stopping rule's target [m]: the wall's mean |deviation| at which the part is right.
DEFAULT_TARGET = 0.05e-3
#: Stop when a part's mean |deviation| is not below this fraction of the previous part's.
STALL_RATIO = 0.8
_WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def study_deflection_model(study: Study, *, progress: Progress | None = None) -> DeflectionModel:
    """Robot (tool, stiffness), placement and tool + holder tip compliance of a study's cell."""
    return cell_deflection_model(cell_from_study(study), progress=progress)


@dataclass(frozen=True, eq=False)
class StudyCompensation:
    """A compensation of a study's robot part, with what the writers need."""

    study: Study
    cell: Cell
    compensation: Compensation
    dn_before: F64
    dn_after: F64
    T_base_work: F64
    tool: RobotTool
    tool_rotation: float
    inputs: tuple[Path, ...]
    robot: RobotModel | None = None


#: ``--offset``'s readings of an offset the diagnosis cannot attribute (docs/compensate.md).
OFFSET_READINGS = ("scan", "part")


def diagnosed_inputs(
    pp: pd.DataFrame, offset: str | None = None, diagnosis: list[dict] | None = None
) -> tuple[F64, F64]:
    """The robot run's tip wrench (N, 6) [N, N·m] and normal deviation (N,) m to compensate, as
    the analysis's diagnosis left them (docs/diagnosis.md): the wrench its force correction gave
    (``robot_corrected_*``: a flange sensor at fault against the CNC dynamometer) when present,
    else the measured one; the deviation less the pattern the diagnosis put on the scan
    (``scan_pattern_dn``, mm: a sideways shift or a rotation of the scan, which no command can
    correct) when present.

    ``offset_pattern_dn`` (mm) is an offset of the robot part the diagnosis cannot attribute:
    the robot scan's registration (the part is right there) or the robot's work object (the
    part formed so). ``offset`` says which: ``"scan"`` leaves it out of the deviation (as a
    scan's fault), ``"part"`` keeps it (corrected); without it the offset is refused
    (:class:`InputError`, naming its size from ``diagnosis``, the summary's entries)."""
    cols = [f"robot_corrected_{w}" for w in _WRENCH]
    if not all(c in pp for c in cols):
        cols = [f"robot_{w}" for w in _WRENCH]
    W = pp[cols].to_numpy(dtype=float)
    dn = pp["robot_dn"].to_numpy(dtype=float) * 1e-3
    if "scan_pattern_dn" in pp:
        dn = dn - np.nan_to_num(pp["scan_pattern_dn"].to_numpy(dtype=float)) * 1e-3
    _check_offset(offset)
    if "offset_pattern_dn" in pp:
        if offset is None:
            raise InputError(unattributed_offset_message(pp, diagnosis), field="--offset")
        if offset == "scan":
            dn = dn - np.nan_to_num(pp["offset_pattern_dn"].to_numpy(dtype=float)) * 1e-3
    return W, dn


def _check_offset(offset: str | None) -> None:
    """InputError unless ``offset`` is None or one of :data:`OFFSET_READINGS`."""
    if offset is not None and offset not in OFFSET_READINGS:
        raise InputError(f"expected scan or part, got {offset!r}", field="--offset")


def unattributed_offset_message(pp: pd.DataFrame, diagnosis: list[dict] | None) -> str:
    """Why compensate refuses to guess: the offset's size and its two readings."""
    f = {str(e.get("suspect")): e for e in diagnosis or [] if isinstance(e, dict)}
    what = []
    for name, unit, words in (
        ("scan_shift", "mm", "a sideways offset"),
        ("scan_rotation", "°", "a turn about the part axis"),
        ("work_object_tilt", "mm", "a tilt (sideways at the deepest analysed point)"),
    ):
        e = f.get(name) or {}
        lo, hi, est = e.get("ci_low"), e.get("ci_high"), e.get("estimate")
        lim = (e.get("detection_limits") or [None, None])[1]
        if None not in (lo, hi, est, lim) and lo > lim and e.get("verdict") != "fault":
            what.append(f"{words} of {est:.3f} {unit} [{lo:.3f}, {hi:.3f}]")
    if not what:  # results without the diagnosis's entries: the pattern's size
        v = np.abs(pp["offset_pattern_dn"].to_numpy(dtype=float))
        what.append(f"an offset of up to {np.nanmax(v):.3f} mm of normal deviation")
    return (
        f"the robot part carries {' and '.join(what)} that the analysis cannot attribute: the "
        "robot scan's registration (the part is right there, only its measurement is misplaced) "
        "or the robot's work object (the robot formed the part displaced); compensate will not "
        "guess — check the scan's reference marks or measure the work object, then give "
        "--offset scan (leave it out of the correction) or --offset part (correct it as the "
        "part's)"
    )


def _diagnosis(summary: object) -> list[dict] | None:
    """The diagnosis's entries of an analysis summary (None when it has none)."""
    d = getattr(summary, "diagnosis", None)
    return d if isinstance(d, list) else None


def _per_point(
    study: Study, results: Path | None, progress: Progress | None
) -> tuple[pd.DataFrame, list[dict] | None]:
    """The analysis's per-point table and its diagnosis's entries (None without them)."""
    if results is None:
        if not study.has_cnc:  # springback model-based (robot_only): its per-point columns
            from roboisf.decompose.robot_only import analyze_robot_only

            return analyze_robot_only(study, progress=progress).per_point, None
        r = analyze(study, progress=progress)
        return r.per_point, _diagnosis(r.summary)
    f = Path(results) / "per_point.parquet"
    if not f.is_file():
        raise InputError(
            "expected an `roboisf analyze` results folder with per_point.parquet", file=results
        )
    try:
        df = pd.read_parquet(f)
    except Exception as e:  # pyarrow raises many types for a damaged file
        raise InputError(
            f"not a readable Parquet file ({type(e).__name__}: {e}); run `roboisf analyze` "
            "again to rewrite it",
            file=f,
        ) from None
    need = ["robot_dn", "robot_valid", *(f"robot_{w}" for w in _WRENCH)]
    missing = [c for c in need if c not in df]
    if missing:
        raise InputError(f"missing columns {', '.join(missing)}", file=f, field=missing[0])
    for c in need:
        try:
            v = df[c].to_numpy(dtype=float)
        except (TypeError, ValueError):
            raise InputError("expected numbers", file=f, field=c) from None
        # robot_dn is NaN where the scan has no points (robot_valid false); the rest is finite
        bad = np.isinf(v) if c == "robot_dn" else ~np.isfinite(v)
        if bad.any():
            raise InputError(f"NaN or inf in row {int(np.argmax(bad))}", file=f, field=c)
    # a point the results call measured (robot_valid) has a measured deviation: NaN there is a
    # damaged file, not a hole of the scan (before, compensate said complete: true regardless)
    holes = np.isnan(df["robot_dn"].to_numpy(dtype=float)) & df["robot_valid"].to_numpy(dtype=bool)
    if holes.any():
        raise InputError(
            f"NaN in {int(holes.sum())} rows flagged robot_valid (first: row "
            f"{int(np.argmax(holes))}); a measured point needs a finite deviation: run "
            "`roboisf analyze` again to rewrite the results",
            file=f,
            field="robot_dn",
        )
    diagnosis = None
    if (Path(results) / "summary.json").is_file():
        diagnosis = _diagnosis(read_summary(Path(results) / "summary.json"))
    return df, diagnosis


def compensate_study(
    study: Study | str | Path,
    *,
    results: str | Path | None = None,
    previous: str | Path | None = None,
    options: CompensationOptions | None = None,
    tool_mass: float = 2.0,
    stiffness: str | Path | None = None,
    run: str | None = None,
    target: float = DEFAULT_TARGET,
    progress: Progress | None = None,
    offset: str | None = None,
) -> StudyCompensation:
    """Compensate the robot part of ``study`` (a folder, ``study.toml`` or :class:`Study`).

    ``run`` — which robot run (default: the last one in the file, the newest part of an
    iteration). A run formed with a compensated program says so with its ``compensation`` key
    (the ``per_point.csv`` of the ``roboisf compensate`` output that wrote the program): its
    ``springback_offset_dn`` is ``c_k`` and its ``dn_before`` the previous part's deviation, which
    the stopping rule (:func:`stopping_rule`, ``target`` [m]) compares with this part's.

    ``results`` — an earlier ``roboisf analyze`` output folder to reuse (else analyze runs).
    ``previous`` — the ``roboisf compensate`` output folder of the command that formed the
    study's robot part (its ``springback_offset_dn`` is ``c_k``; the study's robot toolpath is
    that command): the next step of the iteration. Without it ``c_k = 0``.
    ``stiffness`` — a joint-stiffness TOML (``[stiffness] K``, N·m/rad: ``roboisf robot
    identify`` or the ``identified_stiffness.toml`` of ``roboisf analyze``) that replaces the
    study's robot stiffness in the pre-deflection.
    ``offset`` — ``"scan"`` or ``"part"``: whose an offset of the robot part is that the
    analysis could not attribute (the robot scan's registration: left out of the correction;
    the robot's work object: corrected). Refused when such an offset is found and ``offset``
    is None (:func:`diagnosed_inputs`).
    """
    if not isinstance(study, Study):
        study = load_study(study)
    study = study.for_run(study.robot_runs[-1].name if run is None else run)
    if study.robot is None:
        raise InputError(
            "compensation needs a [robot] table (model, placement)", file=study.root / "study.toml"
        )
    cell = cell_from_study(study)
    if stiffness is not None:
        from roboisf.robot import load_stiffness

        K = load_stiffness(stiffness, robot=cell.robot.name)
        cell = replace(cell, robot=cell.robot.with_stiffness(K, source=str(stiffness)))
    o = options or CompensationOptions()
    rspec = study.robot_run
    formed = study_toolpath(study, rspec, cell.part)  # a toolpath CSV or a CAM program
    if results is not None:
        _check_results_run(Path(results), rspec.name)
    _check_offset(offset)  # before the analysis
    pp, diagnosis = _per_point(study, None if results is None else Path(results), progress)
    if results is not None:  # results of this study as its files are now (summary.json)
        check_results(study, results)
    if len(pp) != len(formed):
        raise InputError(
            f"the results have {len(pp)} points but the robot toolpath {len(formed)} (results "
            "of another study?)",
            file=results,
        )
    W, dn = diagnosed_inputs(pp, offset, diagnosis)
    valid = pp["robot_valid"].to_numpy(dtype=bool)
    region = formed.depth > study.analysis.rim_band
    blend = rim_blend(formed.depth, study.analysis.rim_band, o.rim_blend)
    source = edge_source(formed, study.analysis.rim_band, blend)
    state_file = (
        None if previous is None else Path(previous) / "per_point.csv"
    ) or rspec.compensation
    c_prev = None if state_file is None else _previous_offset(state_file, len(formed))
    with task(progress, "deflection model"):
        model = cell_deflection_model(cell, progress=progress)
    comp = compensate(
        cell.part,
        formed,
        model=model,
        wrench=W,
        deviation=np.where(valid, dn, np.nan),
        valid=valid,
        region=region,
        blend=blend,
        source=source,
        formed=formed.tip,
        previous_offset=c_prev,
        options=o,
        progress=progress,
    )
    d_formed = model.deflection(formed.tip, W)[0]
    n = comp.nominal.normal
    land_new = comp.toolpath.tip + comp.deflection
    land_old = formed.tip + d_formed
    # before/after over the analysed wall (below the rim band), as the analysis' statistics
    judged = valid & region
    dn_after = np.where(judged, dn + np.einsum("ij,ij->i", land_new - land_old, n), np.nan)
    T_ft = model.robot.T_flange_tip
    tool = RobotTool(length=float(T_ft[2, 3]), mass=tool_mass)
    inputs = (study.root, *(Path(p) for p in (results, previous, stiffness) if p is not None))
    meta = {
        "study": study.name,
        "robot": cell.robot_name,
        "rim_band_mm": study.analysis.rim_band * 1e3,
        "stiffness": str(stiffness) if stiffness is not None else "study.toml",
    }
    meta["run"] = rspec.name
    meta["stopping"] = stopping_rule(
        np.where(judged, dn, np.nan),
        None if state_file is None else _previous_before(state_file, len(formed)),
        target,
    )
    meta["gain"] = o.gain
    meta.update(_attribution_notes(pp, offset))
    comp = replace(comp, meta=meta)
    return StudyCompensation(
        study,
        cell,
        comp,
        np.where(judged, dn, np.nan),
        dn_after,
        cell.T_base_work,
        tool,
        float(cell.tool_rotation),
        inputs,
        model.robot,
    )


def _attribution_notes(pp: pd.DataFrame, offset: str | None) -> dict[str, object]:
    """compensation.json's record of what the diagnosis left to the user (``offset``: the
    reading given for an offset it could not attribute) or that changes between runs (a
    thermal drift, corrected as the part's), each with one sentence to print."""
    out: dict[str, object] = {}
    if "offset_pattern_dn" in pp:
        v = np.nanmax(np.abs(pp["offset_pattern_dn"].to_numpy(dtype=float)))
        out["unattributed_offset"] = {
            "reading": offset,
            "max_normal_mm": float(v),
            "note": (
                "the robot part's offset the analysis could not attribute was read as the "
                + (
                    "robot scan's registration (--offset scan): left out of the correction"
                    if offset == "scan"
                    else "robot's work object (--offset part): corrected as the part's"
                )
            ),
        }
    elif offset is not None:
        out["unattributed_offset"] = {
            "reading": offset,
            "note": f"--offset {offset} ignored: the analysis found no offset it could not "
            "attribute",
        }
    if "drift_pattern_dn" in pp:
        v = np.nanmax(np.abs(pp["drift_pattern_dn"].to_numpy(dtype=float)))
        out["thermal_drift"] = {
            "max_normal_mm": float(v),
            "note": (
                f"a thermal drift of the robot (up to {v:.3f} mm of normal deviation) is "
                "corrected as the part's: a drift changes from run to run, so the correction "
                "holds only if the next run drifts alike (form after the same warm-up)"
            ),
        }
    return out


def stopping_rule(dn: F64, dn_previous: F64 | None, target: float = DEFAULT_TARGET) -> dict:
    """The iteration's stopping rule on the analysed wall (NaN = not judged), m → a record (mm).

    ``stop`` with ``reason``: ``"target"`` when the mean |dn| is at most ``target`` (the part is
    right: form it); ``"stalled"`` when it is not below :data:`STALL_RATIO` × the previous part's
    (with λ ≤ 1 a working iteration shrinks the residual by ≥ (1 − λ) ≈ 5× per part, so a
    part that gains less than 20 % means what is left is not what the adjustment can remove —
    scan noise, a model error the offsets cannot learn, or a gain too high: lower ``--gain``);
    otherwise ``continue``. The first part (no previous) stops only on the target.
    """
    m = float(np.nanmean(np.abs(dn))) if np.any(np.isfinite(dn)) else float("nan")
    rec: dict[str, object] = {
        "mean_abs_dn_mm": m * 1e3,
        "target_mm": target * 1e3,
        "stall_ratio": STALL_RATIO,
    }
    prev = None
    if dn_previous is not None and np.any(np.isfinite(dn_previous)):
        prev = float(np.nanmean(np.abs(dn_previous)))
        rec["previous_mean_abs_dn_mm"] = prev * 1e3
        rec["ratio_to_previous"] = m / prev if prev > 0 else float("inf")
    if m <= target:
        rec.update(stop=True, reason="target")
    elif prev is not None and m > STALL_RATIO * prev:
        rec.update(stop=True, reason="stalled")
    else:
        rec.update(stop=False, reason="continue")
    return rec


def _state_column(f: Path, n: int, column: str, *, finite: bool) -> F64:
    """Column ``column`` [mm → m] (n,) of a ``roboisf compensate`` per_point.csv."""
    if not f.is_file():
        raise InputError("expected a `roboisf compensate` output folder with per_point.csv", file=f)
    try:
        df = pd.read_csv(f)
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as e:
        raise InputError(f"not a readable CSV ({type(e).__name__}: {e})", file=f) from None
    if column not in df:
        raise InputError(f"missing column {column}", file=f)
    try:
        c = df[column].to_numpy(dtype=float) * 1e-3
    except (TypeError, ValueError):
        raise InputError("expected numbers (mm)", file=f, field=column) from None
    if c.shape != (n,) or (finite and not np.all(np.isfinite(c))):
        raise InputError(
            f"expected {n} finite values (one per toolpath point), got {c.shape[0]}",
            file=f,
            field=column,
        )
    return c


def _check_results_run(results: Path, run: str) -> None:
    """An analyze output records the robot run it is of (``summary.json`` → ``robot_run``, read
    by :func:`roboisf.summary.read_summary`: a file of another version is refused;
    a missing one is left to the fingerprint check, which says what to do)."""
    if not (results / "summary.json").is_file():
        return
    s = read_summary(results / "summary.json")
    got = s.robot_run if isinstance(s, AnalysisSummary) else None
    if got is not None and got != run:
        raise InputError(
            f"these results are of robot run {got!r}, not {run!r}: analyze with --run {run}, "
            "or give --run " + got,
            file=results / "summary.json",
            field="--results",
        )


def _previous_offset(f: Path, n: int) -> F64:
    """``c_k`` [m] (n,) from an earlier ``roboisf compensate`` output's per_point.csv."""
    return _state_column(f, n, "springback_offset_dn", finite=True)


def _previous_before(f: Path, n: int) -> F64 | None:
    """The measured deviation [m] (n,; NaN where not judged) of the part the earlier
    compensation corrected (its ``dn_before``), or None when the file has none."""
    try:
        return _state_column(f, n, "dn_before", finite=False)
    except InputError:
        return None
