"""The compiled mesh closest-point query (parts.mesh_kernel): the canonical answer at ties, and
the same answer whatever the search does (seeded or not, cell size, order, chunking).

The kernel's rule is: the triangle with the smallest point–triangle distance, computed with the
formula of :func:`point_triangle_distance2` (bit-identical arithmetic), the lowest index among
equal ones. A brute force over all triangles with ``argmin`` (first index of the minimum) is
therefore the exact expected answer, ties included.
"""

from __future__ import annotations

import numpy as np
import pytest

from mesh_oracle import brute_closest
from roboisf.parts import Cone, MeshPart, mesh_kernel, tessellate
from roboisf.parts.mesh import spatial_order

pytestmark = pytest.mark.skipif(not mesh_kernel.HAVE_NUMBA, reason="numba not installed")


def _kernel(mesh: MeshPart, X: np.ndarray, seed: bool) -> tuple[np.ndarray, ...]:
    ix = mesh._index
    origin, h, dims, start, items, bvh = ix["grid"]
    n = X.shape[0]
    face, d2, P = np.empty(n, dtype=np.int64), np.empty(n), np.empty((n, 3))
    tol2 = 1e-12 * (h * h + 4.0 * ix["rho_max"] ** 2)
    mesh_kernel.closest_grid(
        np.ascontiguousarray(X), origin, h, dims, start, items,
        ix["a"], ix["ab"], ix["ac"], ix["abab"], ix["abac"], ix["acac"], ix["bnd"], *bvh,
        tol2, seed, face, d2, P,
    )  # fmt: skip
    return face, d2, P


def _flat_grid(n: int = 12, step: float = 2e-3) -> MeshPart:
    """A regular planar grid (every interior vertex shared by 6 triangles: ties everywhere)."""
    u = np.arange(n) * step
    U, V = np.meshgrid(u, u, indexing="ij")
    verts = np.column_stack([U.ravel(), V.ravel(), np.zeros(U.size)])
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    q = (i * n + j).ravel()
    faces = np.concatenate([np.stack([q, q + n, q + 1], 1), np.stack([q + 1, q + n, q + n + 1], 1)])
    return MeshPart(verts, faces)


def _points(mesh: MeshPart, rng: np.random.Generator) -> np.ndarray:
    """On vertices, on edge midpoints, straight above vertices, near, far and outside."""
    V, F = mesh.vertices, mesh.faces
    lo, hi = mesh.bounds
    span = float(np.max(hi - lo))
    vi = rng.integers(0, V.shape[0], 300)
    fi = rng.integers(0, F.shape[0], 300)
    mid = 0.5 * (V[F[fi, 0]] + V[F[fi, 1]])
    above = V[vi] + np.array([0.0, 0.0, 1e-3])
    near = V[vi] + rng.normal(scale=1e-4 * span, size=(300, 3))
    mid_off = mid + rng.normal(scale=1e-2 * span, size=(300, 3))
    far = rng.uniform(lo - 0.5 * span, hi + 0.5 * span, (300, 3))
    return np.concatenate([V[vi], mid, above, near, mid_off, far, [hi + 3 * span]])


def _meshes() -> list[tuple[str, MeshPart]]:
    rng = np.random.default_rng(1)
    V = rng.uniform(-1, 1, (300, 3)) * np.array([0.05, 0.05, 0.01])
    F = rng.integers(0, 300, (250, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    # degenerate triangles: a repeated vertex (a segment) and three collinear vertices
    V = np.concatenate([V, [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]]])
    k = V.shape[0] - 3
    F = np.concatenate([F, [[k, k + 1, k + 1], [k, k + 1, k + 2], [k + 2, k, k + 1]]])
    return [
        ("cone", tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3)),
        ("flat grid", _flat_grid()),
        ("soup with degenerate triangles", MeshPart(V, F)),
    ]


@pytest.mark.parametrize("name,mesh", _meshes(), ids=lambda x: x if isinstance(x, str) else "")
def test_closest_faces_is_the_brute_force_minimum_with_the_lowest_index_at_ties(name, mesh):
    rng = np.random.default_rng(11)
    X = _points(mesh, rng)
    X = X[spatial_order(X)]  # the order point_deviations queries in (seeding is effective)
    fb, db, Pb, d2_all = brute_closest(mesh, X)
    assert np.mean(np.sum(d2_all == db[:, None], axis=1) > 1) > 0.1  # many exact ties
    f, d2, P = mesh.closest_faces(X)
    np.testing.assert_array_equal(f, fb)
    np.testing.assert_array_equal(d2, db)
    np.testing.assert_allclose(P, Pb, rtol=0, atol=1e-15)


@pytest.mark.parametrize("name,mesh", _meshes(), ids=lambda x: x if isinstance(x, str) else "")
def test_seeded_search_and_cell_size_and_order_do_not_change_the_answer(name, mesh, monkeypatch):
    rng = np.random.default_rng(12)
    X = _points(mesh, rng)
    X = X[spatial_order(X)]
    ref = _kernel(mesh, X, seed=False)  # every point searched on its own
    for got in (_kernel(mesh, X, seed=True), mesh.closest_faces(X)):
        for r, g in zip(ref, got, strict=True):
            np.testing.assert_array_equal(g, r)
    # other cell sizes (a different search), shuffled points, small chunks on threads
    monkeypatch.setattr("roboisf.parts.mesh.NUMBA_CHUNK", 97)
    perm = rng.permutation(X.shape[0])
    for cell_edges in (1.0, 2.0, 5.0):
        monkeypatch.setattr(mesh_kernel, "CELL_EDGES", cell_edges)
        other = MeshPart(mesh.vertices, mesh.faces)
        f, d2, P = other.closest_faces(X[perm])
        np.testing.assert_array_equal(f, ref[0][perm])
        np.testing.assert_array_equal(d2, ref[1][perm])
        np.testing.assert_array_equal(P, ref[2][perm])
