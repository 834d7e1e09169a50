"""Virtual Joint Model elastostatics along a path (the VJM of Bharti et al. 2024).

``k_c = J K_θ⁻¹ Jᵀ`` (eq. 4) and ``δ = k_c W`` (eq. 5) at the tool tip; frames: base or work
(same point — the tip — only the axes change). Tool and holder compliances join through the serial
assembly of :mod:`roboisf.frames.compliance`. Optionally the complementary (geometric) stiffness
of the loaded configuration: the equilibrium ``K_θ Δθ = J(q + Δθ)ᵀ W`` linearised as
``(K_θ − K_G) Δθ = Jᵀ W`` with ``K_G = ∂(J(q)ᵀ W)/∂θ``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roboisf.errors import InputError
from roboisf.frames import serial_assembly
from roboisf.progress import Progress
from roboisf.robot.kinematics import rotate_6, rotate_6x6, sweep
from roboisf.robot.model import RobotModel, _check_wrench

__all__ = [
    "ComplianceStats",
    "Contributions",
    "compliance_stats",
    "deflection_contributions",
    "geometric_stiffness",
    "loaded_deflection",
    "rotate_6",
    "rotate_6x6",
    "tip_compliance",
    "vjm_batch",
]

F64 = NDArray[np.float64]


def tip_compliance(
    model: RobotModel,
    q: ArrayLike,
    tool_parts: Sequence[tuple[ArrayLike, ArrayLike]] = (),
    *,
    T_base_work: ArrayLike | None = None,
) -> F64:
    """End-effector compliance at the tip: robot VJM + tool/holder parts (eq. 2), (N, 6, 6).

    ``tool_parts``: ``[(k_i, v_i), …]`` with ``k_i`` (6, 6) the compliance of a tool or holder at
    its reference point *i* in the **tip frame's axes** and ``v_i = tip − point_i`` (3,) m in the
    same axes (see :func:`roboisf.frames.serial_assembly`). Result in base axes, or in work axes
    when ``T_base_work`` is given.
    """
    qv = model.check_q(q)
    k = model.compliance(qv, check_limits=False)  # the fused, chunked VJM path
    if tool_parts:
        R_base_tip = model.fk(qv, check_limits=False)[:, :3, :3]
        k_tool_tip = serial_assembly(list(tool_parts))  # tip axes
        k = k + rotate_6x6(np.broadcast_to(k_tool_tip, k.shape), R_base_tip)
    if T_base_work is not None:
        R_work_base = np.asarray(T_base_work, dtype=float)[:3, :3].T
        k = rotate_6x6(k, R_work_base)
    return k


def geometric_stiffness(model: RobotModel, q: ArrayLike, wrench: ArrayLike) -> F64:
    """``K_G[n, i, j] = ∂(J_iᵀ W)/∂q_j`` (N, 6, 6) N·m/rad for a tip wrench fixed in the base frame.

    Joint j moves the axes and points distal to it: ``dz = z_j × z``, ``dp = z_j × (p − o_j)``.
    """
    qv = model.check_q(q, limits=False)
    W = _check_wrench(wrench, qv.shape[0])
    _R, p, z, o = sweep(model.chain, qv, model.T_flange_tip, want_axes=True)
    assert z is not None and o is not None
    f, m = W[:, :3], W[:, 3:]
    s = model.chain.sign
    K = np.zeros((qv.shape[0], 6, 6))
    for j in range(6):
        zj = z[:, j]
        dp = np.cross(zj, p - o[:, j])  # d p_tip / dθ_j
        for i in range(6):
            zi = z[:, i]
            ri = p - o[:, i]
            # τ_i = z_i·m + z_i·(r_i × f)
            if i > j:  # z_i and o_i move with joint j
                dz = np.cross(zj, zi)
                dr = np.cross(zj, ri)
            else:
                dz = np.zeros_like(zi)
                dr = dp
            dtau = (
                np.einsum("nk,nk->n", dz, m)
                + np.einsum("nk,nk->n", dz, np.cross(ri, f))
                + np.einsum("nk,nk->n", zi, np.cross(dr, f))
            )
            K[:, i, j] = s[i] * s[j] * dtau
    if model.chain.couple23 != 0.0:  # τ_q = Aᵀ τ, ∂/∂q = (∂/∂q') A, q' = A q (q'_3 = q_3 + c q_2)
        A = np.eye(6)
        A[2, 1] = model.chain.couple23
        K = A.T @ K @ A
    return K


def loaded_deflection(model: RobotModel, q: ArrayLike, wrench: ArrayLike) -> F64:
    """Deflection (N, 6) with the complementary stiffness: ``Δq = (K_θ − K_G)⁻¹ Jᵀ W``, ``J Δq``."""
    qv = model.check_q(q)
    W = _check_wrench(wrench, qv.shape[0])
    J = model.jacobian(qv)
    KG = geometric_stiffness(model, qv, W)
    A = np.diag(model.joint_stiffness)[None] - KG
    tau = np.einsum("nji,nj->ni", J, W)
    dq = np.linalg.solve(A, tau[..., None])[..., 0]
    return np.einsum("nij,nj->ni", J, dq)


_AXES = ("x", "y", "z", "rx", "ry", "rz")


@dataclass(frozen=True)
class ComplianceStats:
    """Statistics of each compliance component along a path (the paper reports k_11..k_66).

    mean, std, min, max : (6, 6) float — units per block as in the compliance
    n : int — number of path points
    """

    mean: F64
    std: F64
    min: F64
    max: F64
    n: int

    def diagonal_table(self) -> list[dict[str, float | str]]:
        """Rows ``{"component": "k_11", "mean": …, "std": …, "min": …, "max": …}``."""
        return [
            {
                "component": f"k_{i + 1}{i + 1}",
                "mean": float(self.mean[i, i]),
                "std": float(self.std[i, i]),
                "min": float(self.min[i, i]),
                "max": float(self.max[i, i]),
            }
            for i in range(6)
        ]


def compliance_stats(k: ArrayLike) -> ComplianceStats:
    """Per-component mean, std, min, max of compliances (N, 6, 6) along a path."""
    k = np.asarray(k, dtype=float)
    if k.ndim != 3 or k.shape[1:] != (6, 6) or k.shape[0] == 0:
        raise InputError(f"expected compliances of shape (N, 6, 6), got {k.shape}", field="k")
    return ComplianceStats(k.mean(0), k.std(0), k.min(0), k.max(0), k.shape[0])


@dataclass(frozen=True)
class Contributions:
    """Contribution of each wrench component to each deflection (the paper's Table 4).

    per_point : (N, 6, 6) — ``[n, i, j] = k[n, i, j] · W[n, j]``: deflection i caused by wrench
        component j (m or rad); summing over j gives the deflection.
    mean, mean_abs : (6, 6) — mean over the path (signed, absolute)
    """

    per_point: F64
    mean: F64
    mean_abs: F64

    @property
    def deflection(self) -> F64:
        """Total deflection (N, 6) = sum of the contributions."""
        return self.per_point.sum(axis=2)


def deflection_contributions(k: ArrayLike, wrench: ArrayLike) -> Contributions:
    """Split ``δ = k W`` into per-wrench-component parts; ``k`` (N, 6, 6), ``wrench`` (N, 6)."""
    k = np.asarray(k, dtype=float)
    if k.ndim != 3 or k.shape[1:] != (6, 6):
        raise InputError(f"expected compliances of shape (N, 6, 6), got {k.shape}", field="k")
    W = _check_wrench(wrench, k.shape[0])
    c = k * W[:, None, :]
    return Contributions(c, c.mean(0), np.abs(c).mean(0))


def vjm_batch(
    model: RobotModel,
    q: ArrayLike,
    wrench: ArrayLike,
    *,
    chunk: int = 4096,
    want_compliance: bool = True,
    check_limits: bool = True,
    backend: str | None = None,
    progress: Progress | None = None,
) -> tuple[F64 | None, F64]:
    """FK + Jacobian + ``k_c`` + ``δ`` for many poses, chunked to bound memory.

    Returns ``(k_c (N, 6, 6) or None, δ (N, 6))`` in the base frame; the same numbers as
    :meth:`RobotModel.compliance` / :meth:`RobotModel.deflection` (the same fused path,
    :mod:`roboisf.robot.vjm_kernel`). ``chunk``: poses per chunk of the numpy engine;
    ``backend`` overrides ``model.backend``.
    """
    qv = model.check_q(q, limits=check_limits)
    W = _check_wrench(wrench, qv.shape[0])
    r = model.vjm(
        qv, W, want_compliance=want_compliance, backend=backend, chunk=chunk, progress=progress
    )
    return r.k, r.d
