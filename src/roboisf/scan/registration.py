"""Registration of a scan to the nominal of any part: none, fixture, flange, axisymmetric, icp.

All methods minimise the robustly weighted sum of squared **signed point-to-surface distances**
``r_i = d(T·x_i)`` (the nominal's exact closest point, analytic or mesh) by Gauss–Newton on a
left perturbation ``T ← exp([v; ω]) T``::

    ∂r_i/∂v = n_i,    ∂r_i/∂ω = p_i × n_i          (p_i = T·x_i, n_i the nominal normal)

which is point-to-plane ICP with the nominal surface itself as the target (no correspondence
search). Weights: Huber (k = 1.345 σ, σ = 1.4826·MAD of the residuals); points farther than
``max_distance`` from the nominal get weight 0 (not part of the surface: fixture, clamps). Only
the :class:`~roboisf.parts.Part` interface is used (closest point with its region code, bounds,
symmetry), so every part kind registers the same way.

**Symmetry** (:mod:`roboisf.scan.symmetry`: declared by the part, or detected on a mesh).
A *continuous* symmetry about z (a surface of revolution, ``(p × n)_z ≡ 0``) makes the rotation
about z unobservable: it is **locked** and the result is kept a pure tilt (its rotation has no
twist about z, exactly: after each step the transform is left-multiplied by the rotation about
work z that removes the twist, which changes no distance). A *discrete* symmetry of order n (a
square pyramid: 4) leaves the fit well posed locally, but its answer is defined only modulo
2π/n: the rotation about z is searched over one period (coarse grid of ≤ 5°, then Gauss–Newton)
and the result is reported as the representative nearest to the identity, |rz| ≤ π/n (or to the
caller's ``rz_hint``), with the ambiguity stated. A part with no symmetry is searched over the
full turn. The x/y shift of a symmetric part *is* observable (it is where the axis sits) and is
fitted.

**Observability.** At every iteration each fitted coordinate's share of the normal matrix not
explained by the others (``ρ_k = √(S_k / max_j A_jj)``, S_k the Schur complement, columns of the
rotations scaled by the RMS lever arm so that all are in metres) is checked; a coordinate with
``ρ_k < min_observability`` (a flat plate's x, y and rotation about z) is locked and reported —
never left to drift. The result carries ρ of every coordinate, the condition number of the fitted
normal matrix and the standard errors of the fitted coordinates (σ² A⁻¹, σ the robust residual
scale).

Caveat (physics, not numerics): on a wall a uniform normal offset ``e`` of the formed part is
indistinguishable from a shift along the wall's mean normal (``e / cos α`` in z on a cone). A
registration on the wall absorbs such offsets. ``flange`` avoids it: the undeformed clamped sheet
(flange, z = 0, region 0 of the part's closest-point query) alone fixes z and the two tilts, the
wall only x, y (and the rotation about z when the part is not a surface of revolution), with a
uniform wall offset fitted alongside as a nuisance parameter so that it cannot move them. Use
``none`` when the scan is already in the work frame.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import ConvergenceError, InputError
from roboisf.frames.rotations import matrix_to_quat, matrix_to_rotvec, rot_z, rotvec_to_matrix
from roboisf.frames.se3 import make_transform, transform_points
from roboisf.parts.axisymmetric import SurfaceQuery
from roboisf.parts.base import Part, Symmetry
from roboisf.parts.mesh import MeshPart
from roboisf.scan.symmetry import SymmetryEstimate, part_symmetry

__all__ = ["DOF", "DOF_NAMES", "METHODS", "Registration", "register", "twist_about_z"]

F64 = NDArray[np.float64]

METHODS = ("none", "fixture", "flange", "axisymmetric", "icp")

#: the six coordinates of a registration, in the order of the Gauss–Newton step [v; ω]
DOF = ("x", "y", "z", "rx", "ry", "rz")
DOF_NAMES = {
    "x": "x shift",
    "y": "y shift",
    "z": "z shift",
    "rx": "tilt about x",
    "ry": "tilt about y",
    "rz": "rotation about z",
}

#: flange points must have flange all round them within this distance [m] (not the rim bend)
FLANGE_CLEARANCE = 2e-3
#: iteration after which the Huber scale is kept fixed
FREEZE_SCALE = 5


@dataclass(frozen=True)
class Registration:
    """Result of a registration.

    Attributes
    ----------
    T_work_scan : (4, 4) — maps scan coordinates into the work frame (``p_work = T · p_scan``)
    rms : float, m — RMS signed distance of the inliers after registration (points within
        ``max_distance`` and within 3 robust σ — 1.4826·MAD — of the median residual)
    overlap : float — fraction of the fitted points within ``max_distance`` of the nominal
    n_points : int — points used in the fit
    iterations : int
    method : one of :data:`METHODS`
    dof : int — number of coordinates fitted (0 … 6)
    fitted : tuple of str — the fitted coordinates (:data:`DOF` keys)
    locked : dict — locked coordinate → why (symmetry, fixture, not observable)
    symmetry : SymmetryEstimate or None — the part's symmetry about z and its source (None for
        ``none``)
    observability : dict — coordinate → ρ ∈ [0, 1]: the part of its column of the (lever-arm
        scaled) normal matrix not explained by the other fitted coordinates, relative to the
        strongest column (0: not determined by the scanned surface)
    condition : float — condition number of the fitted normal matrix (NaN for ``none``)
    std : dict — fitted coordinate → standard error (m for shifts, rad for rotations), from the
        robust residual scale and the normal matrix (independent noise assumed)
    """

    T_work_scan: F64
    rms: float
    overlap: float
    n_points: int
    iterations: int
    method: str
    dof: int
    fitted: tuple[str, ...] = ()
    locked: dict[str, str] = field(default_factory=dict)
    symmetry: SymmetryEstimate | None = None
    observability: dict[str, float] = field(default_factory=dict)
    condition: float = math.nan
    std: dict[str, float] = field(default_factory=dict)

    @property
    def translation(self) -> F64:
        """(3,) m — translation of ``T_work_scan``."""
        return self.T_work_scan[:3, 3].copy()

    @property
    def rotvec(self) -> F64:
        """(3,) rad — rotation vector of ``T_work_scan`` (z component 0 when rz is locked by a
        continuous symmetry)."""
        return matrix_to_rotvec(self.T_work_scan[:3, :3])

    @property
    def tilt(self) -> float:
        """rad — angle between the scan's z axis and the work z axis."""
        return float(math.acos(np.clip(self.T_work_scan[2, 2], -1.0, 1.0)))

    @property
    def rotation_about_z(self) -> float:
        """rad — twist of ``T_work_scan`` about work z (swing–twist decomposition), in (−π, π];
        for a discrete symmetry of order n the representative with |rz| ≤ π/n (or nearest to
        the hint)."""
        return twist_about_z(self.T_work_scan)

    @property
    def ambiguity(self) -> float | None:
        """rad — the rotation about z is defined only modulo this (2π/n for a discrete symmetry
        of order n); None when the answer is unique or the rotation is locked."""
        s = self.symmetry
        if s is None or s.order < 2 or "rz" not in self.fitted:
            return None
        return s.symmetry.angle

    def describe(self) -> str:
        """One line for a log: what was fitted, what was locked and why, the ambiguity."""
        parts = [f"{self.method}: {self.dof} DOF fitted ({', '.join(self.fitted) or '-'})"]
        # the locked ones grouped by their reason: a fixture registration's three said once
        by_reason: dict[str, list[str]] = {}
        for k, why in self.locked.items():
            by_reason.setdefault(why, []).append(DOF_NAMES[k])
        for why, names in by_reason.items():
            what = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
            parts.append(f"{what} locked: {why}")
        if self.ambiguity is not None:
            parts.append(
                f"rotation about z {math.degrees(self.rotation_about_z):.4f}°, defined only "
                f"modulo {math.degrees(self.ambiguity):g}° (symmetry {self.symmetry.describe()})"  # type: ignore[union-attr]
            )
        return "; ".join(parts)

    def to_dict(self) -> dict[str, object]:
        """JSON-friendly summary (mm, deg)."""
        sym = self.symmetry
        amb = self.ambiguity

        def unit(k: str, v: float) -> float:
            return float(v) * 1e3 if k in ("x", "y", "z") else math.degrees(float(v))

        return {
            "method": self.method,
            "dof": self.dof,
            "T_work_scan_mm": [[float(v) for v in row] for row in _to_mm(self.T_work_scan)],
            "translation_mm": [float(v) * 1e3 for v in self.translation],
            "rotation_vector_deg": [math.degrees(float(v)) for v in self.rotvec],
            "tilt_deg": math.degrees(self.tilt),
            "rotation_about_z_deg": math.degrees(self.rotation_about_z),
            "rms_mm": self.rms * 1e3,
            "overlap": self.overlap,
            "n_points": self.n_points,
            "iterations": self.iterations,
            "fitted": list(self.fitted),
            "locked": {k: v for k, v in self.locked.items()},
            "symmetry": None
            if sym is None
            else {
                "order": sym.order,
                "kind": "continuous"
                if sym.order == 0
                else ("none" if sym.order == 1 else "discrete"),
                "source": sym.source,
            },
            "ambiguity_deg": None if amb is None else math.degrees(amb),
            "observability": {k: float(v) for k, v in self.observability.items()},
            "condition_number": float(self.condition),
            "std_mm_deg": {k: unit(k, v) for k, v in self.std.items()},
            "summary": self.describe(),
        }


def _to_mm(T: F64) -> F64:
    out = T.copy()
    out[:3, 3] *= 1e3
    return out


def twist_about_z(T: ArrayLike) -> float:
    """Twist angle [rad] about work z of the rotation of ``T`` (4, 4) or ``R`` (3, 3): the γ of
    ``R = R_swing · Rz(γ)``-style swing–twist decomposition, in (−π, π]."""
    M = np.asarray(T, dtype=float)
    q = matrix_to_quat(M[:3, :3])  # (w, x, y, z), w ≥ 0; twist about z = normalise(w, 0, 0, z)
    return 2.0 * math.atan2(float(q[3]), float(q[0]))


def _huber_weights(r: F64, max_distance: float, sigma: float | None = None) -> tuple[F64, float]:
    """Huber weights (k = 1.345 σ) and σ (1.4826·MAD of the residuals within ``max_distance``,
    unless given); weight 0 beyond ``max_distance``."""
    inside = np.abs(r) <= max_distance
    if not inside.any():
        return np.zeros_like(r), math.inf
    if sigma is None:
        ri = r[inside]  # a copy: partitioned in place by the medians (the same values)
        med = np.median(ri, overwrite_input=True)
        sigma = 1.4826 * float(np.median(np.abs(ri - med), overwrite_input=True))
        sigma = max(sigma, 1e-7)  # 0.1 µm floor: a noise-free synthetic scan
    k = 1.345 * sigma
    a = np.abs(r)
    w = np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))
    return np.where(inside, w, 0.0), sigma


def _untwist(T: F64) -> F64:
    """Left-multiply by the rotation about work z that removes the rotation's twist about z."""
    return make_transform(rot_z(-twist_about_z(T))) @ T


#: Points per thread of :func:`_closest` (below two of these the query runs in one call).
_CHUNK = 32_768


def _closest(part: Part, P: F64) -> SurfaceQuery:
    """``part.closest_point(P)`` (P (N, 3) [m]), in chunks on every core for a part whose query
    is numpy (the analytic parts: elementwise, so the rows are the same numbers; numpy releases
    the GIL). A mesh part's compiled query runs on every core itself: called whole."""
    n = P.shape[0]
    nw = min(os.cpu_count() or 1, n // _CHUNK)
    if nw < 2 or isinstance(part, MeshPart):
        return part.closest_point(P)
    edges = np.linspace(0, n, nw + 1).astype(int)
    with ThreadPoolExecutor(max_workers=nw) as pool:
        parts = list(pool.map(lambda i: part.closest_point(P[edges[i] : edges[i + 1]]), range(nw)))
    cls = type(parts[0])
    return cls(*(np.concatenate([getattr(q, f.name) for q in parts]) for f in fields(cls)))


def _flange_points(part: Part, q: SurfaceQuery, w: F64) -> NDArray[np.bool_]:
    """Points whose foot is on the flange (region 0) and clear of the opening: probes
    ``FLANGE_CLEARANCE`` away in 8 horizontal directions must land on the flange at distance 0,
    or past its outer edge (their foot on the flange, farther from the z axis than the point's):
    not over the opening, not on the rim bend, whatever the opening's shape. The 8 probe sets
    are queried in one call (a part's query is per point: the same numbers as 8 calls)."""
    cand = np.flatnonzero((q.region == 0) & (w > 0))
    out = np.zeros(w.shape, dtype=bool)
    if cand.size == 0:
        return out
    m = cand.size
    F = q.point[cand]
    probes = np.empty((8, m, 3))
    for i, a in enumerate(np.arange(8) * (math.pi / 4)):
        d = np.array([math.cos(a), math.sin(a), 0.0]) * FLANGE_CLEARANCE
        np.add(F, d, out=probes[i])
    qq = _closest(part, probes.reshape(8 * m, 3))
    # a probe is good on the flange at distance 0, or on it past the point's distance from
    # the z axis (its foot's, compared only where that decides)
    on_flange = (qq.region == 0).reshape(8, m)
    good = on_flange & (np.abs(qq.distance) <= 1e-6).reshape(8, m)
    undecided = np.flatnonzero(on_flange & ~good)
    if undecided.size:
        rho = np.hypot(F[:, 0], F[:, 1])
        foot = qq.point[undecided]
        good.reshape(-1)[undecided] = np.hypot(foot[:, 0], foot[:, 1]) > rho[undecided % m] + 1e-9
    out[cand[good.all(axis=0)]] = True
    return out


def _observability(A: F64, cols: list[int], k: int) -> float:
    """ρ_k = √(S_k / max diag): Schur complement of coordinate ``k`` given ``cols``."""
    amax = float(np.max(np.diag(A)))
    if amax <= 0:
        return 0.0
    o = [c for c in cols if c != k]
    s = float(A[k, k])
    if o:
        Aoo = A[np.ix_(o, o)]
        s -= float(A[k, o] @ np.linalg.pinv(Aoo, rcond=1e-12, hermitian=True) @ A[o, k])
    return math.sqrt(max(s, 0.0) / amax)


def _search_rz(
    part: Part, X: F64, T: F64, period: float, centre: float, max_distance: float, seed: int
) -> F64:
    """Coarse search of the rotation about work z over one ``period`` centred on ``centre``
    [rad] (steps ≤ 5°): the candidate with the lowest truncated mean squared distance, unless it
    improves on the centre by less than 1 % (a flat part: keep the start). The candidates are
    queried in one call (a part's query is per point: the same numbers as one call each)."""
    rng = np.random.default_rng(seed)
    S = X if X.shape[0] <= 3000 else X[rng.choice(X.shape[0], 3000, replace=False)]
    n = max(4, math.ceil(period / math.radians(5.0)))
    offsets = (np.arange(n) - n // 2) * (period / n)
    base = make_transform(rot_z(centre - twist_about_z(T))) @ T
    Pc = np.concatenate(
        [transform_points(make_transform(rot_z(float(off))) @ base, S) for off in offsets]
    )
    D = part.signed_distance(Pc).reshape(n, S.shape[0])
    cost = np.empty(n)
    for i, d in enumerate(D):
        cost[i] = float(np.mean(np.minimum(d * d, max_distance**2)))
    best = int(np.argmin(cost))
    if cost[best] >= 0.99 * cost[n // 2]:
        best = n // 2
    return make_transform(rot_z(float(offsets[best]))) @ base


class _Equations:
    """One Gauss–Newton iteration's weighted normal equations, the rotation columns scaled by
    the RMS lever arm L (``scale`` = [1, 1, 1, L, L, L, 1]): every column in m. ``H`` and ``G``
    are formed when first asked for (the Newton steps after the scale is frozen, and the last
    iteration's uncertainty): most iterations need neither."""

    def __init__(self, A: F64, b: F64, quad: F64, scale: F64, Js: F64, wr: F64) -> None:
        self.A = A  # (7, 7) Jᵀ W J (IRLS)
        self.b = b  # (7,) Jᵀ ψ(r): the gradient of the Huber cost
        self.quad = quad  # (N,) 1 where the point is in Huber's quadratic zone
        self.scale = scale  # (7,)
        self._Js = Js  # (N, 7) the scaled Jacobian
        self._wr = wr  # (N,) ψ(r) = w·r

    @cached_property
    def H(self) -> F64:
        """(7, 7) Jᵀ 1{|r| ≤ k} J: the Huber cost's Hessian."""
        return self._Js.T @ (self._Js * self.quad[:, None])

    @cached_property
    def G(self) -> F64:
        """(7, 7) Σ ψ² J Jᵀ: the sandwich covariance's meat."""
        return self._Js.T @ (self._Js * (self._wr**2)[:, None])


def _checked_input(
    points: ArrayLike, method: str, T_init: ArrayLike | None, source: str | None
) -> tuple[F64, F64]:
    """The scan points (N, 3) [m] and the starting ``T_work_scan`` (4, 4), checked."""
    if method not in METHODS:
        raise InputError(
            f"unknown registration {method!r}; expected one of {', '.join(METHODS)}",
            field="register",
        )
    X = np.atleast_2d(np.asarray(points, dtype=float))
    if X.ndim != 2 or X.shape[1] != 3 or not np.all(np.isfinite(X)):
        raise InputError(
            f"scan points must be finite (N, 3) coordinates, got shape {X.shape}",
            file=source,
            field="points",
        )
    if T_init is not None:
        T0 = np.asarray(T_init, dtype=float)
        if T0.shape != (4, 4) or not np.all(np.isfinite(T0)):
            raise InputError("T_init must be a finite 4×4 transform", field="T_init")
    T = np.eye(4) if T_init is None else np.asarray(T_init, dtype=float).copy()
    return X, T


def _free_coordinates(
    part: Part, method: str, symmetry: Symmetry | int | None
) -> tuple[SymmetryEstimate | None, NDArray[np.bool_], dict[str, str]]:
    """The part's symmetry, the coordinates ``method`` fits (mask over :data:`DOF`) and why each
    other one is locked."""
    sym: SymmetryEstimate | None = None
    free = np.zeros(6, dtype=bool)
    locked: dict[str, str] = {}
    if method == "none":
        return sym, free, locked
    sym = part_symmetry(part, symmetry=symmetry)
    free[:] = True
    if method == "fixture":
        free[[0, 1, 5]] = False
        for name in ("x", "y", "rz"):
            locked[name] = "fixture registration: kept where the fixture puts the part"
    if sym.order == 0 and free[5]:
        free[5] = False
        locked["rz"] = f"continuous symmetry about z ({sym.how}): changes no distance"
    if method == "axisymmetric" and sym.order != 0:
        raise InputError(
            "the axisymmetric registration needs a part with a continuous symmetry about z; "
            f"this part's symmetry: {sym.describe()}; use icp or flange",
            field="register",
        )
    return sym, free, locked


def _jacobian(P: F64, q: SurfaceQuery) -> F64:
    """(N, 7) ∂r/∂[v; ω; e] at the points ``P`` (N, 3) [m] with their nominal feet ``q``; the
    nuisance column e is left 0. The gradient of the signed distance is (p − q)/r — the face
    normal on a face, the direction from the edge or vertex where the foot is one (a mesh's or a
    pyramid's edges: with the face normal there Gauss–Newton creeps instead of converging
    quadratically)."""
    r = q.distance
    off = np.abs(r) > 1e-9
    rs = np.where(off, r, 1.0)
    D = P - q.point
    # built column by column in a (7, N) array, transposed at the end: every column is
    # contiguous while it is computed (the same operations as on the (N, 3) arrays, without
    # numpy's broadcast over 3-long rows, nor writes 7 apart); J itself C-ordered, as the
    # normal equations' matrix products sum in its layout's order — g = (p − q)/r off the
    # surface, else the normal …
    Jt = np.zeros((7, P.shape[0]))
    on = ~off
    for c in range(3):
        np.divide(D[:, c], rs, out=Jt[c])
        np.copyto(Jt[c], q.normal[:, c], where=on)
    # … and p × g, as np.cross forms it: (p1 g2 − p2 g1, p2 g0 − p0 g2, p0 g1 − p1 g0)
    g = Jt[:3]
    tmp = np.empty(P.shape[0])
    for c, i, k in ((3, 1, 2), (4, 2, 0), (5, 0, 1)):
        np.multiply(P[:, i], g[k], out=Jt[c])
        np.multiply(P[:, k], g[i], out=tmp)
        Jt[c] -= tmp
    return np.ascontiguousarray(Jt.T)


def _flange_weights(
    method: str,
    q: SurfaceQuery,
    r: F64,
    w: F64,
    J: F64,
    flange_mask: NDArray[np.bool_],
    it: int,
    scales: dict[str, float],
    max_distance: float,
    where: str,
) -> tuple[F64, F64]:
    """Residuals and weights of the ``fixture`` and ``flange`` fits (``J`` edited in place).

    ``fixture``: the flange points alone. ``flange``: the flange fixes z and the tilts, the wall
    x, y and rz, each group with its own Huber scale, and a uniform wall offset e fitted as a
    nuisance (column 6); the wall's median offset is removed from its residuals first, so they
    stay noise-sized, in Huber's quadratic zone."""
    on_flange = flange_mask & (w > 0)
    if np.count_nonzero(on_flange) < 50:
        raise ConvergenceError(
            f"{method} registration{where}: only {np.count_nonzero(on_flange)} scan "
            "points on the flange; scan the clamped sheet around the part"
            + (", or use icp" if method == "flange" else "")
        )
    if method == "fixture":
        return r, np.where(on_flange, w, 0.0)
    on_wall = (q.region == 1) & (q.point[:, 2] <= -FLANGE_CLEARANCE) & (w > 0)
    r = r.copy()
    if on_wall.any():
        r[on_wall] -= np.median(r[on_wall], overwrite_input=True)  # of a copy
    w = np.zeros_like(r)
    for name, grp in (("flange", on_flange), ("wall", on_wall)):
        if grp.any():
            w[grp], sg = _huber_weights(r[grp], max_distance, scales.get(name))
            if it == FREEZE_SCALE:
                scales[name] = sg
    for c in (0, 1, 5):
        np.copyto(J[:, c], 0.0, where=on_flange)
    off_flange = ~on_flange
    for c in (2, 3, 4):
        np.copyto(J[:, c], 0.0, where=off_flange)
    J[~(on_flange | on_wall)] = 0.0
    J[on_wall, 6] = -1.0  # r_i − e
    return r, w


def _normal_equations(J: F64, P: F64, r: F64, w: F64) -> _Equations:
    """The iteration's normal equations. Rotation columns × 1/L (L = RMS lever arm): every
    column in m, so observability compares like with like (a column that vanishes, as rotation
    about the axis of a surface of revolution does, stays ~0 instead of being normalised up to
    1). Newton on the Huber cost once its scale is frozen uses H = Jᵀ·1{|r| ≤ k}·J (ψ' = 1 in the
    quadratic zone, 0 outside) instead of IRLS's Jᵀ·(ψ/r)·J, which converges only linearly when
    many points sit in the linear zone (a wall offset against the flange)."""
    L = math.sqrt(float(np.average(np.einsum("ij,ij->i", P, P), weights=w)))
    scale = np.array([1.0, 1.0, 1.0, L, L, L, 1.0])
    Js = J / scale
    A = Js.T @ (Js * w[:, None])
    wr = w * r
    b = Js.T @ wr
    quad = (w >= 1.0).astype(float)
    return _Equations(A, b, quad, scale, Js, wr)


def _lock_unobservable(
    A: F64,
    free: NDArray[np.bool_],
    nuisance: bool,
    locked: dict[str, str],
    min_observability: float,
) -> list[int]:
    """Lock (in ``free`` and ``locked``) what the surface does not determine, worst first, until
    the rest is well posed; returns the columns fitted (the nuisance column 6 included)."""
    while True:
        fit_cols = [int(k) for k in np.flatnonzero(free)] + ([6] if nuisance else [])
        rho = {k: _observability(A, fit_cols, k) for k in fit_cols if k < 6}
        if not rho:
            return fit_cols
        worst = min(rho, key=lambda k: rho[k])
        if rho[worst] >= min_observability:
            return fit_cols
        free[worst] = False
        locked[DOF[worst]] = (
            f"not determined by the scanned surface (observability {rho[worst]:.1e})"
        )


def _step(eq: _Equations, fit_cols: list[int], it: int) -> F64:
    """The Gauss–Newton step ξ (7,) [m, rad, m]: Newton on the frozen Huber cost when enough
    points are in its quadratic zone and H is well conditioned, IRLS otherwise."""
    newton = it > FREEZE_SCALE and np.count_nonzero(eq.quad) >= 10 * len(fit_cols)
    Hf = eq.H[np.ix_(fit_cols, fit_cols)] if newton else None
    if Hf is not None and np.linalg.cond(Hf) < 1e12:
        sol = -np.linalg.solve(Hf, eq.b[fit_cols])
    else:
        sol = -np.linalg.solve(eq.A[np.ix_(fit_cols, fit_cols)], eq.b[fit_cols])
    xi = np.zeros(7)
    xi[fit_cols] = sol
    xi[:6] /= eq.scale[:6]
    # a trust region: the step is shortened (its direction kept) to at most MAX_STEP_TRANSLATION
    # and MAX_STEP_ROTATION. The Newton step on the frozen Huber cost can be wild where points
    # change faces or the cost is flat along a direction: on the paper cone's scan ICP's
    # 6th step was 2 mm / 2° and its 7th 6 mm / 85°, and it never converged; on a square
    # pyramid 10 of 12 seeds diverged. Every step of the fixture, flange and ICP registrations
    # of the paper's two studies is below both limits (≤ 0.51 mm, ≤ 0.21°): unchanged.
    t, r = float(np.linalg.norm(xi[:3])), float(np.linalg.norm(xi[3:6]))
    shrink = min(1.0, MAX_STEP_TRANSLATION / max(t, 1e-300), MAX_STEP_ROTATION / max(r, 1e-300))
    if shrink < 1.0:
        xi *= shrink
    return xi


#: Largest translation [m] and rotation [rad] of one registration step (:func:`_step`).
MAX_STEP_TRANSLATION = 1e-3
MAX_STEP_ROTATION = math.radians(1.0)


def _fit_quality(
    part: Part,
    T: F64,
    X: F64,
    method: str,
    max_distance: float,
    min_overlap: float,
    where: str,
) -> tuple[float, float]:
    """Overlap (share of the points within ``max_distance`` of the nominal) and the RMS residual
    [m] of the inliers: within ``max_distance`` and within 3 robust σ of the median (stray points
    — 1 % of reflections a few mm off — would otherwise dominate the figure)."""
    P = transform_points(T, X)
    r = _closest(part, P).distance
    inside = np.abs(r) <= max_distance
    overlap = float(np.mean(inside))
    if method != "none" and overlap < min_overlap:
        raise ConvergenceError(
            f"{method} registration{where}: only {overlap:.1%} of the points lie within "
            f"{max_distance * 1e3:g} mm of the nominal after the fit (need {min_overlap:.0%})"
        )
    rms = math.inf
    if inside.any():
        ri = r[inside]
        med = float(np.median(ri))
        s_in = max(1.4826 * float(np.median(np.abs(ri - med))), 1e-9)
        core = ri[np.abs(ri - med) <= 3.0 * s_in]
        rms = float(np.sqrt(np.mean(core**2)))
    return overlap, rms


def _uncertainty(
    eq: _Equations, fit_cols: list[int]
) -> tuple[dict[str, float], float, dict[str, float]]:
    """Observability ρ of every coordinate, the condition number of the fitted normal matrix
    and the standard errors of the fitted coordinates [m, rad] from the robust (sandwich)
    covariance of the M-estimate, H⁻¹ (Σ ψ² J Jᵀ) H⁻¹."""
    obs: dict[str, float] = {}
    std: dict[str, float] = {}
    A = eq.A
    for k in range(6):
        obs[DOF[k]] = _observability(A, sorted(set(fit_cols) | {k}), k)
    Af = A[np.ix_(fit_cols, fit_cols)]
    ev = np.linalg.eigvalsh(Af)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
    Hf = eq.H[np.ix_(fit_cols, fit_cols)]
    Hi = np.linalg.pinv(Hf if np.linalg.cond(Hf) < 1e12 else Af, hermitian=True)
    cov = Hi @ eq.G[np.ix_(fit_cols, fit_cols)] @ Hi
    for i, c in enumerate(fit_cols):
        if c < 6:
            std[DOF[c]] = float(math.sqrt(max(cov[i, i], 0.0)) / eq.scale[c])
    return obs, cond, std


def register(
    points: ArrayLike,
    part: Part,
    method: str = "axisymmetric",
    *,
    T_init: ArrayLike | None = None,
    max_distance: float = 5e-3,
    max_points: int = 100_000,
    max_iterations: int = 50,
    tolerance: float = 1e-9,
    max_rotation: float = math.radians(5.0),
    min_overlap: float = 0.5,
    seed: int = 0,
    source: str | None = None,
    symmetry: Symmetry | int | None = None,
    rz_hint: float | None = None,
    search_rz: bool = True,
    min_observability: float = 1e-3,
) -> Registration:
    """Register scan ``points`` (N, 3) [m, scanner frame] to the nominal ``part`` (any Part).

    Parameters
    ----------
    method : ``"none"`` (identity, only the quality figures), ``"fixture"`` (3 DOF: z and the
        two tilts from the flange points only; x, y and the rotation about z stay where the
        fixture puts them, so a uniform lateral deflection of the wall — a robot pushed
        sideways — is measured, not registered away), ``"flange"`` (z and the tilts from the
        flange points only; x, y — and the rotation about z unless the part is a surface of
        revolution — from the wall, with a uniform wall offset fitted as a nuisance: wall
        deviations cannot leak into z), ``"axisymmetric"`` (5 DOF from all points, rotation
        about z locked; needs a continuous symmetry) or ``"icp"`` (6 DOF point-to-plane on the
        part's own surface; the rotation about z locked for a continuous symmetry, searched and
        reported modulo 2π/n for a discrete one)
    T_init : (4, 4), optional — starting ``T_work_scan`` (default identity); the scan must
        start within a few mm and degrees of the nominal, except for the rotation about z of a
        part without continuous symmetry (searched)
    max_distance : float, m — points farther from the nominal are ignored (fixture, clamps)
    max_points : int — random subset used for the fit (the transform is then applied to all)
    tolerance : float — convergence on the step (m and rad)
    max_rotation : float, rad — ``icp`` sanity limit on the tilt: a larger tilt is refused
    min_overlap : float — refuse if fewer of the points end within ``max_distance``
    symmetry : Symmetry or int, optional — override the part's symmetry about z (order: 0
        continuous, n discrete, 1 none); default: declared by the part, else detected
        (:func:`roboisf.scan.symmetry.part_symmetry`)
    rz_hint : float, rad, optional — expected rotation about z: the search is centred on it and
        the representative modulo 2π/n nearest to it is returned (default: the rotation about
        z of ``T_init``, i.e. nearest to the identity when no ``T_init`` is given)
    search_rz : bool — coarse search of the rotation about z before Gauss–Newton
    min_observability : float — coordinates with ρ below this are locked and reported

    Raises
    ------
    InputError — unknown method; ``axisymmetric`` on a part without continuous symmetry.
    ConvergenceError — no convergence in ``max_iterations``, tilt beyond ``max_rotation``
        (``icp``), too little overlap, no flange in the scan (``fixture``, ``flange``).
    """
    X, T = _checked_input(points, method, T_init, source)
    if X.shape[0] > max_points:
        rng = np.random.default_rng(seed)
        X = X[rng.choice(X.shape[0], max_points, replace=False)]
    where = f" ({source})" if source else ""
    sym, free, locked = _free_coordinates(part, method, symmetry)
    nuisance = method == "flange"  # a uniform wall offset, fitted alongside, never applied
    period = 2.0 * math.pi / sym.order if sym is not None and sym.order >= 2 else 2.0 * math.pi
    centre = twist_about_z(T) if rz_hint is None else float(rz_hint)
    if free[5] and search_rz:
        T = _search_rz(part, X, T, period, centre, max_distance, seed)
    it = 0
    step_norm = math.inf
    converged = not free.any()
    flange_mask: NDArray[np.bool_] | None = None
    eq: _Equations | None = None
    fit_cols: list[int] = []
    scales: dict[str, float] = {}
    while not converged:
        if it >= max_iterations:
            raise ConvergenceError(
                f"{method} registration{where} did not converge in {max_iterations} iterations "
                f"(last step {step_norm:.3g}); start closer to the nominal (T_init) or crop "
                "the scan"
            )
        it += 1
        P = transform_points(T, X)
        q = _closest(part, P)
        r = q.distance
        # the robust scale is re-estimated for the first iterations, then frozen: the Huber
        # cost is then a fixed function, which the Newton steps minimise (a moving scale
        # moves the minimum)
        w, sigma = _huber_weights(r, max_distance, scales.get("all"))
        if it == FREEZE_SCALE:
            scales["all"] = sigma
        if np.count_nonzero(w) < 3 * int(free.sum()):
            raise ConvergenceError(
                f"{method} registration{where}: only {np.count_nonzero(w)} points within "
                f"{max_distance * 1e3:g} mm of the nominal; the scan does not overlap the part"
            )
        J = _jacobian(P, q)
        if method in ("fixture", "flange"):
            if flange_mask is None or it <= 3:  # then frozen: no point switches sides
                flange_mask = _flange_points(part, q, w)
            r, w = _flange_weights(method, q, r, w, J, flange_mask, it, scales, max_distance, where)
        eq = _normal_equations(J, P, r, w)
        fit_cols = _lock_unobservable(eq.A, free, nuisance, locked, min_observability)
        if not free.any():
            raise ConvergenceError(
                f"{method} registration{where}: no coordinate is determined by the scanned surface"
            )
        xi = _step(eq, fit_cols, it)
        T = make_transform(rotvec_to_matrix(xi[3:6]), xi[:3]) @ T
        if not free[5] and ((sym is not None and sym.order == 0) or method == "fixture"):
            T = _untwist(T)
        step_norm = float(np.linalg.norm(xi[:6]))
        converged = step_norm < tolerance
    if free[5] and sym is not None and sym.order >= 2:
        # the representative modulo 2π/n nearest to the hint (the part maps onto itself)
        k = round((twist_about_z(T) - centre) / period)
        T = make_transform(rot_z(-k * period)) @ T
    if method == "icp":
        tilt = float(math.acos(np.clip(T[2, 2], -1.0, 1.0)))
        if tilt > max_rotation:
            raise ConvergenceError(
                f"icp registration{where} tilted the scan by {math.degrees(tilt):.3g}°, more "
                f"than the limit of {math.degrees(max_rotation):.3g}°; the start pose is far "
                "off, or the scan does not show enough of the part"
            )
    overlap, rms = _fit_quality(part, T, X, method, max_distance, min_overlap, where)
    fitted = tuple(DOF[k] for k in range(6) if free[k])
    obs: dict[str, float] = {}
    std: dict[str, float] = {}
    cond = math.nan
    if fitted and eq is not None:
        obs, cond, std = _uncertainty(eq, fit_cols)
    return Registration(
        T,
        rms,
        overlap,
        int(X.shape[0]),
        it,
        method,
        len(fitted),
        fitted,
        locked,
        sym,
        obs,
        cond,
        std,
    )
