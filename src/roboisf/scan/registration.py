"""Registration of a scan to the nominal: none, constrained axisymmetric (5 DOF), 6-DOF ICP.

All methods minimise the robustly weighted sum of squared **signed point-to-surface distances**
``r_i = d(T·x_i)`` (the nominal's exact closest point, analytic or mesh) by Gauss–Newton on a
left perturbation ``T ← exp([v; ω]) T``::

    ∂r_i/∂v = n_i,    ∂r_i/∂ω = p_i × n_i          (p_i = T·x_i, n_i the nominal normal)

which is point-to-plane ICP with the nominal surface itself as the target (no correspondence
search). Weights: Huber (k = 1.345 σ, σ = 1.4826·MAD of the residuals); points farther than
``max_distance`` from the nominal get weight 0 (not part of the surface: fixture, clamps).

Axisymmetric parts: rotation about the part axis does not change any distance (``(p × n)_z ≡ 0``
for a surface of revolution), so it is **locked**: 5 unknowns — the x, y, z shift and the two
tilts. The x/y shift *is* observable (it is where the axis sits) and must be fitted, otherwise
an off-centre part biases every deviation by ``±e·sin α`` around the circumference. After each
step the transform is brought back to a pure tilt (its rotation vector has no z component,
exactly) by left-multiplying with a rotation about the work z axis, which leaves every distance
unchanged. A free 6-DOF ICP on such a part is refused (the problem is singular), not allowed to
drift.

Caveat (physics, not numerics): on a cone wall a uniform normal offset ``e`` of the formed part
is indistinguishable from a z shift of ``e / cos α``. A registration on the wall absorbs such
offsets. ``flange`` avoids it: the undeformed clamped sheet (flange, z = 0) alone fixes z and the
two tilts, the wall only the x/y position of the axis (a rotationally uniform deviation does not
move the axis). Use ``none`` when the scan is already in the work frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import ConvergenceError, InputError
from roboisf.frames.rotations import matrix_to_quat, matrix_to_rotvec, rot_z, rotvec_to_matrix
from roboisf.frames.se3 import make_transform, transform_points
from roboisf.parts.axisymmetric import AxisymmetricPart
from roboisf.parts.mesh import MeshPart

__all__ = ["METHODS", "Registration", "register"]

F64 = NDArray[np.float64]

METHODS = ("none", "fixture", "flange", "axisymmetric", "icp")


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
    method : ``"none" | "axisymmetric" | "icp"``
    dof : int — 0, 5 or 6
    """

    T_work_scan: F64
    rms: float
    overlap: float
    n_points: int
    iterations: int
    method: str
    dof: int

    @property
    def translation(self) -> F64:
        """(3,) m — translation of ``T_work_scan``."""
        return self.T_work_scan[:3, 3].copy()

    @property
    def rotvec(self) -> F64:
        """(3,) rad — rotation vector of ``T_work_scan`` (z component 0 for axisymmetric)."""
        return matrix_to_rotvec(self.T_work_scan[:3, :3])

    @property
    def tilt(self) -> float:
        """rad — angle between the scan's z axis and the work z axis."""
        return float(math.acos(np.clip(self.T_work_scan[2, 2], -1.0, 1.0)))

    def to_dict(self) -> dict[str, object]:
        """JSON-friendly summary (mm, deg)."""
        return {
            "method": self.method,
            "dof": self.dof,
            "T_work_scan_mm": [[float(v) for v in row] for row in _to_mm(self.T_work_scan)],
            "translation_mm": [float(v) * 1e3 for v in self.translation],
            "rotation_vector_deg": [math.degrees(float(v)) for v in self.rotvec],
            "tilt_deg": math.degrees(self.tilt),
            "rms_mm": self.rms * 1e3,
            "overlap": self.overlap,
            "n_points": self.n_points,
            "iterations": self.iterations,
        }


def _to_mm(T: F64) -> F64:
    out = T.copy()
    out[:3, 3] *= 1e3
    return out


def _huber_weights(r: F64, max_distance: float) -> tuple[F64, float]:
    inside = np.abs(r) <= max_distance
    if not inside.any():
        return np.zeros_like(r), math.inf
    ri = r[inside]
    sigma = 1.4826 * float(np.median(np.abs(ri - np.median(ri))))
    sigma = max(sigma, 1e-7)  # 0.1 µm floor: a noise-free synthetic scan
    k = 1.345 * sigma
    a = np.abs(r)
    w = np.where(a <= k, 1.0, k / np.maximum(a, 1e-300))
    return np.where(inside, w, 0.0), sigma


def _untwist(T: F64) -> F64:
    """Left-multiply by the rotation about work z that removes the rotation's twist about z."""
    q = matrix_to_quat(T[:3, :3])  # (w, x, y, z); twist about z = normalise(w, 0, 0, z)
    gamma = 2.0 * math.atan2(float(q[3]), float(q[0]))
    return make_transform(rot_z(-gamma)) @ T


def register(
    points: ArrayLike,
    part: AxisymmetricPart | MeshPart,
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
) -> Registration:
    """Register scan ``points`` (N, 3) [m, scanner frame] to the nominal ``part``.

    Parameters
    ----------
    method : ``"none"`` (identity, only the quality figures), ``"fixture"`` (3 DOF: z and the
        two tilts from the flange points only; the axis stays where the fixture puts it, so a
        uniform lateral deflection of the wall — a robot pushed sideways — is measured, not
        registered away), ``"flange"`` (5 DOF like
        axisymmetric, but z and the tilts from the flange points only and the x/y shift from the
        wall: wall deviations cannot leak into z), ``"axisymmetric"`` (5 DOF: x, y, z shift and
        two tilts from all points; rotation about the part axis locked) or ``"icp"`` (6 DOF
        point-to-plane, for non-axisymmetric parts)
    T_init : (4, 4), optional — starting ``T_work_scan`` (default identity); the scan must
        start within a few mm and degrees of the nominal
    max_distance : float, m — points farther from the nominal are ignored (fixture, clamps)
    max_points : int — random subset used for the fit (the transform is then applied to all)
    tolerance : float — convergence on the step (m and rad)
    max_rotation : float, rad — ICP sanity limit: a larger rotation is refused
    min_overlap : float — refuse if fewer of the points end within ``max_distance``

    Raises
    ------
    ConvergenceError — no convergence in ``max_iterations``, singular problem (e.g. ``icp`` on an
        axisymmetric part), rotation beyond ``max_rotation``, or too little overlap.
    """
    if method not in METHODS:
        raise InputError(
            f"unknown registration {method!r}; expected one of {', '.join(METHODS)}",
            field="register",
        )
    X = np.atleast_2d(np.asarray(points, dtype=float))
    if X.shape[0] > max_points:
        rng = np.random.default_rng(seed)
        X = X[rng.choice(X.shape[0], max_points, replace=False)]
    T = np.eye(4) if T_init is None else np.asarray(T_init, dtype=float).copy()
    where = f" ({source})" if source else ""
    if method in ("axisymmetric", "flange", "fixture") and not isinstance(part, AxisymmetricPart):
        raise InputError(
            "axisymmetric registration needs an axisymmetric part; use icp", field="register"
        )
    dof = {"none": 0, "fixture": 3, "flange": 5, "axisymmetric": 5, "icp": 6}[method]
    it = 0
    step_norm = math.inf
    converged = dof == 0
    while not converged:
        if it >= max_iterations:
            raise ConvergenceError(
                f"{method} registration{where} did not converge in {max_iterations} iterations "
                f"(last step {step_norm:.3g}); start closer to the nominal (T_init) or crop "
                "the scan"
            )
        it += 1
        P = transform_points(T, X)
        q = part.closest_point(P)
        r = q.distance
        w, _ = _huber_weights(r, max_distance)
        if np.count_nonzero(w) < 3 * dof:
            raise ConvergenceError(
                f"{method} registration{where}: only {np.count_nonzero(w)} points within "
                f"{max_distance * 1e3:g} mm of the nominal; the scan does not overlap the part"
            )
        pxn = np.cross(P, q.normal)
        J = np.concatenate([q.normal, pxn], axis=1)
        if dof == 5:
            J = J[:, :5]
        if method == "fixture":
            assert isinstance(part, AxisymmetricPart)  # checked on entry
            r_foot = np.hypot(q.point[:, 0], q.point[:, 1])
            on_flange = (q.region == 0) & (w > 0) & (r_foot >= part.opening_radius + 2e-3)
            if np.count_nonzero(on_flange) < 50:
                raise ConvergenceError(
                    f"fixture registration{where}: only {np.count_nonzero(on_flange)} scan "
                    "points on the flange; scan the clamped sheet around the part"
                )
            w = np.where(on_flange, w, 0.0)
            J = J[:, 2:5]  # z shift, tilt about x, tilt about y
        if method == "flange":
            # z and the tilts from the flange only, x/y (the axis position) from the rest
            # 2 mm clear of the rim edge on both sides: the bend there is neither, and points
            # that switch sides between iterations would make the fit oscillate
            assert isinstance(part, AxisymmetricPart)  # checked on entry
            r_foot = np.hypot(q.point[:, 0], q.point[:, 1])
            on_flange = (q.region == 0) & (w > 0) & (r_foot >= part.opening_radius + 2e-3)
            on_wall = (q.region == 1) & (q.point[:, 2] <= -2e-3) & (w > 0)
            # the wall only locates the axis: remove its mean offset (which cannot move the axis,
            # by symmetry) so that its residuals are noise-sized and the Huber fit stays in its
            # quadratic zone (else IRLS degenerates to a slowly converging L1 fit)
            r = r.copy()
            r[on_wall] -= np.median(r[on_wall]) if on_wall.any() else 0.0
            w = np.zeros_like(r)
            for grp in (on_flange, on_wall):
                if grp.any():
                    w[grp] = _huber_weights(r[grp], max_distance)[0]
            if np.count_nonzero(on_flange) < 50:
                raise ConvergenceError(
                    f"flange registration{where}: only {np.count_nonzero(on_flange)} scan points "
                    "on the flange; scan the clamped sheet around the part, or use axisymmetric"
                )
            J[on_flange, :2] = 0.0
            J[~on_flange, 2:] = 0.0
            J[~(on_flange | on_wall)] = 0.0
        # rotation columns × 1/L (L = RMS lever arm): every column in m, so the conditioning
        # test compares like with like (a column that vanishes, as rotation about the axis of
        # a surface of revolution does, stays ~0 instead of being normalised up to 1)
        L = math.sqrt(float(np.average(np.einsum("ij,ij->i", P, P), weights=w)))
        scale = np.array([1.0, L, L]) if dof == 3 else np.array([1.0, 1.0, 1.0, L, L, L])[:dof]
        Js = J / scale
        A = Js.T @ (Js * w[:, None])
        b = Js.T @ (w * r)
        ev = np.linalg.eigvalsh(A)
        if ev[0] <= 1e-9 * ev[-1]:
            names = (
                ["z shift", "tilt about x", "tilt about y"]
                if dof == 3
                else [
                    "x shift",
                    "y shift",
                    "z shift",
                    "tilt about x",
                    "tilt about y",
                    "rotation about z",
                ][:dof]
            )
            null = np.linalg.eigh(A)[1][:, 0]
            worst = names[int(np.argmax(np.abs(null)))]
            hint = (
                " (an axisymmetric part: use the axisymmetric registration)"
                if worst == "rotation about z"
                else ""
            )
            raise ConvergenceError(
                f"{method} registration{where} is singular: the {worst} is not determined by "
                f"the scanned surface{hint}"
            )
        xi = -np.linalg.solve(A, b) / scale
        if dof == 3:
            xi = np.concatenate([[0.0, 0.0], xi, [0.0]])
        if dof == 5:
            xi = np.concatenate([xi, [0.0]])
        T = make_transform(rotvec_to_matrix(xi[3:]), xi[:3]) @ T
        if dof in (3, 5):
            T = _untwist(T)
        step_norm = float(np.linalg.norm(xi))
        converged = step_norm < tolerance
    if dof == 6:
        angle = float(np.linalg.norm(matrix_to_rotvec(T[:3, :3])))
        if angle > max_rotation:
            raise ConvergenceError(
                f"icp registration{where} rotated the scan by {math.degrees(angle):.3g}°, more "
                f"than the limit of {math.degrees(max_rotation):.3g}°; it slid along a symmetry "
                "of the part, or the start pose is far off"
            )
    P = transform_points(T, X)
    r = part.closest_point(P).distance
    inside = np.abs(r) <= max_distance
    overlap = float(np.mean(inside))
    if dof > 0 and overlap < min_overlap:
        raise ConvergenceError(
            f"{method} registration{where}: only {overlap:.1%} of the points lie within "
            f"{max_distance * 1e3:g} mm of the nominal after the fit (need {min_overlap:.0%})"
        )
    rms = math.inf
    if inside.any():
        # inliers: within max_distance and within 3 robust σ of the median (stray points
        # — 1 % of reflections a few mm off — would otherwise dominate the figure)
        ri = r[inside]
        med = float(np.median(ri))
        sigma = max(1.4826 * float(np.median(np.abs(ri - med))), 1e-9)
        core = ri[np.abs(ri - med) <= 3.0 * sigma]
        rms = float(np.sqrt(np.mean(core**2)))
    return Registration(T, rms, overlap, int(X.shape[0]), it, method, dof)
