"""Joint-stiffness identification by elasto-static calibration (after Dumas et al. 2011).

In experiment e the known tip wrench ``W_e`` (base frame) deflects the tip by
``δ_e = Σ_i J_i (J_iᵀ W_e) c_i`` with ``c_i = 1/K_i`` — linear in the compliances. Stacking the
measured components of all experiments gives ``A c = b``, solved by weighted least squares
(weights 1/σ² per measured component). Quality figures: residual RMS, the condition number of the
column-equilibrated weighted matrix, 95 % confidence intervals (Student t, covariance
``s² (AᵀA)⁻¹`` with ``s²`` from the weighted residual), and the relative standard error per joint.
A joint whose column is (numerically) zero cannot be identified: an :class:`InputError` names it
unless a fixed value is given for it; a joint with relative standard error above
``weak_threshold`` is flagged as weakly excited (warning).

Calibration CSV (one experiment per row; ``#`` comment lines first)::

    # units: angle=deg length=mm force=N moment=N*m rotation=rad
    # frame: base            (frame of the wrench: base or tip; displacements are in base)
    q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz[,rx,ry,rz]
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.special import stdtrit

from roboisf.errors import InputError
from roboisf.io.table import read_table
from roboisf.io.units import to_si
from roboisf.robot.model import RobotModel, _check_wrench

__all__ = [
    "CalibrationData",
    "ExperimentDesign",
    "PoorExcitationWarning",
    "StiffnessIdentification",
    "design_experiment",
    "identify_stiffness",
    "read_calibration_csv",
    "write_experiment_csv",
]

F64 = NDArray[np.float64]


class PoorExcitationWarning(UserWarning):
    """The calibration configurations excite a joint too weakly to identify it well."""


@dataclass(frozen=True, eq=False)
class CalibrationData:
    """Elasto-static experiments (SI, base frame).

    q : (M, 6) rad; wrench : (M, 6) [N; N·m] at the tip, base frame;
    displacement : (M, 3) m or (M, 6) [m; rad] measured tip displacement, base frame.
    """

    q: F64
    wrench: F64
    displacement: F64


@dataclass(frozen=True, eq=False)
class StiffnessIdentification:
    """Result of :func:`identify_stiffness`.

    K : (6,) N·m/rad; K_ci : (6, 2) 95 % interval (upper bound inf when the compliance interval
    reaches 0); compliance, compliance_se : (6,) rad/(N·m); rel_se : (6,) relative standard error
    of each compliance; identified : (6,) bool (False for fixed joints); weak : (6,) bool;
    residual : (M·m,) weighted residuals; residual_rms : float, m (unweighted, translation rows);
    condition_number : float; dof : int.
    """

    K: F64
    K_ci: F64
    compliance: F64
    compliance_se: F64
    rel_se: F64
    identified: NDArray[np.bool_]
    weak: NDArray[np.bool_]
    residual: F64
    residual_rms: float
    condition_number: float
    dof: int


def _design(model: RobotModel, data: CalibrationData) -> tuple[F64, F64]:
    J = model.jacobian(data.q, check_limits=False)
    W = _check_wrench(data.wrench, J.shape[0])
    tau = np.einsum("nji,nj->ni", J, W)  # (M, 6)
    cols = J * tau[:, None, :]  # (M, 6 rows, 6 joints): J_i (J_iᵀ W)
    m = data.displacement.shape[1]
    return cols[:, :m, :], data.displacement


def identify_stiffness(
    model: RobotModel,
    data: CalibrationData,
    *,
    sigma_translation: float = 1e-5,
    sigma_rotation: float = 1e-5,
    fixed: dict[int, float] | None = None,
    weak_threshold: float = 0.3,
    confidence: float = 0.95,
) -> StiffnessIdentification:
    """Weighted linear least squares on the joint compliances ``1/K_i``.

    ``sigma_translation`` (m) and ``sigma_rotation`` (rad) are the measurement standard deviations
    used as weights; ``fixed`` maps 0-based joint index → known stiffness (N·m/rad) for joints the
    experiments cannot excite.
    """
    q = model.check_q(data.q, field="calibration q")
    if (
        data.displacement.ndim != 2
        or data.displacement.shape[1] not in (3, 6)
        or data.displacement.shape[0] != q.shape[0]
    ):
        raise InputError(
            f"displacement must be (M, 3) or (M, 6), got {data.displacement.shape}",
            field="displacement",
        )
    if not np.all(np.isfinite(data.displacement)):
        raise InputError("displacement contains NaN or inf", field="displacement")
    A3, b3 = _design(model, CalibrationData(q, data.wrench, data.displacement))
    m = b3.shape[1]
    w = np.where(np.arange(m) < 3, 1.0 / sigma_translation, 1.0 / sigma_rotation)
    A = (A3 * w[None, :, None]).reshape(-1, 6)
    b = (b3 * w[None, :]).reshape(-1)
    fixed = dict(fixed or {})
    for j, Kj in fixed.items():
        if not (0 <= j < 6) or not (Kj > 0):
            raise InputError(
                f"fixed stiffness needs a joint 0..5 and K > 0, got {j}: {Kj}", field="fixed"
            )
    free = np.array([j not in fixed for j in range(6)])
    c_fixed = np.array([1.0 / fixed[j] if j in fixed else 0.0 for j in range(6)])
    b = b - A @ c_fixed
    Af = A[:, free]
    norms = np.linalg.norm(Af, axis=0)
    scale = norms.max() if norms.size else 1.0
    dead = norms <= 1e-9 * scale
    if np.any(dead):
        joints = [int(np.flatnonzero(free)[i]) + 1 for i in np.flatnonzero(dead)]
        raise InputError(
            f"the calibration configurations do not excite joint(s) {joints}: their stiffness "
            "cannot be identified; add configurations/wrenches that load them, or give them as "
            "fixed values",
            field="calibration",
        )
    As = Af / norms
    sv = np.linalg.svd(As, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    nfree = int(free.sum())
    dof = A.shape[0] - nfree
    if dof < 1:
        raise InputError(
            f"{A.shape[0]} measured components cannot identify {nfree} stiffnesses with an error "
            "estimate; add experiments",
            field="calibration",
        )
    if cond > 1e12:
        raise InputError(
            f"the calibration set is rank-deficient (condition number {cond:.3g}): the joints "
            "cannot be separated; vary the configurations",
            field="calibration",
        )
    xs, *_ = np.linalg.lstsq(As, b, rcond=None)
    cf = xs / norms
    r = b - Af @ cf
    s2 = float(r @ r) / dof
    cov_s = s2 * np.linalg.inv(As.T @ As)
    se_f = np.sqrt(np.diag(cov_s)) / norms
    c = c_fixed.copy()
    c[free] = cf
    se = np.zeros(6)
    se[free] = se_f
    # Student's t quantile (scipy.special's inverse CDF: scipy.stats costs 0.6 s to import)
    t = float(stdtrit(dof, 0.5 + confidence / 2))
    lo_c = c - t * se
    hi_c = c + t * se
    if np.any(free & (hi_c <= 0)):
        bad = [int(j) + 1 for j in np.flatnonzero(free & (hi_c <= 0))]
        raise InputError(
            f"identified compliance of joint(s) {bad} is significantly negative: the data do not "
            "fit the VJM (check units, frames and the tool offset)",
            field="calibration",
        )
    # a non-positive estimate inside the noise: the data cannot tell the joint from a rigid one
    pos = c > 0
    with np.errstate(divide="ignore"):
        K = np.where(pos, 1.0 / np.where(pos, c, 1.0), np.inf)
        K_ci = np.stack(
            [1.0 / hi_c, np.where(lo_c > 0, 1.0 / np.where(lo_c > 0, lo_c, 1.0), np.inf)], axis=1
        )
    rel = np.where(free, se / np.abs(np.where(c != 0, c, 1e-300)), 0.0)
    weak = free & ((rel > weak_threshold) | ~pos)
    if np.any(weak):
        warnings.warn(
            f"joint(s) {[int(j) + 1 for j in np.flatnonzero(weak)]} are weakly excited by the "
            f"calibration set (relative standard error {np.round(rel[weak], 2).tolist()}); "
            "their stiffness is poorly determined (K = inf where the estimate is ≤ 0: "
            "indistinguishable from rigid)",
            PoorExcitationWarning,
            stacklevel=2,
        )
    res_unw = r / np.tile(w, q.shape[0])
    rows_t = np.tile(np.arange(m) < 3, q.shape[0])
    rms = float(np.sqrt(np.mean(res_unw[rows_t] ** 2)))
    return StiffnessIdentification(
        K=K,
        K_ci=K_ci,
        compliance=c,
        compliance_se=se,
        rel_se=rel,
        identified=free,
        weak=weak,
        residual=r,
        residual_rms=rms,
        condition_number=cond,
        dof=dof,
    )


_REQ = ["q1", "q2", "q3", "q4", "q5", "q6", "Fx", "Fy", "Fz", "Mx", "My", "Mz", "dx", "dy", "dz"]
_ROT = ["rx", "ry", "rz"]


def read_calibration_csv(path: str | Path, model: RobotModel | None = None) -> CalibrationData:
    """Read a calibration CSV (format in the module docstring) → :class:`CalibrationData` (SI).

    Units default to deg, mm, N, N*m, rad where the ``# units:`` line leaves them out. With
    ``model`` and ``# frame: tip`` the wrench is rotated from tip to base axes.
    """
    p = Path(path)
    t = read_table(p, _REQ, optional=_ROT, what="calibration CSV")
    has_rot = t.has(*_ROT)
    if any(c in t.columns for c in _ROT) and not has_rot:
        raise InputError("give all of rx, ry, rz or none", file=p, line=t.header_line)
    units = {"angle": "deg", "length": "mm", "force": "N", "moment": "N*m", "rotation": "rad"}
    for tok in t.meta.get("units", "").split():
        if "=" not in tok:
            raise InputError(f"bad units entry {tok!r}; expected key=unit", file=p, field="units")
        k, v = tok.split("=", 1)
        if k not in units:
            raise InputError(
                f"unknown units key {k!r}; expected {', '.join(units)}", file=p, field="units"
            )
        units[k] = v
    fa = to_si(units["angle"], "angle", file=p, field="units.angle")
    fl = to_si(units["length"], "length", file=p, field="units.length")
    ff = to_si(units["force"], "force", file=p, field="units.force")
    fm = to_si(units["moment"], "moment", file=p, field="units.moment")
    fr = to_si(units["rotation"], "angle", file=p, field="units.rotation")
    frame = t.meta.get("frame", "base").strip().lower()
    if frame not in ("base", "tip"):
        raise InputError(f"frame must be 'base' or 'tip', got {frame!r}", file=p, field="frame")
    col = t.column
    q = np.stack([col(f"q{i}") for i in range(1, 7)], axis=1) * fa
    W = np.stack([col(c) for c in ("Fx", "Fy", "Fz", "Mx", "My", "Mz")], axis=1)
    W[:, :3] *= ff
    W[:, 3:] *= fm
    d = np.stack([col(c) for c in ("dx", "dy", "dz")], axis=1) * fl
    if has_rot:
        d = np.concatenate([d, np.stack([col(c) for c in _ROT], axis=1) * fr], axis=1)
    if frame == "tip":
        if model is None:
            raise InputError(
                "frame: tip needs the robot model to rotate wrenches", file=p, field="frame"
            )
        R = model.fk(q, check_limits=False)[:, :3, :3]
        W = np.concatenate(
            [np.einsum("nij,nj->ni", R, W[:, :3]), np.einsum("nij,nj->ni", R, W[:, 3:])], axis=1
        )
    return CalibrationData(q=q, wrench=W, displacement=d)


# --------------------------------------------------------------------------------------------
# a designed identification experiment (issue #26)


@dataclass(frozen=True, eq=False)
class ExperimentDesign:
    """A set of poses and tip loads that makes all six joints identifiable.

    q : (M, 6) rad — the poses (controller convention), one experiment per row; wrench : (M, 6)
    [N; N·m] the load at the tip, base axes; tip : (M, 3) m tip positions, base frame; sigma : m
    the displacement measurement's standard deviation assumed; rel_se : (6,) the expected
    relative standard error of each joint's compliance; K_ci : (6, 2) N·m/rad the expected 95 %
    interval around the nominal stiffness; condition_number : of the column-equilibrated
    design."""

    q: F64
    wrench: F64
    tip: F64
    sigma: float
    rel_se: F64
    K_ci: F64
    condition_number: float


def _experiment_rows(model: RobotModel, q: F64, W: F64) -> F64:
    """(M, 3, 6): each experiment's tip translation per unit compliance of each joint."""
    J = model.jacobian(q, check_limits=False)
    tau = np.einsum("nji,nj->ni", J, W)
    return np.asarray(J[:, :3, :] * tau[:, None, :], dtype=float)


def design_experiment(
    model: RobotModel,
    T_base_work: F64,
    *,
    n_experiments: int = 24,
    force: float = 2000.0,
    sigma: float = 0.02e-3,
    reach: float = 1.0,
    n_candidates: int = 40000,
    seed: int = 0,
) -> ExperimentDesign:
    """Poses near the work frame and tip loads chosen for the joints' identifiability.

    Candidates: random joint configurations within the limits whose tip lies within ``reach``
    (m) of the work origin and above its plane, away from singularities, each loaded by
    ``force`` (N) along ±x, ±y, ±z of the base at the model's tool point, whose deflection is
    measured (the paper's auxiliary experiments: a load at the tip, the deflection measured by a
    laser tracker or dial gauges). That point must lie off joint 6's axis — a bracket — or
    joint 6 is never twisted. Experiments are picked
    greedily for the largest determinant of the information matrix of the relative compliances
    (D-optimal), at most two loads per pose. Expected intervals: ``σ² (AᵀA)⁻¹`` at the nominal
    stiffness (``sigma`` m per measured component). Raises :class:`InputError` when the
    candidates cannot make every joint identifiable."""
    rng = np.random.default_rng(seed)
    K = model.joint_stiffness
    c_nom = 1.0 / K
    q = rng.uniform(model.q_min, model.q_max, size=(n_candidates, 6))
    T = model.fk(q, check_limits=False)
    p = T[:, :3, 3]
    p_work = (p - T_base_work[:3, 3]) @ T_base_work[:3, :3]
    keep = (np.linalg.norm(p_work, axis=1) <= reach) & (p_work[:, 2] >= 0.05)
    q = q[keep]
    if len(q) < 2 * n_experiments:
        few = (
            f"only {len(q)} of {n_candidates} random poses of {model.name} put the tip within "
            f"{reach * 1e3:.0f} mm of the work origin"
        )
        if n_experiments > len(q):  # plenty of poses for a sane design: the count is the slip
            raise InputError(
                f"{n_experiments} experiments need {2 * n_experiments} candidate poses at least; "
                f"{few}: ask for fewer experiments (24 identify the six joints to a few %)",
                field="--experiments",
            )
        raise InputError(f"{few}: place the robot closer or raise the reach", field="--design")
    J = model.jacobian(q, check_limits=False)
    sv = np.linalg.svd(J, compute_uv=False)
    q = q[sv[:, -1] / sv[:, 0] > 1e-2]  # away from singularities
    # each pose: ±force along the base axes at the measured point
    loads = np.vstack([np.eye(3), -np.eye(3)]) * force
    n_l = 6
    Wc = np.zeros((len(q) * n_l, 6))
    Wc[:, :3] = np.tile(loads, (len(q), 1))
    qc = np.repeat(q, n_l, axis=0)
    rows = _experiment_rows(model, qc, Wc) * c_nom[None, None, :] / sigma  # relative units
    info = np.zeros((6, 6)) + 1e-9 * np.eye(6)
    chosen: list[int] = []
    per_pose = np.zeros(len(q), int)
    for _ in range(n_experiments):
        # log det(I + Rᵀ R) for each candidate: det(I₃ + R I⁻¹ Rᵀ)
        Iinv = np.linalg.inv(info)
        M = np.einsum("nai,ij,nbj->nab", rows, Iinv, rows) + np.eye(3)[None]
        gain = np.linalg.slogdet(M)[1]
        gain[chosen] = -np.inf
        gain[np.repeat(per_pose >= 2, n_l)] = -np.inf
        k = int(np.argmax(gain))
        chosen.append(k)
        per_pose[k // n_l] += 1
        info += rows[k].T @ rows[k]
    idx = np.array(sorted(chosen))
    dead = np.linalg.norm(rows[idx].reshape(-1, 6), axis=0) < 1e-6 * np.sqrt(np.trace(info))
    if np.any(dead):
        raise InputError(
            f"no load of the design twists joint(s) {[int(j) + 1 for j in np.flatnonzero(dead)]}"
            ": measure and load a point off the joint-6 axis (a bracket)",
            field="--design",
        )
    cov = np.linalg.inv(info)
    rel = np.sqrt(np.diag(cov))
    A = rows[idx].reshape(-1, 6)
    As = A / np.linalg.norm(A, axis=0)
    s = np.linalg.svd(As, compute_uv=False)
    lo_c, hi_c = c_nom * (1 - 1.96 * rel), c_nom * (1 + 1.96 * rel)
    with np.errstate(divide="ignore"):
        K_ci = np.stack([1 / hi_c, np.where(lo_c > 0, 1 / np.where(lo_c > 0, lo_c, 1), np.inf)], 1)
    q_sel, W_sel = qc[idx], Wc[idx]
    return ExperimentDesign(
        q=q_sel,
        wrench=W_sel,
        tip=model.fk(q_sel, check_limits=False)[:, :3, 3],
        sigma=sigma,
        rel_se=rel,
        K_ci=K_ci,
        condition_number=float(s[0] / s[-1]),
    )


def write_experiment_csv(
    design: ExperimentDesign, path: str | Path, robot: str, point: str, command: str
) -> Path:
    """The measuring sheet: the calibration CSV :func:`read_calibration_csv` reads, one row per
    experiment (pose in deg, load in N at the measured point, base axes), with ``dx, dy, dz``
    (mm, base axes) left empty for the measured deflection under the load (loaded minus unloaded
    position). ``point`` names the measured point (the model's tool), ``command`` the identify
    command to run on the filled sheet."""
    from roboisf.io.atomic import atomic_write

    lines = [
        f"# roboisf robot identify --design: {robot}, {len(design.q)} experiments",
        f"# the point: {point}; move to each pose, measure the point unloaded, apply the load",
        "# at the point (N, base axes), measure again; fill dx,dy,dz with loaded minus unloaded",
        f"# (mm, base axes); then run: {command}",
        "# units: angle=deg length=mm force=N moment=N*m",
        "# frame: base",
        "q1,q2,q3,q4,q5,q6,Fx,Fy,Fz,Mx,My,Mz,dx,dy,dz",
    ]
    for q, W in zip(design.q, design.wrench, strict=True):
        cells = [f"{v:.4f}" for v in np.degrees(q)] + [f"{v:.1f}" for v in W[:3]]
        cells += [f"{v:.2f}" for v in W[3:]] + ["", "", ""]
        lines.append(",".join(cells))
    p = Path(path)
    with atomic_write(p) as fh:
        fh.write("\n".join(lines) + "\n")
    return p
