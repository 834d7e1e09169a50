"""P2 tetrahedron basis and the vectorised stiffness assembly against scikit-fem."""

import numpy as np
import pytest

from roboisf.fem import (
    STEEL,
    BallEndTool,
    HolderSection,
    Material,
    ToolHolder,
    ToolInHolder,
    assemble_stiffness,
    assemble_stiffness_skfem,
    mesh_geometry,
)
from roboisf.fem.assembly import p2_tet_gradients, p2_tet_shape, p2_tri_shape, tet_quadrature


def test_p2_shape_partition_of_unity_and_gradients():
    rng = np.random.default_rng(0)
    xi = rng.dirichlet(np.ones(4), size=20)[:, 1:]
    N = p2_tet_shape(xi)
    dN = p2_tet_gradients(xi)
    assert np.allclose(N.sum(axis=1), 1.0, atol=1e-14)
    assert np.allclose(dN.sum(axis=1), 0.0, atol=1e-13)
    eps = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = eps
        fd = (p2_tet_shape(xi + e) - p2_tet_shape(xi - e)) / (2 * eps)
        assert np.allclose(fd, dN[:, :, j], atol=1e-8)
    # nodal (Kronecker) property at gmsh's tet10 node positions
    nodes = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [0.5, 0, 0],
            [0.5, 0.5, 0],
            [0, 0.5, 0],
            [0, 0, 0.5],
            [0, 0.5, 0.5],
            [0.5, 0, 0.5],
        ],
        dtype=float,
    )
    assert np.allclose(p2_tet_shape(nodes), np.eye(10), atol=1e-14)
    tri = np.array([[0, 0], [1, 0], [0, 1], [0.5, 0], [0.5, 0.5], [0, 0.5]], dtype=float)
    Nt, dNt = p2_tri_shape(tri)
    assert np.allclose(Nt, np.eye(6), atol=1e-14)
    assert np.allclose(dNt.sum(axis=1), 0.0, atol=1e-13)


@pytest.fixture(scope="module")
def tool_mesh():
    return mesh_geometry(BallEndTool(10e-3, 30e-3), 3e-3)


@pytest.mark.parametrize("intorder", [2, 4])
def test_assembly_matches_skfem_generic_form(tool_mesh, intorder):
    lame = np.array([STEEL.lame])
    K = assemble_stiffness(tool_mesh, lame, intorder=intorder, chunk=500)
    Ks = assemble_stiffness_skfem(tool_mesh, lame, intorder=intorder)
    scale = abs(K).max()
    assert abs(K - Ks).max() / scale < 1e-12
    assert abs(K - K.T).max() / scale < 1e-14


def test_rigid_motions_are_the_null_space(tool_mesh):
    K = assemble_stiffness(tool_mesh, np.array([STEEL.lame]))
    x = tool_mesh.points
    rng = np.random.default_rng(1)
    p, phi = rng.normal(size=3), rng.normal(size=3) * 100
    u = p + np.cross(phi, x)
    f = K @ u.ravel()
    assert np.abs(f).max() < 1e-9 * abs(K).max() * np.abs(u).max()
    # and a uniform strain gives the right volume integral: Σ u·Ku = 2 · energy
    eps = 1e-4
    u = np.column_stack([eps * x[:, 0], np.zeros(len(x)), np.zeros(len(x))])
    lam, mu = STEEL.lame
    vol = _volume(tool_mesh)
    energy = 0.5 * (lam + 2 * mu) * eps**2 * vol
    assert np.isclose(0.5 * u.ravel() @ (K @ u.ravel()), energy, rtol=1e-10)


def _volume(mesh):
    X, W = tet_quadrature(2)
    dN = p2_tet_gradients(X)
    J = np.einsum("eai,qaj->eqij", mesh.points[mesh.tets], dN)
    return float((np.linalg.det(J) * W).sum())


def test_two_bodies_get_their_own_material():
    tool = BallEndTool(10e-3, 20e-3, material=Material(70e9, 0.33, "aluminium"))
    holder = ToolHolder((HolderSection(10e-3, 20e-3),))
    mesh = mesh_geometry(ToolInHolder(tool, holder), 4e-3)
    assert set(np.unique(mesh.body)) == {0, 1}
    lame = np.array([tool.material.lame, holder.material.lame])
    K = assemble_stiffness(mesh, lame)
    Ks = assemble_stiffness_skfem(mesh, lame)
    assert abs(K - Ks).max() / abs(K).max() < 1e-12
    # the tool (body 0) sits below the nose face at z = 20 mm
    zc = mesh.points[mesh.tets[:, :4]].mean(axis=1)[:, 2]
    assert np.all(zc[mesh.body == 0] < 20e-3) and np.all(zc[mesh.body == 1] > 20e-3)
