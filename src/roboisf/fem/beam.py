"""Timoshenko / Euler–Bernoulli model of a stepped (and tapered) shaft clamped at its top.

The shaft is a stack of slices along z, each in series with the next. A slice at height z of
length dz, bent, sheared, stretched and twisted by the wrench it carries, has the local compliance
``c(z) dz = diag(1/(κGA), 1/(κGA), 1/(EA), 1/(EI), 1/(EI), 1/(GJ)) dz`` about its own position;
moved to the reference point O (the origin, below the shaft) with
``J(v) = [[I, −[v]×], [0, I]]``, ``v = O − (0, 0, z)``, and summed (the paper's serial assembly)::

    k_O = ∫ J(v(z)) c(z) J(v(z))ᵀ dz

integrated with Gauss–Legendre over each segment (exact for uniform segments; tapers have
1/r⁴ stiffness and are integrated to ~1e-10 with 24 points). This gives the familiar cantilever
terms, e.g. for a uniform rod of length L from z = 0: ``k_xx = L³/(3EI) + L/(κGA)``,
``k_x,θy = −L²/(2EI)``, ``k_zz = L/(EA)``, ``k_θzθz = L/(GJ)``. Everything below the lowest
segment (the ball of a tool) is rigid. κ is Cowper's shear coefficient of a (hollow) circle.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.fem.geometry import BallEndTool, ShaftSegment, ToolHolder
from roboisf.fem.material import Material
from roboisf.frames import point_jacobian

__all__ = ["beam_compliance", "cowper_shear_coefficient", "holder_beam", "tool_beam"]

F64 = NDArray[np.float64]


def cowper_shear_coefficient(nu: float, ratio: F64 | float = 0.0) -> F64:
    """Cowper's κ of a hollow circular section, ``ratio = inner/outer`` diameter (0 = solid)."""
    m2 = np.asarray(ratio, dtype=float) ** 2
    return 6 * (1 + nu) * (1 + m2) ** 2 / ((7 + 6 * nu) * (1 + m2) ** 2 + (20 + 12 * nu) * m2)


def beam_compliance(
    segments: Sequence[ShaftSegment],
    material: Material,
    *,
    reference_point: F64 | None = None,
    shear: bool = True,
    n_gauss: int = 24,
) -> F64:
    """6×6 compliance [SI] at ``reference_point`` (default origin) of a shaft clamped at its top.

    segments : ShaftSegment list along z (m); the clamp is at the highest ``z1``.
    shear : False gives Euler–Bernoulli (no shear deformation).
    """
    if not segments:
        raise InputError("a shaft needs at least one segment", field="segments")
    O = np.zeros(3) if reference_point is None else np.asarray(reference_point, dtype=float)
    xg, wg = np.polynomial.legendre.leggauss(n_gauss)
    E, G, nu = material.E, material.G, material.nu
    k = np.zeros((6, 6))
    for s in segments:
        if not s.z1 > s.z0:
            raise InputError(f"segment from z={s.z0} to z={s.z1} m has no length", field="segments")
        z = 0.5 * (s.z1 - s.z0) * xg + 0.5 * (s.z1 + s.z0)
        w = 0.5 * (s.z1 - s.z0) * wg
        D = s.outer0 + (s.outer1 - s.outer0) * (z - s.z0) / (s.z1 - s.z0)
        Di = s.inner
        A = np.pi / 4 * (D**2 - Di**2)
        I = np.pi / 64 * (D**4 - Di**4)
        Jp = 2 * I
        kappa = cowper_shear_coefficient(nu, Di / D)
        c = np.zeros((len(z), 6, 6))
        if shear:
            c[:, 0, 0] = c[:, 1, 1] = 1.0 / (kappa * G * A)
        c[:, 2, 2] = 1.0 / (E * A)
        c[:, 3, 3] = c[:, 4, 4] = 1.0 / (E * I)
        c[:, 5, 5] = 1.0 / (G * Jp)
        v = O[None, :] - np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
        Jm = point_jacobian(v)
        k += np.einsum("n,nij,njk,nlk->il", w, Jm, c, Jm)
    return k


def tool_beam(tool: BallEndTool, *, shear: bool = True) -> F64:
    """Beam-model compliance of a ball-end tool at its tip (ball rigid, shaft from the centre)."""
    return beam_compliance(tool.segments(), tool.material, shear=shear)


def holder_beam(holder: ToolHolder, *, shear: bool = True) -> F64:
    """Beam-model compliance of a holder at the centre of its nose face."""
    return beam_compliance(holder.segments(), holder.material, shear=shear)
