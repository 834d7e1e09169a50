"""MeshPart: exact closest points (vs brute force), orientation, STL vs analytic cone, TOML."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from mesh_oracle import brute_closest
from roboisf.errors import InputError
from roboisf.parts import Cone, MeshPart, load_part, mesh_kernel, tessellate
from roboisf.parts.mesh import point_triangle_distance2

needs_numba = pytest.mark.skipif(not mesh_kernel.HAVE_NUMBA, reason="numba not installed")
BACKENDS = [pytest.param("numba", marks=needs_numba), "numpy"]


def _brute(mesh: MeshPart, X: np.ndarray) -> np.ndarray:
    return brute_closest(mesh, X)[1]


def test_point_triangle_distance_matches_dense_sampling():
    rng = np.random.default_rng(3)
    for _ in range(6):
        a, b, c = rng.normal(size=(3, 3))
        # points around the triangle hit all 7 Voronoi regions
        X = rng.normal(size=(150, 3)) * 2.0
        d2, v, w = point_triangle_distance2(
            X, a, b - a, c - a, (b - a) @ (b - a), (b - a) @ (c - a), (c - a) @ (c - a)
        )
        u = np.linspace(0, 1, 201)
        U, V = np.meshgrid(u, u)
        keep = U + V <= 1
        S = a + U[keep][:, None] * (b - a) + V[keep][:, None] * (c - a)
        dense = ((X[:, None, :] - S[None]) ** 2).sum(-1).min(1)
        assert np.all(d2 <= dense + 1e-12)  # exact is never worse than any sample
        h = np.linalg.norm(b - a) / 200 + np.linalg.norm(c - a) / 200
        assert np.all(np.sqrt(dense) - np.sqrt(d2) <= h)
        # the barycentrics describe a point on the triangle at that distance
        assert np.all((v >= -1e-12) & (w >= -1e-12) & (v + w <= 1 + 1e-12))
        P = a + v[:, None] * (b - a) + w[:, None] * (c - a)
        np.testing.assert_allclose(((X - P) ** 2).sum(1), d2, rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("spread", [0.001, 0.02, 0.3])
def test_closest_faces_exact_vs_brute_force_on_cone_mesh(spread, backend):
    mesh = tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3)
    rng = np.random.default_rng(0)
    base = mesh.vertices[rng.integers(0, mesh.vertices.shape[0], 1000)]
    X = base + rng.normal(scale=spread, size=base.shape)
    _, d2, P = mesh.closest_faces(X, k=4, backend=backend)
    np.testing.assert_allclose(d2, _brute(mesh, X), rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(((X - P) ** 2).sum(1), d2, rtol=1e-9, atol=1e-18)


@pytest.mark.parametrize("backend", BACKENDS)
def test_closest_faces_exact_on_a_triangle_soup(backend):
    # badly shaped, intersecting, varied triangles: the bound must still hold
    rng = np.random.default_rng(1)
    V = rng.uniform(-1, 1, (600, 3)) * np.array([1.0, 1.0, 0.2])
    F = rng.integers(0, 600, (400, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    mesh = MeshPart(V, F)
    X = rng.uniform(-1.5, 1.5, (2000, 3))
    _, d2, _ = mesh.closest_faces(X, k=2, backend=backend)
    np.testing.assert_allclose(d2, _brute(mesh, X), rtol=1e-12, atol=1e-20)


def test_orientation_up_flips_down_facing_faces_and_signs_distance():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    down = MeshPart(V, np.array([[0, 2, 1]]))  # winding normal −z, flipped to +z
    q = down.closest_point([[0.2, 0.2, 0.5], [0.2, 0.2, -0.5]])
    np.testing.assert_allclose(q.normal[:, 2], [1.0, 1.0])
    np.testing.assert_allclose(q.distance, [0.5, -0.5])
    keep = MeshPart(V, np.array([[0, 2, 1]]), orient="winding")
    np.testing.assert_allclose(keep.closest_point([[0.2, 0.2, 0.5]]).distance, [-0.5])
    # a horizontal face at z = 0 is flange, below it bottom, tilted is wall
    assert q.region.tolist() == [0, 0]
    assert np.isnan(q.s).all()


def test_stl_cone_agrees_with_analytic_cone_within_chordal_error(tmp_path):
    cone = Cone()
    e = 0.05e-3
    mesh = tessellate(cone, chordal_error=e, edge=2e-3)
    stl = tmp_path / "cone.stl"
    trimesh.Trimesh(mesh.vertices * 1e3, mesh.faces, process=False).export(stl)
    toml = tmp_path / "cone_mesh.toml"
    toml.write_text('[part]\nkind = "mesh"\nfile = "cone.stl"\n')
    part = load_part(toml)
    assert isinstance(part, MeshPart) and part.n_faces == mesh.n_faces
    rng = np.random.default_rng(2)
    pts, nrm = cone.surface_grid(60, 120)
    inner = (pts[:, 2] < -1e-3) & (pts[:, 2] > -cone.depth + 1e-3)
    pts, nrm = pts[inner], nrm[inner]
    X = pts + nrm * rng.uniform(-2e-3, 2e-3, (pts.shape[0], 1))
    qa = cone.closest_point(X)
    qm = part.closest_point(X)
    diff = np.abs(qm.distance - qa.distance)
    assert diff.max() <= e * (1 + 1e-6)
    assert diff.max() > 0.2 * e  # the facets really are off the true surface (test can fail)
    np.testing.assert_allclose(np.degrees(qm.wall_angle).mean(), 71.0, atol=0.05)
    assert np.all(qm.region == 1)


def test_mesh_part_rejects_bad_input(tmp_path):
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    with pytest.raises(InputError, match="NaN"):
        MeshPart(np.where(V == 1, np.nan, V), np.array([[0, 1, 2]]))
    with pytest.raises(InputError, match="does not exist"):
        MeshPart(V, np.array([[0, 1, 3]]))
    with pytest.raises(InputError, match="non-zero area"):
        MeshPart(V, np.array([[0, 1, 1]]))
    with pytest.raises(InputError, match="generatrix"):
        _ = MeshPart(V, np.array([[0, 1, 2]])).generatrix
    toml = tmp_path / "m.toml"
    toml.write_text('[part]\nkind = "mesh"\nfile = "nope.stl"\n')
    with pytest.raises(InputError, match="not found") as ei:
        load_part(toml)
    assert "nope.stl" in str(ei.value)
    toml.write_text('[part]\nkind = "mesh"\nfile = "x.stl"\nflange_width = 10\n')
    with pytest.raises(InputError, match="flange_width"):
        load_part(toml)
    empty = tmp_path / "e.stl"
    empty.write_bytes(b"")
    toml.write_text('[part]\nkind = "mesh"\nfile = "e.stl"\n')
    with pytest.raises(InputError, match="empty"):
        load_part(toml)


def test_tessellate_facets_within_chordal_error():
    cone = Cone()
    for e in (0.5e-3, 0.05e-3):
        mesh = tessellate(cone, chordal_error=e)
        ix = mesh._index
        centroids = ix["a"] + (ix["ab"] + ix["ac"]) / 3
        d = np.abs(cone.closest_point(centroids).distance)
        assert d.max() <= e
        assert d.max() > 0.3 * e / 3  # centroid sits ~e/3..e off the circle
    assert math.isclose(np.abs(tessellate(cone).vertices[:, 2]).max(), cone.depth)


def test_spatial_order_is_a_permutation_and_results_do_not_depend_on_it():
    from roboisf.parts.mesh import spatial_order
    from roboisf.scan import point_deviations

    mesh = tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3)
    rng = np.random.default_rng(5)
    X = mesh.vertices[rng.integers(0, mesh.vertices.shape[0], 5000)] + rng.normal(
        scale=1e-3, size=(5000, 3)
    )
    o = spatial_order(X)
    assert np.array_equal(np.sort(o), np.arange(5000))
    dev = point_deviations(X, mesh, chunk=700)  # ordered, chunked, threaded
    q = mesh.closest_point(X)  # one plain call
    np.testing.assert_array_equal(dev.dn, q.distance)
    np.testing.assert_array_equal(dev.foot, q.point)


@needs_numba
def test_numba_and_numpy_backends_give_the_same_answers(monkeypatch):
    # near, far, far outside the grid, exactly on vertices; split over threads (small chunks)
    monkeypatch.setattr("roboisf.parts.mesh.NUMBA_CHUNK", 997)
    mesh = tessellate(Cone(), chordal_error=0.3e-3, edge=4e-3)
    rng = np.random.default_rng(7)
    base = mesh.vertices[rng.integers(0, mesh.vertices.shape[0], 6000)]
    scale = np.repeat([0.0, 1e-4, 2e-3, 3e-2, 1.0], 1200)[:, None]
    X = base + rng.normal(size=base.shape) * scale
    f1, d1, P1 = mesh.closest_faces(X, backend="numba")
    f2, d2, P2 = mesh.closest_faces(X, backend="numpy")
    same = f1 == f2
    assert same.mean() > 0.5  # ties (points nearest a shared vertex/edge) name either face
    np.testing.assert_array_equal(d1[same], d2[same])  # same arithmetic: bit-identical
    np.testing.assert_array_equal(P1[same], P2[same])
    np.testing.assert_allclose(d1, d2, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(P1, P2, rtol=0, atol=1e-12)
    q1 = mesh.closest_point(X, backend="numba")
    q2 = MeshPart(mesh.vertices, mesh.faces, backend="numpy").closest_point(X)
    np.testing.assert_allclose(np.abs(q1.distance), np.abs(q2.distance), rtol=1e-12, atol=1e-12)
    off = np.abs(q2.distance) > 1e-9  # off the surface the side is unambiguous
    np.testing.assert_array_equal(np.sign(q1.distance[off]), np.sign(q2.distance[off]))


def test_without_numba_the_c_form_serves_and_without_it_too_the_numpy_path(monkeypatch):
    from roboisf.jit import background, native

    monkeypatch.setattr(mesh_kernel, "HAVE_NUMBA", False)
    monkeypatch.setattr(background, "HAVE_NUMBA", False)  # numba not installed, as ready sees it
    mesh = tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3)
    assert "grid" in mesh._index  # the C form is built (pip install builds it): compiled
    monkeypatch.setattr(native, "_suspended", 1)  # and now no C form either
    mesh = tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3)
    assert "grid" not in mesh._index
    X = mesh.vertices[:300] + 1e-3
    np.testing.assert_array_equal(
        mesh.closest_faces(X)[1], mesh.closest_faces(X, backend="numpy")[1]
    )
    with pytest.raises(InputError, match=r"ROBOISF_NUMBA=0\) or does not import"):
        mesh.closest_faces(X, backend="numba")
    with pytest.raises(InputError, match="numba"):
        MeshPart(mesh.vertices, mesh.faces, backend="numba")


def test_mesh_query_rejects_bad_backend_and_nan_points():
    mesh = tessellate(Cone(), chordal_error=0.3e-3, edge=6e-3)
    with pytest.raises(InputError, match="backend must be"):
        mesh.closest_faces(mesh.vertices[:3], backend="cuda")
    with pytest.raises(InputError, match="backend must be"):
        MeshPart(mesh.vertices, mesh.faces, backend="fast")
    with pytest.raises(InputError, match="NaN"):
        mesh.closest_point([[0.0, np.nan, 0.0]])


def _numpy_morton_codes(X, bits=16):
    """The numpy Morton codes of ``spatial_order`` (its fallback), written out here."""
    from roboisf.parts.mesh_kernel import part1by2 as _part1by2

    lo = X.min(axis=0)
    span = float(np.max(X.max(axis=0) - lo)) or 1.0
    q = ((X - lo) * ((2**bits - 1) / span)).astype(np.uint64)
    code = _part1by2(q[:, 0]) | (_part1by2(q[:, 1]) << np.uint64(1))
    return code | (_part1by2(q[:, 2]) << np.uint64(2))


@needs_numba
@pytest.mark.parametrize("kind", ["random", "ties", "plane", "one", "two"])
def test_compiled_spatial_order_is_the_stable_sort_of_the_numpy_codes(kind):
    """The fused numba codes + radix sort give exactly ``argsort(codes, kind="stable")`` of the
    numpy codes: the same order as before wherever codes differ; ties keep the input order."""
    from roboisf.parts.mesh import in_spatial_order, spatial_order

    rng = np.random.default_rng(3)
    X = rng.normal(size=(30_000, 3)) * [0.2, 0.1, 0.05] + [0.5, -1.0, -0.02]
    if kind == "ties":  # many points share a 16-bit cell: coordinates on a 1e-3 lattice
        X = np.round(X, 3)
    elif kind == "plane":  # z constant: the z bits are all zero (radix passes skipped)
        X[:, 2] = 0.25
    elif kind == "one":
        X = X[:1]
    elif kind == "two":
        X = np.repeat(X[:1], 2, axis=0)
    o = spatial_order(X)
    assert o.dtype == np.int32  # below 2³¹ points: half the sort's index memory
    np.testing.assert_array_equal(o, np.argsort(_numpy_morton_codes(X), kind="stable"))
    # non-contiguous input (a column slice of a wider table) gives the same order
    W = np.hstack([X, X[:, :1]])[:, :3]
    np.testing.assert_array_equal(spatial_order(W), o)
    # the points themselves in that order: the int32 gather is numpy's take, bit for bit
    np.testing.assert_array_equal(in_spatial_order(W), X[o.astype(np.int64)])
    # and put back: the compiled scatter is the inverse of the gather
    np.testing.assert_array_equal(mesh_kernel.scatter_rows(in_spatial_order(X), o), X)


def test_points_in_spatial_order_on_the_numpy_path(monkeypatch):
    """A cold kernel cache: numpy's codes and argsort (int64), the same rows as compiled."""
    from roboisf.jit import background as jit_background
    from roboisf.jit import native
    from roboisf.parts.mesh import in_spatial_order, spatial_order

    X = np.random.default_rng(4).normal(size=(5000, 3))
    monkeypatch.setitem(jit_background._decided, "mesh", False)
    monkeypatch.setattr(native, "_suspended", 1)  # and no C form: the numpy path
    o = spatial_order(X)
    assert o.dtype == np.int64
    np.testing.assert_array_equal(o, np.argsort(_numpy_morton_codes(X), kind="stable"))
    np.testing.assert_array_equal(in_spatial_order(X), X[o])
