"""The robot's joint compliance identified from the forming run itself (normal book).

The VJM deflection at the tip is linear in the joint compliances ``c_i = 1/K_i``::

    δ = Σ_i c_i J_i (J_iᵀ W)            (J_i the i-th column of the tip Jacobian, work axes)

and a scan sees its normal component, so per toolpath point ``p``::

    y_p = n_p · δ_p = Σ_i c_i a_pi,     a_pi = (n_p · J_i,lin) (J_iᵀ W_p)

with ``y`` the measured robot term ``δc,exp · n`` (robot part − springback − tool − holder).
Stacking the used points gives ``A c = y``, solved by least squares (all points weighted alike;
the scan noise is homogeneous). Along one part's path the configurations barely change, so the
six columns are nearly collinear: the **observability** is stated from the singular values of the
column-equilibrated ``A`` (condition number) and from the bootstrap spread of each ``c_i``
(moving blocks of laps, as :func:`roboisf.decompose.check.vjm_check`). A joint is *identified*
when its compliance is positive with a relative standard error below :data:`MAX_REL_SE`. The
identified joints are refitted with the others held at their nominal compliance (**joints**
mode; the held joints are named, also those carrying ≥ :data:`MIN_SHARE` of the predicted
deflection — one joint the path cannot separate is no reason to give up the others, issue #26);
when no joint is identified, or when that model predicts held-out laps (5 contiguous groups of
laps, each left out in turn) no better than one scale, the fit is **one scale on the nominal
compliance**: ``y ≈ s · (A c_nom)``, ``K = K_nom / s`` — what one forming run can always tell.

The result is written as the stiffness TOML ``roboisf robot identify`` writes
(``[stiffness] K = [...]`` N·m/rad, ``ci_low``, ``ci_high``, ``source``), which
``robot deflect``, ``compensate`` and ``plan`` accept with ``--stiffness``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray

from roboisf.decompose.check import (
    N_BOOT,
    boot_weights,
    lap_cross_sums,
    lap_index,
    lap_normal_equations,
    min_norm_solve,
    min_norm_solve_many,
)
from roboisf.errors import InputError
from roboisf.io.atomic import atomic_write
from roboisf.robot.model import RobotModel

__all__ = [
    "MAX_REL_SE",
    "MIN_SHARE",
    "FormingIdentification",
    "forming_design",
    "identify_from_forming",
    "write_stiffness_toml",
]

F64 = NDArray[np.float64]

#: A joint's compliance is identified when its bootstrap relative standard error is below this.
MAX_REL_SE = 0.3
#: A joint whose column carries less than this share of the predicted normal deflection (RMS)
#: is not needed: it keeps its nominal stiffness.
MIN_SHARE = 0.05


def forming_design(
    model: RobotModel,
    q: F64,
    W_work: F64,
    T_base_work: F64,
    normal: F64,
    ball_radius: float = 0.0,
) -> F64:
    """``A`` (N, 6) [m per rad/(N·m)]: the normal deflection of the ball centre per unit
    compliance of each joint.

    q : (N, 6) rad; W_work : (N, 6) [N; N·m] the sheet's wrench on the tool at the tip, work
    axes; T_base_work : (4, 4); normal : (N, 3) unit, work axes; ball_radius : m, the ball
    centre ``tip + R ẑ`` whose normal motion ``analyze`` measures and checks
    (:func:`roboisf.cell.at_ball_centre`; 0: the tip). ``A @ (1/K)`` equals
    ``n · at_ball_centre(model.deflection(q, W, T_base_work), R)``."""
    J = model.jacobian(q, check_limits=False, T_base_work=T_base_work)  # (N, 6, 6) work axes
    tau = np.einsum("nji,nj->ni", J, W_work)  # J_iᵀ W
    # ball centre: δ_C = δ_T + θ × R ẑ, column by column
    lin = J[:, :3, :] + np.cross(J[:, 3:, :], [0.0, 0.0, ball_radius], axisa=1, axisc=1)
    nJ = np.einsum("nj,nji->ni", normal, lin)  # n · J_i at the ball centre
    return np.asarray(nJ * tau, dtype=float)


@dataclass(frozen=True, eq=False)
class FormingIdentification:
    """Joint stiffness from a forming run.

    K : (6,) N·m/rad; K_ci : (6, 2) 95 % bootstrap interval; mode : "joints" (each joint fitted)
    or "scale" (one scale on the nominal compliance); scale, scale_ci : the identified over the
    nominal compliance (both modes: the LS scale of the identified prediction); identified :
    (6,) bool, joints fitted individually; rel_se : (6,) bootstrap relative standard error of each
    joint's compliance in the 6-joint fit; share : (6,) share of each joint in the nominal
    prediction (RMS); singular_values : (6,) of the column-equilibrated design, largest first;
    condition_number; predicted : (N,) m the identified model's normal deflection at every point;
    residual_rms : m, measured − predicted over the used points; n_points, n_laps."""

    K: F64
    K_ci: F64
    K_nominal: F64
    mode: str
    scale: float
    scale_ci: tuple[float, float]
    identified: NDArray[np.bool_]
    rel_se: F64
    share: F64
    singular_values: F64
    condition_number: float
    cv_rms: dict[str, float]
    predicted: F64
    residual_rms: float
    n_points: int
    n_laps: int

    def observability(self) -> str:
        """One sentence: which joints / which combination the run can identify."""
        ok = [int(i) + 1 for i in np.flatnonzero(self.identified)]
        needed = [int(i) + 1 for i in np.flatnonzero(self.share >= MIN_SHARE)]
        base = (
            f"condition number {self.condition_number:.3g} of the equilibrated design; "
            f"joints carrying ≥ {MIN_SHARE:.0%} of the predicted deflection: {needed}"
        )
        cv = ", ".join(f"{k} {v * 1e3:.4f} mm" for k, v in self.cv_rms.items())
        base += f"; held-out-lap RMS error: {cv}"
        held = [int(i) + 1 for i in np.flatnonzero(~self.identified)]
        held_needed = [j for j in held if j in needed]
        if self.mode == "joints":
            tail = (
                f"; joints {held_needed} carry ≥ {MIN_SHARE:.0%} but the path cannot separate "
                "them: held at their nominal stiffness"
                if held_needed
                else ""
            )
            return f"joints {ok} identified, joints {held} held at nominal{tail}; {base}"
        return (
            f"joints not separable (identified alone: {ok or 'none'}); one scale on the nominal "
            f"compliance fitted ({self.scale:.3f}, 95 % [{self.scale_ci[0]:.3f}, "
            f"{self.scale_ci[1]:.3f}]); {base}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "K": self.K.tolist(),
            "ci_low": self.K_ci[:, 0].tolist(),
            "ci_high": [float(v) if math.isfinite(v) else None for v in self.K_ci[:, 1]],
            "K_nominal": self.K_nominal.tolist(),
            "compliance_scale": self.scale,
            "compliance_scale_ci": list(self.scale_ci),
            "identified_joints": [int(i) + 1 for i in np.flatnonzero(self.identified)],
            "relative_se": [float(v) if math.isfinite(v) else None for v in self.rel_se],
            "share_of_prediction": self.share.tolist(),
            "singular_values": self.singular_values.tolist(),
            "condition_number": self.condition_number,
            "cross_validated_rms_mm": {k: v * 1e3 for k, v in self.cv_rms.items()},
            "residual_rms_mm": self.residual_rms * 1e3,
            "observability": self.observability(),
            "n_points": self.n_points,
            "n_laps": self.n_laps,
        }


def _mv(M: F64, v: F64) -> F64:
    """``M @ v`` without BLAS (steady timing on a machine whose cores are shared)."""
    return np.asarray(np.einsum("ij,j->i", M, v), dtype=float)


def _scale_fit(b: F64, y: F64) -> float:
    bb = float(np.sum(b * b))
    return float(np.sum(b * y)) / bb if bb > 0 else math.nan


def _cv_rms(
    fitter: Any, A: F64, y: F64, inv: NDArray[np.intp], n_laps: int, folds: int = 5
) -> float:
    """RMS prediction error on held-out laps: ``folds`` contiguous groups of laps, each left out
    in turn (neighbouring laps resemble each other, so the groups are contiguous). ``fitter``
    takes lap weights (n_laps,)."""
    lap_group = (np.arange(n_laps) * folds) // max(n_laps, 1)
    group = lap_group[inv]
    err = np.zeros_like(y)
    for g in range(folds):
        test = group == g
        if not test.any() or test.all():
            continue
        c = fitter((lap_group != g).astype(float))
        err[test] = y[test] - np.einsum("ij,j->i", A[test], c)
    return float(np.sqrt(np.mean(err**2)))


def identify_from_forming(
    A: F64,
    measured: F64,
    valid: NDArray[np.bool_],
    lap: NDArray[Any],
    K_nominal: F64,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> FormingIdentification:
    """Least-squares joint compliance from the normal robot term (see the module docstring).

    Parameters
    ----------
    A : (N, 6) — :func:`forming_design`
    measured : (N,) m — the measured normal robot term ``δc,exp · n``
    valid : (N,) bool — points used
    lap : (N,) — lap of each point (bootstrap blocks)
    K_nominal : (6,) N·m/rad — the model's stiffness (the fallback's reference)
    """
    K_nominal = np.asarray(K_nominal, dtype=float)
    sel = np.asarray(valid, bool) & np.isfinite(measured) & np.all(np.isfinite(A), axis=1)
    Au, y, lp = A[sel], measured[sel], np.asarray(lap)[sel]
    n_laps = int(np.unique(lp).size)
    if y.size < 20 or n_laps < 3:
        raise InputError(
            f"too few points to identify the robot's compliance ({y.size} points, {n_laps} laps)",
            field="identification",
        )
    c_nom = 1.0 / K_nominal
    pred_nom = Au * c_nom  # (M, 6) each joint's nominal share
    share_rms = np.sqrt(np.mean(pred_nom**2, axis=0))
    share = share_rms / share_rms.sum() if share_rms.sum() > 0 else np.zeros(6)
    norms = np.linalg.norm(Au, axis=0)
    live = norms > 1e-12 * max(norms.max(), 1e-300)
    As = Au[:, live] / norms[live]
    sv = np.zeros(6)
    s_live = np.linalg.svd(As, compute_uv=False)
    sv[: s_live.size] = s_live
    cond = float(s_live[0] / s_live[-1]) if s_live[-1] > 0 else math.inf

    # normal equations per lap: a fit on any multiset of laps sums them (the bootstrap, the
    # held-out-lap check) — the same least squares as on the points, at the cost of the laps
    inv, L = lap_index(lp)
    k = As.shape[1]
    G, h = lap_normal_equations(As, y, inv, L)

    live_idx = np.flatnonzero(live)
    all_cols = np.arange(k)

    def solve(Gs: F64, hs: F64, cols: NDArray[np.intp]) -> F64:
        if cols is not all_cols:
            Gs, hs = Gs[np.ix_(cols, cols)], hs[cols]
        return min_norm_solve(Gs, hs)

    def fit(w: F64) -> F64:
        """6-joint fit on laps weighted by ``w`` (L,) (counts of a bootstrap draw)."""
        c = np.zeros(6)
        c[live] = solve(np.einsum("l,lij->ij", w, G), w @ h, all_cols) / norms[live]
        return c

    weights = boot_weights(L, n_boot, seed)
    c_all = fit(np.ones(L))
    # the replicates' normal equations summed and solved as one stack (the same minimum-norm
    # solutions as fit() of each, to rounding; 1000 lstsq calls were 0.05 s of every analysis)
    G_boot = np.einsum("bl,lij->bij", weights, G)
    boot = np.zeros((weights.shape[0], 6))
    boot[:, live] = min_norm_solve_many(G_boot, weights @ h) / norms[live]
    se = boot.std(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(live & (c_all > 0), se / np.abs(c_all), math.inf)
    identified = live & (c_all > 0) & (rel < MAX_REL_SE)
    b_nom = _mv(Au, c_nom)
    # the joints model: the identified joints refitted with the others held at their nominal
    # compliance (a joint left out of the refit must not keep a share the fit gave it)
    idx_id = np.flatnonzero(identified)
    cols_id = np.searchsorted(live_idx, idx_id)  # their columns in As
    y_fixed = y - _mv(Au[:, ~identified], c_nom[~identified])
    h_fix = lap_cross_sums(As, y_fixed, inv, L)  # the same laps' XᵀX: G above
    bb = np.bincount(inv, weights=b_nom * b_nom, minlength=L)
    by = np.bincount(inv, weights=b_nom * y, minlength=L)

    def fit_joints(w: F64) -> F64:
        c = c_nom.copy()
        if idx_id.size:
            x = solve(np.einsum("l,lij->ij", w, G), w @ h_fix, cols_id)
            c[idx_id] = x / norms[idx_id]
        return c

    def fit_scale(w: F64) -> F64:
        return float(w @ by) / float(w @ bb) * c_nom

    # every joint the path excites is fitted; a needed joint it cannot separate is held at its
    # nominal and named (observability()), not a reason to fall back to one scale
    joints_ok = bool(idx_id.size)
    cv = {"scale": _cv_rms(fit_scale, Au, y, inv, L)}
    if joints_ok:
        cv["joints"] = _cv_rms(fit_joints, Au, y, inv, L)
    # the joints model only when it predicts laps it was not fitted on better than one scale
    if joints_ok and cv["joints"] < cv["scale"]:
        mode = "joints"
        c = fit_joints(np.ones(L))
        boot_c = np.tile(c_nom, (weights.shape[0], 1))
        if idx_id.size:  # fit_joints() of each replicate, as one stack
            G_id = G_boot[:, cols_id[:, None], cols_id[None, :]]
            x_boot = min_norm_solve_many(G_id, (weights @ h_fix)[:, cols_id])
            boot_c[:, idx_id] = x_boot / norms[idx_id]
        lo_c = np.percentile(boot_c, 2.5, axis=0)
        hi_c = np.percentile(boot_c, 97.5, axis=0)
        # the scale of a prediction A c on the nominal one is linear in c
        v = np.einsum("i,ij->j", b_nom, Au) / float(np.sum(b_nom * b_nom))
        scale = float(np.sum(v * c))
        sb = np.einsum("bj,j->b", boot_c, v)
        if np.any(c[idx_id] <= 0):
            mode = "scale"
    else:
        mode = "scale"
    if mode == "scale":
        scale = _scale_fit(b_nom, y)
        sb = (weights @ by) / (weights @ bb)
        if not scale > 0:
            raise InputError(
                f"the measured robot term does not follow the VJM's pattern (scale {scale:.3g} "
                "on the nominal compliance): no stiffness can be identified",
                field="identification",
            )
        c = scale * c_nom
        slo, shi = np.percentile(sb, [2.5, 97.5])
        lo_c, hi_c = slo * c_nom, shi * c_nom
    s_ci = tuple(float(v) for v in np.percentile(sb, [2.5, 97.5]))
    with np.errstate(divide="ignore"):
        K = 1.0 / c
        K_ci = np.stack(
            [1.0 / hi_c, np.where(lo_c > 0, 1.0 / np.where(lo_c > 0, lo_c, 1), np.inf)], 1
        )
    predicted = _mv(A, c)
    resid = float(np.sqrt(np.mean((y - _mv(Au, c)) ** 2)))
    return FormingIdentification(
        K=K,
        K_ci=K_ci,
        K_nominal=K_nominal,
        mode=mode,
        scale=float(scale),
        scale_ci=(s_ci[0], s_ci[1]),
        identified=identified,
        rel_se=rel,
        share=share,
        singular_values=sv,
        condition_number=cond,
        cv_rms=cv,
        predicted=predicted,
        residual_rms=resid,
        n_points=int(y.size),
        n_laps=n_laps,
    )


def write_stiffness_toml(
    r: FormingIdentification, path: str | Path, source: str, robot: str | None = None
) -> Path:
    """Write ``r`` as a stiffness TOML (the ``roboisf robot identify`` format, N·m/rad), with
    the observability as extra keys. An unbounded upper CI is written as 1e300. ``weak`` marks
    the joints not identified separately: held at the nominal in ``joints`` mode (their interval
    is then the nominal value itself, not an estimate) or moved with the others by the one scale
    in ``scale`` mode (their interval is the scale's)."""
    p = Path(path)
    doc = {
        "stiffness": {
            "K": [float(v) for v in r.K],
            "ci_low": [float(v) for v in r.K_ci[:, 0]],
            "ci_high": [float(v) if math.isfinite(v) else 1e300 for v in r.K_ci[:, 1]],
            "weak": [bool(not i) for i in r.identified],
            "residual_rms_m": r.residual_rms,
            "condition_number": r.condition_number if math.isfinite(r.condition_number) else 1e300,
            "mode": r.mode,
            "compliance_scale": r.scale,
            "compliance_scale_ci": list(r.scale_ci),
            "K_nominal": [float(v) for v in r.K_nominal],
            "observability": r.observability(),
            "source": source,
            # the model it was identified on: load_stiffness refuses it for another robot
            **({"robot": robot} if robot else {}),
        }
    }
    with atomic_write(p, "wb", encoding=None) as f:
        f.write(
            b"# joint stiffness K in N*m/rad, 95 % confidence interval [ci_low, ci_high],\n"
            b"# identified from a forming run by roboisf analyze (docs/analyze.md)\n"
        )
        tomli_w.dump(doc, f)
    return p
