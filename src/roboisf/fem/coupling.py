"""Loads on and rigid-motion fit over the coupling surface (a distributing coupling).

On the coupling surface S, with ``r(x) = x − O`` from the reference point O, a small rigid motion
``c = [p; φ]`` moves x by ``G(x) c`` with ``G = [I, −[r]×]`` (3×6). With the area moment matrix
``M = ∫_S Gᵀ G dA`` (6×6):

* **load**: a wrench ``w = [f; m]`` about O is applied as the traction ``t(x) = G(x) M⁻¹ w``,
  linear in position (uniform force plus a moment part ∝ the lever arm). Its resultant is
  ``∫ Gᵀ t dA = M M⁻¹ w = w`` — exact, and exact to rounding for the discrete quadrature too,
  because M is computed with the same surface quadrature and the P2 map is isoparametric.
* **fit**: the area-weighted least-squares rigid motion of a displacement field u on S is
  ``c = M⁻¹ ∫ Gᵀ u dA``.

Load and fit are each other's transpose, so the compliance ``C[:, j] = fit(K⁻¹ load(e_j))`` is
``Lᵀ K⁻¹ L`` — symmetric to rounding (Maxwell–Betti), which is what the tests check.
Everything is evaluated at the surface quadrature points of the curved tri6 facets: ``P`` maps
nodal displacements to the quadrature points, ``dA`` are the quadrature weights × area Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from roboisf.errors import ConvergenceError
from roboisf.fem.assembly import p2_tri_shape, tri_quadrature
from roboisf.frames import matrix_to_rotvec, skew

__all__ = ["SurfaceCoupling", "kabsch_fit"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class SurfaceCoupling:
    """The coupling surface discretised at its quadrature points.

    Attributes
    ----------
    x : (Q, 3) float, m — quadrature points
    dA : (Q,) float, m² — area weights
    P : (3Q, n_dofs) sparse — nodal displacement → displacement at the quadrature points
    M : (6, 6) float — ``∫ Gᵀ G dA`` about the reference point
    reference_point : (3,) float, m
    nodes : (n,) int — mesh nodes on the surface
    """

    x: F64
    dA: F64
    P: sp.csr_matrix
    M: F64
    reference_point: F64
    nodes: NDArray[np.int64]

    @classmethod
    def build(
        cls, points: F64, facets: NDArray[np.int64], reference_point: F64, *, order: int = 4
    ) -> SurfaceCoupling:
        """From mesh ``points`` (N, 3) m and tri6 ``facets`` (K, 6); quadrature degree ``order``."""
        xi, w = tri_quadrature(order)
        N, dN = p2_tri_shape(xi)  # (q, 6), (q, 6, 2)
        xf = points[facets]  # (K, 6, 3)
        x = np.einsum("qa,kai->kqi", N, xf)
        T = np.einsum("qab,kai->kqbi", dN, xf)  # tangents (K, q, 2, 3)
        jac = np.linalg.norm(np.cross(T[:, :, 0], T[:, :, 1]), axis=-1)
        dA = (jac * w[None, :]).ravel()
        x = x.reshape(-1, 3)
        Q = len(x)
        nq = len(w)
        # P[(3 q + i), (3 node + i)] = N_a(q)
        rows = (3 * np.arange(Q)[:, None, None] + np.arange(3)[None, None, :]).repeat(6, axis=1)
        cols = 3 * np.repeat(facets, nq, axis=0)[:, :, None] + np.arange(3)[None, None, :]
        vals = np.broadcast_to(np.tile(N, (len(facets), 1))[:, :, None], rows.shape)
        P = sp.csr_matrix(
            (vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * Q, 3 * len(points))
        )
        O = np.asarray(reference_point, dtype=float)
        G = cls._G(x - O)
        M = np.einsum("q,qia,qib->ab", dA, G, G)
        return cls(x, dA, P, M, O, np.unique(facets))

    @staticmethod
    def _G(r: F64) -> F64:
        G = np.zeros((len(r), 3, 6))
        G[:, :, :3] = np.eye(3)
        G[:, :, 3:] = -skew(r)
        return G

    @property
    def area(self) -> float:
        return float(self.dA.sum())

    @property
    def G(self) -> F64:
        """(Q, 3, 6) rigid-motion map at the quadrature points."""
        return self._G(self.x - self.reference_point)

    def loads(self, wrenches: F64) -> F64:
        """Consistent nodal load vectors (n_dofs, k) of the wrenches (6, k) [N, N·m] about O."""
        try:
            coef = np.linalg.solve(self.M, wrenches)  # (6, k)
        except np.linalg.LinAlgError:
            raise ConvergenceError(
                "the coupling surface cannot carry moments (its area moment matrix is singular)"
            ) from None
        t = np.einsum("qij,jk->qik", self.G, coef) * self.dA[:, None, None]  # (Q, 3, k)
        return np.asarray(self.P.T @ t.reshape(-1, t.shape[-1]))

    def resultant(self, F: F64, points: F64) -> F64:
        """Wrench (6, k) about O of nodal forces ``F`` (n_dofs, k) at ``points`` (N, 3)."""
        f = F.reshape(len(points), 3, -1)
        r = points - self.reference_point
        return np.concatenate([f.sum(axis=0), np.cross(r[:, :, None], f, axis=1).sum(axis=0)])

    def fit(self, U: F64) -> tuple[F64, F64]:
        """Area-weighted rigid motion of nodal displacements ``U`` (n_dofs, k).

        Returns ``(c, residual)``: c (6, k) = [p; φ] about O [m, rad]; residual (Q, 3, k) m at
        the quadrature points (the non-rigid part of the surface motion).
        """
        u = np.asarray(self.P @ U).reshape(len(self.x), 3, -1)
        G = self.G
        rhs = np.einsum("q,qia,qik->ak", self.dA, G, u)
        c = np.linalg.solve(self.M, rhs)
        residual = u - np.einsum("qia,ak->qik", G, c)
        return c, residual

    def fit_statistics(self, c: F64, residual: F64) -> dict[str, F64]:
        """Parameter-to-noise ratio and 95 % CIs of the fitted parameters, per load case.

        ``pnr = RMS(G c) / RMS(residual)`` (area-weighted RMS over S). The covariance treats the
        residual as noise of the weighted least-squares fit: ``cov = σ² (Σ ŵ Gᵀ G)⁻¹`` with weights
        ``ŵ = dA / mean(dA)`` and ``σ² = Σ ŵ |r|² / (3Q − 6)``; the residual of an FE field is
        model error, not random, so read the CIs as a measure of how rigidly S moves.
        """
        G = self.G
        fitted = np.einsum("qia,ak->qik", G, c)
        wsum = self.dA.sum()
        rms_fit = np.sqrt(np.einsum("q,qik->k", self.dA, fitted**2) / wsum)
        rms_res = np.sqrt(np.einsum("q,qik->k", self.dA, residual**2) / wsum)
        what = self.dA / self.dA.mean()
        Mw = np.einsum("q,qia,qib->ab", what, G, G)
        dof = max(3 * len(self.x) - 6, 1)
        sigma2 = np.einsum("q,qik->k", what, residual**2) / dof
        cov_unit = np.linalg.inv(Mw)
        half = 1.959963984540054 * np.sqrt(np.outer(np.diag(cov_unit), sigma2))  # (6, k)
        with np.errstate(divide="ignore"):
            pnr = np.where(rms_res > 0, rms_fit / np.where(rms_res > 0, rms_res, 1.0), np.inf)
        return {"pnr": pnr, "rms_fit": rms_fit, "rms_residual": rms_res, "ci95": half}


def kabsch_fit(points: F64, displacements: F64, reference_point: F64) -> F64:
    """Small rigid motion [p; φ] (6, k) about O fitted to node displacements by Procrustes.

    points : (n, 3) m; displacements : (n, 3, k) m. The displacement is scaled so the rotation is
    ~1e-6 rad, the SVD (Kabsch) rotation found, and the motion scaled back; every node weighs the
    same (the paper's fit), unlike :meth:`SurfaceCoupling.fit`.
    """
    X = points - reference_point
    size = np.ptp(points, axis=0).max()
    out = np.empty((6, displacements.shape[-1]))
    for k in range(displacements.shape[-1]):
        u = displacements[:, :, k]
        s = 1e-6 * size / max(np.abs(u).max(), 1e-300)
        Y = X + s * u
        xc, yc = X.mean(axis=0), Y.mean(axis=0)
        H = (X - xc).T @ (Y - yc)
        U_, _, Vt = np.linalg.svd(H)
        d = np.sign(np.linalg.det(Vt.T @ U_.T))
        R = Vt.T @ np.diag([1.0, 1.0, d]) @ U_.T
        t = yc - R @ xc  # motion of the reference point (origin of X)
        out[:3, k] = t / s
        out[3:, k] = matrix_to_rotvec(R) / s
    return out
