"""Rotational symmetry of a nominal part about the work z axis: declared or detected.

A registration on the part's own surface cannot observe a turn that maps the part onto itself:
about a surface of revolution no rotation about z changes any distance (a *continuous*
symmetry: that rotation must be locked), and a square pyramid looks the same after 90° (a
*discrete* symmetry of order 4: the fit is well posed locally, but its answer is defined only
modulo 90°). :func:`part_symmetry` takes the symmetry from the part when the part knows it
(``part.symmetry.order != 1``, e.g. an analytic cone or pyramid) and otherwise detects it
numerically with :func:`detect_symmetry` — a mesh part declares none (order 1) because a
triangle list does not say.

Detection: points are spread over the part's bounding box and projected onto the surface with
``closest_point`` (their feet lie on the nominal surface); the feet on the wall (region 1: the
flange and the bottom are planes, symmetric under every turn, so they would prove nothing) are
turned about z by an angle θ and their distance to the surface is measured again. The part maps
onto itself under θ when the 90th percentile of those distances is within ``tolerance``
(default ``1e-3`` × the part's largest extent: a mesh maps onto itself only within its
facetting, e.g. 0.05 mm chordal error for :func:`roboisf.parts.tessellate`'s default). Three
generic turns (0.2, 1.0, 2.3 rad) all within tolerance → continuous; otherwise the largest
order n ≤ ``max_order`` whose 2π/n turn is within tolerance; otherwise none (order 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.frames.rotations import rot_z
from roboisf.parts.base import Part, Symmetry

__all__ = ["SymmetryEstimate", "detect_symmetry", "part_symmetry"]

F64 = NDArray[np.float64]

#: generic turns [rad] (no small-order symmetry maps a part onto itself under all three)
GENERIC_TURNS = (0.2, 1.0, 2.3)


@dataclass(frozen=True)
class SymmetryEstimate:
    """The rotational symmetry about work z used by a registration, and where it came from.

    Attributes
    ----------
    symmetry : Symmetry — order 0 continuous, n ≥ 2 discrete, 1 none
    source : ``"part"`` (declared by the part), ``"detected"`` (:func:`detect_symmetry`) or
        ``"given"`` (the caller's override)
    residuals : dict — detection only: turn label (``"0.2 rad"``, ``"2pi/4"``, …) → 90th
        percentile distance [m] of the turned surface samples to the surface
    tolerance : float, m — detection only (NaN otherwise)
    """

    symmetry: Symmetry
    source: str
    residuals: dict[str, float] = field(default_factory=dict)
    tolerance: float = math.nan

    @property
    def order(self) -> int:
        return self.symmetry.order

    def describe(self) -> str:
        """Human-readable one-liner (``"continuous, declared by the part"``)."""
        o = self.order
        kind = "continuous" if o == 0 else ("none" if o == 1 else f"{o}-fold")
        return f"{kind}, {self.how}"

    @property
    def how(self) -> str:
        """Where the symmetry came from, in words."""
        words = {"part": "declared by the part", "detected": "detected", "given": "given"}
        return words.get(self.source, self.source)


def _surface_samples(part: Part, n: int, seed: int) -> F64:
    lo, hi = (np.asarray(b, dtype=float) for b in part.bounds)
    ext = hi - lo
    if not (np.all(np.isfinite(ext)) and ext[:2].min() > 0):
        raise InputError(
            "the part's bounding box is empty or not finite; cannot detect its symmetry",
            field="part.bounds",
        )
    rng = np.random.default_rng(seed)
    pad = 0.05 * ext
    X = lo - pad + rng.random((n, 3)) * (ext + 2 * pad)
    q = part.closest_point(X)
    wall = q.region == 1
    feet = q.point[wall] if np.count_nonzero(wall) >= min(100, n // 4) else q.point
    return np.asarray(feet, dtype=float)


def detect_symmetry(
    part: Part,
    *,
    tolerance: float | None = None,
    n_samples: int = 2000,
    max_order: int = 12,
    seed: int = 0,
) -> SymmetryEstimate:
    """Detect the rotational symmetry of ``part`` about the work z axis (see the module doc).

    Parameters
    ----------
    part : Part
    tolerance : float, m, optional — largest 90th-percentile distance of the turned surface
        samples to the surface that still counts as "maps onto itself" (default ``1e-3`` × the
        largest extent of ``part.bounds``)
    n_samples : int — points spread over the bounding box (their wall feet are the samples)
    max_order : int — largest discrete order tested (2 … max_order)
    seed : int — random seed of the samples

    Returns
    -------
    SymmetryEstimate with ``source = "detected"``
    """
    if max_order < 2:
        raise InputError(f"must be ≥ 2, got {max_order}", field="max_order")
    lo, hi = (np.asarray(b, dtype=float) for b in part.bounds)
    size = float(np.max(hi - lo))
    tol = 1e-3 * size if tolerance is None else float(tolerance)
    if not (math.isfinite(tol) and tol > 0):
        raise InputError(f"must be > 0 m, got {tol!r}", field="tolerance")
    S = _surface_samples(part, n_samples, seed)

    def residual(theta: float) -> float:
        Sr = S @ rot_z(theta).T
        return float(np.quantile(np.abs(part.signed_distance(Sr)), 0.9))

    res: dict[str, float] = {}
    for th in GENERIC_TURNS:
        res[f"{th:g} rad"] = residual(th)
    if all(v <= tol for v in res.values()):
        return SymmetryEstimate(Symmetry(0), "detected", res, tol)
    order = 1
    for n in range(2, max_order + 1):
        r = residual(2.0 * math.pi / n)
        res[f"2pi/{n}"] = r
        if r <= tol:
            order = n
    return SymmetryEstimate(Symmetry(order), "detected", res, tol)


def part_symmetry(
    part: Part, *, symmetry: Symmetry | int | None = None, **detect: float | int | None
) -> SymmetryEstimate:
    """The symmetry to use for ``part``: the caller's ``symmetry`` if given, else the part's
    declared one if it declares one (order ≠ 1), else :func:`detect_symmetry` (``detect`` are
    its keyword arguments)."""
    if symmetry is not None:
        s = symmetry if isinstance(symmetry, Symmetry) else Symmetry(int(symmetry))
        if s.order < 0:
            raise InputError(f"symmetry order must be ≥ 0, got {s.order}", field="symmetry")
        return SymmetryEstimate(s, "given")
    declared = part.symmetry
    if declared.order != 1:
        return SymmetryEstimate(declared, "part")
    return detect_symmetry(part, **detect)  # type: ignore[arg-type]
