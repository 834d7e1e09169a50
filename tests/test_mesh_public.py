"""The closest-point engines on meshes other projects wrote (tests/data/mesh/README.md: trimesh's
test models, a triangle soup and a CAD part): the C form and the numba form give the same bits,
and both the brute-force minimum over every triangle (mesh_oracle); numpy's k-d tree search the
same faces' distances to rounding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mesh_oracle import brute_closest
from native_forms import c_library, numba_form
from roboisf.parts import MeshPart, mesh_kernel
from roboisf.parts.mesh import read_mesh

DATA = Path(__file__).parent / "data" / "mesh"


@pytest.mark.parametrize("name", ["trimesh_soup.stl", "trimesh_featuretype.stl"])
def test_closest_points_on_a_public_mesh_c_numba_numpy_and_brute_force(name: str) -> None:
    c_library(mesh_kernel)
    V, F = read_mesh(DATA / name, unit="mm")
    mesh = MeshPart(V, F)
    rng = np.random.default_rng(0)
    lo, hi = V.min(axis=0), V.max(axis=0)
    span = hi - lo
    # around and inside the part, and on it (its vertices nudged): every Voronoi region met
    X = np.vstack(
        [
            rng.uniform(lo - 0.2 * span, hi + 0.2 * span, (600, 3)),
            V[rng.integers(0, len(V), 200)] + rng.normal(0.0, 1e-3 * span.max(), (200, 3)),
        ]
    )
    got = mesh.closest_faces(X)
    with numba_form("roboisf.parts.mesh_kernel"):
        want = mesh.closest_faces(X, backend="numba")
    for a, b in zip(got, want, strict=True):
        assert np.array_equal(a, b)
    face, d2, _, _ = brute_closest(mesh, X)
    # the same minimum distance (a tie between two faces may name either: the same d²)
    np.testing.assert_array_equal(got[1], d2)
    assert np.mean(got[0] == face) > 0.99
    _, d2_np, _ = mesh.closest_faces(X, backend="numpy")
    np.testing.assert_allclose(np.sqrt(d2_np), np.sqrt(d2), rtol=0, atol=1e-12)
