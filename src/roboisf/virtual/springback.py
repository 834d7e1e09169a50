"""Phenomenological springback model of the virtual cell.

Springback is the elastic recovery of the part when it is unclamped. A scan sees only its
component along the surface normal, so the virtual cell models exactly that: a normal
displacement ``s`` (m, positive towards the tool side, the direction the sheet recovers to) ::

    s(depth, α) = amplitude · (1 − exp(−depth / rise_depth)) · sin(α)^angle_exponent · taper

with ``taper`` fading it out over the last ``fracture_taper`` of depth before a fracture (the
paper's VWACF: "springback ... diminishes near the fracture area").

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

    def __post_init__(self) -> None:
        if not (self.amplitude >= 0 and math.isfinite(self.amplitude)):
            raise InputError("must be ≥ 0 and finite", field="springback.amplitude")
        for name in ("rise_depth", "fracture_taper"):
            if not getattr(self, name) > 0:
                raise InputError("must be > 0", field=f"springback.{name}")

    def normal(self, depth: ArrayLike, wall_angle: ArrayLike) -> F64:
        """Normal springback [m] (N,) at contact depth [m] and wall angle [rad]."""
        depth = np.asarray(depth, dtype=float)
        a = np.asarray(wall_angle, dtype=float)
        rise = 1.0 - np.exp(-depth / self.rise_depth)
        shape = np.sin(np.clip(a, 0.0, math.pi / 2)) ** self.angle_exponent
        taper = np.clip((self.fracture_depth - depth) / self.fracture_taper, 0.0, 1.0)
        return self.amplitude * rise * shape * taper
