"""Does the robot model hold? The measured robot term against the VJM, along the path.

``analyze`` measures the robot's deflection as what is left of the robot part's deviation when
springback, tool and holder are taken out (``δc,exp``, normal book), and predicts it with the VJM
(``δc,VJM = n · k_c W``). A single "mean |Δ|" hides whether the model is right; this module
answers with a ratio and its uncertainty:

* **ratio** — the weighted least-squares slope through the origin of measured on predicted,
  ``r = Σ x y / Σ x²`` (``x`` the VJM's normal deflection, ``y`` the measured one, all points
  used weighted alike: the scan noise is homogeneous). ``r = 1`` when the model's joint
  stiffness is right; a robot ``s`` times as compliant as modelled gives ``r ≈ s``.
* **confidence interval** — a moving-block bootstrap over laps (points along a path are not
  independent: a lap's deviations share springback, registration and force errors, and
  neighbouring laps resemble each other). Blocks of ``ℓ = ⌈L^{1/3}⌉`` consecutive laps (``L``
  laps used, Künsch's rate) are drawn with replacement, the slope recomputed, and the 2.5 / 97.5
  percentiles of :data:`N_BOOT` replicates taken (seeded: the same data give the same interval).
* **verdict** — ``not_observable`` when the predicted robot term is below twice the per-point
  scatter of the measurement about the fitted ``r · x`` (the scatter of the measured term itself
  would count the robot's own point-to-point variation, large on a coarse path, as noise);
  ``mismatch`` when the whole interval lies outside ``[1 − tol, 1 + tol]`` (``tol`` =
  :data:`RATIO_TOLERANCE`, the model error accepted) — however wide it is: a ratio of 3 ± 0.35
  is a mismatch; ``consistent`` when the interval meets that band and is no wider than
  ±:data:`MAX_HALF_WIDTH`; ``not_observable`` when it meets the band but is wider (the data cannot
  tell a 10 % error).

Per-depth ratios (equal-count depth bins) show whether the mismatch is a scale (flat) or a shape
(growing with depth: a stiffness error of the joints the wall's depth loads most, or an
unmodelled compliance).

Also here: :func:`term_statistics` (signed mean, RMS and mean |·| of each normal term — a
zero-mean error, scan noise or a sideways misregistration, has a mean |·| but no signed mean),
:func:`lateral_offset` (the first harmonic a sideways scan shift leaves in the normal deviation,
which the 3-DOF fixture registration cannot see).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "MAX_HALF_WIDTH",
    "N_BOOT",
    "RATIO_TOLERANCE",
    "LateralOffset",
    "VjmCheck",
    "boot_weights",
    "lap_blocks",
    "lap_cross_sums",
    "lap_index",
    "lap_normal_equations",
    "lateral_offset",
    "min_norm_solve",
    "min_norm_solve_many",
    "point_scatter",
    "term_statistics",
    "vjm_check",
]

F64 = NDArray[np.float64]

#: Accepted relative model error of the robot term: a ratio whose interval meets [0.9, 1.1] is
#: ``consistent``.
RATIO_TOLERANCE = 0.10
#: An interval wider than ±0.25 around the ratio cannot tell a 10 % error: ``not_observable``.
MAX_HALF_WIDTH = 0.25
#: Bootstrap replicates.
N_BOOT = 1000
#: Depth bins of the per-depth ratios.
N_DEPTH_BINS = 6


def lap_blocks(n_laps: int, rng: np.random.Generator, n_boot: int) -> NDArray[np.intp]:
    """Moving-block bootstrap draws over ``n_laps`` laps in path order: (n_boot, m) lap indices.

    Each row is ``⌈L/ℓ⌉`` blocks of ``ℓ = ⌈L^{1/3}⌉`` consecutive laps drawn with replacement
    (about ``L`` laps). Statistics that are sums over points are summed per lap first and then
    over a row's laps — the same as resampling the points, at the cost of the laps."""
    ell = max(1, math.ceil(n_laps ** (1 / 3)))
    n_blocks = math.ceil(n_laps / ell)
    starts = rng.integers(0, n_laps - ell + 1, size=(n_boot, n_blocks))
    return (starts[:, :, None] + np.arange(ell)[None, None, :]).reshape(n_boot, -1)


def lap_index(lap: NDArray[Any]) -> tuple[NDArray[np.intp], int]:
    """(M,) index of each point's lap among the sorted distinct laps, and their number."""
    laps, inv = np.unique(lap, return_inverse=True)
    return inv.astype(np.intp), int(laps.size)


def lap_normal_equations(X: F64, y: F64, inv: NDArray[np.intp], L: int) -> tuple[F64, F64]:
    """Per-lap ``XᵀX`` (L, k, k) and ``Xᵀy`` (L, k) of ``X`` (M, k), ``y`` (M,) with each point's
    lap ``inv`` (M,) in ``0 … L − 1``: a fit on any multiset of laps sums them (the bootstrap,
    the held-out-lap checks) — the same least squares as on the points, at the cost of the laps."""
    # per-lap sums by bincount: the same additions in the same (point) order as np.add.at, so
    # the same bits, 2-3x faster; XᵀX's upper triangle only, mirrored (xᵢxⱼ = xⱼxᵢ exactly)
    k = X.shape[1]
    G = np.empty((L, k, k))
    for i in range(k):
        for j in range(i, k):
            G[:, i, j] = np.bincount(inv, weights=X[:, i] * X[:, j], minlength=L)
            G[:, j, i] = G[:, i, j]
    return G, lap_cross_sums(X, y, inv, L)


def lap_cross_sums(X: F64, y: F64, inv: NDArray[np.intp], L: int) -> F64:
    """Per-lap ``Xᵀy`` (L, k) of :func:`lap_normal_equations` alone (another right-hand side
    for the same laps' ``XᵀX``)."""
    h = np.empty((L, X.shape[1]))
    for i in range(X.shape[1]):
        h[:, i] = np.bincount(inv, weights=X[:, i] * y, minlength=L)
    return h


def min_norm_solve(G: F64, h: F64) -> F64:
    """The minimum-norm least-squares solution of ``G x = h`` (k, k), (k,) → (k,)
    (``numpy.linalg.lstsq``, its default cut-off)."""
    x, *_ = np.linalg.lstsq(G, h, rcond=None)
    return np.asarray(x, dtype=float)


def min_norm_solve_many(G: F64, h: F64) -> F64:
    """:func:`min_norm_solve` of each system of a stack: ``G`` (B, k, k), ``h`` (B, k) → (B, k).
    The same minimum-norm solutions (the pseudo-inverse with ``lstsq``'s default cut-off,
    singular values ≤ k·eps of the largest dropped), equal to rounding; one batched SVD instead
    of B ``lstsq`` calls (≈ 35 µs each in Python: the diagnosis's 400 replicates × 7 fits, the
    identification's 2 × 1000)."""
    k = G.shape[-1]
    P = np.linalg.pinv(G, rcond=np.finfo(float).eps * k)
    return np.asarray(np.einsum("bij,bj->bi", P, h), dtype=float)


def boot_weights(L: int, n_boot: int, seed: int) -> F64:
    """(n_boot, L) how many times each of ``L`` laps is drawn in each of ``n_boot`` moving-block
    bootstrap replicates (:func:`lap_blocks`, seeded: the same data give the same interval)."""
    rng = np.random.default_rng(seed)
    draws = lap_blocks(L, rng, n_boot)
    return np.stack([np.bincount(d, minlength=L) for d in draws]).astype(float)


def _slope(x: F64, y: F64) -> float:
    # elementwise sums (not BLAS): steady on a machine whose cores are shared
    sxx = float(np.sum(x * x))
    return float(np.sum(x * y)) / sxx if sxx > 0 else math.nan


def point_scatter(y: F64, lap: NDArray[Any]) -> float:
    """Robust per-point noise of ``y`` along the path: 1.4826 · MAD of successive differences
    within a lap, / √2 (a smooth field's differences are ~0, white noise's have √2 σ)."""
    same = lap[1:] == lap[:-1]
    dy = np.diff(y)[same]
    if dy.size < 2:
        return math.nan
    return float(1.4826 * np.median(np.abs(dy - np.median(dy))) / math.sqrt(2))


@dataclass(frozen=True)
class VjmCheck:
    """The measured/VJM robot-deflection ratio (normal book) with its interval and verdict.

    ``ratio``, ``ci_low``, ``ci_high`` dimensionless; ``rms_predicted``, ``rms_measured``,
    ``noise``, ``residual_rms`` m; ``per_depth`` rows of ``depth_lo``, ``depth_hi`` (m), ``ratio``,
    ``n``."""

    ratio: float
    ci_low: float
    ci_high: float
    verdict: str
    reason: str
    n_points: int
    n_laps: int
    block_laps: int
    rms_predicted: float
    rms_measured: float
    noise: float
    residual_rms: float
    tolerance: float
    per_depth: list[dict[str, float]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """summary.json's ``vjm_check`` (lengths in mm)."""

        def f(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "ratio": f(self.ratio),
            "ci_low": f(self.ci_low),
            "ci_high": f(self.ci_high),
            "verdict": self.verdict,
            "reason": self.reason,
            "method": (
                "least-squares slope through the origin of the measured on the VJM-predicted "
                "normal robot deflection; 95 % interval from a moving-block bootstrap over laps "
                f"({N_BOOT} replicates, blocks of {self.block_laps} laps)"
            ),
            "tolerance": self.tolerance,
            "n_points": self.n_points,
            "n_laps": self.n_laps,
            "rms_predicted_mm": self.rms_predicted * 1e3,
            "rms_measured_mm": self.rms_measured * 1e3,
            "noise_mm": f(self.noise * 1e3),
            "residual_rms_mm": self.residual_rms * 1e3,
            "per_depth": [
                {
                    "depth_lo_mm": r["depth_lo"] * 1e3,
                    "depth_hi_mm": r["depth_hi"] * 1e3,
                    "ratio": f(r["ratio"]),
                    "n": int(r["n"]),
                }
                for r in self.per_depth
            ],
        }


def vjm_check(
    measured: F64,
    predicted: F64,
    valid: NDArray[np.bool_],
    lap: NDArray[Any],
    depth: F64,
    *,
    tolerance: float = RATIO_TOLERANCE,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> VjmCheck:
    """Ratio of the measured to the VJM-predicted robot deflection along the path.

    Parameters
    ----------
    measured, predicted : (N,) m — normal robot deflection, measured (``δc,exp · n``) and VJM
    valid : (N,) bool — points used (both scans, below the rim band)
    lap : (N,) int — lap of each point (the bootstrap's blocks)
    depth : (N,) m — depth below the sheet plane (per-depth ratios)
    tolerance : accepted relative model error (the ``consistent`` band is ``1 ± tolerance``)
    """
    sel = np.asarray(valid, bool) & np.isfinite(measured) & np.isfinite(predicted)
    y, x, lp, z = measured[sel], predicted[sel], np.asarray(lap)[sel], depth[sel]
    n = int(y.size)
    n_laps = int(np.unique(lp).size)
    ell = max(1, math.ceil(n_laps ** (1 / 3))) if n_laps else 0
    rms_x = float(np.sqrt(np.mean(x**2))) if n else 0.0
    rms_y = float(np.sqrt(np.mean(y**2))) if n else 0.0
    noise = point_scatter(y, lp) if n else math.nan
    common = dict(
        n_points=n,
        n_laps=n_laps,
        block_laps=ell,
        rms_predicted=rms_x,
        rms_measured=rms_y,
        noise=noise,
        tolerance=tolerance,
    )
    if n < 10 or n_laps < 3 or rms_x == 0.0:
        return VjmCheck(
            math.nan,
            math.nan,
            math.nan,
            "not_observable",
            f"too few points/laps ({n} points, {n_laps} laps) or no predicted robot deflection",
            residual_rms=math.nan,
            **common,  # type: ignore[arg-type]
        )
    r = _slope(x, y)
    resid = float(np.sqrt(np.mean((y - r * x) ** 2)))
    # the measurement's noise: the scatter left about the fitted model (not of y itself, whose
    # real point-to-point variation the successive differences would count as noise)
    noise = point_scatter(y - r * x, lp) if math.isfinite(r) else noise
    common["noise"] = noise
    rng = np.random.default_rng(seed)
    inv, L = lap_index(lp)
    sxy = np.bincount(inv, weights=x * y, minlength=L)
    sxx = np.bincount(inv, weights=x * x, minlength=L)
    draws = lap_blocks(L, rng, n_boot)
    with np.errstate(invalid="ignore", divide="ignore"):
        boot = sxy[draws].sum(axis=1) / sxx[draws].sum(axis=1)
    boot = boot[np.isfinite(boot)]
    lo, hi = (float(v) for v in np.percentile(boot, [2.5, 97.5]))
    per_depth = []
    # quantiles of the laps' few depths repeat on a part of few laps (a 12 mm cone: bins
    # "7.7–7.7 mm, 0 points"): each edge once, and no empty bin
    edges = np.unique(np.quantile(z, np.linspace(0, 1, N_DEPTH_BINS + 1)))
    nb = len(edges) - 1
    for k in range(nb):
        m = (z >= edges[k]) & ((z < edges[k + 1]) if k < nb - 1 else (z <= edges[k + 1]))
        if not m.any():
            continue
        per_depth.append(
            {
                "depth_lo": float(edges[k]),
                "depth_hi": float(edges[k + 1]),
                "ratio": _slope(x[m], y[m]) if m.sum() >= 3 else math.nan,
                "n": float(m.sum()),
            }
        )
    if math.isfinite(noise) and rms_x < 2 * noise:
        verdict = "not_observable"
        reason = (
            f"the predicted robot deflection (RMS {rms_x * 1e3:.3f} mm) is below twice the "
            f"measurement's point scatter ({noise * 1e3:.3f} mm)"
        )
    elif hi < 1 - tolerance or lo > 1 + tolerance:
        verdict = "mismatch"
        reason = (
            f"the robot gives way {r:.2f}× as much as the VJM predicts (95 % interval "
            f"[{lo:.2f}, {hi:.2f}] outside 1 ± {tolerance:g})"
        )
    elif (hi - lo) / 2 > MAX_HALF_WIDTH:
        verdict = "not_observable"
        reason = (
            f"the 95 % interval [{lo:.2f}, {hi:.2f}] is wider than ±{MAX_HALF_WIDTH:g}: the robot "
            "term cannot be told from the other terms' errors"
        )
    else:
        verdict = "consistent"
        reason = (
            f"measured/VJM {r:.2f} (95 % interval [{lo:.2f}, {hi:.2f}] meets 1 ± {tolerance:g})"
        )
    return VjmCheck(r, lo, hi, verdict, reason, residual_rms=resid, per_depth=per_depth, **common)  # type: ignore[arg-type]


def term_statistics(
    normal: dict[str, F64], valid: NDArray[np.bool_]
) -> dict[str, dict[str, float]]:
    """Signed mean, RMS and mean |·| [mm] of each normal term over the used points.

    ``normal`` maps a term name to its (N,) normal component [m]. A term whose mean |·| is far
    above its |signed mean| is mostly zero-mean (noise, a sideways misregistration, an error that
    changes sign around the part), not a deflection of one sign."""
    out = {}
    for k, v in normal.items():
        u = v[valid]
        u = u[np.isfinite(u)]
        if u.size == 0:
            continue
        out[k] = {
            "mean_mm": float(np.mean(u)) * 1e3,
            "rms_mm": float(np.sqrt(np.mean(u**2))) * 1e3,
            "mean_abs_mm": float(np.mean(np.abs(u))) * 1e3,
            "std_mm": float(np.std(u)) * 1e3,
        }
    return out


@dataclass(frozen=True)
class LateralOffset:
    """A sideways shift ``(sx, sy)`` [m] (work axes) that explains part of a normal deviation
    field: its size, its standard error and the share of the field's variance it explains."""

    shift: F64
    se: float
    explained: float

    @property
    def size(self) -> float:
        return float(np.hypot(*self.shift))

    @property
    def direction_deg(self) -> float:
        return math.degrees(math.atan2(self.shift[1], self.shift[0]))


def lateral_offset(
    dn: F64, normal: F64, lap: NDArray[Any], valid: NDArray[np.bool_]
) -> LateralOffset | None:
    """Fit ``dn ≈ a_lap + n_x s_x + n_y s_y`` by least squares (a constant per lap, a shift).

    A scan shifted sideways by ``s`` moves every measured point by ``s``: the normal deviation
    changes by ``n · s`` — on a round wall the first harmonic in angle, amplitude ``sin α |s|``.
    The fixture registration (z and tilts) cannot see it. Returns None when the normals do not
    vary enough around the laps to tell (a flat patch). ``se`` is the plain LS standard error
    (points taken as independent: a lower bound)."""
    sel = np.asarray(valid, bool) & np.isfinite(dn)
    if sel.sum() < 20:
        return None
    y, N, lp = dn[sel], normal[sel, :2], np.asarray(lap)[sel]
    _, inv = np.unique(lp, return_inverse=True)
    cnt = np.bincount(inv).astype(float)

    def demean(v: F64) -> F64:
        return v - (np.bincount(inv, weights=v) / cnt)[inv]

    A = np.column_stack([demean(N[:, 0]), demean(N[:, 1])])
    yd = demean(y)
    AtA = A.T @ A
    if np.linalg.cond(AtA) > 1e8 or np.min(np.linalg.eigvalsh(AtA)) < 1e-3 * y.size:
        return None
    s = np.asarray(np.linalg.solve(AtA, A.T @ yd), dtype=np.float64)
    r = yd - A @ s
    dof = max(1, y.size - 2 - cnt.size)
    s2 = float(r @ r) / dof
    se = float(np.sqrt(s2 * np.max(np.diag(np.linalg.inv(AtA)))))
    tot = float(yd @ yd)
    return LateralOffset(s, se, 1.0 - float(r @ r) / tot if tot > 0 else 0.0)
