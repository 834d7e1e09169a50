"""Forming-force model of a cell (used by the virtual cell and by `plan`).

Axial force (tool axis) — **Aerens et al. (2010)** steady-state formula::

    F_z = 0.0716 · R_m · t^1.57 · d^0.41 · Δh^0.09 · α · cos α       [N; MPa, mm, mm, mm, deg]

(R_m tensile strength, t sheet thickness, d tool diameter, Δh step-down, α wall angle). It holds
once the force has settled; over the first millimetres it rises as ``1 − exp(−depth / rise_depth)``
(the paper's cone: "rises, then saturates").

Variable-wall-angle parts (VWACF): Aerens' formula is a constant-angle steady state and peaks at
α ≈ 49°, while the paper's VWACF force keeps growing with wall angle to ≈ 475 N and drops at
fracture. We model ``F_z = F_peak · sin α / sin α_f`` up to the fracture wall angle ``α_f`` and an
exponential drop after it (``mode="variable"``).

In-plane components are ratios of F_z: "radial" (pushing the tool into the part, along the
horizontal part of the wall normal — the radial direction on a surface of revolution, the wall's
own normal on a pyramid or freeform part) and tangential (friction, opposing the direction of
travel, horizontal and perpendicular to the former). The force acts at the contact point P, so
about the tool tip T the moment is ``(P − T) × F``.

The wrench is the one **the sheet exerts on the tool** (``F_z > 0``), at the tip, in work axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.path.toolpath import Toolpath

__all__ = ["ForceModel", "aerens_axial_force", "tip_wrench"]

F64 = NDArray[np.float64]


def aerens_axial_force(
    tensile_strength: float,
    thickness: float,
    tool_diameter: float,
    step_down: float,
    wall_angle: F64 | float,
) -> F64:
    """Aerens' steady axial force [N] (inputs SI: Pa, m, m, m, rad)."""
    a_deg = np.degrees(np.asarray(wall_angle, dtype=float))
    return (
        0.0716
        * (tensile_strength / 1e6)
        * (thickness * 1e3) ** 1.57
        * (tool_diameter * 1e3) ** 0.41
        * (step_down * 1e3) ** 0.09
        * a_deg
        * np.cos(np.radians(a_deg))
    )


@dataclass(frozen=True)
class ForceModel:
    """Parameters of the forming force (SI).

    Attributes
    ----------
    mode : "aerens" (constant wall angle) or "variable" (VWACF-type, rising to fracture)
    tensile_strength : Pa — AA1050 between O (≈76 MPa) and H14 (≈110 MPa); 90 MPa gives 492 N
        for the paper's cone, inside the 400–590 N the formula spans for this sheet.
    rise_depth : m — e-folding depth of the initial rise
    radial_ratio, tangential_ratio : in-plane components as fractions of F_z
    peak_force : N — ``variable`` mode: F_z at the fracture wall angle
    fracture_wall_angle : rad — ``variable`` mode: where the sheet fractures (78°: on the default
        VWACF with a Ø10 ball, 31 mm deep; the ball never touches that wall beyond ≈ 83.5°)
    fracture_drop_depth : m — e-folding depth of the force drop after fracture
    noise : N — standard deviation of white sensor noise (applied by the log writer)
    """

    mode: Literal["aerens", "variable"] = "aerens"
    tensile_strength: float = 90e6
    rise_depth: float = 4e-3
    radial_ratio: float = 0.28
    tangential_ratio: float = 0.10
    peak_force: float = 475.0
    fracture_wall_angle: float = math.radians(78.0)
    fracture_drop_depth: float = 0.5e-3
    noise: float = 2.0

    def __post_init__(self) -> None:
        for name in ("tensile_strength", "rise_depth", "peak_force", "fracture_drop_depth"):
            if not getattr(self, name) > 0:
                raise InputError("must be > 0", field=f"force.{name}")
        for name in ("radial_ratio", "tangential_ratio", "noise"):
            if not getattr(self, name) >= 0:
                raise InputError("must be ≥ 0", field=f"force.{name}")
        if self.mode not in ("aerens", "variable"):
            raise InputError("must be 'aerens' or 'variable'", field="force.mode")

    def axial(self, toolpath: Toolpath, thickness: float, step_down: float) -> F64:
        """F_z [N] per toolpath point (N,)."""
        depth = toolpath.depth
        rise = 1.0 - np.exp(-depth / self.rise_depth)
        a = toolpath.wall_angle
        if self.mode == "aerens":
            return (
                aerens_axial_force(
                    self.tensile_strength, thickness, 2 * toolpath.tool_radius, step_down, a
                )
                * rise
            )
        frac = self.fracture_depth(toolpath)
        fz = (
            self.peak_force
            * np.sin(np.minimum(a, self.fracture_wall_angle))
            / math.sin(self.fracture_wall_angle)
        )
        after = np.clip(depth - frac, 0.0, None)
        return fz * rise * np.exp(-after / self.fracture_drop_depth)

    def fracture_depth(self, toolpath: Toolpath) -> float:
        """Depth [m] where the wall angle first reaches ``fracture_wall_angle`` (inf if never)."""
        if self.mode != "variable":
            return math.inf
        hit = np.nonzero(toolpath.wall_angle >= self.fracture_wall_angle)[0]
        return float(toolpath.depth[hit[0]]) if hit.size else math.inf


def _outward(toolpath: Toolpath) -> F64:
    """(N, 2) unit horizontal direction out of the part at each contact point: minus the
    horizontal part of the tool-side wall normal (on any part the sheet pushes the tool back
    along it; on a surface of revolution it is the radial direction). Where the wall is flat
    (|n_xy| < 1e-6: bottom, flange) the radial direction from the z axis."""
    P = toolpath.contact
    radial = P[:, :2] / np.maximum(np.linalg.norm(P[:, :2], axis=1, keepdims=True), 1e-12)
    nxy = -toolpath.normal[:, :2]
    norm = np.linalg.norm(nxy, axis=1, keepdims=True)
    return np.where(norm > 1e-6, nxy / np.maximum(norm, 1e-300), radial)


def tip_wrench(toolpath: Toolpath, model: ForceModel, *, thickness: float, step_down: float) -> F64:
    """Wrench [f; m] (N, 6) the sheet exerts on the tool, about the tip, in work axes."""
    fz = model.axial(toolpath, thickness, step_down)
    P = toolpath.contact
    r_hat = _outward(toolpath)
    # direction of travel: ±φ̂, the sign taken per lap from its net angular travel (robust at the
    # step-down plunges, where the local path direction is vertical)
    phi_hat = np.stack([-r_hat[:, 1], r_hat[:, 0]], axis=1)
    step = np.gradient(toolpath.tip[:, :2], axis=0)
    turn = np.einsum("ij,ij->i", step, phi_hat)
    lap_turn = np.bincount(toolpath.lap, weights=turn, minlength=toolpath.n_laps)
    d = np.where(lap_turn[toolpath.lap] >= 0, 1.0, -1.0)[:, None] * phi_hat
    f = np.zeros((len(toolpath), 3))
    f[:, :2] = -model.radial_ratio * fz[:, None] * r_hat - model.tangential_ratio * fz[:, None] * d
    f[:, 2] = fz
    m = np.cross(P - toolpath.tip, f)
    return np.concatenate([f, m], axis=1)
