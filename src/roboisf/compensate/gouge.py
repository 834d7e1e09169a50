"""Gouge check: the compensated command never puts the ball deeper into the part than intended.

The rule, per toolpath point i (work frame, SI):

* ``C_i`` — the ball centre where it will be *while forming*: the commanded tip plus the predicted
  deflection under the forming load, plus ``R ẑ`` (a compliance pre-deflection puts the
  *unloaded* command inside the surface by design: the load brings it back);
* ``d_i`` — the signed distance of ``C_i`` from the nominal surface (+ on the tool side;
  ``part.closest_point``), so a ball exactly on the nominal has ``d_i = R``;
* ``e_i = max(0, −c_i)`` — the intended over-bend: the springback compensation's commanded
  normal offset ``c_i`` into the material (0 without springback compensation);
* **gouge** where ``d_i < R − e_i − tol``  (deeper than intended by more than ``tol``), or where
  ``e_i > max_overbend`` (an over-bend beyond what the user allows — a scan artefact fed back,
  a run-away iteration).

``tol`` defaults to 10 µm, ``max_overbend`` to 2 mm (the paper's largest springback is ≈ 1.1 mm
in-plane; 1.3 mm normal on the virtual cone).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError, short_indices
from roboisf.parts.base import Part

__all__ = ["GougeReport", "gouge_check"]

F64 = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class GougeReport:
    """Per point (N,): ``distance`` d_i [m], ``allowed`` R − e_i − tol [m], ``gouge`` flags."""

    distance: F64
    allowed: F64
    intended: F64
    gouge: NDArray[np.bool_]
    tool_radius: float
    tol: float
    max_overbend: float

    @property
    def indices(self) -> NDArray[np.int64]:
        return np.flatnonzero(self.gouge)

    @property
    def ok(self) -> bool:
        return not bool(self.gouge.any())

    def report(self) -> dict[str, object]:
        """JSON-able summary (mm)."""
        margin = self.distance - self.allowed
        return {
            "ok": self.ok,
            "rule": "distance of the loaded ball centre from the nominal >= R - intended "
            "over-bend - tol; intended over-bend <= max_overbend",
            "tool_radius_mm": self.tool_radius * 1e3,
            "tol_mm": self.tol * 1e3,
            "max_overbend_mm": self.max_overbend * 1e3,
            "min_margin_mm": float(margin.min()) * 1e3,
            "max_intended_overbend_mm": float(self.intended.max()) * 1e3,
            "gouge_indices": self.indices.tolist(),
        }

    def raise_if_gouging(self) -> None:
        """InputError naming the gouging indices (nothing must be written then)."""
        if self.ok:
            return
        idx = self.indices
        worst = int(idx[np.argmin((self.distance - self.allowed)[idx])])
        raise InputError(
            f"the compensated command gouges the part at {idx.size} points (indices "
            f"{short_indices(idx)}): at point {worst} the ball centre is "
            f"{self.distance[worst] * 1e3:.3f} mm from the nominal, allowed ≥ "
            f"{self.allowed[worst] * 1e3:.3f} mm (intended over-bend "
            f"{self.intended[worst] * 1e3:.3f} mm, limit {self.max_overbend * 1e3:.3f} mm); "
            "lower the gain, smooth more or raise the over-bend limit",
            field="gouge",
        )


def gouge_check(
    part: Part,
    tip: ArrayLike,
    tool_radius: float,
    *,
    deflection: ArrayLike | None = None,
    normal_offset: ArrayLike | None = None,
    tol: float = 10e-6,
    max_overbend: float = 2e-3,
) -> GougeReport:
    """Check commanded tips (N, 3) m against the nominal surface of ``part`` (module rule).

    ``deflection`` (N, 3) m — predicted tip deflection under load (default 0);
    ``normal_offset`` (N,) m — the intended commanded normal offset c_i (default 0).
    """
    p = np.asarray(tip, dtype=float)
    n = len(p)
    d = np.zeros((n, 3)) if deflection is None else np.asarray(deflection, dtype=float)
    c = np.zeros(n) if normal_offset is None else np.asarray(normal_offset, dtype=float)
    if p.shape != (n, 3) or d.shape != (n, 3) or c.shape != (n,):
        raise InputError("tip (N, 3), deflection (N, 3) and normal_offset (N,) expected")
    if not (tol >= 0 and max_overbend >= 0 and tool_radius > 0):
        raise InputError("tol and max_overbend must be ≥ 0, tool_radius > 0", field="gouge")
    centre = p + d
    centre[:, 2] += tool_radius
    dist = part.closest_point(centre).distance
    e = np.clip(-c, 0.0, None)
    allowed = tool_radius - e - tol
    bad = (dist < allowed) | (e > max_overbend)
    return GougeReport(dist, allowed, e, bad, float(tool_radius), float(tol), float(max_overbend))
