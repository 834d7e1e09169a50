"""Springback without a CNC twin: a robot-only study, model-based (docs/analyze.md, "Without a
CNC run").

Most robot cells have no CNC to form the same part stiffly. Then springback is what is left of
the robot part's measured normal deviation once the modelled terms are taken out::

    ŝ = dn_robot − n · (δt + δth + δc,VJM + command)            (per toolpath point, m)

— the tool and holder from their compliances and the measured wrench, the robot from the VJM at
the logged joints, the commanded offset of a compensated run. It is exactly as right as the
robot model: a robot κ× softer than its model leaves ``(κ − 1) n·δc,VJM`` in ŝ.

**Model check.** Springback depends on where the sheet is formed (depth, wall angle) and hardly
changes along a lap at one depth, while the robot's deflection does (its configuration turns
with the tool). So within each lap the residual is regressed on the VJM's normal deflection,
both taken relative to their lap means::

    ŝ_i − ŝ_lap = β (v_i − v_lap) + ε_i,       v = n·δc,VJM

``β`` = 0 when the model holds; a robot κ× softer gives ``β = κ − 1``; a springback that couples
to the robot's deflection gives ``β ≠ 0`` too (then springback and robot are not separable by
any model). Its 95 % interval is a moving-block bootstrap over laps
(:func:`roboisf.decompose.check.lap_blocks`). The bias the robot model may put into ŝ is
bounded by ``b = max(|β_lo|, |β_hi|) · RMS(v)``; **separable** when ``b ≤ tol`` (default
0.05 mm) and the VJM varies enough along the laps to test (``RMS(v − v_lap) ≥ MIN_SPREAD``),
else **not separable** and no springback number is given. The per-point uncertainty carried
through is ``σ_i = σ_β |v_i| ⊕ σ_noise`` (σ_β from the bootstrap, σ_noise the scan's point
scatter) and the springback statistics carry the interval from ``β`` at its two ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.decompose.check import N_BOOT, lap_blocks, lap_index, point_scatter
from roboisf.errors import InputError
from roboisf.summary import RobotOnlySummary, dumps

__all__ = ["MIN_SPREAD", "SEPARABLE_TOL", "SpringbackEstimate", "springback_without_cnc"]

F64 = NDArray[np.float64]

#: Largest bias [m] the robot model may put into the springback for it to be called separable.
SEPARABLE_TOL = 0.05e-3
#: Smallest within-lap RMS variation [m] of the VJM's normal deflection that can test the model.
MIN_SPREAD = 0.01e-3


@dataclass(frozen=True, eq=False)
class SpringbackEstimate:
    """Model-based springback of a robot-only study (work frame, SI).

    springback_dn : (N,) m — ŝ, NaN where not used (or everywhere when not separable)
    sigma_dn : (N,) m — its 1σ uncertainty per point (model ⊕ scan noise)
    beta, beta_lo, beta_hi : the residual-on-VJM slope within laps and its 95 % interval
    bias_bound : m — ``max(|β_lo|, |β_hi|) · RMS(v)``
    spread : m — RMS of the VJM's normal deflection about its lap means
    separable : bool; ``reason`` says why not
    """

    springback_dn: F64
    sigma_dn: F64
    beta: float
    beta_lo: float
    beta_hi: float
    bias_bound: float
    spread: float
    noise: float
    separable: bool
    reason: str
    stats: dict[str, float]

    @property
    def label(self) -> str:
        return "model-based" if self.separable else "not separable"

    def to_dict(self) -> dict[str, Any]:
        """``summary.json``'s ``springback_model_based`` (mm)."""
        return {
            "label": self.label,
            "separable": self.separable,
            "reason": self.reason,
            "beta": self.beta,
            "beta_95": [self.beta_lo, self.beta_hi],
            "bias_bound_mm": self.bias_bound * 1e3,
            "vjm_spread_mm": self.spread * 1e3,
            "scan_noise_mm": self.noise * 1e3,
            "tolerance_mm": SEPARABLE_TOL * 1e3,
            **({k: v * 1e3 for k, v in self.stats.items()} if self.separable else {}),
        }


def _lap_centered(v: F64, idx: NDArray[np.intp], n_laps: int) -> F64:
    """``v`` minus its lap mean (per lap over the given points)."""
    s = np.bincount(idx, weights=v, minlength=n_laps)
    c = np.bincount(idx, minlength=n_laps)
    return v - (s / np.maximum(c, 1))[idx]


def springback_without_cnc(
    normal: F64,
    dn_robot: F64,
    tool: F64,
    holder: F64,
    vjm: F64,
    valid: NDArray[np.bool_],
    lap: NDArray[Any],
    *,
    command: F64 | None = None,
    tol: float = SEPARABLE_TOL,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> SpringbackEstimate:
    """Springback of a robot part from the modelled robot, tool and holder terms (module doc).

    Parameters
    ----------
    normal : (N, 3) — nominal tool-side normals
    dn_robot : (N,) m — the robot part's measured normal deviation
    tool, holder, vjm : (N, 3) m — deflections at the ball centre (measured wrench)
    valid : (N,) bool — points to use (scanned, below the rim band)
    lap : (N,) int — lap of each point
    command : (N, 3) m, optional — commanded tip − nominal tip (a compensated run)
    tol : m — the largest accepted bias of the robot model in the springback
    """
    n = np.asarray(normal, dtype=float)
    N = n.shape[0]
    for name, a, shape in (
        ("dn_robot", dn_robot, (N,)),
        ("tool", tool, (N, 3)),
        ("holder", holder, (N, 3)),
        ("vjm", vjm, (N, 3)),
        ("valid", valid, (N,)),
        ("lap", lap, (N,)),
    ):
        if np.shape(a) != shape:
            raise InputError(f"expected shape {shape}, got {np.shape(a)}", field=name)
    used = np.asarray(valid, dtype=bool) & np.isfinite(dn_robot)
    if used.sum() < 10:
        raise InputError("fewer than 10 scanned toolpath points below the rim band")
    modelled = tool + holder + vjm + (0.0 if command is None else command)
    s_hat = dn_robot - np.einsum("ij,ij->i", modelled, n)
    v_all = np.einsum("ij,ij->i", vjm, n)
    idx, n_laps = lap_index(np.asarray(lap)[used])
    s, v = s_hat[used], v_all[used]
    x, y = _lap_centered(v, idx, n_laps), _lap_centered(s, idx, n_laps)
    sxy = np.bincount(idx, weights=x * y, minlength=n_laps)
    sxx = np.bincount(idx, weights=x * x, minlength=n_laps)
    spread = float(np.sqrt(np.mean(x**2)))
    beta = float(sxy.sum() / sxx.sum()) if sxx.sum() > 0 else math.nan
    rows = lap_blocks(n_laps, np.random.default_rng(seed), n_boot)
    with np.errstate(invalid="ignore", divide="ignore"):
        boot = sxy[rows].sum(axis=1) / sxx[rows].sum(axis=1)
    boot = boot[np.isfinite(boot)]
    lo, hi = (
        (float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5)))
        if boot.size
        else (math.nan, math.nan)
    )
    sigma_beta = float(np.std(boot)) if boot.size else math.nan
    rms_v = float(np.sqrt(np.mean(v**2)))
    bias = max(abs(lo), abs(hi)) * rms_v
    noise = point_scatter(y - beta * x, np.asarray(lap)[used]) if math.isfinite(beta) else math.nan
    if not spread >= MIN_SPREAD:
        separable, reason = (
            False,
            (
                f"the VJM's deflection varies by {spread * 1e3:.4f} mm RMS along the laps (< "
                f"{MIN_SPREAD * 1e3:g} mm): the robot model cannot be checked on this path"
            ),
        )
    elif not bias <= tol:
        separable, reason = (
            False,
            (
                f"the residual follows the VJM within the laps (β = {beta:.3f}, 95 % "
                f"[{lo:.3f}, {hi:.3f}]): the robot model may be off by up to {bias * 1e3:.3f} mm "
                f"(> {tol * 1e3:g} mm) — the robot is not its model, or springback couples to its "
                "deflection; measure a CNC twin or identify the robot first"
            ),
        )
    else:
        separable, reason = (
            True,
            (
                f"robot model consistent within the laps (β = {beta:.3f}, 95 % "
                f"[{lo:.3f}, {hi:.3f}]; bias ≤ {bias * 1e3:.3f} mm)"
            ),
        )
    sigma = np.sqrt((sigma_beta * np.abs(v_all)) ** 2 + (noise if math.isfinite(noise) else 0) ** 2)
    sb = np.where(used, s_hat, np.nan) if separable else np.full(N, np.nan)
    stats: dict[str, float] = {}
    if separable:
        # the interval of each statistic with β at its ends: ŝ − β v is the springback if the
        # robot were (1 + β)× its model
        ends = [s - b * v for b in (lo, hi)]
        stats = {
            "mean_abs_dn": float(np.mean(np.abs(s))),
            "rms_dn": float(np.sqrt(np.mean(s**2))),
            "max_abs_dn": float(np.max(np.abs(s))),
            "mean_abs_dn_lo": min(float(np.mean(np.abs(e))) for e in ends),
            "mean_abs_dn_hi": max(float(np.mean(np.abs(e))) for e in ends),
            "mean_sigma_dn": float(np.mean(sigma[used])),
        }
    return SpringbackEstimate(
        sb,
        np.where(used, sigma, np.nan),
        beta,
        lo,
        hi,
        bias,
        spread,
        noise,
        separable,
        reason,
        stats,
    )


@dataclass(frozen=True, eq=False)
class RobotOnlyResult:
    """``analyze`` of a study without a CNC run: the model-based springback and the modelled
    terms, per point (``per_point``, mm, the columns ``compensate`` reads) and summarised."""

    study: Any
    cell: Any
    estimate: SpringbackEstimate
    per_point: Any
    #: ``summary.json`` (:mod:`roboisf.summary`)
    summary: RobotOnlySummary


def analyze_robot_only(study: Any, *, progress: Any = None) -> RobotOnlyResult:
    """The robot run of a study with no CNC run (:class:`roboisf.study.Study`): logs, joints,
    scan and the modelled terms as :func:`roboisf.decompose.pipeline.analyze` takes them, then
    :func:`springback_without_cnc`. Ground truth of a virtual cell is attached when present."""
    import pandas as pd

    from roboisf.cell import at_ball_centre, cell_from_study, tip_compliances
    from roboisf.decompose import pipeline as pl
    from roboisf.path.toolpath import tool_points
    from roboisf.progress import task
    from roboisf.study.toolpaths import study_toolpath
    from roboisf.sync.run import align_run

    cell = cell_from_study(study)
    rob = study.robot_run
    warnings: list[str] = []
    with task(progress, "toolpath"):
        tp = study_toolpath(study, rob, cell.part)
    nominal_tip = tool_points(tp.contact, tp.normal, tp.tool_radius)[1]
    command = tp.tip - nominal_tip
    has_command = bool(np.max(np.abs(command)) > 1e-9)
    with task(progress, f"{rob.name} logs"):
        log = pl.read_run_force_log(study, rob)
        joints = None if rob.joints is None else pl.read_run_joint_log(rob)
        al = align_run(cell, rob, tp, log, joints)
        q, q_source = pl._joint_angles(cell, rob, tp, al.joints, joints)
        R_fk = cell.robot.fk(q, check_limits=False)[:, :3, :3] if rob.forces.tool_mass else None
        W = pl.run_tip_wrench(
            study,
            rob,
            tp,
            warnings=warnings,
            alignment=None if rob.sync == "time" else al.forces,
            log=log,
            R_base_tip=R_fk,
        )
    with task(progress, f"scan {rob.name}"):
        dev = pl._compare(study, cell, rob, tp, progress).toolpath
    assert dev is not None
    _, _, k_t, k_th = tip_compliances(cell, progress=progress)
    R = cell.tool.radius
    tool = at_ball_centre(W @ k_t.T, R)
    holder = at_ball_centre(W @ k_th.T, R)
    k_c = cell.robot.compliance(q, T_base_work=cell.T_base_work)
    vjm = at_ball_centre(np.einsum("nij,nj->ni", k_c, W), R)
    valid = dev.valid & (tp.depth > study.analysis.rim_band)
    est = springback_without_cnc(
        tp.normal,
        dev.dn,
        tool,
        holder,
        vjm,
        valid,
        tp.lap,
        command=command if has_command else None,
    )
    n = tp.normal
    cols: dict[str, Any] = {
        "index": np.arange(len(tp)),
        "lap": tp.lap,
        "depth": tp.depth * 1e3,
        "angle_deg": np.degrees(tp.angle),
    }
    for j, name in enumerate(("Fx", "Fy", "Fz", "Mx", "My", "Mz")):
        cols[f"robot_{name}"] = W[:, j]
    cols["robot_dn"] = dev.dn * 1e3
    cols["robot_valid"] = dev.valid
    for name, vec in (("tool", tool), ("tool_holder", holder), ("vjm", vjm), ("command", command)):
        cols[f"{name}_dn"] = np.einsum("ij,ij->i", vec, n) * 1e3
    cols["springback_dn"] = est.springback_dn * 1e3
    cols["springback_sigma_dn"] = est.sigma_dn * 1e3
    cols["used"] = valid
    per_point = pd.DataFrame(cols)
    truth: dict[str, Any] | None = None
    truth_file = pl.run_truth_dir(study) / "per_point.parquet"
    if truth_file.is_file():
        t = pd.read_parquet(truth_file)
        col = "springback_robot_dn" if "springback_robot_dn" in t else "springback_dn"
        if len(t) == len(per_point) and col in t:
            per_point["truth_springback_dn"] = t[col].to_numpy()
            if est.separable:
                err = (per_point["springback_dn"] - per_point["truth_springback_dn"])[valid]
                truth = {"springback_rms_error_mm": float(np.sqrt(np.mean(err**2)))}
    summary = RobotOnlySummary(
        study=study.name,
        run=rob.name,
        kind="robot-only",
        robot=cell.robot_name,
        joint_angles=q_source,
        springback_model_based=est.to_dict(),
        modelled_mean_abs_dn_mm={
            k: float(np.mean(np.abs(per_point[f"{k}_dn"].to_numpy()[valid])))
            for k in ("tool", "tool_holder", "vjm", "command")
        },
        measured_mean_abs_dn_mm=float(np.mean(np.abs(dev.dn[valid]))) * 1e3,
        warnings=warnings,
        truth=truth,
    )
    return RobotOnlyResult(study, cell, est, per_point, summary)


def write_robot_only(result: RobotOnlyResult, out_dir: Any, *, progress: Any = None) -> Any:
    """``per_point.parquet``, ``summary.json`` and ``report.html`` (model-based springback,
    no figures) into ``out_dir`` (replaced only when complete)."""
    from pathlib import Path

    from roboisf.io.atomic import atomic_path, atomic_write, staged_directory
    from roboisf.report.robot_only import write_robot_only_report

    out_dir = Path(out_dir)
    with staged_directory(out_dir, "analyze") as stage:
        with atomic_path(stage / "per_point.parquet") as tmp:
            result.per_point.to_parquet(tmp, index=False)
        with atomic_write(stage / "summary.json") as fh:
            fh.write(dumps(result.summary))
        write_robot_only_report(result.summary.to_dict(), stage)
    return out_dir
