"""Vectorised stiffness assembly of isoparametric P2 tetrahedra (linear isotropic elasticity).

For a tet with physical basis gradients ``G[q, a, i] = ∂N_a/∂x_i`` at quadrature point q and
weights ``w_q |det J_q|``, the element matrix of isotropic elasticity is, per node pair (a, b) and
components (i, j)::

    K[a i, b j] = λ A[a i b j] + μ A[a j b i] + μ δ_ij Σ_k A[a k b k],   A = Σ_q w G_a,i G_b,j

so one ``einsum`` over (elements, quadrature points) gives every element matrix at once; the global
matrix is summed from COO triplets into CSR. DOF numbering: ``3 * node + component``.
:func:`assemble_stiffness_skfem` assembles the same matrix with scikit-fem's generic
``BilinearForm`` machinery (the reference the tests and the benchmark compare against).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from roboisf.errors import InputError
from roboisf.fem.mesh import TetMesh
from roboisf.progress import Progress, task

__all__ = [
    "assemble_stiffness",
    "assemble_stiffness_skfem",
    "p2_tet_gradients",
    "p2_tri_shape",
    "tet_quadrature",
    "tri_quadrature",
]

F64 = NDArray[np.float64]

# gmsh tet10 mid-edge node → its two vertices
TET_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [2, 3], [1, 3]])
TRI_EDGES = np.array([[0, 1], [1, 2], [0, 2]])


def tet_quadrature(order: int) -> tuple[F64, F64]:
    """Points (nq, 3) on the reference tet and weights (nq,) (sum 1/6), exact to ``order``."""
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTet

    X, W = get_quadrature(RefTet, order)
    return np.ascontiguousarray(X.T), np.asarray(W)


def tri_quadrature(order: int) -> tuple[F64, F64]:
    """Points (nq, 2) on the reference triangle and weights (nq,) (sum 1/2)."""
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTri

    X, W = get_quadrature(RefTri, order)
    return np.ascontiguousarray(X.T), np.asarray(W)


def p2_tet_gradients(xi: F64) -> F64:
    """Reference gradients of the 10 P2 shape functions at ``xi`` (nq, 3) → (nq, 10, 3)."""
    xi = np.atleast_2d(xi)
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])  # barycentric (nq, 4)
    dL = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    out = np.empty((len(xi), 10, 3))
    out[:, :4] = (4.0 * L - 1.0)[:, :, None] * dL[None]
    a, b = TET_EDGES[:, 0], TET_EDGES[:, 1]
    out[:, 4:] = 4.0 * (L[:, a, None] * dL[b][None] + L[:, b, None] * dL[a][None])
    return out


def p2_tet_shape(xi: F64) -> F64:
    """Values of the 10 P2 shape functions at ``xi`` (nq, 3) → (nq, 10)."""
    xi = np.atleast_2d(xi)
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])
    return np.column_stack([L * (2 * L - 1), 4.0 * L[:, TET_EDGES[:, 0]] * L[:, TET_EDGES[:, 1]]])


def p2_tri_shape(xi: F64) -> tuple[F64, F64]:
    """Values (nq, 6) and reference gradients (nq, 6, 2) of the tri6 shape functions."""
    xi = np.atleast_2d(xi)
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])
    dL = np.array([[-1.0, -1.0], [1, 0], [0, 1]])
    N = np.column_stack([L * (2 * L - 1), 4.0 * L[:, TRI_EDGES[:, 0]] * L[:, TRI_EDGES[:, 1]]])
    dN = np.empty((len(xi), 6, 2))
    dN[:, :3] = (4.0 * L - 1.0)[:, :, None] * dL[None]
    a, b = TRI_EDGES[:, 0], TRI_EDGES[:, 1]
    dN[:, 3:] = 4.0 * (L[:, a, None] * dL[b][None] + L[:, b, None] * dL[a][None])
    return N, dN


def _lame_per_tet(mesh: TetMesh, lame: F64) -> tuple[F64, F64]:
    lame = np.atleast_2d(np.asarray(lame, dtype=float))
    if lame.shape[1] != 2 or mesh.body.max() >= len(lame):
        raise InputError("one (λ, μ) pair is needed per body", field="materials")
    return lame[mesh.body, 0], lame[mesh.body, 1]


def assemble_stiffness(
    mesh: TetMesh,
    lame: F64,
    *,
    intorder: int = 2,
    chunk: int = 4000,
    progress: Progress | None = None,
) -> sp.csr_matrix:
    """Global stiffness (3N, 3N) CSR [N/m] of the P2 mesh.

    Parameters
    ----------
    mesh : TetMesh
    lame : (n_bodies, 2) float, Pa — (λ, μ) of each body
    intorder : int — degree of the tet quadrature (2 is exact for straight P2 tets)
    chunk : int — elements per vectorised batch (bounds the memory)

    Raises :class:`InputError` if an element is inverted (the mesh failed).
    """
    lam_e, mu_e = _lame_per_tet(mesh, lame)
    X, W = tet_quadrature(intorder)
    dN = p2_tet_gradients(X)  # (q, 10, 3)
    ne = len(mesh.tets)
    blocks = []
    with task(progress, "assemble", ne) as advance:
        for s in range(0, ne, chunk):
            t = mesh.tets[s : s + chunk]
            x = mesh.points[t]  # (e, 10, 3)
            J = np.einsum("eai,qaj->eqij", x, dN)  # ∂x_i/∂ξ_j
            det = np.linalg.det(J)
            if np.any(det <= 0):
                bad = int(np.count_nonzero(np.any(det <= 0, axis=1)))
                raise InputError(
                    f"the mesh has {bad} inverted or degenerate quadratic tetrahedra; "
                    "try a smaller mesh size",
                    field="mesh_size",
                )
            Jinv = np.linalg.inv(J)  # ∂ξ_j/∂x_i  as Jinv[e,q,j,i]
            G = np.einsum("qaj,eqji->eqai", dN, Jinv)  # (e, q, 10, 3)
            # A[e, (a i), (b j)] = Σ_q w_q det_q G[q, a, i] G[q, b, j]: one batched matmul
            Gf = G.reshape(len(t), len(W), 30)
            wd = (det * W[None, :])[:, :, None]
            A = np.matmul(Gf.transpose(0, 2, 1), Gf * wd).reshape(len(t), 10, 3, 10, 3)
            tr = np.einsum("eakbk->eab", A)
            lam = lam_e[s : s + chunk, None, None, None, None]
            mu = mu_e[s : s + chunk, None, None, None, None]
            Ke = lam * A + mu * A.transpose(0, 1, 4, 3, 2)
            Ke += mu * tr[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
            # node-pair blocks (e, a, b, i, j): 3×3 blocks summed at node level (9× fewer keys)
            blocks.append(Ke.transpose(0, 1, 3, 2, 4).reshape(-1, 3, 3))
            advance(len(t))
    return _sum_blocks(mesh.tets, np.concatenate(blocks), mesh.n_nodes)


def _sum_blocks(tets: NDArray[np.int64], blocks: F64, n_nodes: int) -> sp.csr_matrix:
    """Sum element 3×3 node blocks (e·10·10, 3, 3) into a CSR matrix (3N, 3N)."""
    keys = (tets[:, :, None] * n_nodes + tets[:, None, :]).ravel()
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    new = np.r_[True, keys[1:] != keys[:-1]]
    ukeys = keys[new]
    # scatter-sum as a sparse product: S[unique, entry] = 1
    S = sp.csr_matrix(
        (np.ones(len(keys)), (np.cumsum(new) - 1, order)), shape=(len(ukeys), len(keys))
    )
    data = np.asarray(S @ blocks.reshape(-1, 9)).reshape(-1, 3, 3)
    rows, cols = np.divmod(ukeys, n_nodes)
    indptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=n_nodes))]
    K = sp.bsr_matrix((data, cols, indptr), shape=(3 * n_nodes, 3 * n_nodes))
    return K.tocsr()


def to_skfem(mesh: TetMesh) -> tuple[Any, NDArray[np.int64]]:
    """The mesh as a scikit-fem ``MeshTet2`` plus, for each skfem P2 DOF node, our node index.

    Returns ``(m, node_of_skfem_dof)``; skfem numbers vertex nodes first, then edges.
    """
    from skfem import MeshTet2

    # skfem's importer takes meshio/VTK tet10 order: edges (0,1) (1,2) (0,2) (0,3) (1,3) (2,3)
    t = mesh.tets[:, [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]].T
    m = MeshTet2(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(t), sort_t=False)
    # match skfem doflocs to our points by position (exact copies of the same floats)
    from scipy.spatial import cKDTree

    d, idx = cKDTree(mesh.points).query(m.doflocs.T)
    if np.max(d) > 1e-12 * np.ptp(mesh.points):
        raise RuntimeError("skfem node relabelling did not preserve the node positions")
    return m, idx


def assemble_stiffness_skfem(mesh: TetMesh, lame: F64, *, intorder: int = 2) -> sp.csr_matrix:
    """Reference assembly with scikit-fem's generic ``BilinearForm``, returned in our DOF order."""
    from skfem import Basis, BilinearForm, ElementTetP2, ElementVector
    from skfem.helpers import ddot, sym_grad, trace

    lam_e, mu_e = _lame_per_tet(mesh, lame)
    m, node_of = to_skfem(mesh)
    basis = Basis(m, ElementVector(ElementTetP2()), intorder=intorder)

    @BilinearForm
    def elasticity(u: Any, v: Any, w: Any) -> Any:
        eu, ev = sym_grad(u), sym_grad(v)
        return 2.0 * w["mu"] * ddot(eu, ev) + w["lam"] * trace(eu) * trace(ev)

    nq = len(basis.W)
    Ks = elasticity.assemble(
        basis,
        lam=np.repeat(lam_e[:, None], nq, axis=1),
        mu=np.repeat(mu_e[:, None], nq, axis=1),
    ).tocsr()
    # skfem DOF → our DOF
    perm = np.empty(basis.N, dtype=np.int64)
    nodal = basis.nodal_dofs  # (3, n_vertices)
    perm[nodal.T.ravel()] = (3 * node_of[: nodal.shape[1], None] + np.arange(3)).ravel()
    edge = basis.edge_dofs  # (3, n_edges)
    perm[edge.T.ravel()] = (3 * node_of[nodal.shape[1] :, None] + np.arange(3)).ravel()
    P = sp.csr_matrix((np.ones(basis.N), (perm, np.arange(basis.N))), shape=(basis.N, basis.N))
    return (P @ Ks @ P.T).tocsr()
