"""Springback per toolpath point, learned from the history's analysed parts.

The target is the analysis's normal springback ``springback_dn`` (m, ``δs = δ_CNC − δt,CNC`` on
the normal) at the points the analysis used (below the rim band, scanned on both parts); the
inputs are the local geometry of :mod:`roboisf.learn.features` and the sheet's material. The
regression is scikit-learn's ``HistGradientBoostingRegressor`` (squared error, the material as a
categorical input), each part weighted alike whatever its number of points.

**Validated by leaving whole parts out.** Points of one part are not independent (neighbours
share their geometry and their scan), so a random split would report the fit, not the
prediction of a new part. Each part is predicted by a model trained on all the others;
:attr:`SpringbackLearner.validation` gives, per part, the RMS of its springback, the RMS error
of its prediction and their ratio.

**Calibrated intervals.** The interval is split-conformal on those leave-part-out residuals:
``prediction ± q`` with ``q`` the ⌈(n + 1)·coverage⌉-th smallest of the n out-of-part absolute
residuals, so a point of a new part, drawn like the history's parts, falls inside with at least
``coverage`` probability. It is one width for every point: honest for parts like the history's,
not a promise for a shape outside it (:meth:`SpringbackLearner.outside` names the features of a
new part that leave the training range).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.learn.features import FEATURE_TOLERANCE, FEATURES, point_features

__all__ = ["SpringbackLearner", "fit_springback", "history_features", "require_sklearn"]

F64 = NDArray[np.float64]

#: gradient boosting settings: shallow trees, many small steps, leaves of ≥ 20 points
_PARAMS = {
    "max_iter": 200,
    "learning_rate": 0.08,
    "max_leaf_nodes": 15,
    "min_samples_leaf": 20,
    "l2_regularization": 1e-3,
}


@contextmanager
def _one_thread() -> Iterator[None]:
    """One OpenMP thread for scikit-learn inside: on a few thousand points the threads' spinning
    costs ~10× the work on a shared machine (62 s → 5 s wall for the 8 fits of a 7-part
    history, 2 busy cores). Set after sklearn has loaded its OpenMP runtime (threadpoolctl only
    limits loaded libraries)."""
    require_sklearn()
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="openmp"):
        yield


def require_sklearn() -> Any:
    """The ``sklearn.ensemble`` module, or a one-line error naming the extra to install."""
    try:
        from sklearn import ensemble
    except ImportError:
        raise InputError(
            "the learned springback model needs scikit-learn: pip install 'roboisf[history]'"
        ) from None
    return ensemble


def history_features(
    table: Any,
) -> tuple[F64, F64, NDArray[np.int64], list[str], NDArray[np.bool_]]:
    """Features of every point of the history's parts.

    ``table`` is :func:`roboisf.history.store.points_table`'s frame. Returns ``X`` (N, F),
    the springback target ``y`` (N,) m, the part id per point, the material per point and the
    mask of the points the learner trains on (used, finite target).
    """
    X, y, pid, mat, ok = [], [], [], [], []
    for part_id, g in table.groupby("part_id", sort=True):
        g = g.sort_values("idx")
        X.append(
            point_features(
                g[["x", "y", "z"]].to_numpy(float),
                g[["nx", "ny", "nz"]].to_numpy(float),
                g["wall_angle"].to_numpy(float),
                g["lap"].to_numpy(np.int64),
                step_down=float(g["step_down"].iloc[0]),
                tool_radius=float(g["tool_radius"].iloc[0]),
                sheet_thickness=float(g["sheet_thickness"].iloc[0]),
            )
        )
        target = g["springback_dn"].to_numpy(float)
        y.append(target)
        pid.append(np.full(len(g), int(part_id)))
        mat.extend(g["material"].astype(str).tolist())
        ok.append((g["used"].to_numpy() == 1) & np.isfinite(target))
    if not X:
        raise InputError("the history has no parts to learn from", field="--history")
    return np.vstack(X), np.concatenate(y), np.concatenate(pid), mat, np.concatenate(ok)


@dataclass(frozen=True, eq=False)
class SpringbackLearner:
    """A fitted springback model (SI).

    model : the fitted regressor (inputs: :data:`FEATURES` + material code)
    materials : the materials seen, in code order
    half_width : float, m — the conformal interval's half-width at ``coverage``
    coverage : float — the nominal coverage of the interval
    validation : list of dict — per part left out: ``part_id``, ``part_kind``, ``n_points``,
        ``rms_springback_m``, ``rms_error_m``, ``relative_error`` (their ratio) and
        ``coverage`` (share of its points inside ``prediction ± half_width``)
    feature_range : (F, 2) float — min and max of each feature over the training points
    """

    model: Any
    materials: tuple[str, ...]
    half_width: float
    coverage: float
    validation: list[dict[str, Any]] = field(default_factory=list)
    feature_range: F64 = field(default_factory=lambda: np.zeros((len(FEATURES), 2)))
    n_points: int = 0
    n_parts: int = 0
    #: (n,) m — the out-of-part residuals (truth − prediction of a model without the point's
    #: part), the interval's calibration set
    residuals: F64 = field(default_factory=lambda: np.zeros(0))

    def _inputs(self, X: F64, material: str) -> F64:
        if material not in self.materials:
            raise InputError(
                f"the history has no part in material {material!r} (it has: "
                f"{', '.join(self.materials)})",
                field="material",
            )
        code = np.full((len(X), 1), float(self.materials.index(material)))
        return np.hstack([X, code])

    def predict(self, X: F64, material: str = "unknown") -> tuple[F64, F64, F64]:
        """Springback (N,) m with its interval's low and high ends, for features (N, F)."""
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != len(FEATURES):
            raise InputError(f"expected features (N, {len(FEATURES)}), got {X.shape}")
        with _one_thread():
            p = np.asarray(self.model.predict(self._inputs(X, material)), dtype=float)
        return p, p - self.half_width, p + self.half_width

    def outside(self, X: F64, margin: float = 0.05) -> dict[str, float]:
        """Features for which more than ``margin`` of the points of ``X`` leave the training
        range: name → that share (the model extrapolates there: trees predict the edge).

        A point is outside beyond 2 % of the range or the feature's absolute tolerance
        (:data:`~roboisf.learn.features.FEATURE_TOLERANCE`), whichever is wider: a feature the
        history holds at one value (a cone's meridian curvature, 0) is not left by noise."""
        lo, hi = self.feature_range[:, 0], self.feature_range[:, 1]
        atol = np.array([FEATURE_TOLERANCE[f] for f in FEATURES])
        reach = np.maximum(0.02 * (hi - lo), atol)
        out = (X < lo - reach) | (X > hi + reach)
        share = out.mean(axis=0)
        return {f: float(s) for f, s in zip(FEATURES, share, strict=True) if s > margin}

    def summary(self) -> dict[str, Any]:
        """The model's figures for a report (mm)."""
        rel = [v["relative_error"] for v in self.validation]
        return {
            "method": "HistGradientBoostingRegressor (scikit-learn), leave-one-part-out "
            "validation, split-conformal interval",
            "features": [*FEATURES, "material"],
            "materials": list(self.materials),
            "n_parts": self.n_parts,
            "n_points": self.n_points,
            "coverage": self.coverage,
            "interval_half_width_mm": self.half_width * 1e3,
            "median_relative_error": float(np.median(rel)) if rel else None,
            "validation": [
                {
                    **{k: v for k, v in row.items() if not k.endswith("_m")},
                    "rms_springback_mm": row["rms_springback_m"] * 1e3,
                    "rms_error_mm": row["rms_error_m"] * 1e3,
                }
                for row in self.validation
            ],
        }


def _fit(X: F64, y: F64, w: F64, n_features: int, seed: int) -> Any:
    ensemble = require_sklearn()
    cat = np.zeros(X.shape[1], dtype=bool)
    cat[n_features:] = True
    model = ensemble.HistGradientBoostingRegressor(
        categorical_features=cat, random_state=seed, **_PARAMS
    )
    with _one_thread():
        return model.fit(X, y, sample_weight=w)


def fit_springback(
    table: Any,
    *,
    coverage: float = 0.9,
    kinds: dict[int, str] | None = None,
    seed: int = 0,
) -> SpringbackLearner:
    """Fit the springback model on the history's per-point table (module docstring).

    table : :func:`roboisf.history.store.points_table` frame
    coverage : the interval's nominal coverage, in (0, 1)
    kinds : part id → part kind, for the validation rows (default: the table's ``part_kind``)
    """
    if not 0 < coverage < 1:
        raise InputError(f"must be in (0, 1), got {coverage}", field="coverage")
    X, y, pid, mat, ok = history_features(table)
    materials = tuple(sorted(set(mat)))
    code = np.array([materials.index(m) for m in mat], dtype=float)[:, None]
    Xm = np.hstack([X, code])[ok]
    y, pid = y[ok], pid[ok]
    parts = np.unique(pid)
    if len(parts) < 2:
        raise InputError(
            f"the history has {len(parts)} part(s) with measured springback; the model needs "
            "at least 2 (it is validated by leaving whole parts out)",
            field="--history",
        )
    counts = {p: int(np.sum(pid == p)) for p in parts}
    w = np.array([1.0 / counts[p] for p in pid])
    if kinds is None:
        kinds = {int(k): str(v) for k, v in table.groupby("part_id")["part_kind"].first().items()}
    F = X.shape[1]
    resid = np.empty(len(y))
    for p in parts:
        test = pid == p
        m = _fit(Xm[~test], y[~test], w[~test], F, seed)
        with _one_thread():
            resid[test] = y[test] - m.predict(Xm[test])
    n = len(resid)
    rank = min(n, math.ceil((n + 1) * coverage))
    half = float(np.sort(np.abs(resid))[rank - 1])
    validation = []
    for p in parts:
        test = pid == p
        rms = float(np.sqrt(np.mean(y[test] ** 2)))
        err = float(np.sqrt(np.mean(resid[test] ** 2)))
        validation.append(
            {
                "part_id": int(p),
                "part_kind": kinds.get(int(p), "?"),
                "n_points": int(test.sum()),
                "rms_springback_m": rms,
                "rms_error_m": err,
                "relative_error": err / rms if rms > 0 else math.inf,
                "coverage": float(np.mean(np.abs(resid[test]) <= half)),
            }
        )
    model = _fit(Xm, y, w, F, seed)
    rng = np.column_stack([Xm[:, :F].min(axis=0), Xm[:, :F].max(axis=0)])
    return SpringbackLearner(
        model,
        materials,
        half,
        coverage,
        validation,
        rng,
        n_points=n,
        n_parts=len(parts),
        residuals=resid,
    )
