"""Phenomenological springback model of the virtual cell.

Springback is the elastic recovery of the part when it is unclamped. A scan sees only its
component along the surface normal, so the virtual cell models exactly that: a normal
displacement ``s`` (m, positive towards the tool side, the direction the sheet recovers to) ::

    s(depth, α) = amplitude · (1 − exp(−depth / rise_depth)) · sin(α)^angle_exponent · taper

with ``taper`` fading it out over the last ``fracture_taper`` of depth before a fracture (the
paper's VWACF: "springback ... diminishes near the fracture area").

**Geometry rule** (``curvature_gain`` > 0, off by default): a tightly curved contour is stiffer
in its hoop direction and recovers less, so the field is multiplied by ::

    g(κ) = 1 − curvature_gain · tanh(max(κ, 0) · curvature_length)

with ``κ`` the contour's curvature in the sheet plane at the contact
(:func:`roboisf.toolpath.geometry.contour_curvature`, 1/m). With the defaults of the
``curvature_gain`` key (0.4, 15 mm) a cone's lap of radius 43 mm keeps 87 %, one of 8 mm 62 %,
a pyramid's flat wall 100 % and its 10 mm corner 64 %. It is the synthetic truth the learned
springback model (:mod:`roboisf.learn`) is checked against — a rule of the cell, not the
learner's form (docs/virtual-cell.md, "Springback that depends on geometry").

Tuning (see ``tests/test_virtual_models.py``): the paper's cone (71°) reports mean |δx| ≈ |δy| ≈
0.72 mm and mean |δz| ≈ 0.49 mm (R_m 1.132 mm). A purely normal field on a 71° wall gives
mean |δx| = (2/π) sin α · s and mean |δz| = cos α · s; ``amplitude = 1.33 mm`` lands at
|δx| ≈ |δy| ≈ 0.75, |δz| ≈ 0.40 mm, R_m ≈ 1.13 mm over the analysed wall (z < −20 mm) — the
z component cannot match 0.49 with a normal-only field (the paper's vectors include tangential
parts a scan cannot separate). For the VWACF (39 mm arc, fracture at 78°) an amplitude of
0.96 mm gives R_m ≈ 0.53 mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError

__all__ = ["SpringbackModel"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class SpringbackModel:
    """Normal springback field. Lengths in m, angles in rad."""

    amplitude: float = 1.33e-3
    rise_depth: float = 8e-3
    angle_exponent: float = 1.0
    fracture_depth: float = math.inf
    fracture_taper: float = 8e-3
    curvature_gain: float = 0.0
    curvature_length: float = 15e-3

    def __post_init__(self) -> None:
        if not (self.amplitude >= 0 and math.isfinite(self.amplitude)):
            raise InputError("must be ≥ 0 and finite", field="springback.amplitude")
        for name in ("rise_depth", "fracture_taper"):
            if not getattr(self, name) > 0:
                raise InputError("must be > 0", field=f"springback.{name}")
        if not (0 <= self.curvature_gain < 1):
            raise InputError("must be in [0, 1)", field="springback.curvature_gain")
        if not (self.curvature_length > 0 and math.isfinite(self.curvature_length)):
            raise InputError("must be > 0 and finite", field="springback.curvature_length")

    def normal(
        self, depth: ArrayLike, wall_angle: ArrayLike, curvature: ArrayLike | None = None
    ) -> F64:
        """Normal springback [m] (N,) at contact depth [m], wall angle [rad] and, for the
        geometry rule (``curvature_gain`` > 0, then required), the contour curvature [1/m]."""
        depth = np.asarray(depth, dtype=float)
        a = np.asarray(wall_angle, dtype=float)
        rise = 1.0 - np.exp(-depth / self.rise_depth)
        shape = np.sin(np.clip(a, 0.0, math.pi / 2)) ** self.angle_exponent
        taper = np.clip((self.fracture_depth - depth) / self.fracture_taper, 0.0, 1.0)
        s = self.amplitude * rise * shape * taper
        if self.curvature_gain > 0:
            if curvature is None:
                raise InputError(
                    "the geometry rule needs the contour curvature", field="springback.curvature"
                )
            k = np.clip(np.asarray(curvature, dtype=float), 0.0, None)
            s = s * (1.0 - self.curvature_gain * np.tanh(k * self.curvature_length))
        return np.asarray(s, dtype=float)
